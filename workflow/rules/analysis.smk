# Analyses of the final packing of every sample.


rule check:
    input:
        packing("{sample}", "{stage}"),
    output:
        f"{RESULTS}/analysis/{{sample}}/{{stage}}.check.json",
    log:
        f"{LOGS}/check/{{sample}}_{{stage}}.log",
    benchmark:
        f"{BENCH}/check/{{sample}}_{{stage}}.tsv"
    threads: job_threads("check")
    resources:
        **job_resources("check"),
    wildcard_constraints:
        stage="[a-z]+(_k[0-9.e+-]+_p[0-9.e+-]+)?",
    conda:
        "../envs/jamflow.yaml"
    params:
        read=lambda wildcards: read_flags(wildcards.stage),
    shell:
        "jamflow check {input} --json {params.read} > {output} 2> {log}"


rule gaps:
    input:
        lambda wildcards: final_packings(wildcards.variant),
    output:
        f"{RESULTS}/analysis/gaps{{variant}}.nc",
    log:
        f"{LOGS}/analysis/gaps{{variant}}.log",
    benchmark:
        f"{BENCH}/analysis/gaps{{variant}}.tsv"
    threads: job_threads("gaps")
    resources:
        **job_resources("gaps"),
    params:
        read=read_flags(FINAL),
        fit_min=opt("gaps", "fit_min"),
        fit_max=opt("gaps", "fit_max"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow gaps {input} {output} --fit-min {params.fit_min} --fit-max {params.fit_max}"
        " {params.read} > {log} 2>&1"


rule forces:
    input:
        lambda wildcards: final_packings(wildcards.variant),
    output:
        f"{RESULTS}/analysis/forces{{variant}}.nc",
    log:
        f"{LOGS}/analysis/forces{{variant}}.log",
    benchmark:
        f"{BENCH}/analysis/forces{{variant}}.tsv"
    threads: job_threads("forces")
    resources:
        **job_resources("forces"),
    params:
        read=read_flags(FINAL),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow forces {input} {output} {params.read} > {log} 2>&1"


rule rdf:
    input:
        packing("{sample}", f"{FINAL}{{variant}}"),
    output:
        f"{RESULTS}/analysis/{{sample}}/rdf{{variant}}.nc",
    log:
        f"{LOGS}/analysis/rdf_{{sample}}{{variant}}.log",
    benchmark:
        f"{BENCH}/analysis/rdf_{{sample}}{{variant}}.tsv"
    threads: job_threads("rdf")
    resources:
        **job_resources("rdf"),
    params:
        read=read_flags(FINAL),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow rdf {input} {output} {params.read} > {log} 2>&1"


rule certify:
    input:
        packing("{sample}", f"{FINAL}{{variant}}"),
    output:
        f"{RESULTS}/analysis/{{sample}}/certify{{variant}}.nc",
    log:
        f"{LOGS}/analysis/certify_{{sample}}{{variant}}.log",
    benchmark:
        f"{BENCH}/analysis/certify_{{sample}}{{variant}}.tsv"
    threads: job_threads("certify")
    resources:
        **job_resources("certify"),
    params:
        preset=PRESET,
        strict="--strict" if opt("certify", "strict") else "",
        loads=optional_flag("--loads", opt("certify", "loads")),
        read=read_flags(FINAL),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow certify {input} {output} {params.strict} {params.loads} --preset {params.preset}"
        " {params.read} > {log} 2>&1"


rule ls_gaps:
    input:
        lambda wildcards: [packing(s, f"ls{wildcards.variant}") for s in samples()],
    output:
        f"{RESULTS}/analysis/ls-gaps{{variant}}.nc",
    log:
        f"{LOGS}/analysis/ls-gaps{{variant}}.log",
    benchmark:
        f"{BENCH}/analysis/ls-gaps{{variant}}.tsv"
    threads: job_threads("gaps")
    resources:
        **job_resources("gaps"),
    params:
        fit_min=opt("gaps", "fit_min"),
        fit_max=opt("gaps", "fit_max"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        # an LS snapshot at finite pressure has no contacts (so no rattlers): every positive gap is binned
        "jamflow gaps {input} {output} --gap-tol 0 --include-rattlers --fit-min {params.fit_min} --fit-max {params.fit_max}"
        " > {log} 2>&1"


rule overlap_series:
    input:
        lambda wildcards: [packing(wildcards.sample, f"{FINAL}{ls_variant(float(wildcards.kappa), p)}") for p in LS_TARGETS],
    output:
        f"{RESULTS}/analysis/{{sample}}/overlap_k{{kappa}}.nc",
    log:
        f"{LOGS}/analysis/overlap_{{sample}}_k{{kappa}}.log",
    benchmark:
        f"{BENCH}/analysis/overlap_{{sample}}_k{{kappa}}.tsv"
    threads: job_threads("overlap")
    resources:
        **job_resources("overlap"),
    params:
        targets=" ".join(f"{p:g}" for p in LS_TARGETS),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow overlap-series {input} {output} --p-target {params.targets}"
        " --growth-rate {wildcards.kappa} > {log} 2>&1"


rule jamming_table:
    input:
        series=overlap_series_files(),
        eos=eos_files(),
    output:
        f"{RESULTS}/analysis/jamming-table.nc",
    log:
        f"{LOGS}/analysis/jamming-table.log",
    benchmark:
        f"{BENCH}/analysis/jamming-table.tsv"
    threads: job_threads("jamming_table")
    resources:
        **job_resources("jamming_table"),
    params:
        p_min=opt("jamming_table", "fit_min"),
        p_max=opt("jamming_table", "fit_max"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow jamming-table {input.series} {output} --eos {input.eos}"
        " --fit-min {params.p_min} --fit-max {params.p_max} > {log} 2>&1"
