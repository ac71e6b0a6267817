"""The stage table: every ``jamflow`` command, the bodies its input packing may hold, and what to use instead.

One table, read by the command line (each command checks its input packing against it
before any work and refuses what it cannot do in one line), by the workflow's plan-time
checks and by the test that runs every command on every body kind. A stage never treats
bodies as free spheres: it handles them, or it is refused here.

Body kinds of a packing (:func:`jamflow.state.packing.Packing.body_kind`):

=========  =====================================================================
``spheres``  periodic spheres without links (discs in 2D)
``linked``   spheres joined by fixed-length links (rigid clusters, chains, cemented contacts)
``shapes``   2D non-spherical bodies with orientations (ellipses, circulo-polygons, ...)
``walls``    spheres jammed between hard walls (CALiPPSO ``--walls``; wall contacts kept apart)
=========  =====================================================================
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

__all__ = ["BODY_KINDS", "STAGES", "Stage", "refusal", "require", "stage"]

#: Every body kind a packing can hold (module docstring).
BODY_KINDS: tuple[str, ...] = ("spheres", "linked", "shapes", "walls")

_SPHERES = frozenset({"spheres"})


@dataclass(frozen=True)
class Stage:
    """One command of the stage table.

    Attributes
    ----------
    command : str
        The ``jamflow`` subcommand.
    summary : str
        What it does, in one line.
    accepts : frozenset of str
        Body kinds of :data:`BODY_KINDS` its input packings may hold; empty for a
        command that reads no packing (it makes one, or reads other datasets).
    instead : mapping of str to str
        For a refused body kind, what to run instead (shown in the refusal).
    """

    command: str
    summary: str
    accepts: frozenset[str] = frozenset()
    instead: Mapping[str, str] = field(default_factory=dict)

    @property
    def reads_packings(self) -> bool:
        """Whether the command's inputs are packings (and so are checked against :attr:`accepts`)."""
        return bool(self.accepts)


def _stage(command: str, summary: str, accepts: frozenset[str] | set[str] = frozenset(),
           **instead: str) -> Stage:
    return Stage(command, summary, frozenset(accepts), {k.replace("_", "-"): v for k, v in instead.items()})


_SOFT_SHAPES = "shapes: `jamflow soft-jam` and `jamflow modes` (shapes have their own energy model)"
_EVENT_DRIVEN = "the event-driven dynamics moves plain periodic spheres"

