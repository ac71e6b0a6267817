# Figures (PNG and PDF) registered in the Snakemake report.


rule plot_packing:
    input:
        packing("{sample}", f"{FINAL}{{variant}}"),
    output:
        png=report(
            f"{RESULTS}/figures/packing_{{sample}}{{variant}}.png",
            caption="../report/packing.rst",
            category="Packings",
            subcategory="{sample}",
        ),
        pdf=f"{RESULTS}/figures/packing_{{sample}}{{variant}}.pdf",
    log:
        f"{LOGS}/figures/packing_{{sample}}{{variant}}.log",
    benchmark:
        f"{BENCH}/figures/packing_{{sample}}{{variant}}.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    params:
        read=read_flags(FINAL),
    shell:
        "jamflow plot packing {input} {output.png} {params.read} > {log} 2>&1"


rule plot_gaps:
    input:
        [f"{RESULTS}/analysis/gaps{v}.nc" for v in variants()],
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
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    params:
        labels=" ".join(variant_labels()),
    shell:
        "jamflow plot gaps {input} {output.png} --labels {params.labels} > {log} 2>&1"


rule plot_forces:
    input:
        # after LS: the packings crunched from the largest target pressure
        f"{RESULTS}/analysis/forces{variants()[-1]}.nc",
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
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot forces {input} {output.png} > {log} 2>&1"


rule plot_gap_windows:
    input:
        # the packings jammed from the largest target pressure (after LS), as in plot_forces
        f"{RESULTS}/analysis/gaps{variants()[-1]}.nc",
    output:
        png=report(
            f"{RESULTS}/figures/gaps-windows.png",
            caption="../report/fit-windows.rst",
            category="Analyses",
        ),
        pdf=f"{RESULTS}/figures/gaps-windows.pdf",
    log:
        f"{LOGS}/figures/gaps-windows.log",
    benchmark:
        f"{BENCH}/figures/gaps-windows.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot fit-windows {input} {output.png} > {log} 2>&1"


rule plot_force_windows:
    input:
        f"{RESULTS}/analysis/forces{variants()[-1]}.nc",
    output:
        png=report(
            f"{RESULTS}/figures/forces-windows.png",
            caption="../report/fit-windows.rst",
            category="Analyses",
        ),
        pdf=f"{RESULTS}/figures/forces-windows.pdf",
    log:
        f"{LOGS}/figures/forces-windows.log",
    benchmark:
        f"{BENCH}/figures/forces-windows.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot fit-windows {input} {output.png} > {log} 2>&1"


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
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    params:
        # same order as rdf_files(): samples outer, variants inner
        labels=" ".join(f"{s}:{v}" for s in samples() for v in variant_labels()),
    shell:
        "jamflow plot rdf {input} {output.png} --labels {params.labels} > {log} 2>&1"


rule plot_stress_strain:
    input:
        shear_summaries(),
    output:
        png=report(
            f"{RESULTS}/figures/stress-strain.png",
            caption="../report/stress-strain.rst",
            category="Flow",
        ),
        pdf=f"{RESULTS}/figures/stress-strain.pdf",
    log:
        f"{LOGS}/figures/stress-strain.log",
    benchmark:
        f"{BENCH}/figures/stress-strain.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    params:
        labels=shear_labels(),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot stress-strain {input} {output.png} --labels {params.labels} > {log} 2>&1"


rule plot_flow_curve:
    input:
        f"{RESULTS}/analysis/flow-curve.nc",
    output:
        png=report(
            f"{RESULTS}/figures/flow-curve.png",
            caption="../report/flow-curve.rst",
            category="Flow",
        ),
        pdf=f"{RESULTS}/figures/flow-curve.pdf",
    log:
        f"{LOGS}/figures/flow-curve.log",
    benchmark:
        f"{BENCH}/figures/flow-curve.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot flow-curve {input} {output.png} > {log} 2>&1"


