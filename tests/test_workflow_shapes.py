"""The shapes scenes (VanderWerf et al. figures): planning and the smallest real run."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from test_workflow import _planned_jobs, _snakemake, _workdir

from jamflow.io import read_dataset, read_packing

#: sixteen circulo-lines and disks at high P0 (fewer bodies: the neighbour cutoff must fit the box) at a high P0 (jams in seconds), with disks, modes and angles
TINY = {
    "scene": "tiny-shapes",
    "shapes": {"n": 16, "phi": 0.5, "seeds": [3], "pressures": [1.0e-3, 1.0e-2], "pressure_chain": True, "disks": True,
               "modes": True, "contact_angles": True, "parallel_contacts": "twice",
               "families": [{"shape": "circulo-line", "asphericities": [1.2]}]},
    "figures": ["phi-asphericity", "z-asphericity", "spectra", "quartic-pressure", "contact-angles", "shape-packing"],
}


def test_vanderwerf_scenes_plan_one_jamming_job_per_body_pressure_and_seed(tmp_path):
    work = _workdir(tmp_path)
    expected = {"fig5": 2 + 3 + 1 + 1 + 1, "fig8": 2 + 3 + 1, "fig7": 3, "fig10-11": 1, "fig14": 3}
    for name, n_jam in expected.items():
        scene = yaml.safe_load((work / "config" / "scenes" / f"vanderwerf-{name}.yaml").read_text())["shapes"]
        jobs = _planned_jobs(work, "--configfile", f"config/scenes/vanderwerf-{name}.yaml")
        assert jobs["jam_shapes"] == n_jam * len(scene["seeds"]) * len(scene["pressures"]), name
        assert jobs.get("shape_modes", 0) == (n_jam * len(scene["seeds"]) * len(scene["pressures"])
                                              if scene.get("modes") else 0), name


def test_shape_and_system_together_are_refused(tmp_path):
    work = _workdir(tmp_path)
    scene = {**TINY, "system": {"d": 2, "n": 16, "phi": 0.3, "seeds": [1]}}
    path = work / "scene.yaml"
    path.write_text(yaml.safe_dump(scene))
    res = _snakemake(work, "-n", "--configfile", str(path))
    assert res.returncode != 0 and "Error validating config" in res.stderr + res.stdout


@pytest.mark.slow  # ~1-2 CPU minutes of FIRE (16 bodies, four jammings, spectra); 10+ wall minutes when loaded
def test_tiny_shape_scene_runs(tmp_path):
    work = _workdir(tmp_path)
    path = work / "scene.yaml"
    path.write_text(yaml.safe_dump(TINY))
    res = _snakemake(work, "-j1", "--configfile", str(path), timeout=3600)
    assert res.returncode == 0, res.stderr[-3000:]
    out = work / "results" / "tiny-shapes"
    survey = read_dataset(out / "analysis" / "shape-survey.nc", "shape-survey")
    assert sorted(survey.group_family.values) == ["circulo_line", "disk"]
    for p0 in ("0.001", "0.01"):
        packing = read_packing(out / "shapes" / "circulo-line_A1.2" / f"p{p0}" / "seed3.nc", None)
        assert abs(packing.pressure / float(p0) - 1.0) < 1e-5
        modes = read_dataset(out / "shapes" / "circulo-line_A1.2" / f"p{p0}" / "seed3.modes.nc", "modes")
        assert np.all(np.diff(modes.eigenvalue.values) >= 0.0)
    # the chain compresses the same packing: phi_J grows with P0
    phi = survey.phi_J.values[survey.family.values == "circulo_line"]
    assert phi[1] > phi[0]
    for fig in TINY["figures"]:
        assert (out / "figures" / f"{fig}.png").stat().st_size > 10_000, fig
