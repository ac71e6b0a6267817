# Linked packings (soft-chains-of-spheres paper): the scenes chains-fig2 (rigid trimers,
# jammed, packing figures per dimension) and chains-fig5 (cemented monomer packings,
# moduli against the added links per sphere). Everything under results/<scene>/chains/.

wildcard_constraints:
    d="[23]",
    seed="[0-9]+",
    cement="[0-9]+",
    draw="[0-9]+",


rule chains_start:
    output:
        f"{CHAINS_DIR}/d{{d}}/seed{{seed}}/start.nc",
    log:
        f"{LOGS}/chains/start_d{{d}}_seed{{seed}}.log",
    benchmark:
        f"{BENCH}/chains/start_d{{d}}_seed{{seed}}.tsv"
    threads: job_threads("init")
    resources:
        **job_resources("init"),
    params:
        command=lambda wildcards, output: chains_start_command(wildcards, output[0]),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "{params.command} > {log} 2>&1"


rule chains_jam:
    input:
        f"{CHAINS_DIR}/d{{d}}/seed{{seed}}/start.nc",
    output:
        f"{CHAINS_DIR}/d{{d}}/seed{{seed}}/jammed.nc",
    log:
        f"{LOGS}/chains/jam_d{{d}}_seed{{seed}}.log",
    benchmark:
        f"{BENCH}/chains/jam_d{{d}}_seed{{seed}}.tsv"
    threads: job_threads("soft")
    resources:
        **job_resources("soft"),
    params:
        options=chains_jam_options(),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow soft-jam {input} {output} {params.options} > {log} 2>&1"


rule chains_check:
    input:
        f"{CHAINS_DIR}/d{{d}}/seed{{seed}}/jammed.nc",
    output:
        f"{CHAINS_DIR}/d{{d}}/seed{{seed}}/jammed.check.json",
    log:
        f"{LOGS}/chains/check_d{{d}}_seed{{seed}}.log",
    benchmark:
        f"{BENCH}/chains/check_d{{d}}_seed{{seed}}.tsv"
    threads: job_threads("check")
    resources:
        **job_resources("check"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow check {input} --json > {output} 2> {log}"


rule chains_plot_packing:
    input:
        f"{CHAINS_DIR}/d{{d}}/seed{{seed}}/jammed.nc",
    output:
        png=report(
            f"{RESULTS}/figures/chains-packing_d{{d}}_seed{{seed}}.png",
            caption="../report/chains-packing.rst",
            category="Linked packings",
            subcategory="d = {d}",
        ),
        pdf=f"{RESULTS}/figures/chains-packing_d{{d}}_seed{{seed}}.pdf",
    log:
        f"{LOGS}/figures/chains-packing_d{{d}}_seed{{seed}}.log",
    benchmark:
        f"{BENCH}/figures/chains-packing_d{{d}}_seed{{seed}}.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot packing {input} {output.png} --soft > {log} 2>&1"


rule chains_cement:
    input:
        f"{CHAINS_DIR}/d3/seed{{seed}}/jammed.nc",
    output:
        f"{CHAINS_DIR}/d3/seed{{seed}}/cement{{cement}}_draw{{draw}}.nc",
    log:
        f"{LOGS}/chains/cement_seed{{seed}}_{{cement}}_{{draw}}.log",
    benchmark:
        f"{BENCH}/chains/cement_seed{{seed}}_{{cement}}_{{draw}}.tsv"
    threads: job_threads("init")
    resources:
        **job_resources("init"),
    params:
        # one seed per (packing, count, draw): the draws of different counts are independent
        seed=lambda wildcards: 1_000_000 * int(wildcards.seed) + 1000 * int(wildcards.cement) + int(wildcards.draw),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow link {input} {output} --cement {wildcards.cement} --seed {params.seed} --with-strain > {log} 2>&1"


rule chains_moduli:
    input:
        f"{CHAINS_DIR}/d3/seed{{seed}}/cement{{cement}}_draw{{draw}}.nc",
    output:
        f"{CHAINS_DIR}/d3/seed{{seed}}/moduli_cement{{cement}}_draw{{draw}}.nc",
    log:
        f"{LOGS}/chains/moduli_seed{{seed}}_{{cement}}_{{draw}}.log",
    benchmark:
        f"{BENCH}/chains/moduli_seed{{seed}}_{{cement}}_{{draw}}.tsv"
    threads: job_threads("moduli")
    resources:
        **job_resources("moduli"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow moduli {input} {output} > {log} 2>&1"


rule chains_moduli_table:
    input:
        [f"{CHAINS_DIR}/d3/seed{s}/moduli_cement{k}_draw{r}.nc" for s, k, r in chains_cemented()]
        if CHAINS.get("figure") == "fig5"
        else [],
    output:
        f"{RESULTS}/analysis/chains-moduli.nc",
    log:
        f"{LOGS}/analysis/chains-moduli.log",
    benchmark:
        f"{BENCH}/analysis/chains-moduli.tsv"
    threads: job_threads("analysis")
    resources:
        **job_resources("analysis"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow chains-moduli {input} {output} > {log} 2>&1"


rule chains_plot_moduli:
    input:
        f"{RESULTS}/analysis/chains-moduli.nc",
    output:
        png=report(
            f"{RESULTS}/figures/chains-moduli.png",
            caption="../report/chains-moduli.rst",
            category="Linked packings",
            subcategory="moduli",
        ),
        pdf=f"{RESULTS}/figures/chains-moduli.pdf",
    log:
        f"{LOGS}/figures/chains-moduli.log",
    benchmark:
        f"{BENCH}/figures/chains-moduli.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot chains-moduli {input} {output.png} > {log} 2>&1"
