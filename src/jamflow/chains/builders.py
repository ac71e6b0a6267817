"""Builders of linked packings: rigid clusters, chains, cementing, link files (chains paper Sec. II A, F).

Links are fixed centre-to-centre distances (:class:`~jamflow.state.bodies.Links`). A bond
angle at sphere ``b`` between bonds ``a-b`` and ``b-c`` is frozen by the link ``a-c``
(paper Fig. 1). The builders here make

- **chains** of ``M`` touching spheres (bond length = contact distance) with random
  bond angles, free or frozen (:func:`chain_offsets`, :func:`chain_links`); a trimer
  is a chain of three with its angle frozen (a rigid cluster);
- **rigid clusters** of arbitrary shape from body-frame offsets
  (:func:`rigid_cluster_links`): every pair is a candidate link and a greedy rank
  test keeps an independent, rigidifying subset;
- **cemented** packings (:func:`cement`, paper Sec. VI and Fig. 5): ``k`` randomly
  chosen contacts become links at their current length, and the bond angles they
  create are frozen;
- links **read from a text file** (:func:`read_link_file`).

Degenerate (redundant) links make the constraint Jacobian rank deficient (a straight
triple with its angle frozen, a rigid square with both diagonals);
:func:`remove_degenerate_links` finds them per cluster by a greedy Gram–Schmidt rank
test in the order links are given (bonds before angle links, so a chain keeps its
bonds) and drops them with one message each.

Bad input (:func:`check_linked_start`): links that cross in 2D (two crossing chains
are a stable, unphysical state that no minimisation undoes, paper Fig. 3), a cluster
spanning more than half the box (it would meet its own periodic image, and the
minimum-image convention of a link would become ambiguous under compression) and
link lengths no configuration satisfies (Newton re-affixing fails).
"""

from __future__ import annotations

from dataclasses import dataclass
from math import pi

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..box import Box
from ..neighbors.pairs import pairs_within
from ..protocols.initial import draw_diameters
from ..state.bodies import Links
from ..state.packing import Packing, linked_volume, sphere_volume
from ..tolerances import LINK_RANK_RTOL, OVERLAP_TOL
from .dimers import (
    DIMER_DIAMETER_RATIO,
    DIMER_SEPARATION,
    DIMER_SIZE_RATIO,
    check_dimer,
    dimer_asphericity,
)
from .growth import grow_chain

__all__ = [
    "BOND_ANGLE_RANGE",
    "CLUSTER_KINDS",
    "DILUTE_PHI",
    "OVERLAP_PHI",
    "SIZE_CLASSES",
    "Sizes",
    "cement",
    "cement_links",
    "cement_pairs",
    "chain_links",
    "chain_offsets",
    "check_linked_start",
    "cluster_extent",
    "crossing_links",
    "frozen_angles",
    "linked_packing",
    "read_link_file",
    "remove_degenerate_links",
    "rigid_cluster_links",
]

#: Cluster kinds of :func:`linked_packing`.
CLUSTER_KINDS = ("trimer", "chain", "dimer")

#: How :func:`linked_packing` draws sizes of a mixture: one diameter per cluster (every
#: sphere of a cluster the same, the cluster a scaled copy) or one per sphere (bonds are
#: the contact distances of their two spheres).
SIZE_CLASSES = ("cluster", "sphere")

#: Range [rad] of random bond angles (the angle at a sphere between its two bonds).
#: Below pi/3 the spheres next-but-one overlap (their distance ``2 b sin(theta/2)`` is
#: below the bond length ``b``); at pi the triple is straight and a frozen angle is a
#: degenerate link (its QR diagonal goes as ``sin(theta)``): 5 pi / 6 keeps
#: ``sin(theta) >= 1/2``, far from :data:`~jamflow.tolerances.LINK_RANK_RTOL`.
BOND_ANGLE_RANGE: tuple[float, float] = (pi / 3.0, 5.0 * pi / 6.0)

#: Trial placements per cluster before random placement without crossing links gives up.
PLACEMENT_TRIES: int = 1000


