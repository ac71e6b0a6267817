# One rule per step, analysis, study and figure of the scene's plan (jamflow.scenes): each
# calls the jamflow CLI; outputs, inputs and costs come from the plan.

wildcard_constraints:
    **WILDCARDS,


for _spec in PLAN.rules.values():

    rule:
        name:
            _spec.name
        input:
            job_inputs(_spec.name),
        output:
            rule_outputs(_spec),
        log:
            _spec.log,
        benchmark:
            _spec.benchmark
        threads: job_threads(_spec.name)
        resources:
            **job_resources(_spec.name),
        group:
            job_group(_spec.name)
        localrule: _spec.local
        params:
            cmd=job_command(_spec.name),
        conda:
            "../envs/jamflow.yaml"
        shell:
            "{params.cmd}"
