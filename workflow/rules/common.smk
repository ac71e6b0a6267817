# The scene and its plan: jamflow.scenes checks it against the stage table (jamflow.stages)
# and plans every job (paths, commands, costs); the schema states its top-level shape.
# A scene that cannot run fails here, in one line naming the key, before any job.
import sys
from pathlib import Path

from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

from jamflow.scenes import SceneError, cost_report, plan_scene, read_scene
from jamflow.scenes.plan import WILDCARDS
from jamflow.scenes.resources import request_mb, request_minutes

try:
    PLAN = plan_scene(read_scene(dict(config)))
except SceneError as error:
    raise WorkflowError(f"Error in scene: {error}") from None
# the schema states the scene's top-level shape (read_scene has checked it, with suggestions)
validate(config, str(Path(workflow.basedir) / "workflow" / "schemas" / "config.schema.yaml"))

# each job's threads, memory and runtime per rule and the scene's expected core-hours
print("\n".join(cost_report(PLAN)), file=sys.stderr)


def job_inputs(rule):
    return lambda wildcards: PLAN.job(rule, wildcards).inputs


def job_command(rule):
    """The job's shell command (jamflow CLI), with its log path from the rule's template."""
    spec = PLAN.rules[rule]
    return lambda wildcards: PLAN.job(rule, wildcards).command(spec.log.format(**dict(wildcards.items())))


def job_threads(rule):
    return lambda wildcards: PLAN.job(rule, wildcards).threads


def job_resources(rule):
    """mem_mb and runtime [min] requests from the resource table; a retry asks for `attempt` times both."""

    def mem_mb(wildcards, attempt):
        return request_mb(PLAN.job(rule, wildcards).mem_mb, attempt)

    def runtime(wildcards, attempt):
        return request_minutes(PLAN.job(rule, wildcards).cpu_s, attempt)

    return {"mem_mb": mem_mb, "runtime": runtime}


def job_group(rule):
    """Cluster group of the job: whole samples bundled to about `resources.group_minutes` each."""
    return lambda wildcards: PLAN.job(rule, wildcards).group


def rule_outputs(spec):
    """The rule's outputs; a figure's PNG goes into `snakemake --report` with its caption (workflow/report/)."""
    if not spec.name.startswith("figure_"):
        return spec.outputs
    figure = spec.name.removeprefix("figure_").replace("_", "-")
    caption = {"gaps-windows": "fit-windows", "forces-windows": "fit-windows"}.get(figure, figure)
    png = report(spec.outputs[0], caption=f"../report/{caption}.rst", category="Figures")
    return [png, *spec.outputs[1:]]


localrules:
    all,
