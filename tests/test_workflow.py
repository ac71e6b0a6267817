"""The Snakemake workflow: lint, config validation, planning, and a real run of the default scene."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from jamflow.analysis.overlap import contact_overlap
from jamflow.packing import Packing

REPO = Path(__file__).resolve().parents[1]


def _workdir(tmp_path: Path) -> Path:
    """A copy of the workflow in a temporary folder, with the vendored test data."""
    work = tmp_path / "work"
    work.mkdir()
    shutil.copy(REPO / "Snakefile", work / "Snakefile")
    shutil.copytree(REPO / "workflow", work / "workflow")
    shutil.copytree(REPO / "config", work / "config")
    shutil.copytree(REPO / "tests" / "data", work / "tests" / "data")
    return work


def _snakemake(work: Path, *args: str, timeout: float = 600) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    # the rules call the jamflow console script installed beside this interpreter
    env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
    return subprocess.run(
        [sys.executable, "-m", "snakemake", *args],
        cwd=work, capture_output=True, text=True, timeout=timeout, env=env,
    )


def _planned_jobs(work: Path, *args: str) -> dict[str, int]:
    """Rule name -> job count from a dry run's job table."""
    res = _snakemake(work, "-n", "--quiet", "rules", *args)
    assert res.returncode == 0, res.stderr + res.stdout
    counts: dict[str, int] = {}
    for line in (res.stdout + res.stderr).splitlines():
        parts = line.split()
        if len(parts) == 2 and parts[1].isdigit() and parts[0] not in ("total", "job"):
            counts[parts[0]] = int(parts[1])
    return counts


def test_lint_is_clean(tmp_path):
    res = _snakemake(_workdir(tmp_path), "--lint")
    assert res.returncode == 0, res.stderr
    assert "Congratulations" in res.stdout + res.stderr, res.stdout + res.stderr


@pytest.mark.parametrize(
    "patch, key",
    [
        ({"bogus_key": 1}, "bogus_key"),
        ({"system": {"d": 2, "n": 16, "phi": 0.3, "seeds": [1], "dispersty": "bi"}}, "dispersty"),
        ({"system": {"d": "two", "n": 16, "phi": 0.3, "seeds": [1]}}, "two"),
        # issue 17: these passed the dry run and failed at job time, after the LS work
        ({"calippso": {"solver": "foo"}}, "calippso.solver: 'foo' is not one of"),
        ({"system": {"d": 7, "n": 16, "phi": 0.3, "seeds": [1]}}, "system.d: 7 is greater than the maximum of 5"),
        ({"ls": {"growth_rates": [1e-3], "p_targets": [1e6, 1e3]}}, "ls.p_targets must be strictly increasing"),
        ({"jamming_table": {"fit_min": 1e9, "fit_max": 1e5}}, "jamming_table.fit_min (1e+09) must be below"),
    ],
)
def test_malformed_config_fails_at_start_naming_the_key(tmp_path, patch, key):
    work = _workdir(tmp_path)
    scene = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    scene.update(patch)
    bad = work / "bad.yaml"
    bad.write_text(yaml.safe_dump(scene))
    res = _snakemake(work, "-n", "--configfile", str(bad))
    out = res.stderr + res.stdout
    assert res.returncode != 0
    assert "Error validating config" in out and key in out
    # one line names the problem; the schema itself is not dumped
    assert "$schema" not in out and "description" not in out, out


def test_scene_schema_enums_come_from_the_package():
    from jamflow.calippso import SOLVERS
    from jamflow.presets import PRESET_NAMES

    schema = yaml.safe_load((REPO / "workflow" / "schemas" / "config.schema.yaml").read_text())
    props = schema["properties"]
    assert props["calippso"]["properties"]["solver"]["enum"] == [*SOLVERS, None]
    assert props["preset"]["enum"] == list(PRESET_NAMES)


def test_dry_run_plans_only_what_the_scene_asks_for(tmp_path):
    work = _workdir(tmp_path)
    scene = {
        "scene": "only-import",
        "import": {"ls-d3": "tests/data/calippso-ls/Centers-after-LS--N-1024--d-3.dat"},
        "analyses": ["check"],
        "figures": [],
    }
    path = work / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    jobs = _planned_jobs(work, "--configfile", str(path))
    assert jobs == {"import_dat": 1, "check": 1, "all": 1}


