"""The scene grammar: read a scene, apply its scale, check it against the stage table.

A scene (YAML, ``docs/scenes.md``) names its bodies, a sampler (seeds), a chain of
stages, analyses per packing, studies that pool packings, and figures::

    scene: NAME
    bodies: {spheres: {d: 3, n: 256, phi: 0.3}}      # or linked / shapes / import, or a list
    seeds: [1, 2, 3]                                   # or {count: 20}: 1 .. 20
    chain: [{ls: {growth_rate: [1.0e-3, 3.0e-4], p_target: [1.0e+3, 1.0e+5]}}, calippso]
    analyses: [check]                                  # of the last step unless {of: STEP}
    studies: [{overlap-series: {over: [p_target]}}]    # pool over the named scan dimensions
    figures: [phi-j-series]
    scales: {paper: {bodies.spheres.n: 1024, seeds: {count: 20}}}

Any option given as a list is a scan dimension (product over lists, pairs of lists
listed under ``zip`` are zipped). Every check here runs before any job and raises
:class:`SceneError` with one line naming the key, with a did-you-mean suggestion for a typo.
"""

from __future__ import annotations

import copy
import difflib
from dataclasses import dataclass, field
from typing import Any

from ..stages import STAGES, Stage, refusal

__all__ = ["BODY_SOURCES", "Entry", "Scene", "SceneError", "did_you_mean", "read_scene"]

#: Body kinds a scene may name, and the command that makes them.
BODY_SOURCES: dict[str, str] = {"spheres": "init", "linked": "init-chains", "shapes": "init-shapes",
                                "import": "import-dat"}
#: Top-level keys of a scene.
TOP_KEYS = ("scene", "scale", "preset", "bodies", "seeds", "chain", "analyses", "studies", "figures", "zip",
            "scales", "resources", "tradeoff")
#: Keys a chain step, an analysis or a study may carry beside its command's options.
STEP_KEYS = ("name", "draws", "sequence")
ANALYSIS_KEYS = ("name", "of")
STUDY_KEYS = ("name", "of", "over", "analysis")
#: Keys of the resources block: limits a plan must respect.
RESOURCE_KEYS = ("max_mem_mb", "group_minutes")
SCALES = ("laptop", "paper")
PRESETS = ("fast", "default", "publication")
TRADEOFF_STAGES = ("soft", "shapes", "chains", "aqs", "overdamped", "certify", "calippso", "ls")


class SceneError(ValueError):
    """A scene that cannot run: one line naming the key."""


def did_you_mean(word: Any, choices: list[str] | tuple[str, ...]) -> str:
    """``"; did you mean 'x'?"`` for the closest of ``choices``, or ``""``."""
    close = difflib.get_close_matches(str(word), list(choices), n=1, cutoff=0.6)
    return f"; did you mean {close[0]!r}?" if close else ""


def _fail(key: str, message: str) -> SceneError:
    return SceneError(f"{key}: {message}")


@dataclass
class Entry:
    """One body block, chain step, analysis or study of a scene.

    Attributes
    ----------
    name : str
        Unique name (the command unless the scene names it); the file name of its outputs.
    command : str
        The ``jamflow`` command (:data:`jamflow.stages.STAGES`).
    options : dict
        The command's options as the scene gives them (lists are scans).
    extra : dict
        The grammar's own keys (``of``, ``over``, ``draws``, ``name``, body ``kind``).
    key : str
        Where it sits in the scene, for messages (``chain.ls``).
    """

    name: str
    command: str
    options: dict[str, Any]
    extra: dict[str, Any] = field(default_factory=dict)
    key: str = ""

    @property
    def stage(self) -> Stage:
        return STAGES[self.command]


@dataclass
class Scene:
    """A checked scene at one scale (:func:`read_scene`)."""

    name: str
    scale: str
    preset: str
    bodies: list[Entry]
    seeds: list[int]
    chain: list[Entry]
    analyses: list[Entry]
    studies: list[Entry]
    figures: list[Entry]
    zips: list[list[str]]
    resources: dict[str, Any]
    tradeoff: dict[str, Any] | None

    def step(self, name: str) -> Entry:
        for e in (*self.bodies, *self.chain):
            if e.name == name:
                return e
        raise KeyError(name)


