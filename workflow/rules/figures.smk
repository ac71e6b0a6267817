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
    shell:
        "jamflow plot packing {input} {output.png} > {log} 2>&1"
