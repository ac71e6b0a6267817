"""Bitwise fingerprint of every contact-network consumer on a few sphere packings.

Guards the refactor onto :mod:`jamflow.network`: run it on the code before a change
(``--write before.json``) and after (``--compare before.json``); every hash must
match, i.e. the numbers are bit for bit the same. Consumers: ``jamflow check``
(:func:`~jamflow.analysis.contacts.summarize`), the jamming certificate (strict,
exact contacts and gap-aware), the rigidity matrix with and without strain columns
and its positive self-stress, the event-driven network (``S``, forces and
velocities, constrained subset, self-stress) and a short event-driven compression
to jamming (its final packing, forces and rattlers).

Inputs (all in ``tests/data`` or built from seeds): the 2D LS packing N = 64, the
3D LS packing N = 1024 of the CALiPPSO examples (contacts at relative gap <= 3e-3),
a 12 x 8 triangular lattice, and 16 bidisperse discs compressed to jamming.

Run: ``python benchmarks/network_bitwise.py --write before.json`` (about a minute).
Since the certificate decides exact-contact backbones by the Roth-Whiteley test
(fewer LP records, a constructed motion), compare its LP path with ``--lp-only``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import sys
from pathlib import Path

import numpy as np
from api_paths import find

summarize = find("summarize", "jamflow.analysis.contacts")
read_packing = find("read_packing", "jamflow.io")
read_dat = find("read_dat", "jamflow.io")
rigidity_matrix = find("rigidity_matrix", "jamflow.network.rigidity", "jamflow.rigidity")
positive_self_stress = find("positive_self_stress", "jamflow.network.self_stress")
certify = find("certify", "jamflow.protocols.certify", "jamflow.strict_jamming")
random_packing = find("random_packing", "jamflow.protocols.initial", "jamflow.initial")
lattice_packing = find("lattice_packing", "jamflow.protocols.lattices", "jamflow.lattices")
Drive = find("Drive", "jamflow.protocols.overdamped.driving", "jamflow.overdamped.driving")
FlowOptions = find("FlowOptions", "jamflow.protocols.overdamped.integrate", "jamflow.overdamped.integrate")
constrained_subset = find("constrained_subset", "jamflow.protocols.overdamped.jamming", "jamflow.overdamped.jamming")
self_stress = find("self_stress", "jamflow.protocols.overdamped.jamming", "jamflow.overdamped.jamming")
solve_network = find("solve_network", "jamflow.protocols.overdamped.network", "jamflow.overdamped.network")
Stop = find("Stop", "jamflow.protocols.overdamped.run", "jamflow.overdamped.run")
run_flow = find("run_flow", "jamflow.protocols.overdamped.run", "jamflow.overdamped.run")
s_matrix = find("s_matrix", "jamflow.protocols.overdamped.solver", "jamflow.overdamped.solver")

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"


def _h(*arrays) -> str:
    m = hashlib.sha256()
    for a in arrays:
        if isinstance(a, (str, int, float, bool)) or a is None:
            m.update(repr(a).encode())
        else:
            a = np.ascontiguousarray(a)
            m.update(str(a.dtype).encode() + str(a.shape).encode() + a.tobytes())
    return m.hexdigest()[:16]


def _sparse(R) -> str:
    R = R.tocsr()
    return _h(R.data, R.indices, R.indptr, R.shape[0], R.shape[1])


#: extra keyword arguments of every certify call (``--lp-only``: the LP path alone)
CERTIFY_OPTIONS: dict = {}


def _cert(p, **kw) -> str:
    c = certify(p, **kw, **CERTIFY_OPTIONS)
    return _h(c.classification, c.contacts, c.gap, c.rattler_stage, c.motion, c.motion_strain, c.cage,
              np.array([r.objective for r in c.lp]), np.array([r.max_displacement for r in c.lp]),
              np.array([r.iterations for r in c.lp]))


def _guarded(fn, *args, **kwargs) -> str:
    """Hash of the outputs of ``fn(*args)``, or of the error it raised (a failure is a fingerprint too)."""
    try:
        out = fn(*args, **kwargs)
    except (ValueError, RuntimeError) as exc:
        return _h(type(exc).__name__, str(exc))
    return _h(*(out if isinstance(out, tuple) else (out,)))


def _forces_velocities(*args):
    sol = solve_network(*args)
    return sol.force, sol.velocity


def fingerprints() -> dict[str, str]:
    out: dict[str, str] = {}
    ls2 = read_packing(DATA / "ls_2d_mono_n64_p1e6.nc")
    ls3 = read_dat(DATA / "calippso-ls" / "Centers-after-LS--N-1024--d-3.dat")
    tri = lattice_packing("triangular", (12, 8))
    for name, p, gap_tol in (("ls2d", ls2, None), ("ls3d", ls3, 3e-3), ("tri", tri, None)):
        out[f"{name}/check"] = _h(json.dumps(summarize(p, gap_tol).as_dict(), sort_keys=True))
        out[f"{name}/certify_strict"] = _cert(p, strict=True, gap_tol=gap_tol, rhs="zero", loads=1, seed=0)
        if gap_tol is not None:
            out[f"{name}/certify_gaps"] = _cert(p, strict=True, gap_tol=gap_tol, rhs="gaps", loads=1, seed=1)
        cert = certify(p, gap_tol=gap_tol, loads=1, seed=0, **CERTIFY_OPTIONS)
        bc = cert.backbone_contacts
        out[f"{name}/rigidity"] = _sparse(rigidity_matrix(p, bc))
        out[f"{name}/rigidity_strain"] = _sparse(rigidity_matrix(p, bc, strain=True, volume_preserving=False))
        idx = np.flatnonzero(~cert.rattler)
        out[f"{name}/rigidity_sub"] = _sparse(rigidity_matrix(p, bc, strain=True, particles=idx))
        if name == "tri":  # scipy's nnls aborted (double free) on the LS 2D network
            out[f"{name}/self_stress"] = _h(positive_self_stress(rigidity_matrix(p, bc)))
        out[f"{name}/self_stress_lp"] = _guarded(positive_self_stress, rigidity_matrix(p, bc), method="lp")
        # event-driven network: fixed images from the minimum image at this geometry
        dx = p.box.minimum_image(p.position[bc[:, 1]] - p.position[bc[:, 0]])
        images = np.rint((p.position[bc[:, 0]] + dx - p.position[bc[:, 1]]) @ p.box.inverse.T).astype(np.int64)
        R = p.position[bc[:, 1]] - p.position[bc[:, 0]] + images @ p.box.matrix.T
        unit = R / np.linalg.norm(R, axis=1)[:, None]
        out[f"{name}/s_matrix"] = _sparse(s_matrix(bc, unit, p.n))
        cs = constrained_subset(p.n, p.d, bc)
        out[f"{name}/constrained_subset"] = _h(cs.member, cs.n_contacts)
        # a hypostatic sub-network (every other contact) so that S S^T is regular
        sub = bc[::2]
        E = np.zeros((p.d, p.d))
        E[0, 1] = 1.0
        out[f"{name}/solve_network"] = _guarded(
            _forces_velocities, p.position, p.box.matrix, sub, images[::2], E)
        if p.n <= 100:
            out[f"{name}/overdamped_self_stress"] = _guarded(
                self_stress, p.position, p.box.matrix, bc, images, np.ones(len(bc)))
    start = random_packing(16, 2, 0.5, "bi", seed=2)
    rng = np.random.default_rng(2)
    start = start.evolve(diameter=start.diameter * (1 - 0.03 * rng.uniform(size=start.n)))
    res = run_flow(start, Drive("compress"), Stop(strain=5.0),
                   FlowOptions(dt_max=1e-2, step_drift=1e-6, drift_tol=1e-5), unit="small_diameter",
                   record_every=100)
    fin = res.final
    out["flow/final"] = _h(fin.position, fin.contacts, fin.force, fin.rattler, res.jammed)
    out["flow/check"] = _h(json.dumps(summarize(fin).as_dict(), sort_keys=True))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group(required=True)
    g.add_argument("--write", type=Path, help="write the fingerprints to this JSON file")
    g.add_argument("--compare", type=Path, help="compare with fingerprints written earlier")
    ap.add_argument("--lp-only", action="store_true",
                    help="certify with self_stress_test=False (the LP path of the code before the Roth-Whiteley test)")
    args = ap.parse_args()
    if args.lp_only:
        CERTIFY_OPTIONS["self_stress_test"] = False
    fp = fingerprints()
    for k, v in fp.items():
        print(f"{k:32s} {v}")
    if args.write:
        args.write.write_text(json.dumps(fp, indent=1, sort_keys=True))
        return 0
    ref = json.loads(args.compare.read_text())
    diff = sorted(k for k in set(ref) | set(fp) if ref.get(k) != fp.get(k))
    print(f"{len(fp) - len(diff)} of {len(set(ref) | set(fp))} fingerprints identical; differing: {diff or 'none'}")
    return 1 if diff else 0


if __name__ == "__main__":
    sys.exit(main())
