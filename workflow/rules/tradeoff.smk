# Speed against accuracy: one sweep per stage (jamflow tradeoff) and its Pareto plot.


rule tradeoff:
    output:
        f"{RESULTS}/tradeoff/{{stage}}.nc",
    log:
        f"{LOGS}/tradeoff/{{stage}}.log",
    benchmark:
        f"{BENCH}/tradeoff/{{stage}}.tsv"
    threads: job_threads("tradeoff")
    resources:
        **job_resources("tradeoff"),
    wildcard_constraints:
        stage="[a-z]+",
    params:
        options=stage_options("tradeoff", quick="--quick", seed="--seed"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow tradeoff {wildcards.stage} {output} {params.options} > {log} 2>&1"


rule plot_pareto:
    input:
        f"{RESULTS}/tradeoff/{{stage}}.nc",
    output:
        png=report(
            f"{RESULTS}/figures/pareto_{{stage}}.png",
            caption="../report/pareto.rst",
            category="Speed versus accuracy",
            subcategory="{stage}",
        ),
        pdf=f"{RESULTS}/figures/pareto_{{stage}}.pdf",
    log:
        f"{LOGS}/figures/pareto_{{stage}}.log",
    benchmark:
        f"{BENCH}/figures/pareto_{{stage}}.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    wildcard_constraints:
        stage="[a-z]+",
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot pareto {input} {output.png} > {log} 2>&1"