def _entries(value: Any, key: str) -> list[tuple[str, dict[str, Any]]]:
    """A list of ``command`` or ``{command: {options}}`` as (command, options) pairs."""
    if value is None:
        return []
    if not isinstance(value, list):
        raise _fail(key, f"must be a list, got {value!r}")
    out = []
    for i, item in enumerate(value):
        if isinstance(item, str):
            out.append((item, {}))
        elif isinstance(item, dict) and len(item) == 1:
            (command, options), = item.items()
            options = {} if options is None else options
            if not isinstance(options, dict):
                raise _fail(f"{key}.{command}", f"options must be a mapping, got {options!r}")
            out.append((str(command), dict(options)))
        else:
            raise _fail(f"{key}[{i}]", f"must be a name or {{name: {{options}}}}, got {item!r}")
    return out


def _find(entries: list[Any], name: str) -> list[dict[str, Any]]:
    """The option mappings of the entries of a list named ``name``: its command or kind, its
    ``name``, a body block's ``kind-family`` (``shapes-ellipse``), its index, or ``*`` for all."""
    found = []
    for k, item in enumerate(entries):
        if isinstance(item, str):
            item = entries[k] = {item: {}}
        (command, options), = item.items()
        if options is None:
            options = item[command] = {}
        family = options.get("family", options.get("builder"))
        if name in ("*", str(k), command, options.get("name"), f"{command}-{family}"):
            found.append(options)
    return found


def _set(config: dict[str, Any], dotted: str, value: Any, where: str) -> None:
    """Set ``bodies.spheres.n``, ``chain.ls.growth_rate``, ``seeds`` ... in ``config``."""
    parts = dotted.split(".")
    head = parts[0]
    if head not in TOP_KEYS or head in ("scales", "scale", "scene"):
        raise _fail(f"{where}.{dotted}", f"{head!r} is not a key a scale may set{did_you_mean(head, TOP_KEYS)}")
    if len(parts) == 1:
        config[head] = copy.deepcopy(value)
        return
    if head in ("chain", "analyses", "studies", "bodies"):
        if len(parts) != 3:
            raise _fail(f"{where}.{dotted}", f"give {head}.<name>.<option>")
        entries = config.get(head)
        if head == "bodies" and isinstance(entries, dict):
            entries = config["bodies"] = [{k: v} for k, v in entries.items()]
        targets = _find(entries or [], parts[1])
        if not targets:
            raise _fail(f"{where}.{dotted}", f"the scene has no {head} entry {parts[1]!r}")
        for options in targets:
            options[parts[2]] = copy.deepcopy(value)
        return
    node = config.setdefault(head, {})
    for p in parts[1:-1]:
        node = node.setdefault(p, {})
    node[parts[-1]] = copy.deepcopy(value)


def apply_scale(config: dict[str, Any]) -> dict[str, Any]:
    """The scene at its ``scale`` (``laptop`` as written; others from ``scales``), without ``scales``."""
    config = copy.deepcopy(config)
    scale = config.pop("scale", "laptop")
    scales = config.pop("scales", {}) or {}
    if scale not in SCALES:
        raise _fail("scale", f"must be one of {', '.join(SCALES)}, got {scale!r}{did_you_mean(scale, SCALES)}")
    unknown = [s for s in scales if s not in SCALES or s == "laptop"]
    if unknown:
        raise _fail(f"scales.{unknown[0]}", "a scene gives the paper scale here (the laptop scale is the scene "
                    f"itself){did_you_mean(unknown[0], SCALES)}")
    if scale != "laptop":
        if scale not in scales:
            raise _fail("scale", f"this scene gives no {scale!r} scale (it has: laptop"
                        f"{''.join(', ' + s for s in scales)})")
        for dotted, value in (scales[scale] or {}).items():
            _set(config, dotted, value, f"scales.{scale}")
    config["scale"] = scale
    return config


