"""A checked scene as jobs: one path per (bodies, scan point, sample, stage), the commands, the costs.

Paths (``docs/scenes.md``)::

    results/<scene>/<bodies>/<point>/<sample>/<step>.nc          a packing after a step
    results/<scene>/<bodies>/<point>/<sample>/<step>.<analysis>.nc   an analysis of it
    results/<scene>/studies/<study>/<kept point>.nc              a study of one kept point
    results/<scene>/studies/<study>.nc                           the study along its kept dimensions
    results/<scene>/figures/<figure>.png

``<point>`` is ``key=value,key=value`` over the scan dimensions up to that step (``base``
without any); a step that writes one packing per value of an option (LS snapshots per
``p_target``) puts that dimension last. Every job's scan point also goes into its
datasets' attributes (environment ``JAMFLOW_SCAN_POINT``, :mod:`jamflow.provenance`).
"""

from __future__ import annotations

import itertools
import json
import math
import os
import shlex
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from . import resources
from .grammar import Entry, Scene, SceneError

__all__ = ["Job", "Packing", "Plan", "RuleSpec", "format_point", "plan_scene"]

#: Wildcards of the rules and what they match: a packing's folder ``<bodies>/<point>/<sample>``,
#: and for a step that fans out, the point before its fanned dimension (``pre``, empty or ending in a comma).
WILDCARDS: dict[str, str] = {"where": "[^/]+/[^/]+/[^/]+", "body": "[^/]+", "pre": "(|[^/]+,)", "sample": "[^/]+",
                             "group": "[^/]+", "tag": "[^/]+"}
#: Densest packing fraction of equal spheres by dimension (hexagonal, fcc, D4, D5): no packing of
#: these particles fills a smaller box, which bounds half the box from below (rdf's r_max).
DENSEST_PHI: dict[int, float] = {2: 0.9069, 3: 0.7405, 4: 0.6169, 5: 0.4653}
#: rdf's r_max when the scene gives none [mean diameters] (the command's default)
RDF_R_MAX = 3.0


def format_value(value: Any) -> str:
    """A scan value in a path: numbers as ``%g``, a file as its stem, text as it is."""
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, (int, float)):
        return f"{value:g}"
    text = os.path.splitext(os.path.basename(str(value)))[0]
    return "".join(c if c.isalnum() or c in "-_.+" else "-" for c in text)


def format_point(point: dict[str, Any]) -> str:
    """``growth_rate=0.001,p_target=1000``, or ``base`` for no dimension."""
    return ",".join(f"{k}={format_value(v)}" for k, v in point.items()) or "base"


@dataclass
class RuleSpec:
    """One Snakemake rule: output and log templates over :data:`WILDCARDS`."""

    name: str
    outputs: list[str]
    log: str
    local: bool = False

    @property
    def benchmark(self) -> str:
        """Benchmark file template: the log's, under ``benchmarks/``, as TSV."""
        return self.log.replace("/logs/", "/benchmarks/", 1).removesuffix(".log") + ".tsv"


@dataclass
class Job:
    """One job: its files, its command and its cost."""

    rule: str
    wildcards: dict[str, str]
    outputs: list[str]
    inputs: list[str]
    argv: list[str]
    point: dict[str, Any]
    cpu_s: float
    mem_mb: float
    threads: int = 1
    stdout: bool = False
    unit: tuple | None = None
    group: str | None = None
    listing: bool = False

    def command(self, log: str) -> str:
        """The shell command: ``jamflow ...`` with the scan point in the environment, output to ``log``
        (a group's ``bundle`` job lists its inputs instead)."""
        if self.listing:
            files = " ".join(shlex.quote(p) for p in self.inputs)
            return f"printf '%s\\n' {files} > {shlex.quote(self.outputs[0])} 2> {shlex.quote(log)}"
        env = f"JAMFLOW_SCAN_POINT={shlex.quote(json.dumps(self.point, sort_keys=True, default=str))}"
        line = " ".join(shlex.quote(a) for a in ["jamflow", *self.argv])
        if self.stdout:
            # the output is the command's stdout; the log ends with it too, as every job log ends
            # with what its command printed
            out, log = shlex.quote(self.outputs[0]), shlex.quote(log)
            return f"{env} {line} > {out} 2> {log} && cat {out} >> {log}"
        return f"{env} {line} > {shlex.quote(log)} 2>&1"


