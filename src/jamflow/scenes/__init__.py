"""One scene grammar for every body and every study (``docs/scenes.md``).

:func:`read_scene` checks a scene against the stage table (:mod:`jamflow.stages`) and
applies its scale; :func:`plan_scene` turns it into jobs with paths, commands and costs;
the Snakemake workflow (``workflow/rules/common.smk``) makes one rule per step, analysis,
study and figure from the plan. Pure Python: no Snakemake needed to read or plan a scene.
"""

from .grammar import Scene, SceneError, did_you_mean, read_scene
from .plan import Job, Plan, format_point, plan_scene
from .report import cost_report

__all__ = ["Job", "Plan", "Scene", "SceneError", "cost_report", "did_you_mean", "format_point", "plan_scene",
           "read_scene"]