#: Every command, by name.
STAGES: dict[str, Stage] = {s.command: s for s in (
    # making and converting packings
    _stage("init", "random non-overlapping packing of spheres (random sequential addition)"),
    _stage("import-dat", "read a CALiPPSO .dat configuration"),
    _stage("init-chains", "random start of linked spheres: rigid trimers, chains or dimers"),
    _stage("init-shapes", "random packing of 2D shaped bodies"),
    _stage("export-xyz", "extended XYZ or GSD for OVITO and ASE", set(BODY_KINDS)),
    _stage("link", "add links to a packing: cement contacts or read a link list", {"spheres", "linked"},
           shapes="shapes are rigid bodies already; links join spheres",
           walls="links are for periodic packings: jam linked spheres with `jamflow soft-jam`"),
    # jamming
    _stage("ls", "Lubachevsky-Stillinger compression of hard spheres", _SPHERES,
           linked="linked spheres: `jamflow soft-jam` (links are constraints LS does not know)",
           shapes="shapes: `jamflow soft-jam`",
           walls="LS runs in a periodic box; jam between walls with `jamflow calippso --walls`"),
    _stage("calippso", "CALiPPSO: exact jamming of hard spheres by a chain of LPs", {"spheres", "walls"},
           linked="linked spheres: `jamflow soft-jam` then `jamflow certify`",
           shapes="shapes: `jamflow soft-jam`"),
    _stage("soft-jam", "soft jamming onset at a target pressure", {"spheres", "linked", "shapes"},
           walls="soft jamming runs in a periodic box; jam between walls with `jamflow calippso --walls`"),
    _stage("minimize", "energy minimisation at a fixed box", {"spheres", "linked", "shapes"},
           walls="minimisation runs in a periodic box"),
    _stage("certify", "LP certificate: not, locally, collectively or strictly jammed", {"spheres", "linked"},
           shapes="shapes: `jamflow modes` (the quartic modes decide their stability)",
           walls="the certificate of a walled packing is its `jamflow calippso --walls` output"),
    # driving
    _stage("aqs", "athermal quasistatic shear of soft spheres", _SPHERES,
           linked="linked spheres: `jamflow soft-jam --shear-stabilize` and `jamflow moduli`",
           shapes=_SOFT_SHAPES, walls="shear needs a periodic (Lees-Edwards) box"),
    _stage("sd-shear", "Lerner et al.'s steepest-descent shear", _SPHERES,
           linked="linked spheres: `jamflow soft-jam --shear-stabilize` and `jamflow moduli`",
           shapes=_SOFT_SHAPES, walls="shear needs a periodic (Lees-Edwards) box"),
    _stage("shear", "event-driven overdamped shear at fixed volume or pressure", _SPHERES,
           linked=_EVENT_DRIVEN, shapes=_EVENT_DRIVEN, walls="shear needs a periodic (Lees-Edwards) box"),
    _stage("compress", "event-driven overdamped compression", _SPHERES,
           linked=_EVENT_DRIVEN, shapes=_EVENT_DRIVEN, walls=_EVENT_DRIVEN),
    _stage("decompress", "shrink a jammed packing to a dense flow start", _SPHERES,
           linked=_EVENT_DRIVEN, shapes=_EVENT_DRIVEN, walls=_EVENT_DRIVEN),
    _stage("drive", "event-driven dynamics under external or self-propelling forces", _SPHERES,
           linked=_EVENT_DRIVEN, shapes=_EVENT_DRIVEN, walls=_EVENT_DRIVEN),
    # measuring one packing
    _stage("check", "contacts, rattlers, isostaticity, overlaps, force balance", {"spheres", "linked", "shapes"},
           walls="a walled packing's counts (wall contacts included) are in its `jamflow calippso --walls` output"),
    _stage("moduli", "Hessian, lowest modes and elastic moduli", {"spheres", "linked"},
           shapes="shapes: `jamflow modes`",
           walls="moduli need a periodic box"),
    _stage("modes", "normal modes: quartic modes of shapes, constrained-Hessian modes of linked spheres",
           {"shapes", "linked"}, spheres="spheres: `jamflow moduli`", walls="spheres: `jamflow moduli`"),
    # analyses over packings
    _stage("gaps", "gap distribution p(h) and the exponent gamma", _SPHERES,
           linked="gaps between spheres count linked pairs as contacts; not defined for linked spheres",
           shapes="gaps are sphere centre distances; not defined for shapes",
           walls="gaps of a walled packing would miss the wall gaps"),
    _stage("forces", "force distribution P(f) and the exponent theta", _SPHERES,
           linked="link tensions are not contact forces; not defined for linked spheres",
           shapes="shapes: `jamflow contact-angles`, `jamflow modes`",
           walls="force statistics of a walled packing would miss the wall forces"),
    _stage("overlap", "contact-network overlap Q of two packings", _SPHERES,
           linked="Q compares sphere contact networks", shapes="Q compares sphere contact networks",
           walls="Q compares periodic sphere contact networks"),
    _stage("overlap-series", "Q, |Delta phi_J| and LPs against p_tar for one sample", _SPHERES,
           linked="Q compares sphere contact networks", shapes="Q compares sphere contact networks",
           walls="Q compares periodic sphere contact networks"),
    _stage("rdf", "g(r) and crystallinity", _SPHERES,
           linked="g(r) of linked spheres would mix links and contacts",
           shapes="g(r) of centres is not the shapes' structure", walls="g(r) needs a periodic box"),
    _stage("shape-survey", "phi_J and <z> per shape family and asphericity (2D disks: the A = 1 limit)",
           {"shapes", "spheres"}, linked="linked spheres: `jamflow check`", walls="spheres: `jamflow check`"),
    _stage("constraint-curvature", "principal curvatures of the contact constraints of circulo-lines", {"shapes"},
           spheres="constraint curvatures are of circulo-line contacts",
           linked="constraint curvatures are of circulo-line contacts",
           walls="constraint curvatures are of circulo-line contacts"),
    _stage("feasible-region", "feasible region of a circulo-line caged by three points"),
    _stage("contact-angles", "contact-angle density P(psi) of elongated shapes", {"shapes"},
           spheres="contact angles are of elongated shapes", linked="contact angles are of elongated shapes",
           walls="contact angles are of elongated shapes"),
    # datasets and tables
    _stage("jamming-table", "phi_J of the LS equation of state against LS+CALiPPSO"),
    _stage("flow-summary", "stress-strain, friction, steady-state means of a flow run"),
    _stage("flow-curve", "friction and phi against the viscous number"),
    _stage("chains-moduli", "moduli against added links per particle"),
    _stage("plot", "figures (PNG + PDF)"),
    _stage("summary", "one table of a whole scene"),
    _stage("tradeoff", "speed against accuracy of a stage's knobs"),
)}


def stage(command: str) -> Stage:
    """The table's entry of ``command`` (a KeyError names the commands there are)."""
    try:
        return STAGES[command]
    except KeyError:
        raise KeyError(f"no stage {command!r}; the stages are {', '.join(sorted(STAGES))}") from None


def refusal(command: str, kind: str) -> str | None:
    """Why ``command`` refuses a packing of body kind ``kind`` (one line), or None when it accepts it."""
    entry = stage(command)
    if kind not in BODY_KINDS:
        raise ValueError(f"unknown body kind {kind!r}; the kinds are {', '.join(BODY_KINDS)}")
    if not entry.reads_packings or kind in entry.accepts:
        return None
    hint = entry.instead.get(kind)
    what = {"spheres": "plain spheres", "linked": "linked spheres", "shapes": "shaped bodies",
            "walls": "spheres between hard walls"}[kind]
    accepted = ", ".join(k for k in BODY_KINDS if k in entry.accepts)
    return f"{command} does not take {what} (it takes: {accepted})" + (f"; {hint}" if hint else "")


def require(command: str, kind: str) -> None:
    """Raise ``ValueError`` (one line, :func:`refusal`) unless ``command`` takes a packing of body kind ``kind``.

    Every stage function calls it first, so the Python API refuses what the command line refuses.
    """
    why = refusal(command, kind)
    if why:
        raise ValueError(why)