@dataclass
class Packing:
    """A packing (or flow run) a step writes: where, at which point, of which bodies."""

    path: str
    step: str
    command: str
    point: dict[str, Any]
    body: str
    sample: str
    seed: int
    where: str
    kind: str
    soft: bool
    n: int
    d: int
    unit: tuple = ()
    series: str | None = None
    analyses: dict[str, str] = field(default_factory=dict)


@dataclass
class Plan:
    """Every rule and job of a scene, and what the scene asks for."""

    scene: Scene
    results: str
    rules: dict[str, RuleSpec] = field(default_factory=dict)
    jobs: dict[tuple, Job] = field(default_factory=dict)
    packings: list[Packing] = field(default_factory=list)
    targets: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    dims: list[str] = field(default_factory=list)
    eos: dict[tuple, str] = field(default_factory=dict)
    study_groups: dict[str, list[tuple[dict[str, Any], str, list[Any]]]] = field(default_factory=dict)

    def add(self, spec: RuleSpec, job: Job) -> Job:
        self.rules.setdefault(spec.name, spec)
        key = (spec.name, tuple(sorted(job.wildcards.items())))
        self.jobs.setdefault(key, job)
        return self.jobs[key]

    def job(self, rule: str, wildcards: Any) -> Job:
        """The job of ``rule`` at Snakemake's ``wildcards``."""
        return self.jobs[(rule, tuple(sorted((k, str(v)) for k, v in dict(wildcards.items()).items())))]

    def jobs_of(self, rule: str) -> list[Job]:
        return [j for (r, _), j in self.jobs.items() if r == rule]


def _axes(entry: Entry, zips: list[list[str]], section: str) -> list[list[dict[str, Any]]]:
    """Scan axes of an entry: each a list of assignments (zipped keys share one axis).

    A zip group names keys as ``<section>.<entry>.<option>`` (``bodies.spheres.n``, ``chain.ls.growth_rate``)."""
    prefixes = {entry.key, f"{section}.{entry.name}"}
    lists = {k: v for k, v in entry.options.items() if isinstance(v, list) and not entry.stage.option(k).fan_out}
    axes: list[list[dict[str, Any]]] = []
    done: set[str] = set()
    for group in zips:
        keys = [g.split(".")[-1] for g in group if g.rsplit(".", 1)[0] in prefixes]
        mine = [k for k in keys if k in lists]
        if not mine:
            continue
        if len(mine) != len(group) or len({len(lists[k]) for k in mine}) != 1:
            raise SceneError(f"zip: {', '.join(group)} must be lists of one length in one entry "
                             f"({entry.key} has {', '.join(f'{k}: {len(lists.get(k, []))}' for k in keys)})")
        axes.append([dict(zip(mine, values)) for values in zip(*(lists[k] for k in mine))])
        done.update(mine)
    axes += [[{k: v} for v in values] for k, values in lists.items() if k not in done]
    if entry.extra.get("draws"):
        axes.append([{"draw": r} for r in range(entry.extra["draws"])])
    return axes


def _assignments(axes: list[list[dict[str, Any]]]) -> Iterator[dict[str, Any]]:
    for combo in itertools.product(*axes):
        merged: dict[str, Any] = {}
        for part in combo:
            merged.update(part)
        yield merged


def _dim_names(scene: Scene) -> dict[tuple[str, str], str]:
    """Scan dimension name of each (entry, option): the option's, or ``step.option`` where two steps
    (or a step and the bodies) scan an option of one name."""
    bodies = {b.name for b in scene.bodies}
    scanned: dict[str, list[str]] = {}
    for e in (*scene.bodies, *scene.chain):
        scanned[e.name] = [k for k, v in e.options.items() if isinstance(v, list) or e.stage.option(k).fan_out]
        scanned[e.name] += ["draw"] if e.extra.get("draws") else []
    owners: dict[str, set[str]] = {}
    for name, keys in scanned.items():
        for k in keys:
            owners.setdefault(k, set()).add("bodies" if name in bodies else name)
    return {(name, k): k if name in bodies or owners[k] == {name} else f"{name}.{k}"
            for name, keys in scanned.items() for k in keys}


