# Helpers shared by the rules: scene validation, sample names, stage chain, target list,
# options, resources.
# Stage outputs live under results/<scene>/; rules only call the jamflow CLI.

# Scene validation comes first: the schema, reporting the most relevant error in one line
# that names the key (not the whole schema), then the orderings a JSON schema cannot
# state. snakemake's validate fills in the schema's defaults.
import functools
import math
import os
from pathlib import Path

import jsonschema
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

SCENE_SCHEMA = Path(workflow.basedir) / "workflow" / "schemas" / "config.schema.yaml"


def check_scene_schema():
    """Raise one line naming the key of the schema's most relevant error."""
    schema = yaml.safe_load(SCENE_SCHEMA.read_text())
    error = jsonschema.exceptions.best_match(jsonschema.Draft202012Validator(schema).iter_errors(config))
    if error is not None:
        where = ".".join(str(p) for p in error.absolute_path) or "top level"
        raise WorkflowError(f"Error validating config: {where}: {error.message}")


def check_scene_order():
    """Orderings the schema cannot state: increasing LS targets, non-empty fit windows."""
    targets = config.get("ls", {}).get("p_targets", [])
    if any(b <= a for a, b in zip(targets, targets[1:])):
        raise WorkflowError(f"Error validating config: ls.p_targets must be strictly increasing, got {targets}")
    for section in ("jamming_table", "gaps"):
        window = config.get(section, {})
        if {"fit_min", "fit_max"} <= set(window) and not window["fit_min"] < window["fit_max"]:
            raise WorkflowError(f"Error validating config: {section}.fit_min ({window['fit_min']:g}) must be below "
                                f"{section}.fit_max ({window['fit_max']:g})")


check_scene_schema()
validate(config, str(SCENE_SCHEMA))
check_scene_order()


RESULTS = f"results/{config['scene']}"
LOGS = f"{RESULTS}/logs"
BENCH = f"{RESULTS}/benchmarks"
SOURCE_STAGE = "import" if "import" in config else "init"
CHAIN = [SOURCE_STAGE, *config.get("chain", [])]
FINAL = CHAIN[-1]
PRESET = config["preset"]
LS_TARGETS = config.get("ls", {}).get("p_targets", [])
LS_RATES = config.get("ls", {}).get("growth_rates", [])
WALLS = config.get("calippso", {}).get("walls", False)


def check_chain():
    """Stage orders the rules can build: LS compresses a random start and only CALiPPSO may follow it."""
    wanted = set(config.get("analyses", [])) | set(config.get("figures", []))
    needs_crunch = wanted & {"overlap", "jamming-table", "phi-j-series", "gaps-ls-vs-calippso"}
    if needs_crunch and CHAIN[-2:] != ["ls", "calippso"]:
        raise ValueError(f"{', '.join(sorted(needs_crunch))} need(s) the chain [ls, calippso]")
    if "eos" in wanted and "ls" not in CHAIN:
        raise ValueError("the eos figure needs ls in the chain")
    if wanted & {"overlap", "phi-j-series"} and len(LS_TARGETS) < 2:
        raise ValueError("overlap and phi-j-series compare packings from at least two LS p_targets")
    if WALLS and (SOURCE_STAGE != "init" or CHAIN[1:] != ["calippso"]):
        raise ValueError("calippso.walls needs the chain [calippso] from a random system (init --walls); "
                         "the other stages are periodic")
    if WALLS and (config.get("analyses") or set(config.get("figures", [])) - {"packing"}):
        raise ValueError("calippso.walls: the analyses and figures other than packing assume periodic "
                         "boundaries; set analyses: [] and figures: [packing]")
    if "decompress" in CHAIN and CHAIN[CHAIN.index("decompress") - 1] not in ("calippso", "soft"):
        raise ValueError("chain: decompress shrinks a jammed packing and must follow calippso or soft")
    if "ls" not in CHAIN:
        return
    if SOURCE_STAGE != "init" or CHAIN[1] != "ls":
        raise ValueError("chain: ls must come first and needs a random system (an LS snapshot is not a start)")
    if CHAIN[2:] not in ([], ["calippso"], ["calippso", "decompress"]):
        raise ValueError("chain: only calippso may follow ls (and decompress after it)")
    if "ls" not in config:
        raise ValueError("chain has ls but the scene has no 'ls' section with p_targets")
    if "flow" in config and len(LS_RATES) * len(LS_TARGETS) != 1:
        raise ValueError("flow needs one final packing per sample; a chain with ls gives one per (kappa, p_target): "
                         "give one growth rate and one p_target")