rule plot_phi_kappa:
    input:
        f"{RESULTS}/analysis/{{sample}}/shear_{{condition}}_summary.nc",
    output:
        png=report(
            f"{RESULTS}/figures/phi-kappa_{{sample}}_{{condition}}.png",
            caption="../report/phi-kappa.rst",
            category="Flow",
            subcategory="{sample} {condition}",
        ),
        pdf=f"{RESULTS}/figures/phi-kappa_{{sample}}_{{condition}}.pdf",
    log:
        f"{LOGS}/figures/phi-kappa_{{sample}}_{{condition}}.log",
    benchmark:
        f"{BENCH}/figures/phi-kappa_{{sample}}_{{condition}}.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot phi-kappa {input} {output.png} > {log} 2>&1"


rule plot_ed_vs_sd:
    input:
        ed=f"{RESULTS}/flow/{{sample}}/shear_fixed-volume.nc",
        sd=f"{RESULTS}/flow/{{sample}}/sd_fixed-volume.nc",
    output:
        png=report(
            f"{RESULTS}/figures/ed-vs-sd_{{sample}}.png",
            caption="../report/ed-vs-sd.rst",
            category="Flow",
            subcategory="{sample}",
        ),
        pdf=f"{RESULTS}/figures/ed-vs-sd_{{sample}}.pdf",
    log:
        f"{LOGS}/figures/ed-vs-sd_{{sample}}.log",
    benchmark:
        f"{BENCH}/figures/ed-vs-sd_{{sample}}.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot stress-strain {input.ed} {input.sd} {output.png}"
        " --labels event-driven steepest-descent > {log} 2>&1"


rule plot_phi_j_series:
    input:
        overlap_series_files(),
    output:
        png=report(
            f"{RESULTS}/figures/phi-j-series.png",
            caption="../report/phi-j-series.rst",
            category="LS+CALiPPSO",
        ),
        pdf=f"{RESULTS}/figures/phi-j-series.pdf",
    log:
        f"{LOGS}/figures/phi-j-series.log",
    benchmark:
        f"{BENCH}/figures/phi-j-series.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot overlap {input} {output.png} > {log} 2>&1"


rule plot_gaps_ls_vs_calippso:
    input:
        ls=[f"{RESULTS}/analysis/ls-gaps{v}.nc" for v in variants()],
        jammed=[f"{RESULTS}/analysis/gaps{v}.nc" for v in variants()],
    output:
        png=report(
            f"{RESULTS}/figures/gaps-ls-vs-calippso.png",
            caption="../report/gaps-ls-vs-calippso.rst",
            category="LS+CALiPPSO",
        ),
        pdf=f"{RESULTS}/figures/gaps-ls-vs-calippso.pdf",
    log:
        f"{LOGS}/figures/gaps-ls-vs-calippso.log",
    benchmark:
        f"{BENCH}/figures/gaps-ls-vs-calippso.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    params:
        labels=" ".join([*(f"LS:{v}" for v in variant_labels()), *(f"CALiPPSO:{v}" for v in variant_labels())]),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot gaps {input.ls} {input.jammed} {output.png} --labels {params.labels} > {log} 2>&1"


rule plot_jamming_table:
    input:
        f"{RESULTS}/analysis/jamming-table.nc",
    output:
        png=report(
            f"{RESULTS}/figures/jamming-table.png",
            caption="../report/jamming-table.rst",
            category="LS+CALiPPSO",
        ),
        pdf=f"{RESULTS}/figures/jamming-table.pdf",
    log:
        f"{LOGS}/figures/jamming-table.log",
    benchmark:
        f"{BENCH}/figures/jamming-table.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot jamming-table {input} {output.png} > {log} 2>&1"


rule plot_eos:
    input:
        eos_files(),
    output:
        png=report(
            f"{RESULTS}/figures/eos.png",
            caption="../report/eos.rst",
            category="LS+CALiPPSO",
        ),
        pdf=f"{RESULTS}/figures/eos.pdf",
    log:
        f"{LOGS}/figures/eos.log",
    benchmark:
        f"{BENCH}/figures/eos.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    params:
        labels=" ".join(f"{s}:kappa={k:g}" for k in LS_RATES for s in samples()),
    shell:
        "jamflow plot eos {input} {output.png} --labels {params.labels} > {log} 2>&1"
