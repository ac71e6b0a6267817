"""The user guide: its worked example runs (and checks physics), its pages are all in the nav, it builds strictly."""

from __future__ import annotations

import runpy
import subprocess
import sys
from pathlib import Path

import ase.io
import pytest
import yaml

REPO = Path(__file__).resolve().parents[1]
DOCS = REPO / "docs"


def test_quickstart_example_runs_and_its_numbers_are_physical(tmp_path, capsys):
    example = runpy.run_path(str(DOCS / "examples" / "quickstart.py"))
    numbers = example["main"](tmp_path)
    out = capsys.readouterr().out
    assert f"{numbers['phi_J']:.10g}" in out
    # CALiPPSO only inflates: the jammed packing is denser than the LS snapshot it started from
    assert numbers["phi_J"] > numbers["phi_LS"]
    # and the LS equation of state near jamming, phi = phi_J (1 - d / p) (CALiPPSO paper Eq. 15), links them
    d, p = 2, numbers["p_LS"]
    assert (1 - numbers["phi_LS"] / numbers["phi_J"]) * p / d == pytest.approx(1.0, rel=0.2)
    assert numbers["N_c"] == numbers["isostatic count"]
    atoms = ase.io.read(tmp_path / "jammed.xyz", format="extxyz")
    assert len(atoms) == 32 and list(atoms.pbc) == [True, True, False]


def test_every_page_is_in_the_nav_and_every_nav_entry_exists():
    config = yaml.safe_load((REPO / "mkdocs.yml").read_text())
    nav = {next(iter(entry.values())) for entry in config["nav"]}
    pages = {p.relative_to(DOCS).as_posix() for p in DOCS.glob("*.md")}
    assert nav == pages


@pytest.mark.slow
def test_docs_build_without_warnings(tmp_path):
    # needs the docs extra: pip install -e ".[docs]"
    res = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path / "site")],
                         cwd=REPO, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stdout + res.stderr
    assert "WARNING" not in res.stderr
    api = (tmp_path / "site" / "api" / "index.html").read_text()
    for name in ("random_packing", "calippso", "load_scene", "write_xyz", "Packing"):
        assert name in api


def test_every_test_the_reliability_page_names_exists():
    # docs/reliability.md maps each guarantee to its test; a renamed or deleted test must fail here
    import re

    text = (DOCS / "reliability.md").read_text()
    named = set(re.findall(r"\b(test_[a-z0-9_]+)\b(?!\.py)", text)) - {
        name for name in re.findall(r"\b(test_[a-z0-9_]+)\.py", text)}
    defined = {m for path in (REPO / "tests").glob("test_*.py")
               for m in re.findall(r"^def (test_[a-z0-9_]+)\(", path.read_text(), flags=re.M)}
    assert named, "the page names no test"
    assert named <= defined, f"tests named in docs/reliability.md that do not exist: {sorted(named - defined)}"
