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

What a scene may do with a command (:mod:`jamflow.scenes` reads it) is in the same entry:
its ``role`` in a scene (a ``source`` making bodies, a chain ``step`` from packing to
packing, a per-packing ``analysis``, a ``study`` pooling packings), the stages that may
come right before it (``after``), the body kind it leaves (``makes``), whether its
packing carries overlaps (``soft_out``), its argument layout (``form``) and the options
a scene may set (:class:`Option`: flag, type, bounds, choices).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

__all__ = ["BODY_KINDS", "ROLES", "STAGES", "Option", "Stage", "refusal", "require", "stage"]

#: Every body kind a packing can hold (module docstring).
BODY_KINDS: tuple[str, ...] = ("spheres", "linked", "shapes", "walls")

#: What a command is to a scene: ``source`` makes the bodies of every sample, a ``step`` turns
#: a packing into a packing (the chain), an ``analysis`` measures one packing (or one run), a
#: ``study`` pools packings or analyses over scan dimensions; ``tool`` is not used by scenes.
ROLES: tuple[str, ...] = ("source", "step", "analysis", "study", "tool")

_SPHERES = frozenset({"spheres"})


@dataclass(frozen=True)
class Option:
    """One option a scene may give a command.

    Attributes
    ----------
    name : str
        Its key in a scene (snake case).
    kind : {"float", "int", "str", "bool", "choice"}
        Its type; a ``bool`` is a bare flag given when true.
    flag : str
        The command-line flag (``--`` and the name with dashes unless stated); ``-`` for a positional argument.
    gt, ge, lt, le : float, optional
        Bounds; every float must also be finite.
    choices : tuple of str
        The values of a ``choice``.
    required : bool
        A scene must give it.
    fan_out : bool
        A list is not a scan of jobs: one job writes one output per value (LS snapshots).
    per_particle : bool
        The scene gives it per particle; the command gets ``round(value * N)``.
    help : str
        What it sets, with units.
    """

    name: str
    kind: str
    flag: str = ""
    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    le: float | None = None
    choices: tuple[str, ...] = ()
    required: bool = False
    fan_out: bool = False
    per_particle: bool = False
    help: str = ""

    def __post_init__(self) -> None:
        if not self.flag:
            object.__setattr__(self, "flag", "--" + self.name.replace("_", "-"))

    def problem(self, value: object) -> str | None:
        """Why ``value`` is not a valid value of this option (one phrase), or None."""
        import math

        if self.kind == "bool":
            return None if isinstance(value, bool) else f"must be true or false, got {value!r}"
        if self.kind == "choice":
            return None if value in self.choices else f"must be one of {', '.join(self.choices)}, got {value!r}"
        if self.kind == "str":
            return None if isinstance(value, str) and value else f"must be a non-empty string, got {value!r}"
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"must be a number, got {value!r}"
        if self.kind == "int" and not float(value).is_integer():
            return f"must be an integer, got {value!r}"
        if not math.isfinite(value):
            return f"must be finite, got {value!r}"
        for bound, bad, word in ((self.gt, lambda b: value <= b, "above"), (self.ge, lambda b: value < b, "at least"),
                                 (self.lt, lambda b: value >= b, "below"), (self.le, lambda b: value > b, "at most")):
            if bound is not None and bad(bound):
                return f"must be {word} {bound:g}, got {value!r}"
        return None


