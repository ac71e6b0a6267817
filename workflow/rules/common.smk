# Helpers shared by the rules: sample names, stage chain, target list.
# Stage outputs live under results/<scene>/; rules only call the jamflow CLI.

RESULTS = f"results/{config['scene']}"
LOGS = f"{RESULTS}/logs"
BENCH = f"{RESULTS}/benchmarks"
SOURCE_STAGE = "import" if "import" in config else "init"
CHAIN = [SOURCE_STAGE, *config.get("chain", [])]
FINAL = CHAIN[-1]
PRESET = config["preset"]


def samples():
    """Sample names: seed<S> per seed of a random system, or the import keys."""
    if "import" in config:
        return sorted(config["import"])
    return [f"seed{s}" for s in config["system"]["seeds"]]


def seed_of(wildcards):
    """Integer seed of a random-system sample."""
    return int(wildcards.sample.removeprefix("seed"))


def packing(sample, stage):
    """Path of a sample's packing after a stage."""
    return f"{RESULTS}/packings/{sample}/{stage}.nc"


def previous_stage(stage):
    """Input packing of a stage in this scene's chain, as an input function."""

    def _input(wildcards):
        return packing(wildcards.sample, CHAIN[CHAIN.index(stage) - 1])

    return _input


def final_packings():
    return [packing(s, FINAL) for s in samples()]


def rdf_files():
    return [f"{RESULTS}/analysis/{s}/rdf.nc" for s in samples()]


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


def scene_targets():
    """Everything the scene asks for, and nothing else."""
    targets = final_packings()
    analyses = config.get("analyses", [])
    if "check" in analyses:
        targets += [f"{RESULTS}/analysis/{s}/{FINAL}.check.json" for s in samples()]
    for kind in ("gaps", "forces"):
        if kind in analyses:
            targets.append(f"{RESULTS}/analysis/{kind}.nc")
    if "rdf" in analyses:
        targets += rdf_files()
    if "certify" in analyses:
        targets += [f"{RESULTS}/analysis/{s}/certify.nc" for s in samples()]
    if "flow" in config:
        targets += shear_summaries()
    for fig in config.get("figures", []):
        if fig == "packing":
            targets += [f"{RESULTS}/figures/packing_{s}.png" for s in samples()]
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
    condition="fixed-volume|p[0-9.e+-]+",


def optional_flag(flag, value):
    """``flag value``, or nothing when the scene leaves the value to the command's default."""
    return "" if value is None else f"{flag} {value}"


def read_flags(stage):
    """Reading options for a stage's packing: soft packings carry overlaps."""
    return "--soft" if stage == "soft" else ""