def _seeds(value: Any) -> list[int]:
    if isinstance(value, dict):
        if set(value) != {"count"} or not isinstance(value["count"], int) or value["count"] < 1:
            raise _fail("seeds", f"give a list of seeds or {{count: K}} (seeds 1 .. K), got {value!r}")
        return list(range(1, value["count"] + 1))
    if isinstance(value, int) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, list) or not value or any(not isinstance(s, int) or isinstance(s, bool) or s < 0
                                                       for s in value):
        raise _fail("seeds", f"must be non-negative integers, got {value!r}")
    if len(set(value)) != len(value):
        raise _fail("seeds", f"must be distinct, got {value}")
    return list(value)


def _check_options(entry: Entry, own_keys: tuple[str, ...], scans: bool) -> None:
    """Unknown keys, bad values (NaN and inf included), missing required options of one entry."""
    stage = entry.stage
    names = [o.name for o in stage.options]
    for key, value in entry.options.items():
        if key not in names:
            raise _fail(f"{entry.key}.{key}", f"{entry.command} has no option {key!r} (it has: "
                        f"{', '.join(names + list(own_keys)) or 'none'}){did_you_mean(key, names + list(own_keys))}")
        option = stage.option(key)
        values = value if isinstance(value, list) else [value]
        if option.fan_out:
            entry.options[key] = values
        if isinstance(value, list):
            if not value:
                raise _fail(f"{entry.key}.{key}", "an empty list scans nothing")
            if not (scans or option.fan_out):
                raise _fail(f"{entry.key}.{key}", f"a list would scan it, and {entry.key.split('.')[0]} options are "
                            "not scanned: put the stage in the chain to scan it")
            if len(set(map(repr, value))) != len(value):
                raise _fail(f"{entry.key}.{key}", f"a scan lists distinct values, got {value}")
        for v in values:
            problem = option.problem(v)
            if problem:
                raise _fail(f"{entry.key}.{key}", problem)
        if option.fan_out and any(b <= a for a, b in zip(values, values[1:])):
            raise _fail(f"{entry.key}.{key}", f"must be strictly increasing, got {values}")
    for option in stage.options:
        if option.required and option.name not in entry.options:
            raise _fail(f"{entry.key}.{option.name}", f"{entry.command} needs it ({option.help})")


def _bodies(value: Any) -> list[Entry]:
    if value is None:
        return []
    blocks = [{k: v} for k, v in value.items()] if isinstance(value, dict) else value
    out: list[Entry] = []
    for kind, options in _entries(blocks, "bodies"):
        if kind not in BODY_SOURCES:
            raise _fail(f"bodies.{kind}", f"unknown body kind (the kinds are {', '.join(BODY_SOURCES)})"
                        f"{did_you_mean(kind, tuple(BODY_SOURCES))}")
        command = BODY_SOURCES[kind]
        family = options.get("family") or options.get("builder")
        tag = kind if not isinstance(family, str) else f"{kind}-{family}"
        if isinstance(options.get("file"), dict):
            raise _fail("bodies.import.file", "give a path or a list of paths")
        n_same = sum(e.name == tag or e.name.startswith(f"{tag}-") and e.name[len(tag) + 1:].isdigit() for e in out)
        name = tag if not n_same else f"{tag}-{n_same + 1}"
        entry = Entry(name, command, options, {"kind": kind}, f"bodies.{kind}")
        _check_options(entry, (), scans=True)
        out.append(entry)
    return out


def _chain(value: Any) -> list[Entry]:
    out: list[Entry] = []
    for command, options in _entries(value, "chain"):
        key = f"chain.{command}"
        if command not in STAGES:
            steps = [c for c, s in STAGES.items() if s.role == "step"]
            raise _fail(key, f"unknown stage (the chain's stages are {', '.join(steps)}){did_you_mean(command, steps)}")
        role = STAGES[command].role
        if role != "step":
            where = {"analysis": "analyses", "study": "studies", "source": "bodies"}.get(role)
            raise _fail(key, f"{command} is not a chain step" + (f"; list it under {where}" if where else ""))
        extra = {k: options.pop(k) for k in STEP_KEYS if k in options}
        name = extra.get("name") or command
        if "draws" in extra and (not STAGES[command].seeded or not isinstance(extra["draws"], int)
                                 or isinstance(extra["draws"], bool) or extra["draws"] < 1):
            raise _fail(f"{key}.draws", "independent draws (a positive integer) are for stages that draw random "
                        f"numbers ({', '.join(c for c, s in STAGES.items() if s.seeded and s.role == 'step')})")
        entry = Entry(name, command, options, extra, key)
        _check_options(entry, STEP_KEYS, scans=True)
        sequence = extra.get("sequence")
        if sequence is not None and not isinstance(options.get(sequence), list):
            raise _fail(f"{key}.sequence", f"names the option whose listed values run one after the other, each "
                        f"from the packing of the one before; {sequence!r} is not a listed option of {command}"
                        f"{did_you_mean(sequence, [k for k, v in options.items() if isinstance(v, list)])}")
        out.append(entry)
    return out


