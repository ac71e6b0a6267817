"""The Snakemake workflow: lint, plan-time errors, every scene at both scales, scans, one tiny scene
of each body kind end to end, the default scene, and a one-node SLURM run with job groups."""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
import yaml

from jamflow.analysis.overlap import contact_overlap
from jamflow.io import read_packing
from jamflow.network.spheres import contacts_from_gaps, find_rattlers
from jamflow.state.packing import Packing
from jamflow.tolerances import CONTACT_GAP_TOL

REPO = Path(__file__).resolve().parents[1]
SCENES = sorted((REPO / "config" / "scenes").glob("*.yaml"))


def _workdir(tmp_path: Path) -> Path:
    """A copy of the workflow in a temporary folder, with the vendored test data."""
    work = tmp_path / "work"
    work.mkdir()
    shutil.copy(REPO / "Snakefile", work / "Snakefile")
    shutil.copytree(REPO / "workflow", work / "workflow")
    shutil.copytree(REPO / "config", work / "config")
    shutil.copytree(REPO / "tests" / "data", work / "tests" / "data")
    return work


def _snakemake(work: Path, *args: str, timeout: float = 900, env: dict | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ if env is None else env)
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


def _write(work: Path, scene: dict, name: str = "scene.yaml") -> Path:
    path = work / name
    path.write_text(yaml.safe_dump(scene))
    return path


def test_lint_is_clean(tmp_path):
    res = _snakemake(_workdir(tmp_path), "--lint")
    assert res.returncode == 0, res.stderr
    assert "Congratulations" in res.stdout + res.stderr, res.stdout + res.stderr


#: one error of each source (a value, the plan, an unknown key) reaches the dry run in one line;
#: the validator's other messages are checked in-process (tests/test_scenes.py)
@pytest.mark.parametrize("patch, key", [
    ({"bodies": {"spheres": {"d": 2, "n": 32, "phi": float("nan")}}}, "bodies.spheres.phi: must be finite"),
    ({"chain": [{"soft-jam": {"pressure": 1e-3}}, {"link": {"cement": 1000}}], "analyses": [], "studies": [],
      "figures": []}, "chain.link.cement: 1000 cements 1000 contacts"),
    ({"bogus_key": 1}, "bogus_key: unknown scene key"),
])
def test_a_scene_that_cannot_run_fails_at_the_dry_run_in_one_line(tmp_path, patch, key):
    work = _workdir(tmp_path)
    scene = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    scene.update(patch)
    res = _snakemake(work, "-n", "--configfile", str(_write(work, scene)))
    out = res.stderr + res.stdout
    assert res.returncode != 0
    assert "Error in scene: " in out and key in out, out[-3000:]
    assert len([line for line in out.splitlines() if "Error in scene" in line]) == 1
    assert "Traceback" not in out and "$schema" not in out, out[-3000:]


def test_a_dry_run_prints_each_rule_s_requests_and_the_core_hours(tmp_path):
    work = _workdir(tmp_path)
    # a scene of few jobs at both scales: the plan's printout, not its size, is under test
    laptop = _snakemake(work, "-n", "--configfile", "config/scenes/lerner-fig4.yaml")
    paper = _snakemake(work, "-n", "--configfile", "config/scenes/lerner-fig4.yaml", "--config", "scale=paper")
    for res in (laptop, paper):
        assert res.returncode == 0, res.stderr[-3000:]
    hours = [float(re.search(r"jobs, ([0-9.e+-]+) core-hours", r.stderr)[1]) for r in (laptop, paper)]
    assert "at laptop scale" in laptop.stderr and "at paper scale" in paper.stderr and hours[1] > 10 * hours[0]
    # snakemake's own job blocks carry each job's runtime and mem_mb; the plan's table, each rule's threads
    assert re.search(r"resources: .*runtime=\d+, mem_mb=\d+", laptop.stdout + laptop.stderr)
    assert re.search(r"^rule +jobs +threads +mem_mb +runtime \[min\]", laptop.stderr, re.MULTILINE)


