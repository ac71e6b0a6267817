"""Studies (pools of packings or analyses over scan dimensions), figures and speed sweeps of a plan.

A study runs its command once per *kept* scan point (every dimension it does not pool
``over``) and then ``jamflow pool`` joins those outputs into ``studies/<study>.nc`` with
the kept dimensions as coordinates. What each study pools by default:

===============  ====================================================================
gaps, forces     over ``sample``: one distribution per scan point
overlap-series   over ``p_target``: one series per sample and growth rate
contact-angles   over ``sample``
others           over everything (their command groups the rows itself)
===============  ====================================================================
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from .grammar import Entry, SceneError, did_you_mean
from .plan import Job, Packing, Plan, RuleSpec, _rule, format_point, option_argv

__all__ = ["DEFAULT_OVER", "FIGURES", "add_figures", "add_studies", "add_tradeoff"]

#: Dimensions a study pools unless the scene says ``over`` (others: every dimension).
DEFAULT_OVER: dict[str, list[str]] = {"gaps": ["sample"], "forces": ["sample"], "overlap-series": ["p_target"],
                                      "contact-angles": ["sample"]}
#: a study, a pool or a figure reads a few small files: seconds
LIGHT_SECONDS = 5.0
LIGHT_MB = 1000.0


def _full_point(plan: Plan, p: Packing) -> dict[str, Any]:
    body = {"body": p.body} if len(plan.scene.bodies) > 1 else {}
    return {**body, "sample": p.sample, **p.point}


def _records(plan: Plan, s: Entry) -> list[tuple[dict[str, Any], str, Packing | None]]:
    """What a study pools: (scan point, file, packing) of every input."""
    last = plan.scene.chain[-1].name if plan.scene.chain else "source"
    pools = s.stage.pools
    if pools == "packings":
        of = s.extra.get("of", last)
        return [(_full_point(plan, p), p.path, p) for p in plan.packings if p.step == of]
    if pools.startswith("analysis:"):
        command = pools.split(":")[1]
        names = [a.name for a in plan.scene.analyses if a.command == command]
        name = s.extra.get("analysis", names[0])
        if name not in names:
            raise SceneError(f"{s.key}.analysis: no {command} analysis {name!r}{did_you_mean(name, names)}")
        return [(_full_point(plan, p), p.analyses[name], p) for p in plan.packings if name in p.analyses]
    command = pools.split(":")[1]
    study = next(t.name for t in plan.scene.studies if t.command == command)
    return [(kept, out, None) for kept, out, _ in plan.study_groups[study]]


def _over(plan: Plan, s: Entry, dims: list[str]) -> list[str]:
    over = s.extra.get("over", DEFAULT_OVER.get(s.command, "all"))
    over = [over] if isinstance(over, str) else list(over)
    if "all" in over:
        return dims
    for d in over:
        if d not in dims:
            raise SceneError(f"{s.key}.over: no scan dimension {d!r} here (the dimensions are {', '.join(dims)})"
                             f"{did_you_mean(d, dims)}")
    return over


def add_studies(plan: Plan) -> None:
    """One job per study and kept point, and one pool per study."""
    for s in plan.scene.studies:
        records = _records(plan, s)
        if not records:
            raise SceneError(f"{s.key}: nothing to pool (no packing of its step in this scene)")
        dims = list(dict.fromkeys(k for point, _, _ in records for k in point))
        over = _over(plan, s, dims)
        groups: dict[str, tuple[dict[str, Any], list]] = {}
        for point, path, packing in records:
            kept = {k: v for k, v in point.items() if k not in over}
            groups.setdefault(format_point(kept), (kept, []))[1].append((point, path, packing))
        plan.study_groups[s.name] = []
        spec = RuleSpec(_rule(f"study-{s.name}"), [f"{plan.results}/studies/{s.name}/{{group}}.nc"],
                        f"{plan.results}/logs/studies/{s.name}/{{group}}.log", local=True)
        for group, (kept, members) in groups.items():
            out = f"{plan.results}/studies/{s.name}/{group}.nc"
            inputs = [path for _, path, _ in members]
            n = max((p.n for _, _, p in members if p is not None), default=0)
            argv = [s.command, *inputs, out, *option_argv(s, s.options, n), *_point_args(plan, s, kept, members)]
            if s.stage.reads_soft and any(p is not None and p.soft for _, _, p in members):
                argv.append("--soft")
            if s.stage.preset:
                argv += ["--preset", plan.scene.preset]
            eos = _eos(plan, s, members)
            argv += ["--eos", *eos] if eos else []
            plan.add(spec, Job(spec.name, {"group": group}, [out], inputs + eos, argv,
                               {"study": s.name, **kept}, LIGHT_SECONDS, LIGHT_MB))
            plan.study_groups[s.name].append((kept, out, members))
        outs = [out for _, out, _ in plan.study_groups[s.name]]
        pooled = f"{plan.results}/studies/{s.name}.nc"
        pool = RuleSpec(_rule(f"pool-{s.name}"), [pooled], f"{plan.results}/logs/studies/{s.name}.log", local=True)
        points = [format_point(kept) for kept, _, _ in plan.study_groups[s.name]]
        plan.add(pool, Job(pool.name, {}, [pooled], outs, ["pool", *outs, pooled, "--points", *points,
                                                           "--study", s.name], {"study": s.name}, LIGHT_SECONDS,
                           LIGHT_MB))
        plan.targets.append(pooled)


def _point_args(plan: Plan, s: Entry, kept: dict[str, Any], members: list) -> list[str]:
    """Flags of the study's command that take scan values (``--p-target`` of each input, ``--growth-rate``)."""
    argv: list[str] = []
    for dim, flag in s.stage.point_args.items():
        if dim in kept:
            argv += [flag, f"{kept[dim]:g}"]
        elif all(dim in point for point, _, _ in members):
            argv += [flag, *(f"{point[dim]:g}" for point, _, _ in members)]
        elif dim in s.stage.point_args and dim == "p_target":
            raise SceneError(f"{s.key}: {s.command} needs the scan dimension {dim} (an LS step's p_target)")
    if s.command == "flow-curve":
        argv += ["--labels", *(format_point({k: v for k, v in point.items() if k not in kept})
                               for point, _, _ in members)]
    return argv


