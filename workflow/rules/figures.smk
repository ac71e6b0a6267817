# Figures (PNG and PDF) registered in the Snakemake report.


rule plot_packing:
    input:
        packing("{sample}", FINAL),
    output:
        png=report(
            f"{RESULTS}/figures/packing_{{sample}}.png",
            caption="../report/packing.rst",
            category="Packings",
            subcategory="{sample}",
        ),
        pdf=f"{RESULTS}/figures/packing_{{sample}}.pdf",
    log:
        f"{LOGS}/figures/packing_{{sample}}.log",
    benchmark:
        f"{BENCH}/figures/packing_{{sample}}.tsv"
    conda:
        "../envs/jamflow.yaml"
    params:
        read=read_flags(FINAL),
    shell:
        "jamflow plot packing {input} {output.png} {params.read} > {log} 2>&1"


rule plot_gaps:
    input:
        f"{RESULTS}/analysis/gaps.nc",
    output:
        png=report(
            f"{RESULTS}/figures/gaps.png",
            caption="../report/gaps.rst",
            category="Analyses",
        ),
        pdf=f"{RESULTS}/figures/gaps.pdf",
    log:
        f"{LOGS}/figures/gaps.log",
    benchmark:
        f"{BENCH}/figures/gaps.tsv"
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot gaps {input} {output.png} > {log} 2>&1"


rule plot_forces:
    input:
        f"{RESULTS}/analysis/forces.nc",
    output:
        png=report(
            f"{RESULTS}/figures/forces.png",
            caption="../report/forces.rst",
            category="Analyses",
        ),
        pdf=f"{RESULTS}/figures/forces.pdf",
    log:
        f"{LOGS}/figures/forces.log",
    benchmark:
        f"{BENCH}/figures/forces.tsv"
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot forces {input} {output.png} > {log} 2>&1"


rule plot_rdf:
    input:
        rdf_files(),
    output:
        png=report(
            f"{RESULTS}/figures/rdf.png",
            caption="../report/rdf.rst",
            category="Analyses",
        ),
        pdf=f"{RESULTS}/figures/rdf.pdf",
    log:
        f"{LOGS}/figures/rdf.log",
    benchmark:
        f"{BENCH}/figures/rdf.tsv"
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot rdf {input} {output.png} > {log} 2>&1"