@pytest.mark.slow
@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
@pytest.mark.parametrize("scale", ["laptop", "paper"])
def test_every_scene_plans_at_both_scales(tmp_path, path, scale):
    work = _workdir(tmp_path)
    res = _snakemake(work, "-n", "--quiet", "rules", "--configfile", str(path.relative_to(REPO)), "--config",
                     f"scale={scale}", timeout=3600)
    assert res.returncode == 0, res.stderr[-3000:]
    assert f"at {scale} scale" in res.stderr and "core-hours" in res.stderr


@pytest.mark.slow
@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_every_scene_runs_at_laptop_scale(tmp_path, path):
    work = _workdir(tmp_path)
    res = _snakemake(work, "--workflow-profile", "workflow/profiles/default", "--configfile",
                     str(path.relative_to(REPO)), timeout=4 * 3600)
    assert res.returncode == 0, res.stderr[-4000:]
    scene = yaml.safe_load(path.read_text())["scene"]
    assert (work / "results" / scene).is_dir()
    again = _snakemake(work, "-n", "--configfile", str(path.relative_to(REPO)))
    assert "Nothing to be done" in again.stdout + again.stderr


#: one tiny scene of each body kind: a random start, soft jamming at a high P0, the check
TINY = {
    "spheres": {"d": 2, "n": 16, "phi": 0.3, "dispersity": "bi"},
    "linked": {"builder": "trimer", "d": 2, "clusters": 6, "phi": 0.2},
    "shapes": {"family": "circulo-line", "asphericity": 1.2, "n": 16, "phi": 0.4},
}


def _run_tiny_scene(tmp_path: Path, kinds: list[str]) -> None:
    """One scene with a tiny body of each of ``kinds``: every body keeps its kind through
    the chain, the check counts it as such, its log ends with the check's summary, and the
    packing figure is drawn."""
    work = _workdir(tmp_path)
    scene = {"scene": "tiny", "bodies": {kind: TINY[kind] for kind in kinds}, "seeds": [3],
             "chain": [{"soft-jam": {"pressure": 1e-2}}], "analyses": ["check"], "figures": ["packing"]}
    res = _snakemake(work, "-c2", "--configfile", str(_write(work, scene)))
    assert res.returncode == 0, res.stderr[-4000:]
    logs = [q.read_text() for q in (work / "results" / "tiny" / "logs").rglob("*") if q.is_file()]
    for kind in kinds:
        body = {"spheres": "spheres", "linked": "linked-trimer", "shapes": "shapes-circulo-line"}[kind]
        folder = work / "results" / "tiny" / body / "base" / "seed3"
        check_text = (folder / "soft-jam.check.json").read_text()
        check = json.loads(check_text)
        # the check job's log ends with the summary it printed (its output is its stdout)
        assert any(text.endswith(check_text) for text in logs)
        packing = read_packing(folder / "soft-jam.nc", None)
        assert packing.body_kind == kind
        assert check["n_contacts"] > 0 and check["isostatic_count"] > 0
        point = json.loads(xr.load_dataset(folder / "soft-jam.nc").attrs["scan_point"])
        assert point == {"body": body, "sample": "seed3", "seed": 3}
        assert (work / "results" / "tiny" / "figures" / f"packing_{body}_base.png").stat().st_size > 1000


def test_tiny_scenes_of_spheres_and_linked_spheres_run_end_to_end(tmp_path):
    _run_tiny_scene(tmp_path, ["spheres", "linked"])


#: the shapes scene is the heaviest (soft-jam of circulo-lines with rotations, in job processes):
#: slow; the fast suite plans a shapes scene (tests/test_scenes.py) and runs every command on
#: shapes (tests/test_stages.py)
@pytest.mark.slow
def test_a_tiny_scene_of_shapes_runs_end_to_end(tmp_path):
    _run_tiny_scene(tmp_path, ["shapes"])


