# Shaped 2D bodies (VanderWerf et al.): random bidisperse starts, jamming to P0 with
# rotations, spectra, phi_J / <z> against asphericity, contact angles and their figures.
# A body tag is <shape>_A<asphericity> (circulo-polygon<n> for n sides), reuleaux, or disk
# (bidisperse disks of the sphere code at the same N, P0 and seeds: the A = 1 limit).
# Helpers: workflow/rules/shapes_common.smk.


localrules:
    shape_survey,
    contact_angles,
    plot_phi_asphericity,
    plot_z_asphericity,
    plot_contact_angles,
    plot_spectra,
    plot_quartic_pressure,
    plot_shape_packing,


rule init_shapes:
    output:
        f"{RESULTS}/shapes/{{shape_body}}/init_seed{{seed}}.nc",
    log:
        f"{LOGS}/shapes/{{shape_body}}/init_seed{{seed}}.log",
    benchmark:
        f"{BENCH}/shapes/{{shape_body}}/init_seed{{seed}}.tsv"
    threads: job_threads("init")
    resources:
        **job_resources("init"),
    params:
        options=lambda wc: init_shape_options(wc.shape_body),
        n=SHAPES.get("n"),
        phi=SHAPES.get("phi"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow init-shapes {output} {params.options} --n {params.n} --phi {params.phi} --seed {wildcards.seed} "
        "> {log} 2>&1"


rule init_disks:
    output:
        f"{RESULTS}/shapes/disk/init_seed{{seed}}.nc",
    log:
        f"{LOGS}/shapes/disk/init_seed{{seed}}.log",
    benchmark:
        f"{BENCH}/shapes/disk/init_seed{{seed}}.tsv"
    threads: job_threads("init")
    resources:
        **job_resources("init"),
    params:
        n=SHAPES.get("n"),
        phi=SHAPES.get("phi"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow init {output} --d 2 --n {params.n} --phi {params.phi} --dispersity bi --ratio 1.4 "
        "--seed {wildcards.seed} > {log} 2>&1"


rule jam_shapes:
    input:
        jam_start,
    output:
        f"{RESULTS}/shapes/{{body}}/p{{pressure}}/seed{{seed}}.nc",
    log:
        f"{LOGS}/shapes/{{body}}/p{{pressure}}/seed{{seed}}.log",
    benchmark:
        f"{BENCH}/shapes/{{body}}/p{{pressure}}/seed{{seed}}.tsv"
    threads: job_threads("soft")
    resources:
        **job_resources("soft"),
    params:
        options=lambda wc: optional_flag("--force-tol", SHAPES.get("force_tol")),
        preset=PRESET,
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow soft-jam {input} {output} --pressure {wildcards.pressure} --preset {params.preset} "
        "{params.options} --quiet > {log} 2>&1 && jamflow check {output} --json >> {log} 2>&1"


rule shape_modes:
    input:
        f"{RESULTS}/shapes/{{shape_body}}/p{{pressure}}/seed{{seed}}.nc",
    output:
        f"{RESULTS}/shapes/{{shape_body}}/p{{pressure}}/seed{{seed}}.modes.nc",
    log:
        f"{LOGS}/shapes/{{shape_body}}/p{{pressure}}/seed{{seed}}.modes.log",
    benchmark:
        f"{BENCH}/shapes/{{shape_body}}/p{{pressure}}/seed{{seed}}.modes.tsv"
    threads: job_threads("modes")
    resources:
        **job_resources("modes"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow modes {input} {output} > {log} 2>&1"


rule shape_survey:
    input:
        shape_packings(),
    output:
        f"{RESULTS}/analysis/shape-survey.nc",
    log:
        f"{LOGS}/analysis/shape-survey.log",
    benchmark:
        f"{BENCH}/analysis/shape-survey.tsv"
    threads: job_threads("analysis")
    resources:
        **job_resources("analysis"),
    params:
        spectral="--spectral" if SHAPES.get("spectral_count", True) else "",
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow shape-survey {input} {output} {params.spectral} > {log} 2>&1"


rule contact_angles:
    input:
        lambda wc: shape_packings([wc.shape_body], [wc.pressure]),
    output:
        f"{RESULTS}/analysis/contact-angles_{{shape_body}}_p{{pressure}}.nc",
    log:
        f"{LOGS}/analysis/contact-angles_{{shape_body}}_p{{pressure}}.log",
    benchmark:
        f"{BENCH}/analysis/contact-angles_{{shape_body}}_p{{pressure}}.tsv"
    threads: job_threads("analysis")
    resources:
        **job_resources("analysis"),
    params:
        parallel=SHAPES.get("parallel_contacts"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow contact-angles {input} {output} --parallel-contacts {params.parallel} > {log} 2>&1"


rule plot_phi_asphericity:
    input:
        f"{RESULTS}/analysis/shape-survey.nc",
    output:
        png=report(f"{RESULTS}/figures/phi-asphericity.png", caption="../report/phi-asphericity.rst",
                   category="Shapes"),
        pdf=f"{RESULTS}/figures/phi-asphericity.pdf",
    log:
        f"{LOGS}/figures/phi-asphericity.log",
    benchmark:
        f"{BENCH}/figures/phi-asphericity.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot phi-asphericity {input} {output.png} > {log} 2>&1"


rule plot_z_asphericity:
    input:
        f"{RESULTS}/analysis/shape-survey.nc",
    output:
        png=report(f"{RESULTS}/figures/z-asphericity.png", caption="../report/z-asphericity.rst",
                   category="Shapes"),
        pdf=f"{RESULTS}/figures/z-asphericity.pdf",
    log:
        f"{LOGS}/figures/z-asphericity.log",
    benchmark:
        f"{BENCH}/figures/z-asphericity.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot z-asphericity {input} {output.png} > {log} 2>&1"


rule plot_contact_angles:
    input:
        contact_angle_files(),
    output:
        png=report(f"{RESULTS}/figures/contact-angles.png", caption="../report/contact-angles.rst",
                   category="Shapes"),
        pdf=f"{RESULTS}/figures/contact-angles.pdf",
    log:
        f"{LOGS}/figures/contact-angles.log",
    benchmark:
        f"{BENCH}/figures/contact-angles.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot contact-angles {input} {output.png} > {log} 2>&1"


rule plot_spectra:
    input:
        [shape_packing(b, shape_pressures()[0], SHAPES.get("seeds", [0])[0]).replace(".nc", ".modes.nc")
         for b in shape_bodies() if b != "disk"],
    output:
        png=report(f"{RESULTS}/figures/spectra.png", caption="../report/spectra.rst", category="Shapes"),
        pdf=f"{RESULTS}/figures/spectra.pdf",
    log:
        f"{LOGS}/figures/spectra.log",
    benchmark:
        f"{BENCH}/figures/spectra.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    params:
        labels=lambda wc, input: modes_labels(input),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot spectra {input} {output.png} --labels {params.labels} > {log} 2>&1"


rule plot_quartic_pressure:
    input:
        [p.replace(".nc", ".modes.nc") for p in shape_packings([b for b in shape_bodies() if b != "disk"][:1])],
    output:
        png=report(f"{RESULTS}/figures/quartic-pressure.png", caption="../report/quartic-pressure.rst",
                   category="Shapes"),
        pdf=f"{RESULTS}/figures/quartic-pressure.pdf",
    log:
        f"{LOGS}/figures/quartic-pressure.log",
    benchmark:
        f"{BENCH}/figures/quartic-pressure.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot quartic-pressure {input} {output.png} > {log} 2>&1"


rule plot_shape_packing:
    input:
        shape_packings(shape_bodies()[:1], shape_pressures()[:1], SHAPES.get("seeds", [0])[:1]),
    output:
        png=report(f"{RESULTS}/figures/shape-packing.png", caption="../report/shape-packing.rst",
                   category="Shapes"),
        pdf=f"{RESULTS}/figures/shape-packing.pdf",
    log:
        f"{LOGS}/figures/shape-packing.log",
    benchmark:
        f"{BENCH}/figures/shape-packing.tsv"
    threads: job_threads("plot")
    resources:
        **job_resources("plot"),
    conda:
        "../envs/jamflow.yaml"
    shell:
        "jamflow plot packing {input} {output.png} --soft > {log} 2>&1"
