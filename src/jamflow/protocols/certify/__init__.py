"""Jamming certificates: local, collective and strict jamming by randomized LPs.

Implements the randomized linear-programming test of Donev, Torquato, Stillinger and
Connelly, J. Comput. Phys. 197, 139 (2004), in the form of the soft-chains paper,
Sec. V (Eqs. 40-42), for the jamming hierarchy of Torquato and Stillinger:

* **locally jammed**: no particle can move with all others held fixed;
* **collectively jammed**: no subset of particles can move, the periodic box fixed;
* **strictly jammed**: collectively jammed, and no motion exists even when the box
  may also deform at fixed volume (symmetric strain with ``Tr eps = 0``).

A motion ``(y, eps)`` is allowed to first order when no contact closes,
``R (y, eps) >= -g`` with ``R`` the rigidity matrix (:mod:`jamflow.network.rigidity`) and
``g`` either zero (exact contacts) or the contacts' actual gaps ("gap-aware"; the
linearised constraint is conservative because ``|r + dr| >= n . (r + dr)``). The
LP maximises a random load ``b . y`` over the allowed motions with every
coordinate bounded by one mean diameter; the packing (or its backbone) is jammed
when no load of either sign finds a motion. With exact contacts the allowed motions
form a cone ``C``; the optimum for ``+b`` and ``-b`` is zero only when ``b`` is
orthogonal to ``C``, which has probability zero unless ``C`` is trivial, so one
load of both signs decides in exact arithmetic; further loads guard against
motions that round-off hides. With gaps the allowed set is a polytope (the
first-order cage), bounded exactly when the cone of the same network is trivial;
a load that meets a recession direction drives the solution to the bound. The
cage of a rigid network can still be much larger than the gaps when the network
is nearly floppy; its size is reported, and a gap-aware solution at the bound is
decided by the exact-contact LP with the same load (see :class:`_Search`).

Rattlers are removed in stages and each removal is recorded: (1) particles with
fewer than ``d + 1`` backbone contacts, (2) particles that move in the local LP
(all others fixed), (3) rattling clusters: moving connected groups of the
collective LP that neither wrap around the periodic box nor exceed a stated
fraction of the backbone. A moving group that wraps around the box (a sliding row
or plane) or is larger is a collective unjamming motion and is reported.

Modules: ``hierarchy`` (:func:`certify`: the backbone tested kind by kind), ``lp`` (the
motion LP, the random-load search, the LP kinds), ``record`` (the certificate and its
dataset).
"""

from .hierarchy import (
    DEFAULT_LOADS,
    DEFAULT_MAX_CLUSTER_FRACTION,
    DEFAULT_SOLVER,
    SELF_STRESS_TEST_MAX_FRACTION,
    certify,
    moving_clusters,
)
from .lp import COLLECTIVE, LOCAL, STRICT, Motion, MotionLP, random_loads
from .record import (
    CLASSIFICATIONS,
    LP_STAGES,
    RATTLER_STAGES,
    JammingCertificate,
    LPRecord,
    certificate_to_dataset,
)

__all__ = [
    "CLASSIFICATIONS",
    "COLLECTIVE",
    "DEFAULT_LOADS",
    "DEFAULT_MAX_CLUSTER_FRACTION",
    "DEFAULT_SOLVER",
    "LOCAL",
    "LP_STAGES",
    "RATTLER_STAGES",
    "SELF_STRESS_TEST_MAX_FRACTION",
    "STRICT",
    "JammingCertificate",
    "LPRecord",
    "Motion",
    "MotionLP",
    "certificate_to_dataset",
    "certify",
    "moving_clusters",
    "random_loads",
]
