"""The Snakemake workflow: lint, config validation, planning, and a real run of the default scene."""

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
    from jamflow.presets import PRESET_NAMES
    from jamflow.protocols.calippso import SOLVERS

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
        "plot_phi_j_series": 1, "plot_gaps_ls_vs_calippso": 1, "plot_gap_windows": 1, "plot_jamming_table": 1,
        "plot_eos": 1, "all": 1,
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
        ({"chain": ["compress", "decompress"], "compress": {"phi": 0.8}, "decompress": {"phi": 0.7}},
         "decompress shrinks a jammed packing and must follow calippso or soft"),
        ({"chain": ["ls", "calippso", "decompress"], "ls": {"growth_rates": [1e-3], "p_targets": [1e3, 1e5]},
          "decompress": {"phi": 0.8}, "flow": {"strain": 0.1}, "analyses": []},
         "give one growth rate and one p_target"),
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
        # LS + CALiPPSO: rigid backbones, no overlap, balanced forces; isostatic unless
        # pairs without a dual touch too (a degenerate packing, stored with its
        # geometric contacts: seed 1 has one more pair of large discs at gap 2e-15)
        assert summary["counting"] in ("isostatic", "hyperstatic") and summary["isostatic_count"] > 0
        assert summary["isostatic"] == (summary["n_contacts"] == summary["isostatic_count"])
        packing = read_packing(out / "packings" / path.parent.name / path.name.replace(".check.json", ".nc"))
        geo = contacts_from_gaps(packing, CONTACT_GAP_TOL)
        stable = ~find_rattlers(packing.n, packing.d, geo)
        np.testing.assert_array_equal(packing.rattler, ~stable)
        backbone = geo[stable[geo[:, 0]] & stable[geo[:, 1]]]
        assert summary["n_contacts"] == len(backbone)
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
        # N = 64 x 3 samples: an exponent only with enough samples in its window, else NaN and why
        enough = ds.attrs["fit_exponent_n_in_window"] >= ds.attrs["fit_min_in_window"]
        assert np.isfinite(ds.attrs["fit_exponent"]) == enough
        assert enough or "fewer than the minimum" in ds.attrs["fit_exponent_reason"]
        assert ds.attrs["fit_min"] < ds.attrs["fit_max"] and "maximum likelihood" in ds.attrs["fit_method"]
    assert xr.load_dataset(out / "analysis" / f"gaps{variants[-1]}.nc").attrs["rattlers_included"] == 0
    pngs = sorted((out / "figures").glob("*.png"))
    expected = {f"packing_seed{s}{variants[-1]}.png" for s in seeds} | {
        f"{f}.png" for f in ("gaps", "forces", "gaps-windows", "forces-windows", "rdf", "phi-j-series",
                             "gaps-ls-vs-calippso", "eos")}
    assert {p.name for p in pngs} == expected
    assert all(p.stat().st_size > 1000 and p.with_suffix(".pdf").is_file() for p in pngs)
    report = _snakemake(work, "--report", "report.html")
    assert report.returncode == 0, report.stderr[-4000:]
    _assert_report_has_every_figure(work / "report.html", pngs, work)


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


def test_scene_schema_offers_exactly_the_tradeoff_stages():
    from jamflow.tradeoff import STAGES

    schema = yaml.safe_load((REPO / "workflow" / "schemas" / "config.schema.yaml").read_text())
    assert schema["properties"]["tradeoff"]["properties"]["stages"]["items"]["enum"] == list(STAGES)


# --- a real SLURM cluster (workflow/slurm-local/cluster.sh) --------------------------------

#: A tiny LS + CALiPPSO scene: one 2D sample, two LS targets, checked (6 cluster jobs).
SLURM_SCENE = {
    "scene": "slurm-check",
    "system": {"d": 2, "n": 32, "phi": 0.4, "dispersity": "bi", "seeds": [1]},
    "chain": ["ls", "calippso"],
    "ls": {"growth_rates": [1e-3], "p_targets": [1e3, 1e6]},
    "analyses": ["check"],
    "figures": [],
}
#: rules of that scene that run on the submitting host (localrules in common.smk)
SLURM_SCENE_LOCAL_RULES = {"all"}


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