@pytest.mark.slow
def test_a_two_by_three_scan_runs_pools_and_reruns_only_what_changed(tmp_path):
    """A scan over one body option (n) and one stage option (P0): six points, their paths, the
    coordinates in the pooled study, and after changing one list entry only its jobs are planned."""
    work = _workdir(tmp_path)
    scene = {"scene": "scan", "bodies": {"spheres": {"d": 2, "n": [16, 24], "phi": 0.3, "dispersity": "bi"}},
             "seeds": [1], "chain": [{"soft-jam": {"pressure": [1e-3, 1e-2, 1e-1]}}], "analyses": ["check"],
             "studies": ["gaps"]}
    path = _write(work, scene)
    res = _snakemake(work, "-c2", "--configfile", str(path))
    assert res.returncode == 0, res.stderr[-4000:]
    out = work / "results" / "scan"
    made = sorted(p.parent.parent.name for p in out.glob("spheres/*/seed1/soft-jam.nc"))
    assert made == sorted(f"n={n},pressure={p:g}" for n in (16, 24) for p in (1e-3, 1e-2, 1e-1))
    for folder in made:
        attrs = xr.load_dataset(out / "spheres" / folder / "seed1" / "soft-jam.nc").attrs
        n, p = (float(x.split("=")[1]) for x in folder.split(","))
        assert attrs["N"] == n and attrs["point_n"] == n and attrs["point_pressure"] == p
    pooled = xr.load_dataset(out / "studies" / "gaps.nc")
    assert pooled.sizes["point"] == 6
    assert sorted(zip(pooled["n"].values.tolist(), pooled["pressure"].values.tolist())) == sorted(
        (n, p) for n in (16.0, 24.0) for p in (1e-3, 1e-2, 1e-1))
    scene["chain"][0]["soft-jam"]["pressure"] = [1e-3, 1e-2, 5e-2]
    changed = _planned_jobs(work, "--configfile", str(_write(work, scene)))
    # the two new points (one per n): their jamming, check and gaps; the pool; nothing else
    assert changed == {"soft_jam": 2, "check_soft_jam": 2, "study_gaps": 2, "pool_gaps": 1, "bundle": 1, "all": 1}


@pytest.mark.slow
def test_default_scene_runs_end_to_end(tmp_path):
    work = _workdir(tmp_path)
    scene = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    res = _snakemake(work, "--workflow-profile", "workflow/profiles/default", timeout=1800)
    assert res.returncode == 0, res.stderr[-4000:]
    out = work / "results" / scene["scene"]
    seeds = scene["seeds"]
    targets = scene["chain"][0]["ls"]["p_target"]
    points = [f"p_target={p:g}" for p in targets]
    for s in seeds:
        for pt in points:
            for stage in ("ls", "calippso"):
                ds = xr.load_dataset(out / "spheres" / pt / f"seed{s}" / f"{stage}.nc")
                assert ds.attrs["N"] == scene["bodies"]["spheres"]["n"]
                assert ds.attrs["point_p_target"] == float(pt.split("=")[1])
    checks = sorted(out.glob("spheres/*/*/calippso.check.json"))
    assert len(checks) == len(seeds) * len(points)
    for path in checks:
        summary = json.loads(path.read_text())
        # LS + CALiPPSO: rigid backbones, no overlap, balanced forces; isostatic unless
        # pairs without a dual touch too (a degenerate packing, stored with its geometric contacts)
        assert summary["counting"] in ("isostatic", "hyperstatic") and summary["isostatic_count"] > 0
        assert summary["isostatic"] == (summary["n_contacts"] == summary["isostatic_count"])
        packing = read_packing(path.with_name("calippso.nc"))
        geo = contacts_from_gaps(packing, CONTACT_GAP_TOL)
        stable = ~find_rattlers(packing.n, packing.d, geo)
        np.testing.assert_array_equal(packing.rattler, ~stable)
        backbone = geo[stable[geo[:, 0]] & stable[geo[:, 1]]]
        assert summary["n_contacts"] == len(backbone)
        assert summary["max_overlap_rel"] < 1e-8 and summary["force_balance_residual"] < 1e-8
    for path in sorted(out.glob("spheres/*/*/calippso.certify.nc")):
        assert xr.load_dataset(path).attrs["classification"] in ("collectively_jammed", "strictly_jammed")
    series = xr.load_dataset(out / "studies" / "overlap-series.nc")
    assert series.sizes["point"] == len(seeds)
    for k, sample in enumerate(series["sample"].values):
        # Q recomputed independently from the stored CALiPPSO packings (reference: the last target)
        ref = Packing.from_dataset(xr.load_dataset(out / "spheres" / points[-1] / sample / "calippso.nc"))
        for q, pt in zip(series["Q"].values[k], points):
            a = Packing.from_dataset(xr.load_dataset(out / "spheres" / pt / sample / "calippso.nc"))
            assert q == contact_overlap(a, ref)[0]
    for kind in ("gaps", "forces"):
        pooled = xr.load_dataset(out / "studies" / f"{kind}.nc")
        assert pooled["p_target"].values.tolist() == targets
        ds = xr.load_dataset(out / "studies" / kind / f"{points[-1]}.nc")
        enough = ds.attrs["fit_exponent_n_in_window"] >= ds.attrs["fit_min_in_window"]
        assert np.isfinite(ds.attrs["fit_exponent"]) == enough
        assert float(pooled["attr_fit_exponent"].values[-1]) == pytest.approx(ds.attrs["fit_exponent"], nan_ok=True)
    pngs = sorted((out / "figures").glob("*.png"))
    expected = {"packing_spheres_base.png"} | {f"{f}.png" for f in (
        "gaps", "forces", "gaps-windows", "forces-windows", "rdf", "phi-j-series", "eos")}
    assert {p.name for p in pngs} == expected
    assert all(p.stat().st_size > 1000 and p.with_suffix(".pdf").is_file() for p in pngs)