def _eos(plan: Plan, s: Entry, members: list) -> list[str]:
    """The LS equations of state a jamming table reads beside its overlap series (same order)."""
    if "ls.eos" not in s.stage.needs:
        return []
    files = []
    for kept, _, _ in members:
        body = kept.get("body", plan.scene.bodies[0].name)
        rest = {k: v for k, v in kept.items() if k not in ("body", "sample")}
        key = (body, kept["sample"], format_point(rest))
        if key not in plan.eos:
            raise SceneError(f"{s.key}: its overlap series must keep every LS dimension (sample, growth rate)")
        files.append(plan.eos[key])
    return files


def _groups(plan: Plan, command: str, figure: Entry, of: str | None = None) -> list[tuple[dict[str, Any], str]]:
    names = [s.name for s in plan.scene.studies if s.command == command
             and (of is None or s.extra.get("of", _last(plan)) == of)]
    name = figure.options.get("study", names[0] if names else None)
    if name not in plan.study_groups:
        raise SceneError(f"{figure.key}: needs a {command} study" + (f" of {of}" if of else ""))
    return [(kept, out) for kept, out, _ in plan.study_groups[name]]


def _last(plan: Plan) -> str:
    return plan.scene.chain[-1].name if plan.scene.chain else "source"


def _analysis_outputs(plan: Plan, command: str, figure: Entry) -> list[tuple[Packing, str]]:
    names = [a.name for a in plan.scene.analyses if a.command == command]
    if not names:
        raise SceneError(f"{figure.key}: needs the analysis {command}; add it under analyses")
    return [(p, p.analyses[names[0]]) for p in plan.packings if names[0] in p.analyses]


def _labels(points: list[dict[str, Any]]) -> list[str]:
    varying = [k for k in dict.fromkeys(k for p in points for k in p) if len({repr(p.get(k)) for p in points}) > 1]
    return [format_point({k: p[k] for k in varying if k in p}) for p in points]


Figure = Callable[[Plan, Entry], list[tuple[str, list[str], list[str]]]]


#: ``jamflow plot`` kinds that draw one dataset: a study with several kept points draws its last
#: (the largest target pressure, say)
SINGLE = {"forces", "fit-windows", "phi-kappa", "flow-curve", "pareto", "jamming-table", "chains-moduli",
          "phi-asphericity", "z-asphericity"}