def _n_and_d(body: Entry, values: dict[str, Any]) -> tuple[int, int]:
    """Particles and dimension of one body point."""
    if body.command == "init":
        return int(values["n"]), int(values["d"])
    if body.command == "init-shapes":
        return int(values["n"]), 2
    if body.command == "init-chains":
        per = {"trimer": 3, "dimer": 2}.get(values["builder"], int(values.get("chain_length", 3)))
        return int(values["clusters"]) * per, int(values["d"])
    path = values["file"]
    if not os.path.isfile(path):
        raise SceneError(f"bodies.import.file: {path} not found (paths are relative to the working directory)")
    with open(path) as fh:
        d, n = int(fh.readline()), int(fh.readline())
    return n, d


def _seed(sample_seed: int, step: str, point: dict[str, Any]) -> int:
    """A step's own seed: fixed by the sample's seed, the step and the scan point (same scene, same numbers)."""
    return zlib.crc32(f"{sample_seed}|{step}|{format_point(point)}".encode()) % 2**31


def option_argv(entry: Entry, values: dict[str, Any], n: int) -> list[str]:
    """The command-line options of one job: the entry's options with scanned values resolved."""
    argv: list[str] = []
    for option in entry.stage.options:
        if option.name not in values or option.flag == "-":
            continue
        value = values[option.name]
        if option.kind == "bool":
            argv += [option.flag] if value else []
        elif option.fan_out:
            argv += [option.flag, *(f"{v:g}" for v in value)]
        elif option.per_particle:
            argv += [option.flag, str(round(value * n))]
        else:
            argv += [option.flag, f"{value:g}" if isinstance(value, float) else str(value)]
    return argv


