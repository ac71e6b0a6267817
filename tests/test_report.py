"""The Snakemake report's captions: every caption renders as Snakemake renders it, without a Docutils complaint.

Snakemake renders a caption as a Jinja2 template (with ``snakemake.wildcards`` etc.) and
then as reStructuredText with Docutils. A bare ``|x|`` in reStructuredText is a
substitution reference; an undefined one is a Docutils ERROR that shows up as a red
"System Message" in the report. These tests parse every caption with Docutils set to stop
at the first warning, so such markup cannot come back unnoticed.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import docutils.utils
import pytest
from docutils.core import publish_parts
from jinja2 import Environment, StrictUndefined

from jamflow.scenes.studies import FIGURES, caption_of

REPO = Path(__file__).resolve().parents[1]
CAPTIONS = sorted((REPO / "workflow" / "report").glob("*.rst"))
#: The report's front page (the Snakefile's ``report:``), not a figure caption
FRONT_PAGE = REPO / "workflow" / "report" / "workflow.rst"


def _render(path: Path) -> str:
    """The caption as Snakemake renders it (same Jinja2 settings), as HTML; a Docutils warning raises."""
    # the wildcards the figure rules have; StrictUndefined makes a missing one an error too
    # a figure rule's one wildcard (jamflow.scenes.studies.add_figures): an undefined name
    # would render empty and leave a bare ```` that Docutils warns about in the report
    wildcards = SimpleNamespace(tag="spheres_base")
    snakemake = SimpleNamespace(wildcards=wildcards, config={}, params=SimpleNamespace())
    env = Environment(trim_blocks=True, lstrip_blocks=True, undefined=StrictUndefined)
    text = env.from_string(path.read_text()).render(snakemake=snakemake, categories=[], files=[])
    # halt at WARNING (level 2): undefined substitutions (ERROR 3) and malformed markup raise
    return publish_parts(text, writer="html",
                         settings_overrides={"halt_level": 2, "report_level": 5})["body"]


def test_there_are_captions():
    assert len(CAPTIONS) >= 10


@pytest.mark.parametrize("path", CAPTIONS, ids=lambda p: p.name)
def test_caption_renders_without_docutils_messages(path):
    html = _render(path)
    assert "system-message" not in html and "problematic" not in html


def test_an_unescaped_bar_is_caught(tmp_path):
    # the check above would catch the bug it guards against: |Delta phi_J| is a substitution
    bad = tmp_path / "bad.rst"
    bad.write_text("Panels: |Delta phi_J| against p_tar.\n")
    with pytest.raises(docutils.utils.SystemMessage, match="Undefined substitution"):
        _render(bad)


def test_escaped_bars_render_as_bars():
    html = _render(REPO / "workflow" / "report" / "phi-j-series.rst")
    assert "|Delta phi_J|" in html


def test_every_referenced_caption_exists_and_every_caption_is_used():
    # the figure rules take their caption from caption_of (workflow/rules/common.smk)
    assert "caption_of(figure)" in (REPO / "workflow" / "rules" / "common.smk").read_text()
    # every scene figure, and the tradeoff scene's Pareto fronts (figure_pareto)
    referenced = {f"{caption_of(figure)}.rst" for figure in (*FIGURES, "pareto")}
    assert referenced == {p.name for p in CAPTIONS} - {FRONT_PAGE.name}


def test_the_report_has_a_front_page_describing_the_workflow():
    assert f'report: "{FRONT_PAGE.relative_to(REPO).as_posix()}"' in (REPO / "Snakefile").read_text()
    html = _render(FRONT_PAGE)
    assert "system-message" not in html and "scene" in html and "stage table" in html


def test_the_package_depends_on_what_snakemake_report_needs():
    # `snakemake --report` imports pygments, which only snakemake's [reports] extra installs
    import tomllib

    deps = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["dependencies"]
    snakemake = [d for d in deps if d.replace(" ", "").startswith("snakemake[")]
    assert snakemake and "reports" in snakemake[0].split("[", 1)[1].split("]", 1)[0].split(",")