def _planned_resources(work: Path, scene: Path) -> dict[str, list[tuple[int, int]]]:
    """Rule -> (runtime [min], mem_mb) of each job from a dry run's job blocks."""
    res = _snakemake(work, "-n", "--configfile", str(scene))
    assert res.returncode == 0, res.stderr + res.stdout
    planned: dict[str, list[tuple[int, int]]] = {}
    rule = None
    for line in (res.stdout + res.stderr).splitlines():
        line = line.strip()
        if line.startswith(("rule ", "localrule ")) and line.endswith(":"):
            rule = line.split()[1].rstrip(":")
        elif line.startswith("resources:") and rule is not None:
            values = dict(item.split("=", 1) for item in line.removeprefix("resources:").replace(" ", "").split(","))
            if "runtime" in values:  # the target rule `all` asks for nothing
                planned.setdefault(rule, []).append((int(values["runtime"]), int(values["mem_mb"])))
            rule = None
    return planned


@pytest.mark.slow
def test_slurm_run_submits_every_job_and_matches_a_local_run(tmp_path, slurm_cluster):
    """The SLURM profile on a real SLURM with accounting: every non-local job goes through
    sbatch with the rule's runtime and memory, and the packings are the local run's, bit for bit
    (LS is seeded and event-driven, CALiPPSO's HiGHS solves are deterministic: same input,
    same numbers), except the LP wall times."""
    env = slurm_cluster
    outputs = {}
    before = set(_sacct_jobs(env))
    for mode in ("local", "slurm"):
        (tmp_path / mode).mkdir()
        work = _workdir(tmp_path / mode)
        scene = work / "scene.yaml"
        scene.write_text(yaml.safe_dump(SLURM_SCENE))
        started = time.perf_counter()
        if mode == "local":
            res = _snakemake(work, "--workflow-profile", "workflow/profiles/default", "--configfile", str(scene))
        else:
            planned = _planned_resources(work, scene)
            # `timeout -s INT`: SIGINT lets snakemake cancel its SLURM jobs; plain SIGTERM does not stop it
            res = subprocess.run(
                ["timeout", "-s", "INT", "-k", "10", "900", sys.executable, "-m", "snakemake",
                 "--workflow-profile", "workflow/profiles/slurm", "--configfile", str(scene),
                 "--default-resources", "slurm_account=jamflow", "slurm_partition=debug",
                 "--slurm-init-seconds-before-status-checks", "2", "--latency-wait", "5"],
                cwd=work, capture_output=True, text=True, env=env,
            )
        assert res.returncode == 0, res.stderr[-6000:]
        print(f"{mode} run: {time.perf_counter() - started:.0f} s wall")
        out = work / "results" / SLURM_SCENE["scene"]
        outputs[mode] = out
        # the rules no longer silence the commands: a job's log holds what it printed
        for stage in ("ls", "calippso"):
            logs = sorted((out / "logs" / stage).glob("*.log"))
            assert logs and all(log.stat().st_size > 0 for log in logs), (mode, stage)

    jobs = {k: v for k, v in _sacct_jobs(env).items() if k not in before}
    by_rule: dict[str, list[dict[str, str]]] = {}
    for job in jobs.values():
        # the plugin's comment: rule_<name>_wildcards_<...>
        rule = job["Comment"].removeprefix("rule_").split("_wildcards_")[0]
        by_rule.setdefault(rule, []).append(job)
    cluster_planned = {r: v for r, v in planned.items() if r not in SLURM_SCENE_LOCAL_RULES}
    assert {r: len(v) for r, v in by_rule.items()} == {r: len(v) for r, v in cluster_planned.items()}
    for rule, submitted in by_rule.items():
        for job in submitted:
            assert job["State"] == "COMPLETED" and job["ExitCode"] == "0:0", job
            assert job["Account"] == "jamflow" and job["Partition"] == "debug", job
        # each job asked SLURM for what the rule's resources say
        asked = sorted((_minutes(j["Timelimit"]), int(j["ReqMem"].rstrip("M"))) for j in submitted)
        assert asked == sorted(cluster_planned[rule]), (rule, asked, cluster_planned[rule])

    local, slurm = (sorted(p.relative_to(outputs[m]) for p in outputs[m].rglob("packings/**/*.nc"))
                    for m in ("local", "slurm"))
    assert local == slurm and len(local) == 6  # init, two LS snapshots, LS equation of state, two CALiPPSO
    for rel in local:
        a, b = xr.load_dataset(outputs["local"] / rel), xr.load_dataset(outputs["slurm"] / rel)
        assert set(a.data_vars) == set(b.data_vars)
        # wall-clock durations (units s, CALiPPSO's lp_time) differ between any two runs
        clocks = {name for name in a.data_vars if a[name].attrs.get("units") == "s"}
        assert clocks <= {"lp_time"}, clocks
        for name in set(a.data_vars) - clocks:
            np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=f"{rel}:{name}")
    for check in sorted((outputs["local"] / "analysis").rglob("*.check.json")):
        assert json.loads(check.read_text()) == json.loads(
            (outputs["slurm"] / check.relative_to(outputs["local"])).read_text())


