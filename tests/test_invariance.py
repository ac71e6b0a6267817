"""Every analysis of a packing is invariant under a rigid shift, a relabelling and a copy of the file.

A rigid shift of every centre (wrapped into the box) and a relabelling of the particles
(contacts, forces, links, shapes relabelled with them) describe the same physical
packing, so every number an analysis reports must be the same: counts and histograms
exactly, real numbers to round-off (``RTOL``; a shift changes centre differences by a
few ulps), per-particle values relabelled. A copy of the file gives bitwise the same
numbers. The packings are a CALiPPSO-jammed 1:1.4 disc mixture (whose small-large
contacts sit exactly on the g(r) bin edge r = 1 mean diameter), and the soft, linked and
shaped packings of ``tests/data/bodies``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from ls_data import ls_dat
from test_stages import DATA as BODIES

from jamflow.cli import main
from jamflow.io import read_dat, read_dataset, read_packing, write_packing
from jamflow.protocols.calippso import calippso
from jamflow.protocols.initial import random_packing
from jamflow.state.bodies import Links
from jamflow.state.packing import Packing

#: Relative agreement of real numbers under a shift or relabelling: centre differences change
#: by round-off (~1e-16 L), which every derived number carries with some amplification.
RTOL = 1e-9

#: Attributes that describe the run, not the packing (provenance, paths, times).
PROVENANCE = {"history", "date_created", "created", "parameters", "inputs", "source", "git_sha", "jamflow_version",
              "title", "total_time", "newton_time", "time", "Conventions", "command", "files"}


def shifted(packing: Packing, fraction: np.ndarray) -> Packing:
    """Every centre moved by ``fraction`` of the box (fractional coordinates), wrapped."""
    shift = packing.box.to_cartesian(np.asarray(fraction, dtype=np.float64)[None, :])[0]
    return packing.evolve(position=packing.box.wrap(packing.position + shift))


def relabelled(packing: Packing, order: np.ndarray) -> Packing:
    """Particle k of the result is particle ``order[k]`` of ``packing``; pairs follow their particles."""
    new = np.empty_like(order)
    new[order] = np.arange(len(order))

    def pairs(i, j, *values):
        a, b = new[np.asarray(i)], new[np.asarray(j)]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        sort = np.lexsort((hi, lo))
        return (lo[sort], hi[sort], *(None if v is None else np.asarray(v)[sort] for v in values))

    changes = {"position": packing.position[order], "diameter": packing.diameter[order]}
    if packing.contacts is not None:
        i, j, force = pairs(packing.contacts[:, 0], packing.contacts[:, 1], packing.force)
        changes.update(contacts=np.stack([i, j], axis=1), force=force)
    if packing.rattler is not None:
        changes["rattler"] = packing.rattler[order]
    if packing.links is not None:
        i, j, length = pairs(packing.links.i, packing.links.j, packing.links.length)
        changes["links"] = Links(i, j, length)
    if packing.orientation is not None:
        changes.update(orientation=packing.orientation[order], shape_index=packing.shape_index[order])
    return packing.evolve(**changes)


@pytest.fixture(scope="session")
def jammed_mixture(tmp_path_factory) -> Path:
    """A CALiPPSO-jammed 2D 1:1.4 mixture of 64 discs and its random start (``start.nc`` beside it)."""
    folder = tmp_path_factory.mktemp("mixture")
    start = random_packing(64, 2, 0.5, "bi", seed=1)
    write_packing(start, folder / "start.nc")
    write_packing(calippso(start).packing, folder / "jammed.nc")
    return folder / "jammed.nc"


def _variants(path: Path, folder: Path) -> dict[str, tuple[Path, np.ndarray]]:
    """The packing of ``path`` copied, shifted and relabelled (files in ``folder``), with each one's relabelling."""
    packing = read_packing(path, None)
    rng = np.random.default_rng(7)
    order = rng.permutation(packing.n)
    out = {}
    for name, variant, perm in (("copy", None, np.arange(packing.n)),
                                ("shift", shifted(packing, rng.random(packing.d)), np.arange(packing.n)),
                                ("relabel", relabelled(packing, order), order)):
        target = folder / f"{name}_{path.name}"
        if variant is None:
            shutil.copy(path, target)
        else:
            write_packing(variant, target)
        out[name] = (target, perm)
    return out


