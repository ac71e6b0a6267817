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
    shell:
        "jamflow check {input} --json > {output} 2> {log}"