def _o(name: str, kind: str, help: str = "", **kw) -> Option:
    return Option(name, kind, help=help, **kw)


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
    role : str
        Its role in a scene (:data:`ROLES`).
    after : frozenset of str
        Steps (or sources) that may come right before it in a scene's chain; empty: any.
    makes : str or None
        Body kind of its output packing (sources, ``link``); None keeps the input's.
    soft_out : bool or None
        Its output packing may carry overlaps (True), has none (False), or keeps the input's (None).
    form : str
        Argument layout: ``make`` (OUT), ``import`` (FILE OUT), ``step`` and ``analysis`` (IN OUT),
        ``ls`` (IN OUT... --eos EOS), ``flow`` (IN SERIES --final OUT), ``json`` (IN --json > OUT),
        ``pool`` (IN... OUT).
    options : tuple of Option
        What a scene may set.
    reads_soft : bool
        It takes ``--soft`` to read a packing with overlaps.
    preset : bool
        It takes ``--preset``.
    seeded : bool
        It takes ``--seed``, drawn by the scene from the sample's seed.
    pools : str
        Studies: what they pool, ``packings`` or ``analysis:<command>`` or ``study:<command>``.
    point_args : mapping of str to str
        Studies: a scan dimension whose values go to a flag (one per input when pooled, one when kept).
    needs : tuple of str
        Side outputs of earlier steps a study also reads (``ls.eos``).
    """

    command: str
    summary: str
    accepts: frozenset[str] = frozenset()
    instead: Mapping[str, str] = field(default_factory=dict)
    role: str = "tool"
    after: frozenset[str] = frozenset()
    makes: str | None = None
    soft_out: bool | None = None
    form: str = ""
    options: tuple[Option, ...] = ()
    reads_soft: bool = False
    preset: bool = False
    seeded: bool = False
    pools: str = ""
    point_args: Mapping[str, str] = field(default_factory=dict)
    needs: tuple[str, ...] = ()

    @property
    def reads_packings(self) -> bool:
        """Whether the command's inputs are packings (and so are checked against :attr:`accepts`)."""
        return bool(self.accepts)

    def option(self, name: str) -> Option:
        """The option ``name`` (a KeyError names the options there are)."""
        for o in self.options:
            if o.name == name:
                return o
        raise KeyError(f"{self.command} has no option {name!r}; its options are "
                       f"{', '.join(o.name for o in self.options) or 'none'}")


_SCENE_FIELDS = ("role", "after", "makes", "soft_out", "form", "options", "reads_soft", "preset", "seeded",
                 "pools", "point_args", "needs")


def _stage(command: str, summary: str, accepts: frozenset[str] | set[str] = frozenset(), **kw) -> Stage:
    scene = {k: kw.pop(k) for k in _SCENE_FIELDS if k in kw}
    if "after" in scene:
        scene["after"] = frozenset(scene["after"])
    scene["options"] = tuple(scene.get("options", ()))
    return Stage(command, summary, frozenset(accepts), {k.replace("_", "-"): v for k, v in kw.items()}, **scene)


_SOFT_SHAPES = "shapes: `jamflow soft-jam` and `jamflow modes` (shapes have their own energy model)"
_EVENT_DRIVEN = "the event-driven dynamics moves plain periodic spheres"

_PHI = _o("phi", "float", "packing fraction of the random start", gt=0, lt=1)
_D = _o("d", "int", "spatial dimension", ge=2, le=5, required=True)
#: sources of hard (non-overlapping) packings: what LS, CALiPPSO and the event-driven dynamics start from
_HARD_STARTS = ("init", "import-dat")
_FLOW = (
    _o("dt", "float", "largest integration step [1 / rate]", gt=0),
    _o("correct_every", "int", "drift correction every M steps (0: only on the drift tolerance)", ge=0),
    _o("record_every", "int", "record the time series every K steps", ge=1),
    _o("rate", "float", "compression or shear rate", gt=0),
    _o("unit", "choice", "length unit lambda", choices=("mean_diameter", "small_diameter")),
)