def test_gap_scene_plans_no_flow_jobs(tmp_path):
    work = _workdir(tmp_path)
    scene = {
        "scene": "gaps-only",
        "system": {"d": 2, "n": 32, "phi": 0.4, "dispersity": "bi", "seeds": [1, 2]},
        "chain": ["soft"],
        "analyses": ["gaps"],
        "figures": [],
    }
    path = work / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    assert _planned_jobs(work, "--configfile", str(path)) == {"init": 2, "soft_jam": 2, "gaps": 1, "all": 1}


def test_ls_calippso_scene_plans_one_ls_run_per_sample_and_rate(tmp_path):
    work = _workdir(tmp_path)
    scene = {
        "scene": "ls-route",
        "system": {"d": 3, "n": 32, "phi": 0.3, "seeds": [1, 2]},
        "chain": ["ls", "calippso"],
        "ls": {"growth_rates": [1e-3, 1e-4], "p_targets": [1e3, 1e5, 1e7]},
        "analyses": ["overlap", "jamming-table", "gaps"],
        "figures": ["phi-j-series", "gaps-ls-vs-calippso", "jamming-table", "eos"],
    }
    path = work / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    assert _planned_jobs(work, "--configfile", str(path)) == {
        "init": 2, "ls": 4, "calippso": 12, "overlap_series": 4, "jamming_table": 1, "gaps": 6, "ls_gaps": 6,
        "plot_phi_j_series": 1, "plot_gaps_ls_vs_calippso": 1, "plot_jamming_table": 1, "plot_eos": 1, "all": 1,
    }


@pytest.mark.parametrize(
    "patch, message",
    [
        ({"chain": ["soft", "ls"], "ls": {"growth_rates": [1e-3], "p_targets": [1e3]}}, "ls must come first"),
        ({"chain": ["ls", "soft"], "ls": {"growth_rates": [1e-3], "p_targets": [1e3]}}, "only calippso may follow ls"),
        ({"chain": ["soft"], "analyses": ["overlap"]}, "need(s) the chain [ls, calippso]"),
        ({"chain": ["ls", "calippso"], "ls": {"growth_rates": [1e-3], "p_targets": [1e3]}, "analyses": ["overlap"]},
         "at least two LS p_targets"),
        ({"chain": ["soft", "calippso"], "calippso": {"walls": True}, "analyses": []},
         "calippso.walls needs the chain [calippso]"),
        ({"chain": ["calippso"], "calippso": {"walls": True}}, "analyses and figures other than packing"),
    ],
)
def test_impossible_stage_orders_fail_at_start(tmp_path, patch, message):
    work = _workdir(tmp_path)
    scene = {"scene": "bad", "system": {"d": 2, "n": 16, "phi": 0.3, "seeds": [1]}, "figures": [], **patch}
    path = work / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    res = _snakemake(work, "-n", "--configfile", str(path))
    assert res.returncode != 0
    assert message in res.stderr + res.stdout


def test_every_scene_validates_and_plans(tmp_path):
    work = _workdir(tmp_path)
    scenes = sorted((work / "config" / "scenes").glob("*.yaml"))
    assert scenes
    for path in scenes:
        jobs = _planned_jobs(work, "--configfile", str(path))
        assert jobs.get("all") == 1, path.name