def _timing(name: str) -> bool:
    """Wall-clock times of a run (LP times, totals) differ between any two runs."""
    return name in PROVENANCE or "time" in name.split("_") or name.endswith("_seconds")


#: Residuals (force balance, link lengths, overlaps) are round-off themselves: they agree to
#: this absolute amount (they are relative quantities or forces of order 1e-13), not relatively.
RESIDUAL_ATOL = 1e-9


def _residual(name: str) -> bool:
    return any(word in name for word in ("residual", "max_force", "generalized_force", "error", "overlap_rel",
                                         "max_overlap", "max_torque"))


def _close(a, b, exact: bool, what: str) -> None:
    a, b = np.asarray(a), np.asarray(b)
    if a.dtype.kind in "fc" and not exact and _residual(what):
        np.testing.assert_allclose(a, b, rtol=0, atol=RESIDUAL_ATOL, equal_nan=True, err_msg=what)
    elif a.dtype.kind in "fc" and not exact:
        finite = np.abs(a[np.isfinite(a)])
        scale = float(finite.max()) if finite.size else 0.0
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * scale + 1e-300, equal_nan=True, err_msg=what)
    else:
        assert np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"), what


def _same_dataset(a, b, perm: np.ndarray, exact: bool, skip: tuple[str, ...] = ()) -> None:
    """Every variable and numeric attribute agrees, per-particle variables after relabelling."""
    assert set(a.variables) == set(b.variables)
    for name in a.variables:
        if name in skip or _timing(name):
            continue
        va, vb = a[name], b[name]
        if "particle" in va.dims:
            va = va.isel(particle=perm)
        _close(va.values, vb.values, exact or va.dtype.kind in "iub", name)
    for key, value in a.attrs.items():
        if _timing(key) or key in skip or isinstance(value, str):
            continue
        _close(value, b.attrs[key], exact, key)


def _run(*argv) -> None:
    assert main([str(a) for a in argv]) == 0


def _analysed(command: str, path: Path, folder: Path, *options: str):
    out = folder / f"{command}_{path.stem}.nc"
    _run(command, path, out, "--quiet", *options)
    return read_dataset(out)


@pytest.fixture(scope="session")
def ls_snapshot(tmp_path_factory) -> Path:
    """The CALiPPSO authors' 3D LS configuration (N = 1024): enough gaps for a fitted exponent, and Q6."""
    path = tmp_path_factory.mktemp("ls") / "ls3.nc"
    write_packing(read_dat(ls_dat(3)), path)
    return path


#: source, command, options, variables compared exactly (counts)
CASES = [
    ("mixture", "rdf", ("--r-max", "2.5"), ("g",)),
    ("mixture", "gaps", ("--bootstrap", "20"), ("count",)),
    ("mixture", "forces", ("--bootstrap", "20"), ("count_linear", "count_log")),
    ("ls", "rdf", ("--r-max", "2.5"), ("g", "crystal_like", "n_connected")),
    ("ls", "gaps", ("--include-rattlers", "--bootstrap", "20"), ("count",)),
]


@pytest.mark.parametrize("variant", ["copy", "shift", "relabel"])
@pytest.mark.parametrize("source, command, options, exact", CASES, ids=[f"{c[1]}-{c[0]}" for c in CASES])
def test_an_analysis_of_one_packing_is_invariant(jammed_mixture, ls_snapshot, tmp_path, variant, source, command,
                                                 options, exact):
    start = jammed_mixture if source == "mixture" else ls_snapshot
    path, perm = _variants(start, tmp_path)[variant]
    a = _analysed(command, start, tmp_path, *options)
    b = _analysed(command, path, tmp_path, *options)
    _same_dataset(a, b, perm, variant == "copy")
    for name in exact:
        if name in a:
            values = a[name].isel(particle=perm) if "particle" in a[name].dims else a[name]
            assert np.array_equal(values.values, b[name].values), name
    if command == "gaps" and source == "ls":
        assert np.isfinite(a.attrs["fit_exponent"]) and np.isfinite(a.attrs["fit_exponent_stat"])