# --- a real SLURM cluster (workflow/slurm-local/cluster.sh) --------------------------------

#: 200 packings (random 2D starts, one job each) in cluster groups of ~2 expected CPU-minutes.
SLURM_SCENE = {
    "scene": "slurm-survey",
    "bodies": {"spheres": {"d": 2, "n": 16, "phi": 0.3, "dispersity": "bi"}},
    "seeds": {"count": 200},
    "resources": {"group_minutes": 2},
}


@pytest.fixture(scope="module")
def slurm_cluster():
    """A one-node SLURM cluster with accounting, up for this module, torn down after.

    Yields the environment that points SLURM clients at it. The state folder lives under
    /tmp (not pytest's private tmp_path) because munge and mysql must reach it.
    """
    import tempfile

    script = REPO / "workflow" / "slurm-local" / "cluster.sh"
    state = Path(tempfile.mkdtemp(prefix="jamflow-slurm-", dir="/tmp"))
    started = time.perf_counter()
    up = subprocess.run([str(script), "up", str(state)], capture_output=True, text=True, timeout=900)
    print(f"cluster up: {time.perf_counter() - started:.0f} s wall; {up.stderr.strip()}")
    try:
        if up.returncode == 77:
            pytest.skip(up.stderr.strip().splitlines()[-1])
        assert up.returncode == 0, up.stderr[-4000:]
        env = dict(os.environ)
        env["SLURM_CONF"] = str(state / "etc" / "slurm.conf")
        env["PATH"] = f"{Path(sys.executable).parent}{os.pathsep}{env.get('PATH', '')}"
        yield env
    finally:
        subprocess.run([str(script), "down", str(state)], capture_output=True, text=True, timeout=300)
        shutil.rmtree(state, ignore_errors=True)


def _sacct_jobs(env: dict[str, str]) -> dict[str, dict[str, str]]:
    """Allocations (not steps) the accounting database knows: JobID -> fields."""
    fields = ["JobID", "State", "ExitCode", "Account", "Partition", "Timelimit", "ReqMem", "ReqCPUS", "Comment"]
    res = subprocess.run(
        ["sacct", "-X", "-n", "-P", "--starttime", "2000-01-01", "-o", ",".join(f + "%400" for f in fields)],
        capture_output=True, text=True, env=env, check=True,
    )
    rows = [dict(zip(fields, line.split("|"))) for line in res.stdout.splitlines() if line.strip()]
    return {row["JobID"]: row for row in rows}


def _sacct_jobs(env: dict[str, str]) -> dict[str, dict[str, str]]:
    """Allocations (not steps) the accounting database knows: JobID -> fields."""
    fields = ["JobID", "JobName", "State", "ExitCode", "Account", "Partition", "Timelimit", "ReqMem"]
    res = subprocess.run(
        ["sacct", "-X", "-n", "-P", "--starttime", "2000-01-01", "-o", ",".join(f + "%400" for f in fields)],
        capture_output=True, text=True, env=env, check=True,
    )
    rows = [dict(zip(fields, line.split("|"))) for line in res.stdout.splitlines() if line.strip()]
    return {row["JobID"]: row for row in rows}