check_chain()


def variants():
    """Suffixes of a sample's final packings: one per (kappa, p_target) after LS, else one empty."""
    if "ls" not in CHAIN:
        return [""]
    return [ls_variant(k, p) for k in LS_RATES for p in LS_TARGETS]


def ls_variant(kappa, p_target):
    return f"_k{kappa:g}_p{p_target:g}"


def samples():
    """Sample names: seed<S> per seed of a random system, or the import keys (none for a tradeoff-only scene)."""
    if "import" in config:
        return sorted(config["import"])
    if "system" in config:
        return [f"seed{s}" for s in config["system"]["seeds"]]
    return []


def seed_of(wildcards):
    """Integer seed of a random-system sample."""
    return int(wildcards.sample.removeprefix("seed"))


def packing(sample, stage):
    """Path of a sample's packing after a stage."""
    return f"{RESULTS}/packings/{sample}/{stage}.nc"


def previous_stage(stage):
    """Input packing of a stage in this scene's chain, as an input function.

    After LS the wildcard ``variant`` (``_k<kappa>_p<p_target>``) names the snapshot.
    """

    def _input(wildcards):
        return packing(wildcards.sample, f"{CHAIN[CHAIN.index(stage) - 1]}{wildcards.get('variant', '')}")

    return _input


def final_packings(variant=None):
    """Final packings of every sample, of one variant or of all."""
    chosen = variants() if variant is None else [variant]
    return [packing(s, f"{FINAL}{v}") for s in samples() for v in chosen]


def rdf_files():
    return [f"{RESULTS}/analysis/{s}/rdf{v}.nc" for s in samples() for v in variants()]


def ls_snapshots(sample, kappa):
    """The LS run of one sample at one growth rate writes one snapshot per target pressure."""
    return [packing(sample, f"ls{ls_variant(float(kappa), p)}") for p in LS_TARGETS]


def overlap_series_files():
    return [f"{RESULTS}/analysis/{s}/overlap_k{k:g}.nc" for k in LS_RATES for s in samples()]


def eos_files():
    return [f"{RESULTS}/packings/{s}/ls_k{k:g}.eos.nc" for k in LS_RATES for s in samples()]


def flow_start(wildcards):
    """The packing every shear run of a sample starts from: its one final packing."""
    return packing(wildcards.sample, f"{FINAL}{variants()[0]}")


def shear_conditions():
    """Shear runs of the scene: ``fixed-volume`` or ``p<P>`` per fixed pressure P."""
    pressures = config.get("flow", {}).get("pressures", [])
    return [f"p{p:g}" for p in pressures] if pressures else ["fixed-volume"]


def pressure_option(condition):
    """The ``jamflow shear`` option of a shear condition."""
    return "" if condition == "fixed-volume" else optional_flag("--pressure", condition.removeprefix("p"))


def shear_summaries(condition=None):
    conditions = shear_conditions() if condition is None else [condition]
    return [
        f"{RESULTS}/analysis/{s}/shear_{c}_summary.nc" for c in conditions for s in samples()
    ]


def shear_labels():
    return " ".join(f"{s}:{c}" for c in shear_conditions() for s in samples())


def opt(section, key):
    """A stage parameter from the scene, with the schema default filled in."""
    return config.get(section, {})[key]


def variant_labels():
    """Legend labels of the variants, e.g. ``kappa=1e-05,p_tar=1000``."""
    if "ls" not in CHAIN:
        return [FINAL]
    return [f"kappa={k:g},p_tar={p:g}" for k in LS_RATES for p in LS_TARGETS]