class _Builder:
    """Builds the packing jobs of a plan (sources, steps, analyses)."""

    def __init__(self, plan: Plan) -> None:
        self.plan = plan
        self.scene = plan.scene
        self.names = _dim_names(self.scene)
        self.limit_mb = self.scene.resources.get("max_mem_mb", resources.machine_memory_mb())

    def cost(self, command: str, n: int, d: int, values: dict[str, Any], before: str | None,
             key: str, kind: str = "spheres") -> tuple[float, float]:
        cpu, mem = resources.estimate(command, n, d, values, before, kind)
        if mem > self.limit_mb:
            raise SceneError(f"{key}: N = {n} in {d}D needs ~{mem / 1e3:.1f} GB in {command}, more than the "
                             f"{self.limit_mb / 1e3:.1f} GB a job may have (resources.max_mem_mb; this machine's "
                             "memory unless the scene says)")
        return cpu, mem

    def run(self) -> None:
        for body in self.scene.bodies:
            for body_values in _assignments(_axes(body, self.scene.zips, "bodies")):
                for seed in self.scene.seeds:
                    self.sample(body, body_values, seed)

    def named(self, entry: Entry, values: dict[str, Any]) -> dict[str, Any]:
        return {self.names[(entry.name, k)]: v for k, v in values.items()}

    def sample(self, body: Entry, scanned: dict[str, Any], seed: int) -> None:
        values = {**body.options, **scanned}
        n, d = _n_and_d(body, values)
        point = self.named(body, scanned)
        sample = f"seed{seed}"
        unit = (body.name, format_point(point), sample)
        where = f"{body.name}/{format_point(point)}/{sample}"
        out = f"{self.plan.results}/{where}/{body.command}.nc"
        stage = body.stage
        argv = [body.command, out, *option_argv(body, values, n)]
        inputs: list[str] = []
        if body.command == "import-dat":
            argv = [body.command, values["file"], out]
            inputs = [values["file"]]
        if stage.seeded:
            argv += ["--seed", str(seed)]
        cpu, mem = self.cost(body.command, n, d, values, None, body.key)
        spec = RuleSpec(_rule(body.command), [f"{self.plan.results}/{{where}}/{body.command}.nc"],
                        f"{self.plan.results}/logs/{body.command}/{{where}}.log")
        full = {"body": body.name, "sample": sample, "seed": seed, **point}
        self.plan.add(spec, Job(spec.name, {"where": where}, [out], inputs, argv, full, cpu, mem, unit=unit))
        kind = "walls" if values.get("walls") is True else stage.makes
        frontier = [Packing(out, "source", body.command, point, body.name, sample, seed, where, kind, False, n, d,
                            unit)]
        self.plan.packings += frontier
        for step in self.scene.chain:
            frontier = [p for before in frontier for p in self.step(step, before, unit)]
            self.plan.packings += frontier

    def step(self, step: Entry, before: Packing, unit: tuple) -> list[Packing]:
        """The packings of one step from one packing: one per scan point (a ``sequence`` runs its values
        one after the other, each from the packing of the value before)."""
        sequence = step.extra.get("sequence")
        if sequence is None:
            return self.points(step, before, unit, _axes(step, self.scene.zips, "chain"))
        rest = Entry(step.name, step.command, {k: v for k, v in step.options.items() if k != sequence},
                     step.extra, step.key)
        made = []
        for scanned in _assignments(_axes(rest, self.scene.zips, "chain")):
            start = before
            for value in step.options[sequence]:
                (packing,) = self.points(step, start, unit, [[{**scanned, sequence: value}]], before.point)
                made.append(packing)
                start = packing
        return made

    def points(self, step: Entry, before: Packing, unit: tuple, axes: list[list[dict[str, Any]]],
               base_point: dict[str, Any] | None = None) -> list[Packing]:
        stage = step.stage
        fan = next((o.name for o in stage.options if o.fan_out), None)
        made: list[Packing] = []
        for scanned in _assignments(axes):
            values = {**step.options, **scanned}
            point = {**(before.point if base_point is None else base_point), **self.named(step, scanned)}
            kind = stage.makes or before.kind
            soft = before.soft if stage.soft_out is None else stage.soft_out
            cpu, mem = self.cost(step.command, before.n, before.d, values, before.command, step.key, before.kind)
            if step.command == "link":
                _check_cement(step, values, before)
            argv = option_argv(step, values, before.n)
            if stage.seeded:
                argv += ["--seed", str(before.seed if step.command == "ls" else _seed(before.seed, step.name, point))]
            if stage.preset:
                argv += ["--preset", self.scene.preset]
            if before.soft and stage.reads_soft:
                argv.append("--soft")
            if step.command in resources.THREADS:
                argv += ["--threads", str(resources.THREADS[step.command])]
            full = {"body": before.body, "sample": before.sample, "seed": before.seed, **point}
            base = f"{self.plan.results}/{before.body}"
            if fan:
                name = self.names[(step.name, fan)]
                pre = "" if not point else format_point(point) + ","
                outs = [f"{base}/{pre}{name}={format_value(v)}/{before.sample}/{step.name}.nc"
                        for v in values[fan]]
                eos = f"{base}/{pre}{name}=all/{before.sample}/{step.name}.eos.nc"
                spec = RuleSpec(_rule(step.name), [f"{self.plan.results}/{{body}}/{{pre}}{name}={format_value(v)}/"
                                                   f"{{sample}}/{step.name}.nc" for v in values[fan]]
                                + [f"{self.plan.results}/{{body}}/{{pre}}{name}=all/{{sample}}/{step.name}.eos.nc"],
                                f"{self.plan.results}/logs/{step.name}/{{body}}/{{pre}}{{sample}}.log")
                job = Job(spec.name, {"body": before.body, "pre": pre, "sample": before.sample}, [*outs, eos],
                          [before.path], [step.command, before.path, *outs, *argv, "--eos", eos], full, cpu, mem,
                          unit=unit)
                self.plan.add(spec, job)
                self.plan.eos[(before.body, before.sample, format_point(point))] = eos
                for v, out in zip(values[fan], outs):
                    where = f"{before.body}/{pre}{name}={format_value(v)}/{before.sample}"
                    made.append(Packing(out, step.name, step.command, {**point, name: v}, before.body,
                                        before.sample, before.seed, where, kind, soft, before.n, before.d, unit))
                continue
            where = f"{before.body}/{format_point(point)}/{before.sample}"
            out = f"{self.plan.results}/{where}/{step.name}.nc"
            outputs, series = [out], None
            if stage.form == "flow":
                series = f"{self.plan.results}/{where}/{step.name}.series.nc"
                outputs, argv = [out, series], [series, "--final", out, *argv]
            else:
                argv = [out, *argv]
            spec = RuleSpec(_rule(step.name), [f"{self.plan.results}/{{where}}/{step.name}.nc"]
                            + ([f"{self.plan.results}/{{where}}/{step.name}.series.nc"] if series else []),
                            f"{self.plan.results}/logs/{step.name}/{{where}}.log")
            threads = resources.THREADS.get(step.command, 1)
            self.plan.add(spec, Job(spec.name, {"where": where}, outputs, [before.path],
                                    [step.command, before.path, *argv], full, cpu, mem, threads=threads, unit=unit))
            made.append(Packing(out, step.name, step.command, point, before.body, before.sample, before.seed, where,
                                kind, soft, before.n, before.d, unit, series=series))
        return made

    def analyses(self) -> None:
        last = self.scene.chain[-1].name if self.scene.chain else "source"
        for a in self.scene.analyses:
            of = a.extra.get("of", last)
            for p in self.plan.packings:
                if p.step == of:
                    self.analysis(a, p)

    def analysis(self, a: Entry, p: Packing) -> None:
        stage = a.stage
        values = dict(a.options)
        if a.command == "rdf":
            values["r_max"] = self.rdf_r_max(a, p)
        source = p.series if a.command == "flow-summary" else p.path
        if source is None:
            raise SceneError(f"{a.key}.of: {a.command} reads a flow run; {p.step} writes none")
        suffix = "json" if stage.form == "json" else "nc"
        stem = p.path.rsplit("/", 1)[1].removesuffix(".nc")
        out = f"{self.plan.results}/{p.where}/{stem}.{a.name}.{suffix}"
        argv = [a.command, source] + ([] if stage.form == "json" else [out]) + option_argv(a, values, p.n)
        if stage.form == "json":
            argv.append("--json")
        if stage.preset:
            argv += ["--preset", self.scene.preset]
        if p.soft and stage.reads_soft:
            argv.append("--soft")
        cpu, mem = self.cost(a.command, p.n, p.d, {**values, "strain": values.get("strain", 1.0)}, p.command, a.key,
                             p.kind)
        rule = _rule(f"{a.name}-{p.step}")
        spec = RuleSpec(rule, [f"{self.plan.results}/{{where}}/{stem}.{a.name}.{suffix}"],
                        f"{self.plan.results}/logs/{a.name}-{p.step}/{{where}}.log")
        full = {"body": p.body, "sample": p.sample, "seed": p.seed, **p.point}
        self.plan.add(spec, Job(rule, {"where": p.where}, [out], [source], argv, full, cpu, mem,
                                stdout=stage.form == "json", unit=p.unit))
        p.analyses[a.name] = out

    def rdf_r_max(self, a: Entry, p: Packing) -> float:
        """rdf's r_max below half the smallest box these particles can fill (else the command refuses)."""
        volume = math.pi ** (p.d / 2) / math.gamma(p.d / 2 + 1) * 0.5 ** p.d
        half_box = 0.5 * (p.n * volume / DENSEST_PHI.get(p.d, 0.4)) ** (1 / p.d)
        r_max = a.options.get("r_max", RDF_R_MAX)
        if r_max < half_box:
            return r_max
        if "r_max" in a.options:
            raise SceneError(f"{a.key}.r_max: {r_max:g} mean diameters reaches half the box of N = {p.n} in "
                             f"{p.d}D (at least {half_box:.3g} at the densest packing); give less")
        clipped = math.floor(0.95 * half_box * 100) / 100
        note = (f"{a.key}: r_max {clipped:g} mean diameters (the default {RDF_R_MAX:g} reaches half the box of "
                f"N = {p.n} in {p.d}D)")
        if note not in self.plan.notes:
            self.plan.notes.append(note)
        return clipped