#: Every command, by name.
STAGES: dict[str, Stage] = {s.command: s for s in (
    # making and converting packings
    _stage("init", "random non-overlapping packing of spheres (random sequential addition)",
           role="source", makes="spheres", soft_out=False, form="make", seeded=True, options=(
               _D, _o("n", "int", "number of spheres", ge=2, required=True),
               Option("phi", "float", gt=0, lt=1, required=True, help="packing fraction of the random start"),
               _o("dispersity", "choice", "size distribution", choices=("mono", "bi", "poly", "lognormal")),
               _o("ratio", "float", "bidisperse size ratio", gt=1),
               _o("fraction", "float", "bidisperse number fraction of small spheres", gt=0, lt=1),
               _o("width", "float", "polydisperse relative width", ge=0),
               _o("species_spread", "float", "bidisperse relative standard deviation within each species", ge=0),
               _o("walls", "bool", "every sphere inside the box: a start for calippso --walls"))),
    _stage("import-dat", "read a CALiPPSO .dat configuration", role="source", makes="spheres", soft_out=False,
           form="import", options=(_o("file", "str", "the .dat file, relative to the working directory",
                                      flag="-", required=True),)),
    _stage("init-chains", "random start of linked spheres: rigid trimers, chains or dimers",
           role="source", makes="linked", soft_out=False, form="make", seeded=True, options=(
               Option("d", "int", ge=2, le=3, required=True, help="spatial dimension"),
               _o("clusters", "int", "clusters K (N = K M spheres)", ge=1, required=True),
               _o("builder", "choice", "cluster kind", flag="--cluster", choices=("trimer", "chain", "dimer"),
                  required=True),
               _o("chain_length", "int", "spheres per chain M", ge=2),
               _o("free_angles", "bool", "bonds only (flexible chains)"),
               _o("bond_angle", "float", "every bond angle [degrees]", gt=0, lt=180),
               _o("diameter_ratio", "float", "dimer: large over small monomer diameter", ge=1),
               _o("separation", "float", "dimer: monomer centre distance [small-monomer diameters]", gt=0),
               _o("size_ratio", "float", "dimer: length of large over small dimers", ge=1),
               _PHI, _o("overlap", "bool", "the chains paper's overlapping start (links may cross)"))),
    _stage("init-shapes", "random packing of 2D shaped bodies", role="source", makes="shapes", soft_out=False,
           form="make", seeded=True, options=(
               _o("family", "choice", "shape family", flag="--shape",
                  choices=("ellipse", "circulo-line", "circulo-polygon", "dumbbell", "reuleaux"), required=True),
               _o("asphericity", "float", "asphericity A = p^2 / (4 pi a)", gt=1),
               _o("aspect_ratio", "float", "length over width", gt=1),
               _o("sides", "int", "circulo-polygon sides", ge=3),
               _o("random", "bool", "circulo-polygon: a random convex polygon per body"),
               _o("n", "int", "bodies (even: half small, half large)", ge=2, required=True), _PHI)),
    _stage("export-xyz", "extended XYZ or GSD for OVITO and ASE", set(BODY_KINDS)),
    _stage("link", "add links to a packing: cement contacts or read a link list", {"spheres", "linked"},
           shapes="shapes are rigid bodies already; links join spheres",
           walls="links are for periodic packings: jam linked spheres with `jamflow soft-jam`",
           role="step", after=("soft-jam", "minimize", "calippso"), makes="linked", form="step", seeded=True,
           options=(_o("cement", "int", "contacts turned into links", ge=0),
                    _o("cement_per_sphere", "float", "contacts turned into links per sphere, n_l / N", flag="--cement",
                       ge=0, per_particle=True),
                    _o("with_strain", "bool", "judge degenerate links with the strain degrees of freedom (moduli)"))),
    # jamming
    _stage("ls", "Lubachevsky-Stillinger compression of hard spheres", _SPHERES,
           linked="linked spheres: `jamflow soft-jam` (links are constraints LS does not know)",
           shapes="shapes: `jamflow soft-jam`",
           walls="LS runs in a periodic box; jam between walls with `jamflow calippso --walls`",
           role="step", after=_HARD_STARTS, soft_out=False, form="ls", preset=True, seeded=True, options=(
               _o("growth_rate", "float", "slow growth rate kappa [mean diameter / time]", gt=0, required=True),
               _o("p_target", "float", "reduced target pressures, one snapshot each", gt=0, lt=1e14, fan_out=True,
                  required=True),
               _o("fast_growth_rate", "float", "growth rate of the fast first stage (0 skips it)", ge=0),
               _o("fast_until", "float", "reduced pressure ending the fast stage", gt=0),
               _o("beta", "float", "inverse temperature of the velocity rescaling", gt=0),
               _o("max_collisions", "int", "collision budget", ge=1))),
    _stage("calippso", "CALiPPSO: exact jamming of hard spheres by a chain of LPs", {"spheres", "walls"},
           linked="linked spheres: `jamflow soft-jam` then `jamflow certify`",
           shapes="shapes: `jamflow soft-jam`",
           role="step", after=(*_HARD_STARTS, "ls", "compress", "decompress"), soft_out=False, form="step",
           preset=True, options=(
               _o("tol_s", "float", "largest stable displacement [mean diameter]", gt=0),
               _o("tol_gamma", "float", "convergence on sqrt(Gamma*) - 1", gt=0),
               _o("solver", "choice", "HiGHS strategy", choices=("ipm", "simplex", "hybrid", "ipm-center")),
               _o("solver_tol", "float", "HiGHS tolerance of the scaled rows", ge=1e-10, le=2e-8),
               _o("walls", "bool", "hard walls on the box faces"),
               _o("finish", "choice", "newton finish or the paper's pure LP chain", choices=("newton", "lp")),
               _o("max_iterations", "int", "largest number of LPs", ge=1))),
    _stage("soft-jam", "soft jamming onset at a target pressure", {"spheres", "linked", "shapes"},
           walls="soft jamming runs in a periodic box; jam between walls with `jamflow calippso --walls`",
           role="step", soft_out=True, form="step", preset=True, options=(
               _o("pressure", "float", "target pressure P0 [epsilon / mean diameter^d]", gt=0),
               _o("force_tol", "float", "final max per-particle |F| [epsilon / mean diameter]", gt=0),
               _o("pressure_rtol", "float", "final |P - P0| / P0", gt=0),
               _o("delta_phi", "float", "first step in packing fraction of the bisection or search", gt=0),
               _o("onset", "choice", "compress/decompress bisection or the onset search",
                  choices=("bisection", "search")),
               _o("exponent", "float", "potential exponent w (2 harmonic, 2.5 Hertz)", ge=2),
               _o("box_dof", "choice", "final enthalpy minimisation box", choices=("isotropic", "full")),
               _o("max_steps", "int", "FIRE step budget", ge=1),
               _o("shear_stabilize", "bool", "strain free at fixed volume, then the enthalpy with the whole box free"),
               _o("jam_protocol", "choice", "linked packings: bisection or energy", choices=("bisection", "energy")),
               _o("energy_tol", "float", "energy per sphere ending --jam-protocol energy", gt=0))),
    _stage("minimize", "energy minimisation at a fixed box", {"spheres", "linked", "shapes"},
           walls="minimisation runs in a periodic box", role="step", soft_out=True, form="step", options=(
               _o("force_tol", "float", "largest per-particle force at the end", gt=0),
               _o("method", "choice", "minimiser", choices=("fire", "cg", "sd")),
               _o("max_steps", "int", "step budget", ge=1))),
    _stage("certify", "LP certificate: not, locally, collectively or strictly jammed", {"spheres", "linked"},
           shapes="shapes: `jamflow modes` (the quartic modes decide their stability)",
           walls="the certificate of a walled packing is its `jamflow calippso --walls` output",
           role="analysis", after=("calippso", "soft-jam", "minimize", "link"), form="analysis", reads_soft=True,
           preset=True, options=(
               _o("strict", "bool", "also test strict jamming"),
               _o("loads", "int", "random loads per LP kind", ge=1),
               _o("solver", "choice", "HiGHS algorithm", choices=("ipm", "simplex", "choose")))),
    # driving
    _stage("aqs", "athermal quasistatic shear of soft spheres", _SPHERES,
           linked="linked spheres: `jamflow soft-jam --shear-stabilize` and `jamflow moduli`",
           shapes=_SOFT_SHAPES, walls="shear needs a periodic (Lees-Edwards) box",
           role="step", after=("soft-jam", "minimize"), soft_out=True, form="flow", preset=True, options=(
               _o("strain", "float", "total strain", gt=0, required=True),
               _o("step", "float", "strain step", gt=0),
               _o("pressure", "float", "fixed pressure P0", gt=0),
               _o("force_tol", "float", "FIRE tolerance per strain step", gt=0))),
    _stage("sd-shear", "Lerner et al.'s steepest-descent shear", _SPHERES,
           linked="linked spheres: `jamflow soft-jam --shear-stabilize` and `jamflow moduli`",
           shapes=_SOFT_SHAPES, walls="shear needs a periodic (Lees-Edwards) box",
           role="analysis", after=("compress", "decompress", "calippso"), form="analysis", options=(
               _o("strain", "float", "total strain", gt=0, required=True),
               _o("step", "float", "strain step (paper 1e-6)", gt=0),
               _o("dt", "float", "steepest-descent step (paper 0.1)", gt=0),
               _o("grad_tol", "float", "max |grad U| stop (paper 1e-9)", gt=0),
               _o("delta_r", "float", "tentative network distance (paper 1e-5)", gt=0),
               _o("unit", "choice", "length unit lambda", choices=("mean_diameter", "small_diameter")))),
    _stage("shear", "event-driven overdamped shear at fixed volume or pressure", _SPHERES,
           linked=_EVENT_DRIVEN, shapes=_EVENT_DRIVEN, walls="shear needs a periodic (Lees-Edwards) box",
           role="step", after=("compress", "decompress", "calippso"), soft_out=False, form="flow", preset=True,
           reads_soft=True, options=(
               _o("strain", "float", "total shear strain", gt=0, required=True),
               _o("pressure", "float", "fixed pressure [gamma_dot xi0^-1 lambda^(2-d)]; absent: fixed volume", gt=0),
               *_FLOW)),
    _stage("compress", "event-driven overdamped compression", _SPHERES,
           linked=_EVENT_DRIVEN, shapes=_EVENT_DRIVEN, walls=_EVENT_DRIVEN,
           role="step", after=(*_HARD_STARTS, "decompress"), soft_out=False, form="flow", preset=True, options=(
               Option("phi", "float", gt=0, lt=1, help="target packing fraction (absent: to jamming)"),
               _o("strain", "float", "give up after this compressive strain", gt=0), *_FLOW)),
    _stage("decompress", "shrink a jammed packing to a dense flow start", _SPHERES,
           linked=_EVENT_DRIVEN, shapes=_EVENT_DRIVEN, walls=_EVENT_DRIVEN,
           role="step", after=("calippso", "soft-jam"), soft_out=False, form="step", reads_soft=True,
           options=(Option("phi", "float", gt=0, lt=1, required=True, help="target packing fraction"),)),
    _stage("drive", "event-driven dynamics under external or self-propelling forces", _SPHERES,
           linked=_EVENT_DRIVEN, shapes=_EVENT_DRIVEN, walls=_EVENT_DRIVEN),
    # measuring one packing
    _stage("check", "contacts, rattlers, isostaticity, overlaps, force balance", {"spheres", "linked", "shapes"},
           walls="a walled packing's counts (wall contacts included) are in its `jamflow calippso --walls` output",
           role="analysis", form="json", reads_soft=True, options=(
               _o("gap_tol", "float", "relative gap counted as contact", ge=0),
               _o("parallel_contacts", "choice", "shapes: a parallel circulo contact counts once or twice",
                  choices=("once", "twice")))),
    _stage("moduli", "Hessian, lowest modes and elastic moduli", {"spheres", "linked"},
           shapes="shapes: `jamflow modes`", walls="moduli need a periodic box",
           role="analysis", after=("soft-jam", "minimize", "link"), form="analysis",
           options=(_o("modes", "int", "lowest non-translational eigenvalues", ge=1),)),
    _stage("modes", "normal modes: quartic modes of shapes, constrained-Hessian modes of linked spheres",
           {"shapes", "linked"}, spheres="spheres: `jamflow moduli`", walls="spheres: `jamflow moduli`",
           role="analysis", after=("soft-jam", "minimize"), form="analysis", options=(
               _o("lambda_c", "float", "shapes: cutoff between regions 1 and 2 [k]", gt=0),
               _o("strain", "choice", "linked spheres: include the strain at fixed volume",
                  choices=("auto", "yes", "no")))),
    # analyses over packings
    _stage("gaps", "gap distribution p(h) and the exponent gamma", _SPHERES,
           linked="gaps between spheres count linked pairs as contacts; not defined for linked spheres",
           shapes="gaps are sphere centre distances; not defined for shapes",
           walls="gaps of a walled packing would miss the wall gaps",
           role="study", form="pool", pools="packings", reads_soft=True, options=(
               _o("fit_min", "float", "lower end of the scaling range", gt=0),
               _o("fit_max", "float", "upper end of the scaling range", gt=0),
               _o("gap_tol", "float", "pairs with h <= this are contacts (0 for LS snapshots)", ge=0),
               _o("include_rattlers", "bool", "keep pairs with a rattler (LS snapshots)"))),
    _stage("forces", "force distribution P(f) and the exponent theta", _SPHERES,
           linked="link tensions are not contact forces; not defined for linked spheres",
           shapes="shapes: `jamflow contact-angles`, `jamflow modes`",
           walls="force statistics of a walled packing would miss the wall forces",
           role="study", form="pool", pools="packings", reads_soft=True, options=(
               _o("fit_min", "float", "lower end of the small-force scaling range", gt=0),
               _o("fit_max", "float", "upper end of the small-force scaling range", gt=0))),
    _stage("overlap", "contact-network overlap Q of two packings", _SPHERES,
           linked="Q compares sphere contact networks", shapes="Q compares sphere contact networks",
           walls="Q compares periodic sphere contact networks"),
    _stage("overlap-series", "Q, |Delta phi_J| and LPs against p_tar for one sample", _SPHERES,
           linked="Q compares sphere contact networks", shapes="Q compares sphere contact networks",
           walls="Q compares periodic sphere contact networks",
           role="study", form="pool", pools="packings", reads_soft=True,
           point_args={"p_target": "--p-target", "growth_rate": "--growth-rate"}),
    _stage("rdf", "g(r) and crystallinity", _SPHERES,
           linked="g(r) of linked spheres would mix links and contacts",
           shapes="g(r) of centres is not the shapes' structure", walls="g(r) needs a periodic box",
           role="analysis", form="analysis", reads_soft=True, options=(
               _o("r_max", "float", "largest r [mean diameters], below half the box", gt=0),
               _o("bins", "int", "r bins", ge=1))),
    _stage("shape-survey", "phi_J and <z> per shape family and asphericity (disks as the A = 1 limit)",
           {"shapes", "spheres"}, linked="linked spheres: `jamflow check`", walls="spheres: `jamflow check`",
           role="study", form="pool", pools="packings", options=(
               _o("spectral", "bool", "also count contacts as N_c^0 - N_1 from each packing's spectrum (Fig. 8)"),
               _o("lambda_c", "float", "with spectral: cutoff between regions 1 and 2 [k]", gt=0))),
    _stage("constraint-curvature", "principal curvatures of the contact constraints of circulo-lines", {"shapes"},
           spheres="constraint curvatures are of circulo-line contacts",
           linked="constraint curvatures are of circulo-line contacts",
           walls="constraint curvatures are of circulo-line contacts",
           role="study", form="pool", pools="packings"),
    _stage("feasible-region", "feasible region of a circulo-line caged by three points"),
    _stage("contact-angles", "contact-angle density P(psi) of elongated shapes", {"shapes"},
           spheres="contact angles are of elongated shapes", linked="contact angles are of elongated shapes",
           walls="contact angles are of elongated shapes",
           role="study", form="pool", pools="packings", options=(
               _o("parallel_contacts", "choice", "a parallel circulo contact counts once or twice",
                  choices=("once", "twice")),
               _o("bins", "int", "bins on [0, pi/2]", ge=1))),
    # datasets and tables
    _stage("jamming-table", "phi_J of the LS equation of state against LS+CALiPPSO",
           role="study", form="pool", pools="study:overlap-series", needs=("ls.eos",), options=(
               _o("fit_min", "float", "lowest reduced pressure of the Eq. 15 fit", gt=0),
               _o("fit_max", "float", "highest reduced pressure of the Eq. 15 fit", gt=0))),
    _stage("flow-summary", "stress-strain, friction, steady-state means of a flow run",
           role="analysis", after=("shear", "aqs", "compress"), form="analysis", options=(
               _o("strain_min", "float", "start of the steady-state window", ge=0),
               _o("blocks", "int", "blocks of the error estimate", ge=2))),
    _stage("flow-curve", "friction and phi against the viscous number",
           role="study", form="pool", pools="analysis:flow-summary"),
    _stage("chains-moduli", "moduli against added links per particle",
           role="study", form="pool", pools="analysis:moduli"),
    _stage("pool", "one netCDF of a study: its datasets along the scan dimensions they keep"),
    _stage("plot", "figures (PNG + PDF)"),
    _stage("summary", "one table of a whole scene"),
    _stage("reproduce", "the reproduced-figures page: paper numbers beside each paper scene's"),
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