def scene_targets():
    """Everything the scene asks for, and nothing else."""
    targets = final_packings()
    analyses = config.get("analyses", [])
    if "check" in analyses:
        targets += [f"{RESULTS}/analysis/{s}/{FINAL}{v}.check.json" for s in samples() for v in variants()]
    for kind in ("gaps", "forces"):
        if kind in analyses:
            targets += [f"{RESULTS}/analysis/{kind}{v}.nc" for v in variants()]
    if "rdf" in analyses:
        targets += rdf_files()
    if "certify" in analyses:
        targets += [f"{RESULTS}/analysis/{s}/certify{v}.nc" for s in samples() for v in variants()]
    if "overlap" in analyses:
        targets += overlap_series_files()
    if "jamming-table" in analyses:
        targets.append(f"{RESULTS}/analysis/jamming-table.nc")
    if "flow" in config:
        targets += shear_summaries()
    targets += chains_targets()  # workflow/rules/chains.smk
    for stage in config.get("tradeoff", {}).get("stages", []):
        targets += [f"{RESULTS}/tradeoff/{stage}.nc", f"{RESULTS}/figures/pareto_{stage}.png"]
    targets += shape_targets()
    for fig in config.get("figures", []):
        if fig == "packing":
            targets += [f"{RESULTS}/figures/packing_{s}{variants()[-1]}.png" for s in samples()]
        elif fig == "phi-kappa":
            targets += [
                f"{RESULTS}/figures/phi-kappa_{s}_{c}.png"
                for c in shear_conditions()
                if c != "fixed-volume"
                for s in samples()
            ]
        elif fig == "ed-vs-sd":
            targets += [f"{RESULTS}/figures/ed-vs-sd_{s}.png" for s in samples()]
        else:
            targets.append(f"{RESULTS}/figures/{fig}.png")
        if fig in ("gaps", "forces", "gaps-ls-vs-calippso"):
            # the exponent-against-window diagnostic goes with every fitted distribution
            targets.append(f"{RESULTS}/figures/{fig.removesuffix('-ls-vs-calippso')}-windows.png")
    return targets


wildcard_constraints:
    sample="[A-Za-z0-9-]+",
    variant="(_k[0-9.e+-]+_p[0-9.e+-]+)?",
    kappa="[0-9.e+-]+",
    condition="fixed-volume|p[0-9.e+-]+",


def optional_flag(flag, value):
    """``flag value``, or nothing when the scene leaves the value to the command's default."""
    return "" if value is None else f"{flag} {value}"


def read_flags(stage):
    """Reading options for a stage's packing: soft packings carry overlaps."""
    return "--soft" if stage == "soft" else ""


def stage_options(section, **flags):
    """The scene's options of a stage as command-line flags, as a params function.

    ``flags`` maps a key of the scene's ``section`` to its flag. A null value leaves the
    option to the command's default (or, given as ``(flag, value)``, passes ``value``);
    a boolean gives the bare flag when true. Evaluated per job, so a section the scene
    does not use is never read.
    """

    def _options(wildcards):
        parts = []
        for key, spec in flags.items():
            flag, if_null = spec if isinstance(spec, tuple) else (spec, None)
            value = opt(section, key)
            value = if_null if value is None else value
            if isinstance(value, bool):
                parts.append(flag if value else "")
            else:
                parts.append(optional_flag(flag, value))
        return " ".join(p for p in parts if p)

    return _options


# Requests per job: threads, mem_mb [MB] and runtime [min] from the scene (N, d), the
# stage and its protocol options, so that a scheduler gets honest requests and a long
# LS or CALiPPSO job is not killed at a flat default. Expected CPU times are fitted to
# runs on the 2-core development machine (docs/notes/resources.md gives the runs and
# numbers; CALiPPSO from docs/notes/calippso-scaling.md); a job asks for RUNTIME_SAFETY times
# its expectation, at least RUNTIME_FLOOR_MIN, and a retry (profile `retries`) asks for
# `attempt` times both runtime and memory.
RUNTIME_SAFETY = 5
RUNTIME_FLOOR_MIN = 10
#: every jamflow process holds ~0.25 GB (Python, numpy, xarray, numba, matplotlib)
MEM_FLOOR_MB = 1000
#: LS CPU seconds per sphere and per decade of pressure above the fast stage at
#: kappa = 1e-3 (cost ~ N / kappa per decade): 2D N = 1024 to p = 1e11 in 8.6 s, 3D
#: N = 1024 in 17 s; 5D bounded by the extremes suite's N = 1024 run, 4D in between
LS_SECONDS_PER_SPHERE = {2: 1e-3, 3: 2e-3, 4: 8e-3, 5: 3e-2}
#: overdamped flow, scaled as N^2 (events per strain ~N, each event re-solves the contact
#: network), an assumption, not a fit: compression of N = 100 2D discs from phi = 0.5 to
#: 0.83 took 75 CPU-s; shear of N = 1024 2D discs per unit strain 358 CPU-s at fixed
#: volume (phi = 0.83) and 1017 CPU-s at fixed pressure p = 100 (the flow-curve scene;
#: docs/notes/overdamped-profile.md, round 3), N = 100 at phi = 0.82 26 CPU-s (N^1.1 between
#: the two sizes, so N^2 errs on the long side)
COMPRESS_SECONDS = 75
SHEAR_SECONDS_PER_STRAIN = 1017
SHEAR_REFERENCE_N = 1024
FLOW_EXPONENT = 2
#: Threads per stage (default 1): the LS, FIRE and event-driven kernels are serial numba,
#: and `jamflow calippso --threads 2` took the same 7.7 CPU-s as 1 on the authors' 3D
#: N = 1024 LS packing (HiGHS's IPX and simplex are serial); the calippso rule passes its
#: threads to HiGHS, so raising this entry reaches the solver
STAGE_THREADS = {"calippso": 1}