def _check_cement(step: Entry, values: dict[str, Any], before: Packing) -> None:
    """Cementing more links than a jammed packing has contacts is impossible: a jammed packing of
    N spheres in d dimensions has about the isostatic d N contacts (z = 2d), fewer without its rattlers."""
    for name in ("cement", "cement_per_sphere"):
        if name not in values:
            continue
        count = values[name] * (before.n if name == "cement_per_sphere" else 1)
        if count > before.d * before.n:
            raise SceneError(f"{step.key}.{name}: {values[name]:g} cements {round(count)} contacts, but a jammed "
                             f"packing of N = {before.n} spheres in {before.d}D has about d N = {before.d * before.n}"
                             f" (z = 2d), fewer without its rattlers")


def _rule(name: str) -> str:
    return name.replace("-", "_").replace(".", "_")


def group_units(plan: Plan) -> None:
    """Bundle the packings' jobs for a cluster: a group runs whole samples until it holds ~``group_minutes``
    of expected CPU time, so that a survey of thousands of short jobs is a few submissions."""
    target = 60 * plan.scene.resources.get("group_minutes", 60)
    totals: dict[tuple, float] = {}
    for job in plan.jobs.values():
        if job.unit is not None:
            totals[job.unit] = totals.get(job.unit, 0.0) + job.cpu_s
    bundle, filled, of_unit = 0, 0.0, {}
    for unit, seconds in totals.items():
        if filled and filled + seconds > target:
            bundle, filled = bundle + 1, 0.0
        of_unit[unit] = f"bundle{bundle}"
        filled += seconds
    for job in plan.jobs.values():
        if job.unit is not None:
            job.group = of_unit[job.unit]


