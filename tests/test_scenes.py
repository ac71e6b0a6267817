"""The scene grammar (jamflow.scenes): plan-time checks from the stage table, scans, paths, costs.

Pure Python (no Snakemake): every error a scene can meet before any job, each naming its key
in one line; the scan product, zip, sequence and fan-out; the paths and scan points; the cost
report and the cluster groups. The workflow tests (tests/test_workflow.py) run scenes.
"""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import pytest
import yaml

from jamflow.cli import build_parser
from jamflow.scenes import SceneError, cost_report, plan_scene, read_scene
from jamflow.scenes.resources import request_minutes
from jamflow.stages import STAGES

REPO = Path(__file__).resolve().parents[1]

#: A small scene of every part of the grammar: a body scan, a fan-out step, analyses, studies.
BASE = {
    "scene": "t",
    "bodies": {"spheres": {"d": 2, "n": 64, "phi": 0.4, "dispersity": "bi"}},
    "seeds": [1, 2],
    "chain": [{"ls": {"growth_rate": 1e-3, "p_target": [1e3, 1e6]}}, "calippso"],
    "analyses": ["check"],
    "studies": ["gaps", "overlap-series"],
    "figures": ["gaps", "phi-j-series"],
}


def _scene(**changes):
    scene = copy.deepcopy(BASE)
    scene.update(changes)
    return scene


def _error(scene) -> str:
    with pytest.raises(SceneError) as info:
        plan_scene(read_scene(scene))
    message = str(info.value)
    assert "\n" not in message
    return message


def test_every_option_of_the_table_is_a_flag_of_its_command_with_the_same_choices():
    parsers = build_parser().subcommands
    for stage in STAGES.values():
        for option in stage.options:
            if option.flag == "-":
                continue
            actions = {f: a for a in parsers[stage.command]._actions for f in a.option_strings}
            assert option.flag in actions, (stage.command, option.flag)
            if option.kind == "choice":
                assert set(option.choices) == set(actions[option.flag].choices), (stage.command, option.name)
            if option.kind == "bool":
                assert actions[option.flag].nargs == 0, (stage.command, option.name)


@pytest.mark.parametrize("scene, key, words", [
    # unknown keys and stages, with a suggestion for the typo
    (_scene(chian=[]), "chian", "did you mean 'chain'?"),
    (_scene(chain=[{"lss": {"growth_rate": 1e-3, "p_target": 1e3}}]), "chain.lss", "did you mean 'ls'?"),
    (_scene(chain=[{"ls": {"growth_rate": 1e-3, "p_targets": [1e3]}}]), "chain.ls.p_targets",
     "did you mean 'p_target'?"),
    (_scene(bodies={"sphere": {"d": 2, "n": 8, "phi": 0.3}}), "bodies.sphere", "did you mean 'spheres'?"),
    (_scene(analyses=["chekc"]), "analyses.chekc", "did you mean 'check'?"),
    (_scene(figures=["gap"]), "figures.gap", "did you mean 'gaps'?"),
    # a stage that cannot take the scene's bodies: the table's refusal and what to use instead
    (_scene(bodies={"linked": {"builder": "trimer", "d": 2, "clusters": 8}}), "chain.ls",
     "ls does not take linked spheres"),
    (_scene(bodies={"shapes": {"family": "ellipse", "asphericity": 1.1, "n": 16}}, chain=[{"soft-jam": {}}],
            analyses=["certify"], studies=[], figures=[]), "analyses.certify", "jamflow modes"),
    # a missing prerequisite: the stage before it is not one it can follow
    (_scene(chain=[{"soft-jam": {"pressure": 1e-3}}, "calippso"], studies=[], figures=[]), "chain.calippso",
     "cannot follow soft-jam"),
    (_scene(chain=["calippso", {"ls": {"growth_rate": 1e-3, "p_target": 1e3}}], studies=[], figures=[]),
     "chain.ls", "cannot follow calippso"),
    (_scene(studies=["jamming-table"], figures=[]), "studies.jamming-table", "pools the study overlap-series"),
    (_scene(studies=["chains-moduli"], figures=[]), "studies.chains-moduli", "add it under analyses"),
    (_scene(figures=["eos", "flow-curve"]), "figures.flow-curve", "needs a flow-curve study"),
    # bad values, NaN and inf included
    (_scene(bodies={"spheres": {"d": 2, "n": 16, "phi": math.nan}}), "bodies.spheres.phi", "must be finite"),
    (_scene(chain=[{"ls": {"growth_rate": math.inf, "p_target": 1e3}}]), "chain.ls.growth_rate", "must be finite"),
    (_scene(bodies={"spheres": {"d": 7, "n": 16, "phi": 0.3}}), "bodies.spheres.d", "at most 5"),
    (_scene(chain=[{"ls": {"growth_rate": 1e-3, "p_target": [1e6, 1e3]}}]), "chain.ls.p_target",
     "strictly increasing"),
    (_scene(chain=[{"ls": {"growth_rate": 1e-3, "p_target": 1e3}}, {"calippso": {"solver": "foo"}}]),
     "chain.calippso.solver", "must be one of ipm, simplex, hybrid, ipm-center"),
    (_scene(chain=[{"ls": {"p_target": 1e3}}]), "chain.ls.growth_rate", "ls needs it"),
    (_scene(analyses=[{"check": {"gap_tol": [0.0, 1e-8]}}]), "analyses.check.gap_tol", "not scanned"),
    # impossible combinations
    (_scene(chain=[{"soft-jam": {"pressure": 1e-3}}, {"link": {"cement": 200}}], analyses=["moduli"], studies=[],
            figures=[]), "chain.link.cement", "about d N = 128"),
    (_scene(studies=[{"gaps": {"over": ["sampel"]}}]), "studies.gaps.over", "did you mean 'sample'?"),
    (_scene(analyses=[{"rdf": {"r_max": 10}}]), "analyses.rdf.r_max", "reaches half the box"),
    (_scene(bodies={"spheres": {"d": 3, "n": 10_000_000, "phi": 0.3}}, studies=[], figures=[]), "bodies.spheres",
     "more than the"),
    (_scene(scale="paper"), "scale", "gives no 'paper' scale"),
])
def test_a_scene_that_cannot_run_fails_at_plan_time_in_one_line_naming_the_key(scene, key, words):
    message = _error(scene)
    assert message.startswith(f"{key}:") or message.startswith(f"{key.split('.')[0]}"), message
    assert key in message and words in message, message


