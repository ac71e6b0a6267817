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
    wildcard_constraints:
        stage="[a-z]+",
    conda:
        "../envs/jamflow.yaml"
    params:
        read=lambda wildcards: read_flags(wildcards.stage),
    shell:
        "jamflow check {input} --json {params.read} > {output} 2> {log}"


rule gaps:
    input:
        final_packings(),
    output:
        f"{RESULTS}/analysis/gaps.nc",
    log:
        f"{LOGS}/analysis/gaps.log",
    benchmark:
        f"{BENCH}/analysis/gaps.tsv"
    params:
        read=read_flags(FINAL),
        fit_min=opt("gaps", "fit_min"),
        fit_max=opt("gaps", "fit_max"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow gaps {input} {output} --fit-min {params.fit_min} --fit-max {params.fit_max}"
        " {params.read} --quiet > {log} 2>&1"


rule forces:
    input:
        final_packings(),
    output:
        f"{RESULTS}/analysis/forces.nc",
    log:
        f"{LOGS}/analysis/forces.log",
    benchmark:
        f"{BENCH}/analysis/forces.tsv"
    params:
        read=read_flags(FINAL),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow forces {input} {output} {params.read} > {log} 2>&1"


rule rdf:
    input:
        packing("{sample}", FINAL),
    output:
        f"{RESULTS}/analysis/{{sample}}/rdf.nc",
    log:
        f"{LOGS}/analysis/rdf_{{sample}}.log",
    benchmark:
        f"{BENCH}/analysis/rdf_{{sample}}.tsv"
    params:
        read=read_flags(FINAL),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow rdf {input} {output} {params.read} > {log} 2>&1"


rule certify:
    input:
        packing("{sample}", FINAL),
    output:
        f"{RESULTS}/analysis/{{sample}}/certify.nc",
    log:
        f"{LOGS}/analysis/certify_{{sample}}.log",
    benchmark:
        f"{BENCH}/analysis/certify_{{sample}}.tsv"
    params:
        preset=PRESET,
        strict="--strict" if opt("certify", "strict") else "",
        loads=optional_flag("--loads", opt("certify", "loads")),
        read=read_flags(FINAL),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow certify {input} {output} {params.strict} {params.loads} --preset {params.preset}"
        " {params.read} --quiet > {log} 2>&1"