def _one(kind: str, command: str, of: str | None = None) -> Figure:
    """A figure of a study's outputs, one curve per kept point (or the last kept point's)."""
    def make(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
        groups = _groups(plan, command, figure, of)
        groups = groups[-1:] if kind in SINGLE else groups
        labels = ["--labels", *_labels([k for k, _ in groups])] if len(groups) > 1 else []
        return [("", [out for _, out in groups], [kind, *(out for _, out in groups), "OUT", *labels])]
    return make


def _windows(command: str) -> Figure:
    def make(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
        _, out = _groups(plan, command, figure)[-1]
        return [("", [out], ["fit-windows", out, "OUT"])]
    return make


def _packing(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
    """One packing figure per body point (first sample): the last packing of the step ``of``."""
    of = figure.options.get("of", _last(plan))
    first = f"seed{plan.scene.seeds[0]}"
    chosen: dict[str, Packing] = {}
    for p in plan.packings:
        if p.step == of and p.sample == first:
            chosen[f"{p.unit[0]}_{p.unit[1]}".replace(",", "_")] = p
    return [(tag, [p.path], ["packing", p.path, "OUT", *(["--soft"] if p.soft else [])])
            for tag, p in chosen.items()]


def _eos_figure(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
    files = list(plan.eos.values())
    if not files:
        raise SceneError(f"{figure.key}: needs an ls step in the chain")
    labels = [f"{b}:{s}:{p}" for b, s, p in plan.eos]
    return [("", files, ["eos", *files, "OUT", "--labels", *labels])]


def _series_labels(pairs: list[tuple[Packing, str]], plan: Plan) -> list[str]:
    return _labels([_full_point(plan, p) for p, _ in pairs])


def _from_analysis(kind: str, command: str) -> Figure:
    def make(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
        pairs = _analysis_outputs(plan, command, figure)
        labels = _series_labels(pairs, plan)
        return [("", [f for _, f in pairs], [kind, *(f for _, f in pairs), "OUT",
                                              *(["--labels", *labels] if len(pairs) > 1 else [])])]
    return make


def _phi_kappa(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
    pairs = [(p, f) for p, f in _analysis_outputs(plan, "flow-summary", figure) if "pressure" in plan.scene.step(
        p.step).options]
    if not pairs:
        raise SceneError(f"{figure.key}: needs a shear step at fixed pressure (its pressure option)")
    return [(format_point(_full_point(plan, p)), [f], ["phi-kappa", f, "OUT"]) for p, f in pairs]


def _ed_vs_sd(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
    sd = _analysis_outputs(plan, "sd-shear", figure)
    made = []
    for p, f in sd:
        runs = [q for q in plan.packings if q.command == "shear" and q.sample == p.sample and q.body == p.body
                and "pressure" not in plan.scene.step(q.step).options]
        if not runs:
            raise SceneError(f"{figure.key}: needs a shear step at fixed volume beside the sd-shear analysis")
        made.append((p.sample, [runs[0].series, f], ["stress-strain", runs[0].series, f, "OUT", "--labels",
                                                     "event-driven", "steepest-descent"]))
    return made


def _spectra(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
    pairs = _analysis_outputs(plan, "modes", figure)
    first = f"seed{plan.scene.seeds[0]}"
    chosen: dict[str, tuple[Packing, str]] = {}
    for p, f in pairs:
        key = f"{p.body}:{format_point({k: v for k, v in p.point.items() if k != 'pressure'})}"
        if p.sample == first and key not in chosen:
            chosen[key] = (p, f)
    labels = [f"{p.body},{format_point(p.point)}" for p, _ in chosen.values()]
    files = [f for _, f in chosen.values()]
    return [("", files, ["spectra", *files, "OUT", "--labels", *labels])]


def _quartic(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
    pairs = _analysis_outputs(plan, "modes", figure)
    p0 = pairs[0][0]
    same = [f for p, f in pairs if p.body == p0.body and {k: v for k, v in p.point.items() if k != "pressure"}
            == {k: v for k, v in p0.point.items() if k != "pressure"}]
    return [("", same, ["quartic-pressure", *same, "OUT"])]


def _gaps_ls_vs_jammed(plan: Plan, figure: Entry) -> list[tuple[str, list[str], list[str]]]:
    ls = _groups(plan, "gaps", figure, of="ls")
    jammed = _groups(plan, "gaps", Entry(figure.name, figure.command, {}, {}, figure.key), of=_last(plan))
    labels = [*(f"LS:{x}" for x in _labels([k for k, _ in ls])), *(f"CALiPPSO:{x}" for x in _labels(
        [k for k, _ in jammed]))]
    files = [o for _, o in ls] + [o for _, o in jammed]
    return [("", files, ["gaps", *files, "OUT", "--labels", *labels])]


#: Every figure a scene may ask for: how its inputs and its ``jamflow plot`` command come from the plan.
FIGURES: dict[str, Figure] = {
    "packing": _packing, "eos": _eos_figure, "phi-j-series": _one("overlap", "overlap-series"),
    "gaps": _one("gaps", "gaps"), "forces": _one("forces", "forces"), "gaps-windows": _windows("gaps"),
    "forces-windows": _windows("forces"), "gaps-ls-vs-calippso": _gaps_ls_vs_jammed,
    "jamming-table": _one("jamming-table", "jamming-table"), "rdf": _from_analysis("rdf", "rdf"),
    "stress-strain": _from_analysis("stress-strain", "flow-summary"), "phi-kappa": _phi_kappa,
    "flow-curve": _one("flow-curve", "flow-curve"), "ed-vs-sd": _ed_vs_sd,
    "phi-asphericity": _one("phi-asphericity", "shape-survey"), "z-asphericity": _one("z-asphericity", "shape-survey"),
    "contact-angles": _one("contact-angles", "contact-angles"), "spectra": _spectra, "quartic-pressure": _quartic,
    "chains-moduli": _one("chains-moduli", "chains-moduli"),
}


def add_figures(plan: Plan) -> None:
    """One job per figure (per body, sample or run where the figure is of one)."""
    for figure in plan.scene.figures:
        if figure.command not in FIGURES:
            raise SceneError(f"{figure.key}: unknown figure (the figures are {', '.join(FIGURES)})"
                             f"{did_you_mean(figure.command, tuple(FIGURES))}")
        made = FIGURES[figure.command](plan, figure)
        for tag, inputs, argv in made:
            stem = f"{plan.results}/figures/{figure.command}" + ("_{tag}" if tag else "")
            spec = RuleSpec(_rule(f"figure-{figure.command}"), [f"{stem}.png", f"{stem}.pdf"],
                            f"{plan.results}/logs/figures/{figure.command}" + ("_{tag}" if tag else "") + ".log",
                            local=True)
            png = spec.outputs[0].format(tag=tag)
            job = Job(spec.name, {"tag": tag} if tag else {}, [png, png.removesuffix(".png") + ".pdf"], inputs,
                      ["plot", *(png if a == "OUT" else a for a in argv)], {"figure": figure.command},
                      LIGHT_SECONDS, LIGHT_MB)
            plan.add(spec, job)
            plan.targets.append(png)


def add_tradeoff(plan: Plan) -> None:
    """Speed against accuracy: one sweep and one Pareto plot per stage (``tradeoff:``)."""
    block = plan.scene.tradeoff
    if not block:
        return
    quick = ["--quick"] if block.get("quick") else []
    sweep = RuleSpec("tradeoff", [f"{plan.results}/tradeoff/{{tag}}.nc"], f"{plan.results}/logs/tradeoff/{{tag}}.log")
    pareto = RuleSpec("figure_pareto", [f"{plan.results}/figures/pareto_{{tag}}.png",
                                        f"{plan.results}/figures/pareto_{{tag}}.pdf"],
                      f"{plan.results}/logs/figures/pareto_{{tag}}.log", local=True)
    for stage in block["stages"]:
        out = f"{plan.results}/tradeoff/{stage}.nc"
        png = f"{plan.results}/figures/pareto_{stage}.png"
        # a full sweep of all stages takes about a quarter of an hour, a quick one a minute
        plan.add(sweep, Job("tradeoff", {"tag": stage}, [out], [], ["tradeoff", stage, out, *quick, "--seed",
                                                                   str(block.get("seed", 0))],
                            {"stage": stage}, 60.0 if quick else 900.0, LIGHT_MB))
        plan.add(pareto, Job("figure_pareto", {"tag": stage}, [png, png.removesuffix(".png") + ".pdf"], [out],
                             ["plot", "pareto", out, png], {"stage": stage}, LIGHT_SECONDS, LIGHT_MB))
        plan.targets += [out, png]