def test_the_default_scene_at_32_spheres_plans_rdf_within_half_the_box():
    scene = yaml.safe_load((REPO / "config" / "config.yaml").read_text())
    scene["bodies"]["spheres"]["n"] = 32
    plan = plan_scene(read_scene(scene))
    rdf = [j for j in plan.jobs.values() if j.rule == "rdf_calippso"]
    r_max = {float(j.argv[j.argv.index("--r-max") + 1]) for j in rdf}
    # 32 discs of mean diameter 1 fill at least a box of side sqrt(32 pi / 4 / 0.9069) = 5.27
    assert r_max == {2.5} and any("r_max 2.5" in n for n in plan.notes)


def test_a_two_by_three_scan_gives_six_points_with_their_paths_and_scan_points():
    scene = {"scene": "scan", "bodies": {"spheres": {"d": 2, "n": [16, 24], "phi": 0.3, "dispersity": "bi"}},
             "seeds": [1, 2], "chain": [{"soft-jam": {"pressure": [1e-3, 1e-2, 1e-1]}}], "studies": ["gaps"]}
    plan = plan_scene(read_scene(scene))
    jams = {j.outputs[0]: j for j in plan.jobs.values() if j.rule == "soft_jam"}
    points = {(j.point["n"], j.point["pressure"]) for j in jams.values()}
    assert points == {(n, p) for n in (16, 24) for p in (1e-3, 1e-2, 1e-1)}
    assert len(jams) == 12  # two samples each
    assert "results/scan/spheres/n=16,pressure=0.01/seed2/soft-jam.nc" in jams
    job = jams["results/scan/spheres/n=16,pressure=0.01/seed2/soft-jam.nc"]
    assert job.inputs == ["results/scan/spheres/n=16/seed2/init.nc"]
    assert job.argv[job.argv.index("--pressure") + 1] == "0.01"
    assert json.loads(job.command("log").split("'")[1]) == {"body": "spheres", "sample": "seed2", "seed": 2,
                                                            "n": 16, "pressure": 0.01}
    # gaps pools over samples: one study job per (n, pressure), pooled into one file
    groups = [j for j in plan.jobs.values() if j.rule == "study_gaps"]
    assert len(groups) == 6 and all(len(j.inputs) == 2 and "--soft" in j.argv for j in groups)
    pool = next(j for j in plan.jobs.values() if j.rule == "pool_gaps")
    assert pool.argv[-2:] == ["--study", "gaps"] and len(pool.inputs) == 6
    assert "results/scan/studies/gaps.nc" in plan.targets


