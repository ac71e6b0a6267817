# Packing stages: a source (init or import) followed by the scene's chain.


rule init:
    output:
        packing("{sample}", "init"),
    log:
        f"{LOGS}/init/{{sample}}.log",
    benchmark:
        f"{BENCH}/init/{{sample}}.tsv"
    params:
        seed=seed_of,
        system=config.get("system", {}),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow init {output} --d {params.system[d]} --n {params.system[n]}"
        " --phi {params.system[phi]} --dispersity {params.system[dispersity]}"
        " --ratio {params.system[ratio]} --fraction {params.system[fraction]}"
        " --width {params.system[width]} --species-spread {params.system[species_spread]}"
        " --seed {params.seed} --quiet > {log} 2>&1"


rule import_dat:
    input:
        lambda wildcards: config["import"][wildcards.sample],
    output:
        packing("{sample}", "import"),
    log:
        f"{LOGS}/import/{{sample}}.log",
    benchmark:
        f"{BENCH}/import/{{sample}}.tsv"
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow import-dat {input} {output} --quiet > {log} 2>&1"


rule soft_jam:
    input:
        previous_stage("soft"),
    output:
        packing("{sample}", "soft"),
    log:
        f"{LOGS}/soft/{{sample}}.log",
    benchmark:
        f"{BENCH}/soft/{{sample}}.tsv"
    params:
        preset=PRESET,
        pressure=lambda wildcards: opt("soft", "pressure"),
        force_tol=lambda wildcards: optional_flag("--force-tol", opt("soft", "force_tol")),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow soft-jam {input} {output} --pressure {params.pressure}"
        " {params.force_tol} --preset {params.preset} --quiet > {log} 2>&1"
