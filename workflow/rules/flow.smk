# Event-driven overdamped hard-sphere dynamics (Lerner, During, Wyart): compression as a
# chain stage, shear (fixed volume or fixed pressure) of every sample's final packing.


rule compress:
    input:
        previous_stage("compress"),
    output:
        packing=packing("{sample}", "compress"),
        series=f"{RESULTS}/flow/{{sample}}/compress.nc",
    log:
        f"{LOGS}/compress/{{sample}}.log",
    benchmark:
        f"{BENCH}/compress/{{sample}}.tsv"
    threads: job_threads("compress")
    resources:
        **job_resources("compress"),
    params:
        preset=PRESET,
        options=stage_options(
            "compress", phi="--phi", dt="--dt", correct_every="--correct-every", record_every="--record-every"
        ),
        read=lambda wildcards: read_flags(CHAIN[CHAIN.index("compress") - 1]),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow compress {input} {output.series} --final {output.packing} {params.options}"
        " --preset {params.preset} {params.read} > {log} 2>&1"


rule shear:
    input:
        flow_start,
    output:
        series=f"{RESULTS}/flow/{{sample}}/shear_{{condition}}.nc",
        final=f"{RESULTS}/flow/{{sample}}/shear_{{condition}}_final.nc",
    log:
        f"{LOGS}/shear/{{sample}}_{{condition}}.log",
    benchmark:
        f"{BENCH}/shear/{{sample}}_{{condition}}.tsv"
    threads: job_threads("shear")
    resources:
        **job_resources("shear"),
    params:
        preset=PRESET,
        options=stage_options(
            "flow", strain="--strain", dt="--dt", correct_every="--correct-every", record_every="--record-every", unit="--unit"
        ),
        pressure=lambda wildcards: pressure_option(wildcards.condition),
        read=read_flags(FINAL),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow shear {input} {output.series} --final {output.final} {params.options}"
        " {params.pressure} --preset {params.preset} {params.read} > {log} 2>&1"


rule flow_summary:
    input:
        f"{RESULTS}/flow/{{sample}}/shear_{{condition}}.nc",
    output:
        f"{RESULTS}/analysis/{{sample}}/shear_{{condition}}_summary.nc",
    log:
        f"{LOGS}/analysis/shear_summary_{{sample}}_{{condition}}.log",
    benchmark:
        f"{BENCH}/analysis/shear_summary_{{sample}}_{{condition}}.tsv"
    threads: job_threads("flow_summary")
    resources:
        **job_resources("flow_summary"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow flow-summary {input} {output} > {log} 2>&1"


rule flow_curve:
    input:
        shear_summaries(),
    output:
        f"{RESULTS}/analysis/flow-curve.nc",
    log:
        f"{LOGS}/analysis/flow-curve.log",
    benchmark:
        f"{BENCH}/analysis/flow-curve.tsv"
    threads: job_threads("flow_curve")
    resources:
        **job_resources("flow_curve"),
    params:
        labels=shear_labels(),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow flow-curve {input} {output} --labels {params.labels} > {log} 2>&1"


rule sd_shear:
    input:
        flow_start,
    output:
        f"{RESULTS}/flow/{{sample}}/sd_fixed-volume.nc",
    log:
        f"{LOGS}/sd_shear/{{sample}}.log",
    benchmark:
        f"{BENCH}/sd_shear/{{sample}}.tsv"
    threads: job_threads("sd_shear")
    resources:
        **job_resources("sd_shear"),
    params:
        flow=stage_options("flow", strain="--strain", unit="--unit"),
        sd=stage_options("sd", step="--step", dt="--dt", grad_tol="--grad-tol", delta_r="--delta-r"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow sd-shear {input} {output} {params.flow} {params.sd} > {log} 2>&1"