def test_a_zipped_scan_pairs_its_lists():
    scene = {"scene": "z", "bodies": {"spheres": {"d": [2, 3], "n": [16, 32], "phi": 0.3}}, "seeds": [1],
             "zip": [["bodies.spheres.d", "bodies.spheres.n"]]}
    plan = plan_scene(read_scene(scene))
    assert {(j.point["d"], j.point["n"]) for j in plan.jobs.values() if j.rule == "init"} == {(2, 16), (3, 32)}
    bad = {**scene, "bodies": {"spheres": {"d": [2, 3], "n": [16, 32, 64], "phi": 0.3}}}
    assert "zip" in _error(bad)


def test_ls_writes_one_snapshot_per_target_in_one_job_and_calippso_jams_each():
    plan = plan_scene(read_scene(_scene(chain=[{"ls": {"growth_rate": [1e-3, 1e-4], "p_target": [1e3, 1e6]}},
                                               "calippso"])))
    ls = [j for j in plan.jobs.values() if j.rule == "ls"]
    assert len(ls) == 4  # two samples x two growth rates
    job = next(j for j in ls if j.wildcards == {"body": "spheres", "pre": "growth_rate=0.001,", "sample": "seed1"})
    assert job.outputs == ["results/t/spheres/growth_rate=0.001,p_target=1000/seed1/ls.nc",
                           "results/t/spheres/growth_rate=0.001,p_target=1e+06/seed1/ls.nc",
                           "results/t/spheres/growth_rate=0.001,p_target=all/seed1/ls.eos.nc"]
    assert job.argv[job.argv.index("--seed") + 1] == "1"
    assert len([j for j in plan.jobs.values() if j.rule == "calippso"]) == 8
    series = [j for j in plan.jobs.values() if j.rule == "study_overlap_series"]
    # pooled over p_target: one series per sample and growth rate, with the targets and the rate
    assert len(series) == 4
    one = series[0]
    assert one.argv[one.argv.index("--p-target") + 1:][:2] == ["1000", "1e+06"] and "--growth-rate" in one.argv


def test_a_sequence_starts_each_value_from_the_packing_of_the_one_before():
    scene = {"scene": "s", "bodies": {"shapes": {"family": "circulo-line", "asphericity": 1.03, "n": 16}},
             "seeds": [1], "chain": [{"soft-jam": {"pressure": [1e-7, 1e-6, 1e-5], "sequence": "pressure"}}],
             "analyses": ["modes"], "figures": ["quartic-pressure"]}
    plan = plan_scene(read_scene(scene))
    jams = sorted((j for j in plan.jobs.values() if j.rule == "soft_jam"), key=lambda j: j.point["pressure"])
    assert jams[0].inputs[0].endswith("base/seed1/init-shapes.nc")
    assert jams[1].inputs == [jams[0].outputs[0]] and jams[2].inputs == [jams[1].outputs[0]]
    quartic = next(j for j in plan.jobs.values() if j.rule == "figure_quartic_pressure")
    assert len(quartic.inputs) == 3


def test_draws_give_each_cementing_its_own_reproducible_seed():
    scene = _scene(bodies={"spheres": {"d": 3, "n": 64, "phi": 0.3}}, seeds=[1],
                   chain=[{"soft-jam": {"pressure": 1e-4}}, {"link": {"cement_per_sphere": [0, 0.5], "draws": 3}}],
                   analyses=["moduli"], studies=["chains-moduli"], figures=["chains-moduli"])
    first, again = plan_scene(read_scene(scene)), plan_scene(read_scene(scene))
    links = [j for j in first.jobs.values() if j.rule == "link"]
    seeds = [j.argv[j.argv.index("--seed") + 1] for j in links]
    assert len(links) == 6 and len(set(seeds)) == 6
    assert seeds == [j.argv[j.argv.index("--seed") + 1] for j in again.jobs.values() if j.rule == "link"]
    assert sorted(j.argv[j.argv.index("--cement") + 1] for j in links) == ["0"] * 3 + ["32"] * 3


