# jamflow workflow: a scene (config/*.yaml) names a system, a protocol chain, analyses and
# figures; this file includes the scene validation (rules/common.smk) and the stages.
from snakemake.utils import min_version

min_version("9.0")


# The default scene, unless a scene is given with --configfile (scenes are not merged
# into the default: a scene file is complete on its own).
if not config:

    configfile: "config/config.yaml"



include: "workflow/rules/common.smk"
include: "workflow/rules/pack.smk"
include: "workflow/rules/flow.smk"
include: "workflow/rules/analysis.smk"
include: "workflow/rules/figures.smk"
include: "workflow/rules/tradeoff.smk"
include: "workflow/rules/chains.smk"
include: "workflow/rules/shapes_common.smk"
include: "workflow/rules/shapes.smk"


rule all:
    input:
        scene_targets(),
    default_target: True