def chain_offsets(m: int, d: int, bond: float, angles: ArrayLike, rng: np.random.Generator) -> NDArray[np.float64]:
    """Centres of a chain of ``m`` spheres relative to its centroid, shape (m, d) [length].

    Parameters
    ----------
    m : int
        Number of spheres, >= 1.
    d : int
        Dimension, 2 or 3.
    bond : float or array_like, shape (m - 1,)
        Bond length(s) [length].
    angles : array_like, shape (m - 2,)
        Bond angle at spheres ``1 .. m-2`` [rad], in ``(0, pi]``.
    rng : numpy.random.Generator
        Draws the first bond direction, in 2D the sense of each turn and in 3D the
        torsion of each bond (uniform).
    """
    angles = np.asarray(angles, dtype=np.float64).reshape(-1)
    if angles.size != max(m - 2, 0):
        raise ValueError(f"a chain of {m} spheres has {max(m - 2, 0)} bond angles, got {angles.size}")
    bonds = np.broadcast_to(np.asarray(bond, dtype=np.float64), (max(m - 1, 0),))
    x = np.zeros((m, d))
    u = rng.normal(size=d)
    u /= np.linalg.norm(u)
    for k in range(1, m):
        if k >= 2:
            turn = pi - angles[k - 2]  # angle between successive bond directions
            if d == 2:
                turn *= rng.choice((-1.0, 1.0))
                c, s = np.cos(turn), np.sin(turn)
                u = np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])
            else:
                w = rng.normal(size=d)
                w -= (w @ u) * u
                w /= np.linalg.norm(w)
                u = np.cos(turn) * u + np.sin(turn) * w
        x[k] = x[k - 1] + bonds[k - 1] * u
    return x - x.mean(axis=0)


def chain_links(m: int, offset: int, x: NDArray[np.float64], free_angles: bool,
                frozen: ArrayLike | None = None) -> tuple[list, list]:
    """Links of one chain: bonds ``(k, k+1)`` and angle links ``(k, k+2)`` freezing the bond angles.

    Every angle is frozen unless ``free_angles``; ``frozen`` (shape (m - 2,), bool: the
    angle at sphere ``k + 1``) picks them one by one (semi-flexible chains). Returns
    ``(pairs, lengths)`` with global indices ``offset + k`` and the distances of ``x``
    (shape (m, d), unwrapped). Bonds come first.
    """
    mask = np.full(max(m - 2, 0), not free_angles) if frozen is None else np.asarray(frozen, dtype=bool)
    pairs = [(offset + k, offset + k + 1) for k in range(m - 1)]
    pairs += [(offset + k, offset + k + 2) for k in range(m - 2) if mask[k]]
    lengths = [float(np.linalg.norm(x[b - offset] - x[a - offset])) for a, b in pairs]
    return pairs, lengths


def frozen_angles(m: int, free_angles: bool, fraction: float | None, every: int | None,
                  rng: np.random.Generator) -> NDArray[np.bool_]:
    """Which bond angles of a chain of ``m`` are frozen, shape (m - 2,): all, none (``free_angles``),
    each with probability ``fraction`` (drawn from ``rng``), or those at spheres ``k`` with ``k % every == 0``."""
    n = max(m - 2, 0)
    if fraction is not None:
        return rng.random(n) < fraction
    if every is not None:
        return (np.arange(1, n + 1) % every) == 0
    return np.full(n, not free_angles)


def rigid_cluster_links(x: ArrayLike, offset: int = 0) -> tuple[list, list]:
    """Links making spheres at ``x`` (shape (m, d), body frame) one rigid cluster.

    Candidates are every pair, nearest first; :func:`_independent` keeps those that
    raise the rank of the constraint Jacobian, so the result is rigid (rank
    ``d m - d (d + 1) / 2`` for a cluster spanning ``d`` dimensions) and not degenerate.
    """
    x = np.asarray(x, dtype=np.float64)
    m = len(x)
    a, b = np.triu_indices(m, 1)
    r = np.linalg.norm(x[b] - x[a], axis=1)
    order = np.argsort(r, kind="stable")
    a, b, r = a[order], b[order], r[order]
    keep = _independent(a, b, x[b] - x[a], m)
    return [(offset + int(p), offset + int(q)) for p, q in zip(a[keep], b[keep])], list(r[keep])


def _independent(i: NDArray[np.int64], j: NDArray[np.int64], vec: NDArray[np.float64], n: int,
                 strain: bool = False) -> NDArray[np.bool_]:
    """Greedy rank test of link gradients in the given order (local indices).

    The gradient of link ``(i, j)`` is ``-u`` on ``i`` and ``+u`` on ``j``,
    ``u = vec / |vec|`` (with ``strain``, also its strain column ``sym(u vec^T)`` of
    :mod:`jamflow.models.strain`, unscaled); it is kept when its component orthogonal
    to the kept ones (Gram–Schmidt, applied twice for stability) has a norm above
    :data:`~jamflow.tolerances.LINK_RANK_RTOL` times its own.
    """
    d = vec.shape[1]
    u = vec / np.linalg.norm(vec, axis=1)[:, None]
    m = d * (d + 1) // 2 if strain else 0
    if strain:
        from ..models.strain import strain_components

        columns = strain_components(u[:, :, None] * vec[:, None, :], 1.0)
    basis = np.zeros((0, n * d + m))
    keep = np.zeros(len(i), dtype=bool)
    for k in range(len(i)):
        g = np.zeros(n * d + m)
        g[i[k] * d:(i[k] + 1) * d] = -u[k]
        g[j[k] * d:(j[k] + 1) * d] = u[k]
        if strain:
            g[n * d:] = columns[k]
        g /= np.linalg.norm(g)
        for _ in range(2):
            g -= basis.T @ (basis @ g)
        norm = float(np.linalg.norm(g))
        if norm > LINK_RANK_RTOL:
            basis = np.vstack([basis, g / norm])
            keep[k] = True
    return keep