def test_the_paper_scale_changes_only_what_it_names():
    scene = yaml.safe_load((REPO / "config" / "scenes" / "calippso-fig3.yaml").read_text())
    laptop, paper = read_scene(scene), read_scene({**scene, "scale": "paper"})
    assert laptop.bodies[0].options["n"] == 256 and paper.bodies[0].options["n"] == 1024
    assert paper.seeds == list(range(1, 21)) and laptop.seeds == [1, 2, 3]
    assert paper.chain[1].options == laptop.chain[1].options == {"finish": "lp"}


def test_the_cost_report_gives_requests_per_rule_and_the_core_hours():
    plan = plan_scene(read_scene(_scene()))
    lines = cost_report(plan)
    assert lines[0].split()[:5] == ["rule", "jobs", "threads", "mem_mb", "runtime"]
    ls = next(line for line in lines if line.startswith("ls "))
    assert ls.split()[1] == "2"
    assert "core-hours" in lines[-1] and f"{len(plan.jobs)} jobs" in lines[-1]
    assert all(request_minutes(j.cpu_s) >= 2 for j in plan.jobs.values())


def test_costs_grow_with_the_scene():
    def cpu(n, kappa, rule):
        scene = _scene(bodies={"spheres": {"d": 3, "n": n, "phi": 0.3}},
                       chain=[{"ls": {"growth_rate": kappa, "p_target": [1e3, 1e9]}}, "calippso"],
                       studies=[], figures=[])
        return max(j.cpu_s for j in plan_scene(read_scene(scene)).jobs.values() if j.rule == rule)

    assert cpu(1024, 1e-5, "ls") > cpu(1024, 1e-3, "ls") and cpu(4096, 1e-5, "ls") > cpu(1024, 1e-5, "ls")
    assert cpu(4096, 1e-3, "calippso") > cpu(1024, 1e-3, "calippso")


def test_cluster_groups_bundle_whole_samples_to_about_the_stated_cpu_time():
    scene = {"scene": "g", "bodies": {"shapes": {"family": "ellipse", "asphericity": [1.01, 1.1], "n": 16}},
             "seeds": {"count": 100}, "chain": [{"soft-jam": {"pressure": 1e-2}}], "analyses": ["check"],
             "resources": {"group_minutes": 30}}
    plan = plan_scene(read_scene(scene))
    grouped = [j for j in plan.jobs.values() if j.group and j.rule != "bundle"]
    groups = {j.group for j in grouped}
    assert len(grouped) == 600 and len(groups) <= 60
    # one bundle job per group reads every sample's last output: the group is one connected component
    bundles = {j.group: j for j in plan.jobs.values() if j.rule == "bundle"}
    assert set(bundles) == groups
    for g, job in bundles.items():
        checks = {j.outputs[0] for j in grouped if j.group == g and j.rule == "check_soft_jam"}
        assert set(job.inputs) == checks
    # a sample's jobs stay together
    by_unit: dict = {}
    for j in grouped:
        by_unit.setdefault(j.unit, set()).add(j.group)
    assert all(len(g) == 1 for g in by_unit.values())
    for g in groups:
        assert sum(j.cpu_s for j in grouped if j.group == g) <= 30 * 60 + max(j.cpu_s for j in grouped) * 3


def test_every_shipped_scene_reads_and_plans_at_both_scales():
    for path in sorted((REPO / "config" / "scenes").glob("*.yaml")) + [REPO / "config" / "config.yaml"]:
        scene = yaml.safe_load(path.read_text())
        for scale in ("laptop", "paper"):
            if path.stem == "chains-fig5" and scale == "paper":
                continue  # 195 000 jobs: tests/test_workflow.py plans it (slow)
            if scale == "paper" and "scales" not in scene:
                continue
            plan = plan_scene(read_scene({**scene, "scale": scale}))
            assert plan.targets, (path.name, scale)


def test_the_grammar_s_enums_come_from_the_package():
    from jamflow.presets import PRESET_NAMES
    from jamflow.protocols.calippso import SOLVERS
    from jamflow.scenes.grammar import PRESETS, TRADEOFF_STAGES
    from jamflow.tradeoff import STAGES as SWEPT

    assert STAGES["calippso"].option("solver").choices == tuple(SOLVERS)
    assert PRESETS == tuple(PRESET_NAMES) and TRADEOFF_STAGES == tuple(SWEPT)
    schema = yaml.safe_load((REPO / "workflow" / "schemas" / "config.schema.yaml").read_text())
    assert schema["properties"]["preset"]["enum"] == list(PRESET_NAMES)
    assert schema["properties"]["tradeoff"]["properties"]["stages"]["items"]["enum"] == list(SWEPT)
