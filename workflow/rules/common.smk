# Helpers shared by the rules: scene validation, sample names, stage chain, target list.
# Stage outputs live under results/<scene>/; rules only call the jamflow CLI.

# Scene validation comes first: the schema, reporting the most relevant error in one line
# that names the key (not the whole schema), then the orderings a JSON schema cannot
# state. snakemake's validate fills in the schema's defaults.
from pathlib import Path

import jsonschema
import yaml
from snakemake.exceptions import WorkflowError
from snakemake.utils import validate

SCENE_SCHEMA = Path(workflow.basedir) / "workflow" / "schemas" / "config.schema.yaml"


def check_scene_schema():
    """Raise one line naming the key of the schema's most relevant error."""
    schema = yaml.safe_load(SCENE_SCHEMA.read_text())
    error = jsonschema.exceptions.best_match(jsonschema.Draft202012Validator(schema).iter_errors(config))
    if error is not None:
        where = ".".join(str(p) for p in error.absolute_path) or "top level"
        raise WorkflowError(f"Error validating config: {where}: {error.message}")


def check_scene_order():
    """Orderings the schema cannot state: increasing LS targets, non-empty fit windows."""
    targets = config.get("ls", {}).get("p_targets", [])
    if any(b <= a for a, b in zip(targets, targets[1:])):
        raise WorkflowError(f"Error validating config: ls.p_targets must be strictly increasing, got {targets}")
    for section in ("jamming_table", "gaps"):
        window = config.get(section, {})
        if {"fit_min", "fit_max"} <= set(window) and not window["fit_min"] < window["fit_max"]:
            raise WorkflowError(f"Error validating config: {section}.fit_min ({window['fit_min']:g}) must be below "
                                f"{section}.fit_max ({window['fit_max']:g})")


check_scene_schema()
validate(config, str(SCENE_SCHEMA))
check_scene_order()


RESULTS = f"results/{config['scene']}"
LOGS = f"{RESULTS}/logs"
BENCH = f"{RESULTS}/benchmarks"
SOURCE_STAGE = "import" if "import" in config else "init"
CHAIN = [SOURCE_STAGE, *config.get("chain", [])]
FINAL = CHAIN[-1]
PRESET = config["preset"]
LS_TARGETS = config.get("ls", {}).get("p_targets", [])
LS_RATES = config.get("ls", {}).get("growth_rates", [])
WALLS = config.get("calippso", {}).get("walls", False)


def check_chain():
    """Stage orders the rules can build: LS compresses a random start and only CALiPPSO may follow it."""
    wanted = set(config.get("analyses", [])) | set(config.get("figures", []))
    needs_crunch = wanted & {"overlap", "jamming-table", "phi-j-series", "gaps-ls-vs-calippso"}
    if needs_crunch and CHAIN[-2:] != ["ls", "calippso"]:
        raise ValueError(f"{', '.join(sorted(needs_crunch))} need(s) the chain [ls, calippso]")
    if "eos" in wanted and "ls" not in CHAIN:
        raise ValueError("the eos figure needs ls in the chain")
    if wanted & {"overlap", "phi-j-series"} and len(LS_TARGETS) < 2:
        raise ValueError("overlap and phi-j-series compare packings from at least two LS p_targets")
    if WALLS and (SOURCE_STAGE != "init" or CHAIN[1:] != ["calippso"]):
        raise ValueError("calippso.walls needs the chain [calippso] from a random system (init --walls); "
                         "the other stages are periodic")
    if WALLS and (config.get("analyses") or set(config.get("figures", [])) - {"packing"}):
        raise ValueError("calippso.walls: the analyses and figures other than packing assume periodic "
                         "boundaries; set analyses: [] and figures: [packing]")
    if "ls" not in CHAIN:
        return
    if SOURCE_STAGE != "init" or CHAIN[1] != "ls":
        raise ValueError("chain: ls must come first and needs a random system (an LS snapshot is not a start)")
    if any(stage != "calippso" for stage in CHAIN[2:]):
        raise ValueError("chain: only calippso may follow ls")
    if "ls" not in config:
        raise ValueError("chain has ls but the scene has no 'ls' section with p_targets")
    if "flow" in config:
        raise ValueError("flow needs one final packing per sample; a chain with ls gives one per (kappa, p_target)")


check_chain()


def variants():
    """Suffixes of a sample's final packings: one per (kappa, p_target) after LS, else one empty."""
    if "ls" not in CHAIN:
        return [""]
    return [ls_variant(k, p) for k in LS_RATES for p in LS_TARGETS]


def ls_variant(kappa, p_target):
    return f"_k{kappa:g}_p{p_target:g}"


def samples():
    """Sample names: seed<S> per seed of a random system, or the import keys (none for a tradeoff-only scene)."""
    if "import" in config:
        return sorted(config["import"])
    if "system" in config:
        return [f"seed{s}" for s in config["system"]["seeds"]]
    return []


