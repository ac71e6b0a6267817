# jamflow workflow: a scene (config/*.yaml, docs/scenes.md) names bodies, seeds, a chain of
# stages, analyses, studies and figures; jamflow.scenes checks it against the stage table and
# plans every job; workflow/rules/common.smk reads the plan, workflow/rules/stages.smk makes
# one rule per step, analysis, study and figure. `--config scale=paper` picks the paper's size.
from snakemake.utils import min_version

min_version("9.0")


# The default scene, unless a scene is given with --configfile (scenes are not merged
# into the default: a scene file is complete on its own).
if "scene" not in config:

    configfile: "config/config.yaml"



report: "workflow/report/workflow.rst"


include: "workflow/rules/common.smk"
include: "workflow/rules/stages.smk"


rule all:
    input:
        PLAN.targets,
    default_target: True