def join_groups(plan: Plan) -> None:
    """One ``bundle`` job per cluster group that lists the group's last outputs.

    Snakemake submits a group's *connected* jobs as one cluster job; the samples of a group
    share no file, so this job, in the group and reading each sample's last outputs, joins
    them into one component (one submission per group, not one per sample)."""
    members: dict[str, list[Job]] = {}
    for job in plan.jobs.values():
        if job.group is not None:
            members.setdefault(job.group, []).append(job)
    spec = RuleSpec("bundle", [f"{plan.results}/bundles/{{group}}.txt"], f"{plan.results}/logs/bundles/{{group}}.log")
    for group, jobs in members.items():
        read = {path for job in jobs for path in job.inputs}
        last = [path for job in jobs for path in job.outputs if path not in read]
        out = f"{plan.results}/bundles/{group}.txt"
        job = plan.add(spec, Job("bundle", {"group": group}, [out], last, [], {"group": group}, 1.0, 100.0))
        job.group, job.listing = group, True
        plan.targets.append(out)


def plan_scene(scene: Scene, results: str = "results") -> Plan:
    """Every job of a checked scene (:func:`jamflow.scenes.read_scene`)."""
    from .studies import add_figures, add_studies, add_tradeoff

    # a paper-scale run writes beside the laptop one, never over it
    plan = Plan(scene, f"{results}/{scene.name}" + ("" if scene.scale == "laptop" else f"-{scene.scale}"))
    builder = _Builder(plan)
    builder.run()
    builder.analyses()
    add_studies(plan)
    add_figures(plan)
    add_tradeoff(plan)
    # every sample's final packings, their analyses, the studies and the figures
    last = scene.chain[-1].name if scene.chain else "source"
    final = [p.path for p in plan.packings if p.step == last]
    analysed = [out for p in plan.packings for out in p.analyses.values()]
    plan.targets = list(dict.fromkeys(final + analysed + plan.targets))
    group_units(plan)
    join_groups(plan)
    return plan