def _dat_header(path):
    """(N, d) of a CALiPPSO .dat file: line 1 is d, line 2 is N."""
    if not os.path.isfile(path):
        raise ValueError(f"import: {path} not found")
    with open(path) as fh:
        d, n = int(fh.readline()), int(fh.readline())
    return n, d


@functools.cache
def scene_size():
    """(N, d) of the scene's packings: the system's, the largest import, or a small stand-in
    for a tradeoff-only scene (its sweeps choose their own inputs)."""
    if "system" in config:
        return config["system"]["n"], config["system"]["d"]
    if "shapes" in config:
        return config["shapes"]["n"], 2
    if "import" in config:
        sizes = [_dat_header(path) for path in config["import"].values()]
        return max(n for n, _ in sizes), max(d for _, d in sizes)
    return 64, 2


def _lp_size(n, d):
    """Size of a CALiPPSO/certificate LP in units of a 3D packing's: N times the growth of
    the constraint count with d, fitted to 5D N = 1024 (218 s) against 3D (4.9 s), whose
    cube root is 3.5; 4D interpolated geometrically, 2D taken as 3D."""
    return n * {2: 1.0, 3: 1.0, 4: 1.9, 5: 3.5}.get(d, 3.5 ** ((d - 3) / 2))


def expected_cpu_seconds(stage, wildcards):
    """Expected CPU time [s] of one job of ``stage`` in this scene (see docs/slurm.md)."""
    n, d = scene_size()
    if stage == "ls":
        kappa = float(wildcards.kappa)
        # the slow stage starts at the end of the fast one (p ~ 1 without a fast stage)
        slow_from = opt("ls", "fast_until") if opt("ls", "fast_growth_rate") else 1.0
        decades = math.log10(max(LS_TARGETS) / slow_from)
        return LS_SECONDS_PER_SPHERE[d] * n * (1 + max(decades, 0.0)) * (1e-3 / kappa)
    if stage == "calippso":
        # near starts (LS snapshots, imports): 694 s at N = 4096, ~N^3; a random start
        # (init) needs 44 times more LPs and time (216 s against 4.9 s at N = 1024)
        start = 44 if CHAIN[CHAIN.index("calippso") - 1] == "init" else 1
        return 694 * (_lp_size(n, d) / 4096) ** 3 * start
    if stage == "certify":
        # 3D N = 4096 from soft jamming: 1683 s, the collective LP by dual simplex
        return 1683 * (_lp_size(n, d) / 4096) ** 3
    if stage == "soft":
        # FIRE to P0 = 1e-8: 2D N = 1024 in 30 s, 3D N = 4096 in 1325 s
        return 1325 * (n / 4096) ** 2 * (d / 3) ** 2
    if stage == "compress":
        return COMPRESS_SECONDS * (n / 100) ** FLOW_EXPONENT
    if stage == "shear":
        return SHEAR_SECONDS_PER_STRAIN * opt("flow", "strain") * (n / SHEAR_REFERENCE_N) ** FLOW_EXPONENT
    if stage == "sd_shear":
        # lerner-fig6 (N = 100, 500 strain steps of 1e-4) takes about a minute: ~0.1 s
        # per strain step, each a steepest-descent minimisation whose length grows ~N
        return 0.1 * opt("flow", "strain") / opt("sd", "step") * (n / 100) ** 2
    if stage == "tradeoff":
        # all stages of a full sweep take about a quarter of an hour, quick ones a minute
        return 60 if opt("tradeoff", "quick") else 900
    # init, import, check, analyses and figures: seconds
    return 10 + 1e-3 * n