def seed_of(wildcards):
    """Integer seed of a random-system sample."""
    return int(wildcards.sample.removeprefix("seed"))


def packing(sample, stage):
    """Path of a sample's packing after a stage."""
    return f"{RESULTS}/packings/{sample}/{stage}.nc"


def previous_stage(stage):
    """Input packing of a stage in this scene's chain, as an input function.

    After LS the wildcard ``variant`` (``_k<kappa>_p<p_target>``) names the snapshot.
    """

    def _input(wildcards):
        return packing(wildcards.sample, f"{CHAIN[CHAIN.index(stage) - 1]}{wildcards.get('variant', '')}")

    return _input


def final_packings(variant=None):
    """Final packings of every sample, of one variant or of all."""
    chosen = variants() if variant is None else [variant]
    return [packing(s, f"{FINAL}{v}") for s in samples() for v in chosen]


def rdf_files():
    return [f"{RESULTS}/analysis/{s}/rdf{v}.nc" for s in samples() for v in variants()]


def ls_snapshots(sample, kappa):
    """The LS run of one sample at one growth rate writes one snapshot per target pressure."""
    return [packing(sample, f"ls{ls_variant(float(kappa), p)}") for p in LS_TARGETS]


def overlap_series_files():
    return [f"{RESULTS}/analysis/{s}/overlap_k{k:g}.nc" for k in LS_RATES for s in samples()]


def eos_files():
    return [f"{RESULTS}/packings/{s}/ls_k{k:g}.eos.nc" for k in LS_RATES for s in samples()]


def shear_conditions():
    """Shear runs of the scene: ``fixed-volume`` or ``p<P>`` per fixed pressure P."""
    pressures = config.get("flow", {}).get("pressures", [])
    return [f"p{p:g}" for p in pressures] if pressures else ["fixed-volume"]


def pressure_option(condition):
    """The ``jamflow shear`` option of a shear condition."""
    return "" if condition == "fixed-volume" else optional_flag("--pressure", condition.removeprefix("p"))


def shear_summaries(condition=None):
    conditions = shear_conditions() if condition is None else [condition]
    return [
        f"{RESULTS}/analysis/{s}/shear_{c}_summary.nc" for c in conditions for s in samples()
    ]


def shear_labels():
    return " ".join(f"{s}:{c}" for c in shear_conditions() for s in samples())


def opt(section, key):
    """A stage parameter from the scene, with the schema default filled in."""
    return config.get(section, {})[key]


def variant_labels():
    """Legend labels of the variants, e.g. ``kappa=1e-05,p_tar=1000``."""
    if "ls" not in CHAIN:
        return [FINAL]
    return [f"kappa={k:g},p_tar={p:g}" for k in LS_RATES for p in LS_TARGETS]


def scene_targets():
    """Everything the scene asks for, and nothing else."""
    targets = final_packings()
    analyses = config.get("analyses", [])
    if "check" in analyses:
        targets += [f"{RESULTS}/analysis/{s}/{FINAL}{v}.check.json" for s in samples() for v in variants()]
    for kind in ("gaps", "forces"):
        if kind in analyses:
            targets += [f"{RESULTS}/analysis/{kind}{v}.nc" for v in variants()]
    if "rdf" in analyses:
        targets += rdf_files()
    if "certify" in analyses:
        targets += [f"{RESULTS}/analysis/{s}/certify{v}.nc" for s in samples() for v in variants()]
    if "overlap" in analyses:
        targets += overlap_series_files()
    if "jamming-table" in analyses:
        targets.append(f"{RESULTS}/analysis/jamming-table.nc")
    if "flow" in config:
        targets += shear_summaries()
    for stage in config.get("tradeoff", {}).get("stages", []):
        targets += [f"{RESULTS}/tradeoff/{stage}.nc", f"{RESULTS}/figures/pareto_{stage}.png"]
    for fig in config.get("figures", []):
        if fig == "packing":
            targets += [f"{RESULTS}/figures/packing_{s}{variants()[-1]}.png" for s in samples()]
        elif fig == "phi-kappa":
            targets += [
                f"{RESULTS}/figures/phi-kappa_{s}_{c}.png"
                for c in shear_conditions()
                if c != "fixed-volume"
                for s in samples()
            ]
        elif fig == "ed-vs-sd":
            targets += [f"{RESULTS}/figures/ed-vs-sd_{s}.png" for s in samples()]
        else:
            targets.append(f"{RESULTS}/figures/{fig}.png")
    return targets


wildcard_constraints:
    sample="[A-Za-z0-9-]+",
    variant="(_k[0-9.e+-]+_p[0-9.e+-]+)?",
    kappa="[0-9.e+-]+",
    condition="fixed-volume|p[0-9.e+-]+",


def optional_flag(flag, value):
    """``flag value``, or nothing when the scene leaves the value to the command's default."""
    return "" if value is None else f"{flag} {value}"


def read_flags(stage):
    """Reading options for a stage's packing: soft packings carry overlaps."""
    return "--soft" if stage == "soft" else ""
