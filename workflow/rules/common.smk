# Helpers shared by the rules: sample names, stage chain, target list.
# Stage outputs live under results/<scene>/; rules only call the jamflow CLI.

RESULTS = f"results/{config['scene']}"
LOGS = f"{RESULTS}/logs"
BENCH = f"{RESULTS}/benchmarks"
SOURCE_STAGE = "import" if "import" in config else "init"
CHAIN = [SOURCE_STAGE, *config.get("chain", [])]
FINAL = CHAIN[-1]


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
    for fig in config.get("figures", []):
        if fig == "packing":
            targets += [f"{RESULTS}/figures/packing_{s}.png" for s in samples()]
        else:
            targets.append(f"{RESULTS}/figures/{fig}.png")
    return targets


wildcard_constraints:
    sample="[A-Za-z0-9_-]+",


def read_flags(stage):
    """Reading options for a stage's packing: soft packings carry overlaps."""
    return "--soft" if stage == "soft" else ""