def extra_memory_mb(stage):
    """Memory [MB] a job of ``stage`` needs beyond the interpreter's."""
    n, d = scene_size()
    if stage in ("calippso", "certify"):
        # peak 0.27 GiB up to N = 1024, 0.59 GiB at 4096 and 3.4 GiB in the first LP at
        # 16384 (3D near starts): ~0.35 GB (N / 4096)^1.6 above the interpreter, doubled
        return 2 * 350 * (_lp_size(n, d) / 4096) ** 1.6
    # neighbour lists, contact networks and time series: linear in N, ~1 kB per sphere
    return 1e-3 * n * d


def job_threads(stage):
    """Threads of a job of ``stage``: one unless STAGE_THREADS says otherwise."""
    return STAGE_THREADS.get(stage, 1)


def job_resources(stage):
    """``mem_mb`` and ``runtime`` of a stage's jobs, for a rule's ``resources:``."""

    def mem_mb(wildcards, attempt):
        # whole 100 MB, so that requests read as round numbers
        return 100 * math.ceil((MEM_FLOOR_MB + extra_memory_mb(stage)) * attempt / 100)

    def runtime(wildcards, attempt):
        minutes = RUNTIME_SAFETY * expected_cpu_seconds(stage, wildcards) / 60
        return math.ceil(max(RUNTIME_FLOOR_MIN, minutes) * attempt)

    return {"mem_mb": mem_mb, "runtime": runtime}


# Light jobs run on the submitting host, not as cluster jobs: figures and summaries that
# read a few small analysis files.
localrules:
    all,
    import_dat,
    gaps,
    forces,
    ls_gaps,
    overlap_series,
    jamming_table,
    flow_summary,
    flow_curve,
    decompress,
    plot_packing,
    plot_gaps,
    plot_forces,
    plot_gap_windows,
    plot_force_windows,
    plot_rdf,
    plot_stress_strain,
    plot_phi_kappa,
    plot_flow_curve,
    plot_ed_vs_sd,
    plot_phi_j_series,
    plot_gaps_ls_vs_calippso,
    plot_jamming_table,
    plot_eos,
    plot_pareto,


# Linked-packing scenes (rules/chains.smk): chains-fig2, chains-fig5.
CHAINS = config.get("chains", {})
CHAINS_DIR = f"{RESULTS}/chains"


def chains_samples():
    """(d, seed) of every linked packing of the scene."""
    dims = CHAINS.get("dims", [2, 3]) if CHAINS.get("figure") == "fig2" else [3]
    return [(d, s) for d in dims for s in CHAINS.get("seeds", [])]


def chains_cemented():
    """(seed, cemented contacts, draw) of every cemented packing of a fig5 scene."""
    return [(s, k, r) for s in CHAINS.get("seeds", []) for k in CHAINS["cement"] for r in range(CHAINS["draws"])]


def chains_targets():
    """The files a chains scene asks for (none for other scenes)."""
    if not CHAINS:
        return []
    if CHAINS["figure"] == "fig2":
        return [
            path
            for d, s in chains_samples()
            for path in (
                f"{RESULTS}/figures/chains-packing_d{d}_seed{s}.png",
                f"{CHAINS_DIR}/d{d}/seed{s}/jammed.check.json",
            )
        ]
    return [f"{RESULTS}/figures/chains-moduli.png"]


def chains_start_command(wildcards, output):
    """fig2: random rigid trimers or dimers without overlaps (dilute: no links pass through each other); fig5: RSA monomers."""
    if CHAINS["figure"] == "fig2":
        return (
            f"jamflow init-chains {output} --d {wildcards.d} --clusters {CHAINS['clusters']}"
            f" --cluster {CHAINS['cluster']} --phi {CHAINS['phi']} --no-overlap --seed {wildcards.seed}"
        )
    return (
        f"jamflow init {output} --d {wildcards.d} --n {CHAINS['spheres']} --phi {CHAINS['phi']}"
        f" --seed {wildcards.seed}"
    )


def chains_jam_options():
    """soft-jam options of a chains scene (none in other scenes, whose rules never run)."""
    if not CHAINS:
        return ""
    flags = "--shear-stabilize" if CHAINS.get("shear_stabilize", True) else ""
    return (
        f"--pressure {CHAINS['pressure']} --pressure-rtol {CHAINS['pressure_rtol']}"
        f" --force-tol {CHAINS['force_tol']} --delta-phi {CHAINS['delta_phi']} {flags}"
    )
