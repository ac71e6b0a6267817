"""The scene table (``jamflow summary``, ``jamflow.load_scene``) equals the datasets' own numbers."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import xarray as xr

import jamflow
from jamflow.cli import main
from jamflow.io import write_dataset

#: discs per sample: enough that the gap and force fits have their minimum number of samples
N = 128
KAPPA, P_TARGETS = 1e-2, (1e3, 1e6)
POINTS = [f"p_target={p:g}" for p in P_TARGETS]


def _cli(*argv: object) -> None:
    assert main([str(a) for a in argv]) == 0


@pytest.fixture(scope="module")
def scene(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """results/<scene> laid out as the workflow lays it out (jamflow.scenes.plan): 2 samples,
    init -> ls -> calippso, a certificate, gaps and forces studies, a flow run."""
    root = tmp_path_factory.mktemp("results") / "mini"
    body = root / "spheres"
    for seed in (1, 2):
        start = body / "base" / f"seed{seed}" / "init.nc"
        start.parent.mkdir(parents=True)
        _cli("init", start, "--d", "2", "--n", str(N), "--phi", "0.5", "--dispersity", "bi", "--seed", seed, "--quiet")
        snapshots = [body / pt / f"seed{seed}" / "ls.nc" for pt in POINTS]
        _cli("ls", start, *snapshots, "--growth-rate", KAPPA, "--p-target", *P_TARGETS, "--seed", seed, "--quiet")
        for snapshot in snapshots:
            _cli("calippso", snapshot, snapshot.with_name("calippso.nc"), "--quiet")
    last = body / POINTS[-1]
    _cli("certify", last / "seed1" / "calippso.nc", last / "seed1" / "calippso.certify.nc", "--quiet")
    finals = [last / f"seed{s}" / "calippso.nc" for s in (1, 2)]
    # a wide window, so the fits have the minimum number of gaps and forces
    _cli("gaps", *finals, root / "studies" / "gaps" / f"{POINTS[-1]}.nc", "--fit-min", "1e-10", "--fit-max", "1e-1",
         "--bins-per-decade", "1", "--quiet")
    _cli("forces", *finals, root / "studies" / "forces" / f"{POINTS[-1]}.nc", "--quiet")
    lss = [last / f"seed{s}" / "ls.nc" for s in (1, 2)]
    _cli("gaps", *lss, root / "studies" / "ls-gaps" / f"{POINTS[-1]}.nc", "--gap-tol", "1e-4", "--include-rattlers",
         "--fit-min", "1e-4", "--fit-max", "1e-1", "--bins-per-decade", "2", "--quiet")
    # a flow time series in the flow schema's variables (its values are what the table must report)
    steps = np.arange(5.0)
    series = xr.Dataset(
        {name: ("step", values) for name, values in {
            "packing_fraction": 0.8 + 1e-3 * steps, "pressure": 3.0 + steps, "shear_stress": 0.1 * steps,
            "n_contacts": 20 + steps}.items()},
        coords={"strain": ("step", 0.01 * steps), "time": ("step", 0.02 * steps)},
        attrs={"N": N, "d": 2, "mode": "shear"},
    )
    write_dataset(series, last / "seed1" / "shear.series.nc")
    return root


def _attrs(root: Path, rel: str) -> dict:
    return xr.load_dataset(root / rel).attrs


def test_one_row_per_packing_and_run_with_the_datasets_numbers(scene):
    table = jamflow.load_scene(scene)
    packings = table[table.kind == "packing"]
    assert len(packings) == 2 * (1 + 2 * len(POINTS))
    assert list(packings[packings["sample"] == "seed1"].stage) == ["init", "ls", "ls", "calippso", "calippso"]
    for row in packings.itertuples():
        a = _attrs(scene, row.file)
        assert row.phi == a["packing_fraction"] and row.N == a["N"] and row.d == a["d"]
        if row.stage == "calippso":
            # n_lp counts LPs; a Newton finish is one more history entry (iterations)
            assert row.phi_J == a["phi_J"] and row.n_lp == a["n_lps"]
            assert a["iterations"] == a["n_lps"] + (a["finish"] == "newton")
            assert row.n_contacts == a["n_contacts"] and row.n_rattlers == a["n_rattlers"]
            # LS + CALiPPSO: isostatic backbone, N_c = d (N_s - 1) + 1
            assert row.isostatic == 1 and row.n_contacts == row.isostatic_count == 2 * (N - row.n_rattlers - 1) + 1
            assert row.max_overlap == a["max_overlap"]
        if row.stage in ("ls", "calippso"):
            assert row.kappa == KAPPA and row.p_target == a["target"] and row.p_target in P_TARGETS
        if row.stage == "ls":
            assert row.pressure == a["pressure"] >= row.p_target
            assert np.isnan(row.phi_J) and np.isnan(row.n_contacts)


def test_study_exponents_and_certificate_land_on_the_packings_they_pooled(scene):
    table = jamflow.load_scene(scene).set_index(["sample", "stage", "p_target"])
    gaps = _attrs(scene, f"studies/gaps/{POINTS[-1]}.nc")
    forces = _attrs(scene, f"studies/forces/{POINTS[-1]}.nc")
    ls_gaps = _attrs(scene, f"studies/ls-gaps/{POINTS[-1]}.nc")
    p_max = P_TARGETS[-1]
    assert np.isfinite([gaps["fit_exponent"], ls_gaps["fit_exponent"]]).all()
    for sample in ("seed1", "seed2"):
        final = table.loc[(sample, "calippso", p_max)]
        assert final.gamma == gaps["fit_exponent"] and final.gamma_err == gaps["fit_exponent_err"]
        assert final.gamma_stat == gaps["fit_exponent_stat"] and final.gamma_sys == gaps["fit_exponent_sys"]
        assert final.gamma_note == gaps["fit_exponent_reason"]
        assert final.theta == pytest.approx(forces["fit_exponent"], nan_ok=True)
        # a refused theta fit (NaN) carries its reason, an accepted one an empty note or a caveat
        assert final.theta_note == forces["fit_exponent_reason"]
        assert np.isfinite(final.theta) or final.theta_note
        assert table.loc[(sample, "ls", p_max)].gamma == ls_gaps["fit_exponent"]
        # no analysis was run for the lower target: nothing attached there
        assert np.isnan(table.loc[(sample, "calippso", P_TARGETS[0])].gamma)
    cert = _attrs(scene, f"spheres/{POINTS[-1]}/seed1/calippso.certify.nc")["classification"]
    assert table.loc[("seed1", "calippso", p_max)].classification == cert
    # the certificate is of the CALiPPSO packing, not of the LS snapshot with the same variant
    assert table.loc[("seed1", "ls", p_max)].classification == ""
    assert table.loc[("seed2", "calippso", p_max)].classification == ""


def test_a_run_row_reports_the_last_record(scene):
    table = jamflow.load_scene(scene)
    (run,) = table[table.kind == "run"].itertuples()
    assert (run.stage, run.strain, run.time, run.pressure, run.phi, run.n_contacts) == (
        "shear", 0.04, 0.08, 7.0, 0.804, 24.0)


def test_dataset_form_has_the_same_values_and_long_names(scene):
    table = jamflow.load_scene(scene)
    ds = jamflow.load_scene(scene, as_="dataset")
    assert ds.sizes["row"] == len(table)
    np.testing.assert_array_equal(ds["phi"].values, table["phi"].values)
    assert all("long_name" in ds[c].attrs for c in table.columns)


def test_cli_prints_phi_j_and_gamma_and_writes_json_and_csv(scene, tmp_path, capsys):
    _cli("summary", scene, "--json", tmp_path / "s.json", "--csv", tmp_path / "s.csv")
    out = capsys.readouterr().out
    table = jamflow.load_scene(scene)
    header = out.splitlines()[1].split()
    assert {"phi_J", "gamma", "gamma_err", "n_contacts", "isostatic_count", "classification"} <= set(header)
    final = table[(table.stage == "calippso") & (table.p_target == P_TARGETS[-1])].iloc[0]
    assert f"{final.phi_J:.10g}" in out and f"{final.gamma:.4g}" in out
    records = json.loads((tmp_path / "s.json").read_text())
    assert len(records) == len(table)
    assert records[0]["kappa"] is None  # NaN is written as null
    csv = pd.read_csv(tmp_path / "s.csv", keep_default_na=False, na_values=[""])
    np.testing.assert_array_equal(csv["phi"].values, table["phi"].values)


def test_scene_yaml_resolves_to_results_of_its_scene(scene, tmp_path, monkeypatch):
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "mini").symlink_to(scene)
    (tmp_path / "s.yaml").write_text("scene: mini\n")
    monkeypatch.chdir(tmp_path)
    assert len(jamflow.load_scene("s.yaml")) == len(jamflow.load_scene(scene))


@pytest.mark.parametrize("bad", ["missing-dir", "empty"])
def test_bad_paths_fail_with_one_line(tmp_path, capsys, bad):
    path = tmp_path / bad
    if bad == "empty":
        path.mkdir()
    assert main(["summary", str(path)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("jamflow summary: error:") and str(path) in err and err.count("\n") == 1


def test_a_hyperstatic_calippso_packing_says_why_in_its_row(tmp_path):
    # 2D monodisperse discs jam hyperstatic (CALiPPSO App. A): the row says by how much and why
    from jamflow.io import write_packing
    from jamflow.protocols.calippso import calippso
    from jamflow.protocols.initial import random_packing

    folder = tmp_path / "hyper" / "spheres" / "base" / "seed1"
    folder.mkdir(parents=True)
    packing = calippso(random_packing(64, 2, 0.5, "mono", seed=11)).packing
    a = packing.attrs
    assert a["hyperstatic"] == 1
    write_packing(packing, folder / "calippso.nc")
    row = jamflow.load_scene(tmp_path / "hyper").iloc[0]
    assert row.n_contacts - row.isostatic_count == a["n_contacts"] - a["isostatic_count"] > 0
    assert row.counting_note.startswith(f"hyperstatic by {a['n_contacts'] - a['isostatic_count']}: ")
    assert f"dual vertex has {a['n_contacts_dual']}" in row.counting_note
    assert f"{a['n_zero_force_contacts']} of them without force" in row.counting_note
