"""The reproduced-figures page (jamflow reproduce) is written from the scenes' outputs."""

from __future__ import annotations

from jamflow.cli import main
from jamflow.io import read_dataset
from jamflow.reproduce import NOT_RUN, SCENES


def _cli(*argv: object) -> None:
    assert main([str(a) for a in argv]) == 0


def test_without_outputs_every_scene_says_not_run_beside_the_papers_numbers(tmp_path):
    out = tmp_path / "docs" / "reproduced.md"
    _cli("reproduce", out, "--results", tmp_path / "results", "--quiet")
    page = out.read_text()
    for scene in SCENES:
        assert f"(`{scene.scene}`)" in page
    # Table I of the CALiPPSO paper, every growth rate, and nothing measured
    for value in ("0.64244(20)", "0.64272(22)", "0.64314(19)", "0.64329(18)"):
        assert value in page
    rows = [line for line in page.splitlines() if line.startswith("| ") and "quantity" not in line]
    assert rows and all(line.rstrip(" |").endswith(NOT_RUN) for line in rows)


def test_a_scene_s_numbers_come_from_its_packings(tmp_path):
    """The walls row counts isostatic packings from the CALiPPSO outputs' own attributes."""
    root = tmp_path / "results" / "walls" / "spheres" / "base"
    for seed in (1, 2):
        start = root / f"seed{seed}" / "init.nc"
        start.parent.mkdir(parents=True)
        _cli("init", start, "--d", "2", "--n", "16", "--phi", "0.3", "--dispersity", "bi", "--walls", "--seed", seed,
             "--quiet")
        _cli("calippso", start, start.with_name("calippso.nc"), "--walls", "--quiet")
    attrs = [read_dataset(root / f"seed{s}" / "calippso.nc").attrs for s in (1, 2)]
    iso = sum(int(a["n_contacts"]) == int(a["isostatic_count"]) for a in attrs)
    # the scene as run here: its plan's outputs are these packings (a missing one would read "incomplete")
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    (scenes / "walls.yaml").write_text(
        "scene: walls\nbodies: {spheres: {d: 2, n: 16, phi: 0.3, dispersity: bi, walls: true}}\n"
        "seeds: [1, 2]\nchain: [{calippso: {walls: true}}]\n")
    out = tmp_path / "reproduced.md"
    _cli("reproduce", out, "--results", tmp_path / "results", "--scenes", scenes, "--quiet")
    row = next(line for line in out.read_text().splitlines() if line.startswith("| N_c = d N_s + 1"))
    laptop, paper = [c.strip() for c in row.strip("|").split("|")][2:]
    assert laptop.startswith(f"{iso} of 2 packings isostatic") and "(2 samples)" in laptop
    assert paper == NOT_RUN
    # no figure was made, so none is copied and the page says so
    assert not list((tmp_path / "reproduced").glob("*.png"))