@pytest.mark.slow
def test_a_survey_of_200_packings_runs_on_slurm_in_groups_and_matches_a_local_run(tmp_path, slurm_cluster,
                                                                                   monkeypatch):
    """200 packings: the SLURM profile submits their cluster groups (jamflow.scenes bundles whole
    samples to about resources.group_minutes), at most a tenth as many submissions as packings,
    and every output equals a local run of the same planned commands (in this process, which
    spares 200 interpreter start-ups on a shared 2-core host)."""
    try:
        import snakemake_executor_plugin_slurm  # noqa: F401
    except ImportError:
        pytest.fail("the SLURM executor plugin is missing: pip install -e '.[slurm]'")
    from jamflow.cli import main
    from jamflow.provenance import SCAN_POINT_ENV
    from jamflow.scenes import plan_scene, read_scene

    env = slurm_cluster
    before = set(_sacct_jobs(env))
    (tmp_path / "slurm").mkdir()
    work = _workdir(tmp_path / "slurm")
    scene = _write(work, SLURM_SCENE)
    started = time.perf_counter()
    # `timeout -s INT`: SIGINT lets snakemake cancel its SLURM jobs; plain SIGTERM does not stop it
    res = subprocess.run(
        ["timeout", "-s", "INT", "-k", "10", "3600", sys.executable, "-m", "snakemake",
         "--workflow-profile", "workflow/profiles/slurm", "--configfile", str(scene),
         "--default-resources", "slurm_account=jamflow", "slurm_partition=debug",
         "--slurm-init-seconds-before-status-checks", "2", "--latency-wait", "5"],
        cwd=work, capture_output=True, text=True, env=env,
    )
    assert res.returncode == 0, res.stderr[-6000:]
    print(f"slurm run: {time.perf_counter() - started:.0f} s wall")
    jobs = {k: v for k, v in _sacct_jobs(env).items() if k not in before}
    n_packings = 200
    print(f"{len(jobs)} SLURM jobs for {n_packings} packings")
    assert 1 <= len(jobs) <= n_packings // 10, len(jobs)
    for job in jobs.values():
        assert job["State"] == "COMPLETED" and job["ExitCode"] == "0:0", job
        assert job["Account"] == "jamflow" and job["Partition"] == "debug", job
    local = tmp_path / "local"
    local.mkdir()
    monkeypatch.chdir(local)
    plan = plan_scene(read_scene(SLURM_SCENE))
    starts = [job for job in plan.jobs.values() if job.rule == "init"]
    assert len(starts) == n_packings
    for job in starts:
        monkeypatch.setenv(SCAN_POINT_ENV, json.dumps(job.point, sort_keys=True))
        assert main([*job.argv, "--quiet"]) == 0
    made = sorted(p.relative_to(local) for p in local.glob("results/slurm-survey/spheres/*/*/*.nc"))
    assert made == sorted(p.relative_to(work) for p in work.glob("results/slurm-survey/spheres/*/*/*.nc"))
    assert len(made) == n_packings
    for rel in made:
        a, b = xr.load_dataset(local / rel), xr.load_dataset(work / rel)
        assert set(a.data_vars) == set(b.data_vars) and a.attrs["scan_point"] == b.attrs["scan_point"]
        for name in a.data_vars:
            np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=f"{rel}:{name}")


def _assert_report_has_every_figure(report: Path, pngs: list[Path], work: Path) -> None:
    """Each figure is embedded byte for byte (base64) under its path, and no caption has a Docutils error."""
    html = report.read_text()
    for png in pngs:
        rel = png.relative_to(work).as_posix()
        assert f'"{rel}": {{"name": "{png.name}"' in html, f"{rel} is not an entry of the report"
        assert base64.b64encode(png.read_bytes()).decode() in html, f"{rel} is not embedded in the report"
    captions = re.findall(r'"caption": "((?:[^"\\]|\\.)*)"', html)
    assert len(captions) >= len(pngs)
    assert not [c for c in captions if "system-message" in c or "problematic" in c]
