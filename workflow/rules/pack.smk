# Packing stages: a source (init or import) followed by the scene's chain.


rule init:
    output:
        packing("{sample}", "init"),
    log:
        f"{LOGS}/init/{{sample}}.log",
    benchmark:
        f"{BENCH}/init/{{sample}}.tsv"
    threads: job_threads("init")
    resources:
        **job_resources("init"),
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
        " --seed {params.seed} {params.walls} > {log} 2>&1"


rule import_dat:
    input:
        lambda wildcards: config["import"][wildcards.sample],
    output:
        packing("{sample}", "import"),
    log:
        f"{LOGS}/import/{{sample}}.log",
    benchmark:
        f"{BENCH}/import/{{sample}}.tsv"
    threads: job_threads("import")
    resources:
        **job_resources("import"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow import-dat {input} {output} > {log} 2>&1"


rule soft_jam:
    input:
        previous_stage("soft"),
    output:
        packing("{sample}", "soft"),
    log:
        f"{LOGS}/soft/{{sample}}.log",
    benchmark:
        f"{BENCH}/soft/{{sample}}.tsv"
    threads: job_threads("soft")
    resources:
        **job_resources("soft"),
    params:
        preset=PRESET,
        options=stage_options("soft", pressure="--pressure", force_tol="--force-tol"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow soft-jam {input} {output} {params.options} --preset {params.preset} > {log} 2>&1"


rule decompress:
    input:
        previous_stage("decompress"),
    output:
        packing("{sample}", "decompress{variant}"),
    log:
        f"{LOGS}/decompress/{{sample}}{{variant}}.log",
    benchmark:
        f"{BENCH}/decompress/{{sample}}{{variant}}.tsv"
    threads: job_threads("decompress")
    resources:
        **job_resources("decompress"),
    params:
        phi=lambda wildcards: opt("decompress", "phi"),
        read=read_flags(CHAIN[CHAIN.index("decompress") - 1]) if "decompress" in CHAIN else "",
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow decompress {input} {output} --phi {params.phi} {params.read} > {log} 2>&1"


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
    threads: job_threads("ls")
    resources:
        **job_resources("ls"),
    params:
        seed=seed_of,
        preset=PRESET,
        targets=" ".join(f"{p:g}" for p in LS_TARGETS),
        # null in the scene skips the fast stage, which the command spells as rate 0
        options=stage_options(
            "ls",
            fast_growth_rate=("--fast-growth-rate", 0),
            fast_until="--fast-until",
            beta="--beta",
            max_collisions="--max-collisions",
        ),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow ls {input} {output.snapshots} --growth-rate {wildcards.kappa} --p-target {params.targets}"
        " {params.options} --seed {params.seed} --eos {output.eos} --preset {params.preset} > {log} 2>&1"


rule calippso:
    input:
        previous_stage("calippso"),
    output:
        packing("{sample}", "calippso{variant}"),
    log:
        f"{LOGS}/calippso/{{sample}}{{variant}}.log",
    benchmark:
        f"{BENCH}/calippso/{{sample}}{{variant}}.tsv"
    threads: job_threads("calippso")
    resources:
        **job_resources("calippso"),
    params:
        preset=PRESET,
        options=stage_options(
            "calippso", tol_s="--tol-s", tol_gamma="--tol-gamma", solver="--solver", solver_tol="--solver-tol", walls="--walls",
            finish="--finish",
        ),
        read=read_flags(CHAIN[CHAIN.index("calippso") - 1]) if "calippso" in CHAIN else "",
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow calippso {input} {output} {params.options} {params.read} --threads {threads}"
        " --preset {params.preset} > {log} 2>&1"