def remove_degenerate_links(
    pairs: ArrayLike, lengths: ArrayLike, position: ArrayLike, box: Box, strain: bool = False,
) -> tuple[Links, list[str]]:
    """Links with redundant (degenerate) ones removed, and one message per removed link.

    Parameters
    ----------
    pairs : array_like of int, shape (L, 2)
        Linked particles in order of priority (earlier links are kept first).
    lengths : array_like, shape (L,)
        Link lengths [length].
    position : array_like, shape (N, d)
        Centres [length]; link directions are their minimum-image differences.
    box : Box
    strain : bool
        Judge independence with the strain degrees of freedom (shear stabilisation,
        compliance): links closing loops around the periodic box then fix the box shape
        and are kept; the strain couples all clusters, so the test is global.

    Returns
    -------
    links : Links
    messages : list of str
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    lengths = np.asarray(lengths, dtype=np.float64).reshape(-1)
    x = np.asarray(position, dtype=np.float64)
    n = len(x)
    i, j = pairs.min(axis=1), pairs.max(axis=1)
    whole = Links(i, j, lengths)  # validates indices, duplicates and lengths
    labels = whole.clusters(n)
    keep = np.ones(len(i), dtype=bool)
    vec = box.minimum_image(x[j] - x[i])
    link_label = labels[i]
    for c in np.unique(link_label) if not strain else [None]:
        idx = np.flatnonzero(link_label == c) if c is not None else np.arange(len(i))
        members = np.unique(np.concatenate([i[idx], j[idx]]))
        local = np.searchsorted(members, np.stack([i[idx], j[idx]]))
        keep[idx] = _independent(local[0], local[1], vec[idx], len(members), strain)
    messages = [f"removed degenerate link ({a}, {b}) of length {r:.6g}: its gradient depends linearly on "
                f"those of the other links of its cluster (rank-deficient constraint Jacobian, chains paper Sec. II B)" for a, b, r in zip(i[~keep], j[~keep], lengths[~keep])]
    return Links(i[keep], j[keep], lengths[keep]), messages


def crossing_links(links: Links, position: ArrayLike, box: Box) -> NDArray[np.int64]:
    """Pairs of links whose segments cross (2D; minimum images), shape (P, 2), link indices ``a < b``.

    Links sharing a sphere never count as crossing. Two segments ``p + t r`` and
    ``q + s w`` cross when the solution has ``0 < t < 1`` and ``0 < s < 1``. Only
    links whose midpoints lie within the longest link of each other are tested
    (segments that cross meet within half their lengths of both midpoints), by a pair
    query on the midpoints; a box narrower than twice the longest link tests every pair.
    """
    if box.d != 2:
        raise ValueError("crossing links are a 2D notion")
    x = np.asarray(position, dtype=np.float64)
    if len(links) < 2:
        return np.empty((0, 2), np.int64)
    r = box.minimum_image(x[links.j] - x[links.i])
    reach = float(np.sqrt(np.max(np.einsum("ka,ka->k", r, r))))
    if reach < 0.5 * float(np.min(box.widths)):
        near = pairs_within(x[links.i] + 0.5 * r, box, reach)
        hit = _cross_pairs(links, near.i, near.j, r, x, box)
        return np.stack([near.i[hit], near.j[hit]], axis=1)
    every = np.arange(len(links))
    out = [np.empty((0, 2), np.int64)]
    for start in range(0, len(links), 512):
        rows = every[start:start + 512]
        hit = _cross(links, rows, every, x, box) & (every[None, :] > rows[:, None])
        ka, kb = np.nonzero(hit)
        out.append(np.stack([rows[ka], kb], axis=1))
    return np.concatenate(out)


def _cross(links: Links, a: NDArray[np.int64], b: NDArray[np.int64], x: NDArray[np.float64],
           box: Box) -> NDArray[np.bool_]:
    """Whether link ``a[p]`` crosses link ``b[q]``, shape (len(a), len(b)) (see :func:`crossing_links`)."""
    r = box.minimum_image(x[links.j] - x[links.i])
    return _cross_pairs(links, a[:, None], b[None, :], r, x, box)


def _cross_pairs(links: Links, a: NDArray[np.int64], b: NDArray[np.int64], r: NDArray[np.float64],
                 x: NDArray[np.float64], box: Box) -> NDArray[np.bool_]:
    """Whether link ``a`` crosses link ``b``, element-wise over the broadcast of ``a`` and ``b``;
    ``r`` (L, d) the minimum-image link vectors."""
    i, j = links.i, links.j
    pq = box.minimum_image(x[i[b]] - x[i[a]])  # start of b relative to start of a
    ra, rb = r[a], r[b]
    den = ra[..., 0] * rb[..., 1] - ra[..., 1] * rb[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (pq[..., 0] * rb[..., 1] - pq[..., 1] * rb[..., 0]) / den
        s = (pq[..., 0] * ra[..., 1] - pq[..., 1] * ra[..., 0]) / den
    share = (i[a] == i[b]) | (i[a] == j[b]) | (j[a] == i[b]) | (j[a] == j[b])
    return ~share & (den != 0.0) & (t > 0.0) & (t < 1.0) & (s > 0.0) & (s < 1.0)


def cluster_extent(links: Links, position: ArrayLike, box: Box) -> NDArray[np.float64]:
    """Largest centre-to-centre distance within each cluster, unwrapped along its links, shape (C,).

    A cluster whose links wind around the box (a cycle of link vectors summing to a
    lattice vector) has infinite extent.
    """
    x = np.asarray(position, dtype=np.float64)
    n = len(x)
    labels = links.clusters(n)
    vec = box.minimum_image(x[links.j] - x[links.i])
    unwrapped = np.full_like(x, np.nan)
    adjacency: list[list[tuple[int, int]]] = [[] for _ in range(n)]
    for k, (a, b) in enumerate(zip(links.i, links.j)):
        adjacency[a].append((b, k))
        adjacency[b].append((a, -k - 1))
    for root in range(n):
        if not np.isnan(unwrapped[root, 0]):
            continue
        unwrapped[root] = x[root]
        stack = [root]
        while stack:
            a = stack.pop()
            for b, k in adjacency[a]:
                if np.isnan(unwrapped[b, 0]):
                    unwrapped[b] = unwrapped[a] + (vec[k] if k >= 0 else -vec[-k - 1])
                    stack.append(b)
    extent = np.zeros(labels.max() + 1)
    closure = np.linalg.norm(unwrapped[links.j] - unwrapped[links.i] - vec, axis=1)
    winding = closure > 1e-6 * np.maximum(links.length, 1.0)
    extent[labels[links.i[winding]]] = np.inf
    for c in np.flatnonzero(np.bincount(labels) > 1):
        if np.isinf(extent[c]):
            continue
        u = unwrapped[labels == c]
        extent[c] = float(np.max(np.linalg.norm(u[:, None, :] - u[None, :, :], axis=2)))
    return extent


def check_linked_start(packing: Packing) -> None:
    """Refuse a linked start that no minimisation can fix (module doc): one clear ``ValueError``."""
    links, box = packing.links, packing.box
    if links is None or not len(links):
        return
    half = 0.5 * float(np.min(box.widths))
    extent = cluster_extent(links, packing.position, box)
    if np.any(extent >= half):
        c = int(np.argmax(extent))
        members = np.flatnonzero(links.clusters(packing.n) == c)
        raise ValueError(f"cluster of particles {members[:6].tolist()}{'...' if len(members) > 6 else ''} spans "
                         f"{extent[c]:.6g}, more than half the smallest box width ({half:.6g}): use more "
                         f"clusters or a larger box")
    if box.d == 2:
        cross = crossing_links(links, packing.position, box)
        if len(cross):
            a, b = cross[0]
            raise ValueError(f"{len(cross)} pair(s) of links cross in 2D, e.g. links ({links.i[a]}, {links.j[a]}) "
                             f"and ({links.i[b]}, {links.j[b]}): crossed chains cannot be untangled by "
                             f"minimisation (chains paper Fig. 3)")
    from ..models.links import LinkedSpheresModel

    model = LinkedSpheresModel(box, packing.diameter, links, packing.position)
    try:
        model.reproject(model.dofs(packing.position))
    except RuntimeError as exc:
        err = np.abs(links.length_errors(packing.position, box))
        k = int(np.argmax(err))
        raise ValueError(f"link lengths are inconsistent: no configuration near the start satisfies them "
                         f"(largest relative error {err[k]:.3g} at link ({links.i[k]}, {links.j[k]}); {exc})") from None


def read_link_file(path: str, position: ArrayLike, box: Box) -> tuple[NDArray[np.int64], NDArray[np.float64]]:
    """Links from a text file: one ``i j [length]`` per line (``#`` starts a comment).

    A missing length is the pair's current minimum-image distance. Returns
    ``(pairs (L, 2), lengths (L,))``; indices and lengths are validated by
    :func:`remove_degenerate_links` / :class:`~jamflow.state.bodies.Links`.
    """
    x = np.asarray(position, dtype=np.float64)
    pairs, lengths = [], []
    with open(path, encoding="utf-8") as fh:
        for number, line in enumerate(fh, 1):
            fields = line.split("#", 1)[0].split()
            if not fields:
                continue
            try:
                if len(fields) not in (2, 3):
                    raise ValueError
                a, b = int(fields[0]), int(fields[1])
                length = float(fields[2]) if len(fields) == 3 else None
            except ValueError:
                raise ValueError(f"{path}:{number}: expected 'i j [length]', got {line.strip()!r}") from None
            if not (0 <= a < len(x) and 0 <= b < len(x)) or a == b:
                raise ValueError(f"{path}:{number}: link ({a}, {b}) must join two different particles of 0..{len(x) - 1}")
            pairs.append((min(a, b), max(a, b)))
            lengths.append(float(np.linalg.norm(box.minimum_image(x[b] - x[a]))) if length is None else length)
    if not pairs:
        raise ValueError(f"{path}: no links")
    return np.array(pairs, np.int64), np.array(lengths)


def cement(packing: Packing, k: int, rng: np.random.Generator, strain: bool = False) -> tuple[Links, list[str]]:
    """Turn ``k`` random contacts into links and freeze the bond angles they create (paper Fig. 5).

    :func:`cement_pairs` draws the contacts, :func:`cement_links` links them.

    Returns
    -------
    links : Links
        Existing plus new links.
    messages : list of str
        One per removed degenerate link.
    """
    return cement_links(packing, cement_pairs(packing, k, rng), strain)


def cement_pairs(packing: Packing, k: int, rng: np.random.Generator) -> NDArray[np.int64]:
    """``k`` distinct random contacts of ``packing`` that are not linked yet, shape (k, 2)."""
    if packing.contacts is None:
        raise ValueError("cementing needs the packing's contacts")
    old = _links_or_empty(packing)
    c = packing.contacts[~old.contains(packing.contacts[:, 0], packing.contacts[:, 1])]
    if not 0 <= k <= len(c):
        raise ValueError(f"cannot cement {k} contacts: the packing has {len(c)} unlinked contacts")
    return c[np.sort(rng.choice(len(c), size=k, replace=False))]


def _links_or_empty(packing: Packing) -> Links:
    if packing.links is not None:
        return packing.links
    return Links(np.empty(0, np.int64), np.empty(0, np.int64), np.empty(0))


def cement_links(packing: Packing, new: NDArray[np.int64], strain: bool = False) -> tuple[Links, list[str]]:
    """Link the pairs ``new`` (K, 2) at their current distances and freeze the bond angles they create.

    For every sphere, each pair of its links of which at least one is new gets an
    angle link between the two other ends at their current distance. Redundant
    links are then removed (:func:`remove_degenerate_links`, with ``strain`` as there;
    existing links and new contact links first).
    """
    old = _links_or_empty(packing)
    x, box = packing.position, packing.box
    pairs = [(int(a), int(b)) for a, b in zip(old.i, old.j)] + [tuple(map(int, p)) for p in new]
    lengths = list(old.length) + list(_distances(new, x, box))
    is_new = [False] * len(old) + [True] * len(new)
    seen = set(pairs)
    partners: dict[int, list[tuple[int, bool]]] = {}
    for (a, b), fresh in zip(pairs, is_new):
        partners.setdefault(a, []).append((b, fresh))
        partners.setdefault(b, []).append((a, fresh))
    angle_pairs = []
    for centre in sorted(partners):
        ends = partners[centre]
        for p in range(len(ends)):
            for q in range(p + 1, len(ends)):
                (a, fa), (b, fb) = ends[p], ends[q]
                pair = (min(a, b), max(a, b))
                if (fa or fb) and pair not in seen:
                    seen.add(pair)
                    angle_pairs.append(pair)
    pairs += angle_pairs
    lengths += list(_distances(np.array(angle_pairs, np.int64).reshape(-1, 2), x, box))
    return remove_degenerate_links(pairs, lengths, x, box, strain)


def _distances(pairs: NDArray[np.int64], x: NDArray[np.float64], box: Box) -> NDArray[np.float64]:
    """Minimum-image centre distances of ``pairs`` (P, 2) [length]."""
    return np.linalg.norm(box.minimum_image(x[pairs[:, 1]] - x[pairs[:, 0]]), axis=1)


@dataclass(frozen=True)
class Sizes:
    """A size mixture of linked spheres (as :func:`jamflow.protocols.initial.draw_diameters`).

    Attributes
    ----------
    dispersity : {"mono", "bi", "poly", "lognormal"}
    ratio, fraction, width : float
        Bidisperse size ratio (> 1) and number fraction of small ones; relative width of
        ``poly`` / ``lognormal``.
    per : {"cluster", "sphere"}
        :data:`SIZE_CLASSES`: one diameter per cluster (a scaled copy; a bidisperse
        mixture of clusters, ``fraction`` of them small) or one per sphere.
    """

    dispersity: str = "mono"
    ratio: float = 1.4
    fraction: float = 0.5
    width: float = 0.1
    per: str = "cluster"

    def __post_init__(self) -> None:
        if self.per not in SIZE_CLASSES:
            raise ValueError(f"sizes are drawn per {' or per '.join(SIZE_CLASSES)}, got {self.per!r}")

    def draw(self, clusters: int, m: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """Diameters of ``clusters`` clusters of ``m`` spheres, shape (clusters m,), cluster-major."""
        if self.per == "cluster":
            return np.repeat(draw_diameters(clusters, self.dispersity, rng, self.ratio, self.fraction, self.width), m)
        return draw_diameters(clusters * m, self.dispersity, rng, self.ratio, self.fraction, self.width)

    def attrs(self) -> dict:
        """Dataset attributes of the mixture."""
        return {"dispersity": self.dispersity, "size_ratio": self.ratio, "small_fraction": self.fraction,
                "size_width": self.width, "sizes_per": self.per}


#: Default packing fraction of the start without overlaps, per d: the densest at which
#: every random sequential placement of the chains tried succeeded
#: (measured: docs/notes/chains.md#dilute-placement-how-dense-a-start-places). The
#: bisection's compression steps of ``delta_phi`` make overlaps too small for a link to
#: pass through a sphere.
DILUTE_PHI: dict[int, float] = {2: 0.2, 3: 0.1}
#: Packing fraction of the paper's start with overlaps (Sec. III), per d: just above the
#: sphere jamming densities, so the bisection decompresses.
OVERLAP_PHI: dict[int, float] = {2: 0.86, 3: 0.66}


def linked_packing(
    d: int, clusters: int, kind: str, rng: np.random.Generator, chain_length: int = 3,
    free_angles: bool = False, phi: float | None = None, bond_angle: float | None = None, no_overlap: bool = True,
    diameter_ratio: float = DIMER_DIAMETER_RATIO, size_ratio: float = DIMER_SIZE_RATIO,
    separation: float = DIMER_SEPARATION, sizes: Sizes | None = None, frozen_fraction: float | None = None,
    frozen_every: int | None = None,
) -> tuple[Packing, list[str]]:
    """A random start of ``clusters`` chains, trimers or dimers at packing fraction ``phi``.

    Chains and trimers are of unit spheres (the length unit) with bonds of the contact
    length 1; bond angles are uniform in :data:`BOND_ANGLE_RANGE` (or all
    ``bond_angle``). Dimers (:mod:`jamflow.chains.dimers`) are a small monomer of
    diameter 1 (the length unit) and a large one of ``diameter_ratio`` at a distance
    ``separation``; every second dimer is scaled by ``size_ratio`` (bidisperse, half
    large). Cluster centroids are uniform in a cubic box and orientations (and 3D
    torsions) uniform. A cluster spanning half the box or more, or in 2D one whose links
    would cross a placed link (or one of its own), is redrawn, up to :data:`PLACEMENT_TRIES` times. By default
    clusters are placed without overlaps at the dilute :data:`DILUTE_PHI` and the jamming bisection compresses them.
    This departs from the paper (Sec. III starts above jamming with overlaps, ``no_overlap=False``): where soft
    spheres overlap, a link can pass through a sphere or another link during the minimisation, and the clusters end
    entangled (refused by :mod:`jamflow.chains.entanglement`) from a third of such starts (docs/notes/chains.md).

    Parameters
    ----------
    d : int
        2 or 3.
    clusters : int
        Number of clusters K; N = K M spheres.
    kind : {"trimer", "chain", "dimer"}
        ``trimer``: M = 3, angle frozen unless ``free_angles``; ``chain``: M = ``chain_length``;
        ``dimer``: M = 2.
    phi : float, optional
        Packing fraction (the union of each cluster's spheres,
        :func:`~jamflow.state.packing.linked_volume`); default :data:`DILUTE_PHI` without
        overlaps (0.2 in 2D, 0.1 in 3D), else :data:`OVERLAP_PHI` (slightly above the
        sphere jamming densities, so the jamming bisection decompresses).
    bond_angle : float, optional
        Every bond angle [rad]; default random.
    no_overlap : bool
        Default True: redraw a cluster whose spheres overlap a placed sphere or each other (random
        sequential placement; relative overlaps up to :data:`~jamflow.tolerances.OVERLAP_TOL`
        pass, e.g. next-nearest spheres at a bond angle of exactly pi/3). The linked
        monomers of a dimer overlap by construction.
    diameter_ratio, size_ratio, separation : float
        Dimers only: large over small monomer diameter, large over small dimer length,
        and the monomers' centre distance in small-monomer diameters
        (defaults: the paper's 1.4, 1.4 and 1).
    frozen_fraction, frozen_every : optional
        Chains only, semi-flexible: freeze each bond angle with probability
        ``frozen_fraction`` (drawn per chain), or the angle at every ``frozen_every``-th
        sphere (1, 2, ... along the chain); the rest are free.
    sizes : Sizes, optional
        Chains and trimers: a size mixture (default: all spheres of diameter 1). Equal
        spheres partly crystallise (2D dimers, flexible chains), which is why studies of
        the jamming point need mixtures. The box is set from the volume of whole spheres:
        with sizes per sphere, unequal next-nearest spheres at a frozen angle near pi/3
        can share a lens, and the packing fraction of the union is then a little below
        ``phi`` (the packing's own is exact).

    Returns
    -------
    packing, messages
        The packing (links, no contacts) and messages about removed degenerate links.
    """
    if d not in (2, 3):
        raise ValueError(f"linked packings are built in d = 2 or 3, got d = {d}")
    if kind not in CLUSTER_KINDS:
        raise ValueError(f"cluster kind must be one of {', '.join(CLUSTER_KINDS)}, got {kind!r}")
    m = {"trimer": 3, "dimer": 2}.get(kind, chain_length)
    if m < 2 and kind == "chain":
        raise ValueError(f"a chain needs at least 2 spheres, got --chain-length {m}")
    if clusters < 1:
        raise ValueError(f"need at least one cluster, got {clusters}")
    _check_semi_flexible(kind, free_angles, frozen_fraction, frozen_every)
    phi = (DILUTE_PHI[d] if no_overlap else OVERLAP_PHI[d]) if phi is None else phi
    if not 0.0 < phi < 1.5:
        raise ValueError(f"packing fraction must lie in (0, 1.5), got {phi}")
    lo, hi = BOND_ANGLE_RANGE
    if bond_angle is not None and not lo <= bond_angle <= pi:
        raise ValueError(f"bond angle must lie in [pi/3, pi] rad, got {bond_angle}")
    scale = np.ones(clusters)
    if kind == "dimer":
        if sizes is not None and sizes.dispersity != "mono":
            raise ValueError("dimers are bidisperse by --size-ratio (the paper's mixture); --dispersity is for "
                             "chains and trimers")
        check_dimer(diameter_ratio, separation)
        if not (np.isfinite(size_ratio) and size_ratio >= 1.0):
            raise ValueError(f"dimer size ratio (large over small dimers) must be >= 1, got {size_ratio}")
        scale[1::2] = size_ratio
        body_d, bond = np.array([1.0, diameter_ratio]), separation
        D = np.concatenate([s * body_d for s in scale])
    else:
        D = np.ones(clusters * m) if sizes is None else sizes.draw(clusters, m, rng)
    n = clusters * m
    # spheres of a chain touch or overlap (a dimer's share a lens): the union's volume
    body_link = Links(np.array([0]), np.array([1]), np.array([bond])) if kind == "dimer" else None
    volume = float(np.sum(scale**d)) * linked_volume(d, body_d, body_link) if kind == "dimer" else \
        float(np.sum(sphere_volume(d, D)))
    side = (volume / phi) ** (1.0 / d)
    box = Box.cubic(d, side)
    x = np.zeros((n, d))
    pairs: list[tuple[int, int]] = []
    lengths: list[float] = []
    for c in range(clusters):
        if kind == "chain":
            frozen = frozen_angles(m, free_angles, frozen_fraction, frozen_every, rng)
            p, r = _grow(c, m, x, D, pairs, box, bond_angle, frozen, no_overlap, rng)
            pairs += p
            lengths += r
            continue
        for _ in range(PLACEMENT_TRIES):
            angles = np.full(max(m - 2, 0), bond_angle) if bond_angle is not None else rng.uniform(lo, hi, max(m - 2, 0))
            own = D[c * m:(c + 1) * m]
            bonds = bond * scale[c] if kind == "dimer" else 0.5 * (own[:-1] + own[1:])
            body = chain_offsets(m, d, bonds, angles, rng)
            if np.max(np.linalg.norm(body[:, None, :] - body[None, :, :], axis=2)) >= 0.5 * side:
                continue  # would meet its own image: redraw the bond directions
            x[c * m:(c + 1) * m] = box.wrap(body + rng.random(d) * side)
            p, r = chain_links(m, c * m, body, free_angles)
            if d == 2 and _crosses(pairs + p, lengths + r, x[:(c + 1) * m], box, len(pairs)):
                continue
            if no_overlap and _overlaps(x[:(c + 1) * m], D[:(c + 1) * m], box, c * m, p):
                continue
            break
        else:
            raise ValueError(f"could not place cluster {c} within half the box width ({0.5 * side:.4g}) and without "
                             f"crossing links{' or overlaps' if no_overlap else ''} in {PLACEMENT_TRIES} tries: "
                             f"lower --phi or add clusters")
        pairs += p
        lengths += r
    links, messages = remove_degenerate_links(pairs, lengths, x, box)
    unit = {"mono": "sphere diameter", "bi": "small sphere diameter"}.get(
        "mono" if sizes is None else sizes.dispersity, "nominal mean sphere diameter")
    attrs = {"length_unit": "small monomer diameter" if kind == "dimer" else unit,
             "cluster_kind": kind, "chain_length": m, "free_angles": int(free_angles)}
    if frozen_fraction is not None or frozen_every is not None:
        attrs.update(frozen_angle_rule=f"fraction {frozen_fraction}" if frozen_fraction is not None
                     else f"every {frozen_every}", n_frozen_angles=int(len(pairs) - clusters * (m - 1)))
    if sizes is not None and kind != "dimer":
        attrs.update(sizes.attrs())
    if kind == "dimer":
        attrs.update(dimer_diameter_ratio=diameter_ratio, dimer_size_ratio=size_ratio, dimer_separation=separation)
        if d == 2:
            attrs["asphericity"] = dimer_asphericity(diameter_ratio, separation)
    packing = Packing(x, D, box, protocol=f"init-chains({kind})", links=links, attrs=attrs)
    check_linked_start(packing)
    return packing, messages


def _check_semi_flexible(kind: str, free_angles: bool, fraction: float | None, every: int | None) -> None:
    """Refuse semi-flexible options that do not describe a chain's frozen angles."""
    if fraction is None and every is None:
        return
    if kind != "chain" or free_angles or (fraction is not None and every is not None):
        raise ValueError("semi-flexible chains (a fraction or every k-th bond angle frozen) are --cluster chain "
                         "without --free-angles, with one of --frozen-fraction and --frozen-every")
    if fraction is not None and not 0.0 <= fraction <= 1.0:
        raise ValueError(f"--frozen-fraction must lie in [0, 1], got {fraction}")
    if every is not None and every < 1:
        raise ValueError(f"--frozen-every must be at least 1, got {every}")


def _grow(c: int, m: int, x: NDArray[np.float64], D: NDArray[np.float64], pairs: list, box: Box,
          bond_angle: float | None, frozen: NDArray[np.bool_], no_overlap: bool,
          rng: np.random.Generator) -> tuple[list, list]:
    """Grow chain ``c`` beside the placed spheres ``x[:c m]`` (:mod:`.growth`), write it into ``x``; its links."""
    own = D[c * m:(c + 1) * m]
    p = np.array(pairs, np.int64).reshape(-1, 2)
    segments = (x[p[:, 0]], box.minimum_image(x[p[:, 1]] - x[p[:, 0]]))
    chain = grow_chain(m, 0.5 * (own[:-1] + own[1:]), own, bond_angle, BOND_ANGLE_RANGE, x[:c * m], D[:c * m],
                       segments, box, frozen, no_overlap, rng)
    if chain is None:
        raise ValueError(f"could not grow chain {c} of {m} spheres without overlaps or crossing links within half "
                         f"the box width ({0.5 * float(np.min(box.widths)):.4g}): lower --phi or use more, "
                         f"shorter chains")
    x[c * m:(c + 1) * m] = box.wrap(chain)
    return chain_links(m, c * m, chain, False, frozen)


def _crosses(pairs: list, lengths: list, x: NDArray[np.float64], box: Box, first_new: int) -> bool:
    """Whether any link from index ``first_new`` of ``pairs`` on crosses any link (2D)."""
    p = np.array(pairs, np.int64)
    order = np.lexsort((p[:, 1], p[:, 0]))  # the row order of Links
    new = np.flatnonzero(order >= first_new)
    return bool(np.any(_cross(Links(p[:, 0], p[:, 1], np.array(lengths)), new, np.arange(len(p)), x, box)))


def _overlaps(x: NDArray[np.float64], diameter: NDArray[np.float64], box: Box, first_new: int,
              linked: list[tuple[int, int]]) -> bool:
    """Whether a sphere from index ``first_new`` of ``x`` overlaps another beyond :data:`OVERLAP_TOL` (minimum images).

    Pairs in ``linked`` (the new cluster's links) are exempt: a dimer's monomers overlap.
    """
    new = np.arange(first_new, len(x))
    r = np.linalg.norm(box.minimum_image(x[None, :, :] - x[new, None, :]), axis=2)
    sigma = 0.5 * (diameter[None, :] + diameter[new, None])
    r[np.arange(len(new)), new] = np.inf
    for a, b in linked:
        r[a - first_new, b] = r[b - first_new, a] = np.inf
    return bool(np.any(r < sigma * (1.0 - OVERLAP_TOL)))
