#!/usr/bin/env bash
# Build the C++ reference for benchmarks/ls_vs_reference.py: PackingGeneration by V. Baranau
# (public repository VasiliBaranov/packing-generation, MIT licence), 3D and 2D.
#
# Usage: benchmarks/build_packing_generation.sh SOURCE_DIR OUT_DIR
#
#   SOURCE_DIR  an unpacked copy of the repository (the folder holding _Release/ and PackingGeneration/),
#               e.g. a work tree exported from a mirror with `git --git-dir=... archive HEAD | tar -x -C DIR`
#   OUT_DIR     where the four executables go:
#                 PackingGeneration3d.exe           the code as published, 3D (timed)
#                 PackingGeneration2d.exe           the same with -DTWO_DIMENSIONAL (timed)
#                 PackingGeneration3d_counting.exe  3D, with the author's own (commented-out) per-step event-type
#                 PackingGeneration2d_counting.exe  counters switched on: prints "Collision occurrence count: K"
#                                                   after every step (used only to count collisions)
#
# Nothing of PackingGeneration is committed to jamflow: this script copies SOURCE_DIR into a temporary build
# folder (SOURCE_DIR itself is not modified), builds there with the shipped _Release makefile and its flags
# (g++ -O3 -funroll-loops -DNDEBUG -DBOOST_DISABLE_ASSERTS; boost and Eigen come with the source), and keeps
# only the executables.
#
# Why two builds per dimension: the published code has its event counters commented out (they cost a
# std::map update per event). The timed executables are built from the unmodified source; the counting
# executables differ only by the two uncommented statements
#   CompositeEventProcessor.cpp:       eventsStatistics[event.type]++;
#   LubachevsckyStillingerStep.cpp:    the loop printing "<type> occurrence count: <n>" per step.
# The dynamics is deterministic for a given generation.conf (seed) and packing.xyzd, so both executables
# follow the same trajectory; ls_vs_reference.py checks this by comparing the reduced pressure they print
# after every step, and takes CPU times from the timed one and collision counts from the counting one.
set -euo pipefail

if [[ $# -ne 2 ]]; then
    echo "usage: $0 SOURCE_DIR OUT_DIR" >&2
    exit 2
fi
src=$(cd "$1" && pwd)
mkdir -p "$2"
out=$(cd "$2" && pwd)
if [[ ! -f "$src/_Release/makefile" ]]; then
    echo "error: $src/_Release/makefile not found: SOURCE_DIR must be the packing-generation source folder" >&2
    exit 1
fi
jobs=${JOBS:-2}
work=$(mktemp -d "${TMPDIR:-/tmp}/packing-generation-build.XXXXXX")
trap 'rm -rf "$work"' EXIT

lsdir=PackingGeneration/Generation/PackingGenerators/LubachevsckyStillinger/Source

enable_counters() {
    local tree=$1
    sed -i 's|^\(\s*\)// eventsStatistics\[event.type\]++;|\1eventsStatistics[event.type]++;|' \
        "$tree/$lsdir/CompositeEventProcessor.cpp"
    # uncomment exactly the five-line loop that prints the event-type counts
    sed -i '/^\/\/        for (int i = 0; i < EVENT_TYPES_COUNT; i++)/,/^\/\/        }/ s|^//||' \
        "$tree/$lsdir/LubachevsckyStillingerStep.cpp"
    grep -q '^\s*eventsStatistics\[event.type\]++;' "$tree/$lsdir/CompositeEventProcessor.cpp"
    grep -q '^\s*printf("%s occurrence count' "$tree/$lsdir/LubachevsckyStillingerStep.cpp"
}

build() {
    local dims=$1
    local tree="$work/src$dims"
    cp -r "$src" "$tree"
    if [[ $dims == 2d ]]; then
        # the only switch between 2D and 3D (Core/Headers/Types.h)
        find "$tree/_Release" -name subdir.mk -exec sed -i 's/^\tg++ -D/\tg++ -DTWO_DIMENSIONAL -D/' {} +
        grep -rq TWO_DIMENSIONAL "$tree/_Release"
    fi
    # "all" explicitly: the generated makefile's first rule is a dependency file, not the executable
    (cd "$tree/_Release" && make clean > /dev/null && make -j"$jobs" all > "$work/build_$dims.log" 2>&1) || {
        tail -n 30 "$work/build_$dims.log" >&2
        exit 1
    }
    cp "$tree/_Release/PackingGeneration.exe" "$out/PackingGeneration$dims.exe"
    enable_counters "$tree"
    (cd "$tree/_Release" && make -j"$jobs" all >> "$work/build_$dims.log" 2>&1) || {
        tail -n 30 "$work/build_$dims.log" >&2
        exit 1
    }
    cp "$tree/_Release/PackingGeneration.exe" "$out/PackingGeneration${dims}_counting.exe"
    if cmp -s "$out/PackingGeneration$dims.exe" "$out/PackingGeneration${dims}_counting.exe"; then
        echo "error: the counting build of $dims did not recompile" >&2
        exit 1
    fi
    rm -rf "$tree"
}

build 3d
build 2d
ls -l "$out"/PackingGeneration*.exe