def _minutes(limit: str) -> int:
    """Minutes of a SLURM time limit ``[D-]HH:MM:SS``."""
    days, _, clock = limit.rpartition("-")
    h, m, s = (int(x) for x in clock.split(":"))
    return (int(days or 0) * 24 + h) * 60 + m + (s > 0)


def test_jobs_ask_for_resources_that_grow_with_the_scene(tmp_path):
    """Every job asks for runtime and memory; LS asks for more at a lower growth rate and
    CALiPPSO at a larger N, so a long job is not killed at a flat default; no rule
    silences its command (--quiet emptied every log)."""
    work = _workdir(tmp_path)
    small = work / "config" / "config.yaml"
    res = _snakemake(work, "-n", "-p", "--configfile", str(small))
    assert res.returncode == 0, res.stderr
    commands = [line for line in res.stdout.splitlines() if line.startswith("Shell command: jamflow")]
    assert commands and not any("--quiet" in c for c in commands)
    assert all("> results/" in c and " 2>" in c for c in commands)  # output goes to the log
    base = _planned_resources(work, small)
    assert all(runtime >= 10 and mem >= 1000 for jobs in base.values() for runtime, mem in jobs)

    def plan(n, kappa):
        scene = {"scene": f"big{n}", "system": {"d": 3, "n": n, "phi": 0.3, "seeds": [1]},
                 "chain": ["ls", "calippso"], "ls": {"growth_rates": [kappa], "p_targets": [1e6, 1e7]},
                 "analyses": ["check"], "figures": []}
        path = work / f"scene{n}_{kappa:g}.yaml"
        path.write_text(yaml.safe_dump(scene))
        return _planned_resources(work, path)

    fast, slow, large = plan(1024, 1e-3), plan(1024, 1e-5), plan(4096, 1e-5)
    assert slow["ls"][0][0] > fast["ls"][0][0] and large["ls"][0][0] > slow["ls"][0][0]
    assert max(r for r, _ in large["calippso"]) > max(r for r, _ in slow["calippso"])
    assert max(m for _, m in large["calippso"]) > max(m for _, m in slow["calippso"])
    assert max(m for _, m in large["calippso"]) > max(m for _, m in large["check"])


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


def _chains_scene(work: Path, name: str, **changes) -> tuple[Path, dict]:
    """A shrunken copy of config/scenes/<name>.yaml (same keys, smaller sizes)."""
    scene = yaml.safe_load((REPO / "config" / "scenes" / f"{name}.yaml").read_text())
    scene["chains"].update(changes)
    path = work / "config" / f"{name}-tiny.yaml"
    path.write_text(yaml.safe_dump(scene))
    return path, scene