def test_default_scene_runs_end_to_end(tmp_path):
    work = _workdir(tmp_path)
    scene = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    res = _snakemake(work, "--workflow-profile", "workflow/profiles/default", timeout=900)
    assert res.returncode == 0, res.stderr[-4000:]
    out = work / "results" / scene["scene"]
    seeds = scene["system"]["seeds"]
    (kappa,) = scene["ls"]["growth_rates"]
    variants = [f"_k{kappa:g}_p{p:g}" for p in scene["ls"]["p_targets"]]
    for stage in ("ls", "calippso"):
        for s in seeds:
            for v in variants:
                ds = xr.load_dataset(out / "packings" / f"seed{s}" / f"{stage}{v}.nc")
                assert ds.attrs["N"] == scene["system"]["n"] and ds.attrs["d"] == scene["system"]["d"]
                assert set(ds.position.dims) == {"particle", "spatial"}
    checks = sorted((out / "analysis").glob("*/calippso_*.check.json"))
    assert len(checks) == len(seeds) * len(variants)
    for path in checks:
        summary = json.loads(path.read_text())
        # LS + CALiPPSO: exactly isostatic backbones, no overlap, balanced forces
        assert summary["isostatic"] and summary["n_contacts"] == summary["isostatic_count"] > 0
        assert summary["max_overlap_rel"] < 1e-8
        assert summary["force_balance_residual"] < 1e-8
    certificates = sorted((out / "analysis").glob("*/certify_*.nc"))
    assert len(certificates) == len(seeds) * len(variants)
    for path in certificates:
        assert xr.load_dataset(path).attrs["classification"] in ("collectively_jammed", "strictly_jammed")
    for s in seeds:
        series = xr.load_dataset(out / "analysis" / f"seed{s}" / f"overlap_k{kappa:g}.nc")
        # Q recomputed independently from the stored CALiPPSO packings (reference: last target)
        ref = Packing.from_dataset(xr.load_dataset(out / "packings" / f"seed{s}" / f"calippso{variants[-1]}.nc"))
        for q, v in zip(series["Q"].values, variants):
            a = Packing.from_dataset(xr.load_dataset(out / "packings" / f"seed{s}" / f"calippso{v}.nc"))
            assert q == contact_overlap(a, ref)[0]
        assert np.all(series["n_lp"].values >= 1)
    for kind in ("gaps", "forces"):
        ds = xr.load_dataset(out / "analysis" / f"{kind}{variants[-1]}.nc")
        assert np.isfinite(ds.attrs["fit_exponent"])
    pngs = sorted((out / "figures").glob("*.png"))
    expected = {f"packing_seed{s}{variants[-1]}.png" for s in seeds} | {
        f"{f}.png" for f in ("gaps", "forces", "rdf", "phi-j-series", "gaps-ls-vs-calippso", "eos")}
    assert {p.name for p in pngs} == expected
    assert all(p.stat().st_size > 1000 and p.with_suffix(".pdf").is_file() for p in pngs)
    report = _snakemake(work, "--report", "report.html")
    assert report.returncode == 0, report.stderr[-4000:]
    assert (work / "report.html").stat().st_size > 10_000


def test_scene_schema_offers_exactly_the_tradeoff_stages():
    from jamflow.tradeoff import STAGES

    schema = yaml.safe_load((REPO / "workflow" / "schemas" / "config.schema.yaml").read_text())
    assert schema["properties"]["tradeoff"]["properties"]["stages"]["items"]["enum"] == list(STAGES)


def test_walls_scene_runs_end_to_end(tmp_path):
    # issue 17: a scene with calippso.walls failed on its own random start (spheres across
    # the faces); init --walls now places them inside, and CALiPPSO jams them between walls
    work = _workdir(tmp_path)
    scene_file = work / "config" / "scenes" / "walls.yaml"
    scene = yaml.safe_load(scene_file.read_text())
    res = _snakemake(work, "-c1", "--workflow-profile", "workflow/profiles/default", "--configfile", str(scene_file))
    assert res.returncode == 0, res.stderr[-4000:]
    out = work / "results" / scene["scene"]
    d = scene["system"]["d"]
    for s in scene["system"]["seeds"]:
        start = xr.load_dataset(out / "packings" / f"seed{s}" / "init.nc")
        ds = xr.load_dataset(out / "packings" / f"seed{s}" / "calippso.nc")
        for data in (start, ds):
            # every sphere inside the walls, up to the overlap tolerance
            rad = 0.5 * data["diameter"].values[:, None]
            x = data["position"].values
            assert np.all(x >= rad * (1 - 1e-8)) and np.all(x <= 1 - rad * (1 - 1e-8))
        assert ds.attrs["boundary"] == "walls" and ds.attrs["converged"] == 1
        # isostatic between walls (no translations): N_c = d N_s + 1, wall contacts included
        n_wall = ds.sizes["wall_contact"]
        pair_force_bearing = int(np.count_nonzero(ds["force"].values > 0))
        assert n_wall > 0
        assert ds.attrs["n_contacts"] == d * ds.attrs["n_stable"] + 1 == pair_force_bearing + n_wall
        assert ds.attrs["max_overlap"] < 1e-8
        assert (out / "figures" / f"packing_seed{s}.png").stat().st_size > 1000