def _measures(value: Any, section: str, role: str, own: tuple[str, ...]) -> list[Entry]:
    out: list[Entry] = []
    for command, options in _entries(value, section):
        key = f"{section}.{command}"
        wanted = [c for c, s in STAGES.items() if s.role == role]
        if command not in wanted:
            hint = f"; it is a {STAGES[command].role}" if command in STAGES else did_you_mean(command, wanted)
            raise _fail(key, f"not one of the {section} ({', '.join(wanted)}){hint}")
        extra = {k: options.pop(k) for k in own if k in options}
        entry = Entry(extra.get("name") or command, command, options, extra, key)
        _check_options(entry, own, scans=False)
        out.append(entry)
    return out


def _unique(entries: list[Entry], section: str) -> None:
    seen: set[str] = set()
    for e in entries:
        if e.name in seen:
            raise _fail(f"{section}.{e.name}", "two entries with one name; give one of them a name: key")
        seen.add(e.name)


def read_scene(config: dict[str, Any]) -> Scene:
    """Check a scene (a parsed YAML mapping, with ``scale`` from the command line) and apply its scale.

    Raises
    ------
    SceneError
        One line naming the first key that is wrong: unknown keys and stages (with a
        suggestion), bad option values (NaN and inf included), options missing, stages that
        cannot take the scene's bodies or cannot follow the stage before them, analyses and
        studies without what they pool.
    """
    if not isinstance(config, dict):
        raise SceneError(f"a scene is a mapping of keys, got {type(config).__name__}")
    for key in config:
        if key not in TOP_KEYS:
            raise _fail(str(key), f"unknown scene key (the keys are {', '.join(TOP_KEYS)}){did_you_mean(key, TOP_KEYS)}")
    config = apply_scale(config)
    name = config.get("scene")
    if not isinstance(name, str) or not name or not all(c.isalnum() or c in "_-" for c in name):
        raise _fail("scene", f"needs a name of letters, digits, - and _, got {name!r}")
    preset = config.get("preset", "default")
    if preset not in PRESETS:
        raise _fail("preset", f"must be one of {', '.join(PRESETS)}, got {preset!r}{did_you_mean(preset, PRESETS)}")
    resources = dict(config.get("resources") or {})
    for key, value in resources.items():
        if key not in RESOURCE_KEYS:
            raise _fail(f"resources.{key}", f"unknown key (the keys are {', '.join(RESOURCE_KEYS)})"
                        f"{did_you_mean(key, RESOURCE_KEYS)}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0 or value == float("inf"):
            raise _fail(f"resources.{key}", f"must be a positive finite number, got {value!r}")
    tradeoff = config.get("tradeoff")
    bodies = _bodies(config.get("bodies"))
    if tradeoff is not None:
        _check_tradeoff(tradeoff)
    elif not bodies:
        raise _fail("bodies", "a scene names its bodies (spheres, linked, shapes or import)")
    seeded = any(STAGES[b.command].seeded for b in bodies)
    if "seeds" not in config and seeded:
        raise _fail("seeds", "random bodies need seeds (a list, or {count: K})")
    seeds = _seeds(config.get("seeds", [0]))
    chain = _chain(config.get("chain"))
    analyses = _measures(config.get("analyses"), "analyses", "analysis", ANALYSIS_KEYS)
    studies = _measures(config.get("studies"), "studies", "study", STUDY_KEYS)
    figures = [Entry(c, c, o, {}, f"figures.{c}") for c, o in _entries(config.get("figures"), "figures")]
    for section, entries in (("chain", chain), ("analyses", analyses), ("studies", studies)):
        _unique(entries, section)
    zips = config.get("zip") or []
    if not isinstance(zips, list) or any(not isinstance(z, list) or len(z) < 2 for z in zips):
        raise _fail("zip", f"give a list of groups of at least two dotted keys, got {zips!r}")
    scene = Scene(name, config["scale"], preset, bodies, seeds, chain, analyses, studies, figures, zips, resources,
                  tradeoff)
    check_order(scene)
    return scene


def _check_tradeoff(block: Any) -> None:
    if not isinstance(block, dict) or not isinstance(block.get("stages"), list) or not block["stages"]:
        raise _fail("tradeoff.stages", "give the stages to sweep")
    for key in block:
        if key not in ("stages", "quick", "seed"):
            raise _fail(f"tradeoff.{key}", f"unknown key{did_you_mean(key, ('stages', 'quick', 'seed'))}")
    for s in block["stages"]:
        if s not in TRADEOFF_STAGES:
            raise _fail("tradeoff.stages", f"{s!r} is not one of {', '.join(TRADEOFF_STAGES)}"
                        f"{did_you_mean(s, TRADEOFF_STAGES)}")


def body_kinds_after(scene: Scene, body: Entry) -> dict[str, str]:
    """The body kind of every step's packing (source included) for one body block."""
    walls = body.options.get("walls") is True
    kind = "walls" if walls else STAGES[body.command].makes
    kinds = {"source": kind}
    for step in scene.chain:
        kind = step.stage.makes or kind
        kinds[step.name] = kind
    return kinds


def check_order(scene: Scene) -> None:
    """What the stage table says about order and bodies (see :func:`read_scene`)."""
    steps = ["source"] + [s.name for s in scene.chain]
    for body in scene.bodies:
        kinds = body_kinds_after(scene, body)
        before = body
        for step in scene.chain:
            why = refusal(step.command, kinds["source" if before is body else before.name])
            if why:
                raise _fail(step.key, why)
            allowed = step.stage.after
            if allowed and before.command not in allowed:
                raise _fail(step.key, f"{step.command} cannot follow {before.command} (it needs one of "
                            f"{', '.join(sorted(allowed))} right before it)")
            before = step
        for m in (*scene.analyses, *scene.studies):
            of = m.extra.get("of", steps[-1] if m.stage.role == "analysis" or m.stage.pools == "packings" else None)
            if of is None:
                continue
            if of not in steps:
                raise _fail(f"{m.key}.of", f"no step {of!r} in the chain (the steps are {', '.join(steps)})"
                            f"{did_you_mean(of, steps)}")
            kind = kinds[of]
            if m.stage.pools in ("packings", "") or m.stage.role == "analysis":
                why = refusal(m.command, kind)
                if why:
                    raise _fail(m.key, why)
            made_by = body.command if of == "source" else scene.step(of).command
            if m.stage.after and made_by not in m.stage.after:
                raise _fail(f"{m.key}.of", f"{m.command} measures packings of {', '.join(sorted(m.stage.after))}, "
                            f"not of {made_by}")
    _check_studies(scene)


def _check_studies(scene: Scene) -> None:
    analyses = {a.command for a in scene.analyses}
    studies = {s.command for s in scene.studies}
    for s in scene.studies:
        pools = s.stage.pools
        if pools.startswith("analysis:") and pools.split(":")[1] not in analyses:
            raise _fail(s.key, f"pools the analysis {pools.split(':')[1]}; add it under analyses")
        if pools.startswith("study:") and pools.split(":")[1] not in studies:
            raise _fail(s.key, f"pools the study {pools.split(':')[1]}; add it under studies")
        for need in s.stage.needs:
            if need.split(".")[0] not in [c.command for c in scene.chain]:
                raise _fail(s.key, f"needs the {need} output of a {need.split('.')[0]} step in the chain")
        over = s.extra.get("over", [])
        if not isinstance(over, (list, str)):
            raise _fail(f"{s.key}.over", f"give a list of scan dimensions, got {over!r}")
