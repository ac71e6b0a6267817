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
    params:
        preset=PRESET,
        phi=lambda wildcards: opt("compress", "phi"),
        dt=lambda wildcards: optional_flag("--dt", opt("compress", "dt")),
        correct_every=lambda wildcards: optional_flag("--correct-every", opt("compress", "correct_every")),
        record_every=lambda wildcards: opt("compress", "record_every"),
        read=lambda wildcards: read_flags(CHAIN[CHAIN.index("compress") - 1]),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow compress {input} {output.series} --final {output.packing} --phi {params.phi}"
        " {params.dt} {params.correct_every} --preset {params.preset}"
        " --record-every {params.record_every} {params.read} --quiet > {log} 2>&1"


rule shear:
    input:
        packing("{sample}", FINAL),
    output:
        series=f"{RESULTS}/flow/{{sample}}/shear_{{condition}}.nc",
        final=f"{RESULTS}/flow/{{sample}}/shear_{{condition}}_final.nc",
    log:
        f"{LOGS}/shear/{{sample}}_{{condition}}.log",
    benchmark:
        f"{BENCH}/shear/{{sample}}_{{condition}}.tsv"
    params:
        preset=PRESET,
        strain=lambda wildcards: opt("flow", "strain"),
        pressure=lambda wildcards: pressure_option(wildcards.condition),
        dt=lambda wildcards: optional_flag("--dt", opt("flow", "dt")),
        correct_every=lambda wildcards: optional_flag("--correct-every", opt("flow", "correct_every")),
        record_every=lambda wildcards: opt("flow", "record_every"),
        unit=lambda wildcards: opt("flow", "unit"),
        read=read_flags(FINAL),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow shear {input} {output.series} --final {output.final} --strain {params.strain}"
        " {params.pressure} {params.dt} {params.correct_every} --preset {params.preset}"
        " --record-every {params.record_every} --unit {params.unit} {params.read} --quiet > {log} 2>&1"


rule flow_summary:
    input:
        f"{RESULTS}/flow/{{sample}}/shear_{{condition}}.nc",
    output:
        f"{RESULTS}/analysis/{{sample}}/shear_{{condition}}_summary.nc",
    log:
        f"{LOGS}/analysis/shear_summary_{{sample}}_{{condition}}.log",
    benchmark:
        f"{BENCH}/analysis/shear_summary_{{sample}}_{{condition}}.tsv"
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow flow-summary {input} {output} > {log} 2>&1"


rule sd_shear:
    input:
        packing("{sample}", FINAL),
    output:
        f"{RESULTS}/flow/{{sample}}/sd_fixed-volume.nc",
    log:
        f"{LOGS}/sd_shear/{{sample}}.log",
    benchmark:
        f"{BENCH}/sd_shear/{{sample}}.tsv"
    params:
        strain=lambda wildcards: opt("flow", "strain"),
        step=lambda wildcards: opt("sd", "step"),
        dt=lambda wildcards: opt("sd", "dt"),
        grad_tol=lambda wildcards: opt("sd", "grad_tol"),
        delta_r=lambda wildcards: opt("sd", "delta_r"),
        unit=lambda wildcards: opt("flow", "unit"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow sd-shear {input} {output} --strain {params.strain} --step {params.step}"
        " --dt {params.dt} --grad-tol {params.grad_tol} --delta-r {params.delta_r}"
        " --unit {params.unit} --quiet > {log} 2>&1"