def test_chains_fig5_plans_one_cementing_and_moduli_job_per_draw(tmp_path):
    work = _workdir(tmp_path)
    path, scene = _chains_scene(work, "chains-fig5", seeds=[1, 2, 3], cement=[0, 8], draws=2)
    jobs = _planned_jobs(work, "--configfile", str(path))
    assert jobs["chains_jam"] == 3 and jobs["chains_cement"] == jobs["chains_moduli"] == 3 * 2 * 2
    assert jobs["chains_moduli_table"] == jobs["chains_plot_moduli"] == 1 and "chains_check" not in jobs


def test_chains_fig2_smallest_variant_runs_and_is_isostatic(tmp_path):
    """12 rigid trimers in 2D, shear-stabilised at P0 = 1e-4: isostatic by the cluster count (docs/chains.md)."""
    work = _workdir(tmp_path)
    path, scene = _chains_scene(work, "chains-fig2", dims=[2], clusters=12)
    res = _snakemake(work, "-c1", "--workflow-profile", "workflow/profiles/default", "--configfile", str(path))
    assert res.returncode == 0, res.stderr[-4000:]
    out = work / "results" / scene["scene"]
    check = json.loads((out / "chains" / "d2" / "seed1" / "jammed.check.json").read_text())
    assert check["n_links"] == 36 and check["max_link_error"] <= 1e-13
    # 12 trimers shear-stabilised: 3 per trimer - 2 translations + 1 + 2 strain = 37 contacts
    assert check["isostatic"] is True and check["n_contacts"] == check["isostatic_count"] == 37
    png = out / "figures" / "chains-packing_d2_seed1.png"
    assert png.stat().st_size > 1000 and png.with_suffix(".pdf").is_file()
    assert (out / "benchmarks" / "chains" / "jam_d2_seed1.tsv").is_file()


def test_vanderwerf_fig3b_smallest_variant_runs_and_dimers_are_isostatic(tmp_path):
    """12 asymmetric dimers in a fixed 2D box: N_c = 3 N' - 1 - N_rot and <z> = 6 (docs/chains.md)."""
    work = _workdir(tmp_path)
    path, scene = _chains_scene(work, "vanderwerf-fig3b", clusters=12, seeds=[1], pressure=1e-5)
    res = _snakemake(work, "-c1", "--workflow-profile", "workflow/profiles/default", "--configfile", str(path))
    assert res.returncode == 0, res.stderr[-4000:]
    out = work / "results" / scene["scene"]
    check = json.loads((out / "chains" / "d2" / "seed1" / "jammed.check.json").read_text())
    assert check["n_dimers"] == check["n_links"] == 12 and check["isostatic"] is True
    assert check["n_contacts"] == 3 * (12 - check["n_rattling_dimers"]) - 1 - check["n_rotators"]
    assert check["z"] == pytest.approx(6.0, rel=1e-14)
    assert (out / "figures" / "chains-packing_d2_seed1.png").stat().st_size > 1000


@pytest.mark.slow
def test_chains_fig5_smallest_variant_runs_and_cementing_stiffens(tmp_path):
    work = _workdir(tmp_path)
    path, scene = _chains_scene(work, "chains-fig5", spheres=32, seeds=[1], cement=[0, 8], draws=1)
    res = _snakemake(work, "-c1", "--workflow-profile", "workflow/profiles/default", "--configfile", str(path))
    assert res.returncode == 0, res.stderr[-4000:]
    out = work / "results" / scene["scene"]
    table = xr.load_dataset(out / "analysis" / "chains-moduli.nc")
    np.testing.assert_allclose(table.links_per_sphere.values, [0.0, 8 / 32])
    assert np.all(table.shear_weighted.values > 0) and table.shear_weighted.values[1] > table.shear_weighted.values[0]
    assert (out / "figures" / "chains-moduli.png").stat().st_size > 1000
