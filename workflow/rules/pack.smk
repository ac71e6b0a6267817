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
        walls="--walls" if WALLS else "",
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow init {output} --d {params.system[d]} --n {params.system[n]}"
        " --phi {params.system[phi]} --dispersity {params.system[dispersity]}"
        " --ratio {params.system[ratio]} --fraction {params.system[fraction]}"
        " --width {params.system[width]} --species-spread {params.system[species_spread]}"
        " --seed {params.seed} {params.walls} --quiet > {log} 2>&1"


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


rule ls:
    input:
        packing("{sample}", "init"),
    output:
        snapshots=[packing("{sample}", f"ls_k{{kappa}}_p{p:g}") for p in LS_TARGETS],
        eos=f"{RESULTS}/packings/{{sample}}/ls_k{{kappa}}.eos.nc",
    log:
        f"{LOGS}/ls/{{sample}}_k{{kappa}}.log",
    benchmark:
        f"{BENCH}/ls/{{sample}}_k{{kappa}}.tsv"
    params:
        seed=seed_of,
        preset=PRESET,
        targets=" ".join(f"{p:g}" for p in LS_TARGETS),
        # null in the scene skips the fast stage, which the command spells as rate 0
        fast=lambda wildcards: opt("ls", "fast_growth_rate") or 0,
        fast_until=lambda wildcards: opt("ls", "fast_until"),
        beta=lambda wildcards: opt("ls", "beta"),
        max_collisions=lambda wildcards: optional_flag("--max-collisions", opt("ls", "max_collisions")),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow ls {input} {output.snapshots} --growth-rate {wildcards.kappa} --p-target {params.targets}"
        " --fast-growth-rate {params.fast} --fast-until {params.fast_until} --beta {params.beta} {params.max_collisions}"
        " --seed {params.seed} --eos {output.eos} --preset {params.preset} --quiet > {log} 2>&1"


rule calippso:
    input:
        previous_stage("calippso"),
    output:
        packing("{sample}", "calippso{variant}"),
    log:
        f"{LOGS}/calippso/{{sample}}{{variant}}.log",
    benchmark:
        f"{BENCH}/calippso/{{sample}}{{variant}}.tsv"
    params:
        preset=PRESET,
        tol_s=lambda wildcards: optional_flag("--tol-s", opt("calippso", "tol_s")),
        tol_gamma=lambda wildcards: optional_flag("--tol-gamma", opt("calippso", "tol_gamma")),
        solver=lambda wildcards: optional_flag("--solver", opt("calippso", "solver")),
        solver_tol=lambda wildcards: optional_flag("--solver-tol", opt("calippso", "solver_tol")),
        walls="--walls" if opt("calippso", "walls") else "",
        read=read_flags(CHAIN[CHAIN.index("calippso") - 1]) if "calippso" in CHAIN else "",
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow calippso {input} {output} {params.tol_s} {params.tol_gamma} {params.solver} {params.solver_tol}"
        " {params.walls} {params.read} --preset {params.preset} --quiet > {log} 2>&1"