def test_g_of_r_of_the_mixture_has_its_small_large_contacts_on_a_bin_edge(jammed_mixture):
    # the case of the issue: without the edge rule the counts of the bins at r = 1 moved under a shift
    p = read_packing(jammed_mixture)
    unit = p.diameter.mean()
    small, large = np.unique(p.diameter)
    assert (small + large) / 2 / unit == pytest.approx(1.0, abs=1e-12)
    r = np.linalg.norm(p.contact_vectors(), axis=1) / unit
    assert np.sum(np.abs(r - 1.0) < 1e-9) > 10


@pytest.mark.parametrize("variant", ["copy", "shift", "relabel"])
def test_certify_is_invariant(jammed_mixture, tmp_path, variant):
    path, perm = _variants(jammed_mixture, tmp_path)[variant]
    a = _analysed("certify", jammed_mixture, tmp_path)
    b = _analysed("certify", path, tmp_path)
    assert a.attrs["classification"] == b.attrs["classification"] != ""
    if "rattler" in a:
        assert np.array_equal(a["rattler"].values[perm], b["rattler"].values)
    if variant == "copy":
        _same_dataset(a, b, perm, True)


@pytest.mark.parametrize("variant", ["copy", "shift", "relabel"])
def test_contact_overlap_of_two_packings_is_invariant(jammed_mixture, tmp_path, variant):
    # both packings of the sample moved (or relabelled) alike: Q(A, B) of the start against the jammed packing
    start = jammed_mixture.parent / "start.nc"
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    start2, perm = _variants(start, tmp_path / "a")[variant]
    jammed2, _ = _variants(jammed_mixture, tmp_path / "b")[variant]
    results = []
    for a, b, name in ((start, jammed_mixture, "q1.nc"), (start2, jammed2, "q2.nc")):
        _run("overlap", a, b, tmp_path / name, "--gap-tol", "0.1", "--quiet")
        results.append(read_dataset(tmp_path / name))
    _same_dataset(*results, perm, variant == "copy")
    assert 0 < results[0].attrs["Q"] <= 1 and results[0].attrs["n_common"] > 0


def _check_json(path: Path, capsys, *options: str) -> dict:
    assert main(["check", str(path), "--json", *options]) == 0
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize("variant", ["copy", "shift", "relabel"])
@pytest.mark.parametrize("source", ["jammed", "spheres_soft.nc", "linked_soft.nc", "shapes_soft.nc"])
def test_check_is_invariant(jammed_mixture, tmp_path, capsys, variant, source):
    path = jammed_mixture if source == "jammed" else BODIES / source
    options = () if source == "jammed" else ("--soft",)
    other, _ = _variants(path, tmp_path)[variant]
    a, b = _check_json(path, capsys, *options), _check_json(other, capsys, *options)
    assert a.keys() == b.keys()
    for key in a:
        if isinstance(a[key], float):
            assert b[key] == pytest.approx(a[key], rel=RTOL, abs=1e-12), key
        else:
            assert a[key] == b[key], key


@pytest.mark.parametrize("variant", ["copy", "shift", "relabel"])
@pytest.mark.parametrize("command, source", [
    ("moduli", "spheres_soft.nc"), ("moduli", "linked_soft.nc"), ("modes", "shapes_soft.nc"),
    ("contact-angles", "shapes_soft.nc"), ("shape-survey", "shapes_soft.nc"),
])
def test_an_analysis_of_soft_linked_and_shaped_bodies_is_invariant(tmp_path, variant, command, source):
    path = BODIES / source
    other, perm = _variants(path, tmp_path)[variant]
    a = _analysed(command, path, tmp_path)
    b = _analysed(command, other, tmp_path)
    # eigenvalues carry the round-off of the Hessian's largest entries
    skip = ("eigenvalue", "fourth_derivative", "rotational_weight") if variant != "copy" else ()
    _same_dataset(a, b, perm, variant == "copy", skip + ("packing",))
    if "eigenvalue" in a and variant != "copy":
        scale = float(np.max(np.abs(a["eigenvalue"].values)))
        np.testing.assert_allclose(a["eigenvalue"].values, b["eigenvalue"].values, rtol=0, atol=1e-9 * scale)
