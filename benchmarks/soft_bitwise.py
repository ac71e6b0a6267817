"""Bitwise regression of the soft-sphere minimisers between two versions of jamflow.

Runs FIRE, isotropic and full-box enthalpy minimisation, steepest descent, CG, the
soft-jam bisection, AQS shear (fixed volume and fixed pressure), Lerner et al.'s
steepest-descent shear (tentative-network stress) and the elastic moduli from fixed
seeded inputs and stores every resulting array in one ``.npz``.
Run it once with each version on ``PYTHONPATH`` and compare the byte strings::

    PYTHONPATH=/path/to/old/src python benchmarks/soft_bitwise.py run /tmp/old.npz
    PYTHONPATH=src python benchmarks/soft_bitwise.py run /tmp/new.npz
    python benchmarks/soft_bitwise.py compare /tmp/old.npz /tmp/new.npz

Only APIs that exist in both versions are called, and nothing is hard-coded: the
reference is whatever the old version computes.
"""

from __future__ import annotations

import sys

import numpy as np


def run(path: str) -> None:
    from api_paths import find

    import jamflow

    steepest_descent = find("steepest_descent", "jamflow.models.spheres.fast", "jamflow.soft")
    elastic_moduli = find("elastic_moduli", "jamflow.models.spheres.hessian", "jamflow.soft.hessian")
    conjugate_gradient = find("conjugate_gradient", "jamflow.models.spheres.model", "jamflow.soft")
    fire = find("fire", "jamflow.models.spheres.model", "jamflow.soft")
    minimize_enthalpy = find("minimize_enthalpy", "jamflow.models.spheres.model", "jamflow.soft")
    random_packing = find("random_packing", "jamflow.protocols.initial", "jamflow.initial")
    aqs_shear = find("aqs_shear", "jamflow.protocols.quasistatic", "jamflow.soft.shear")
    lerner_sd_shear = find("lerner_sd_shear", "jamflow.protocols.quasistatic", "jamflow.soft.shear")
    jam_to_pressure = find("jam_to_pressure", "jamflow.protocols.soft_jam", "jamflow.soft.jamming")

    print("jamflow from", jamflow.__file__)
    out: dict[str, np.ndarray] = {}

    def keep(name: str, res) -> None:
        out[f"{name}.position"] = res.position
        out[f"{name}.box"] = res.box.matrix
        out[f"{name}.scalars"] = np.array([res.energy, res.pressure, res.max_force, res.n_contacts,
                                           res.steps, res.converged, res.rebuilds], dtype=np.float64)

    for d, n, phi in ((2, 48, 0.9), (3, 32, 0.7)):
        start = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=11)
        # compress affinely to phi, lengths in units of the mean diameter
        factor = (start.packing_fraction / phi) ** (1.0 / d) / start.diameter.mean()
        x, box, D = start.position * factor, start.box.scaled(factor), start.diameter / start.diameter.mean()
        tag = f"{d}d"
        keep(f"{tag}.fire", fire(x, box, D, force_tol=1e-12))
        keep(f"{tag}.enthalpy_iso", minimize_enthalpy(x, box, D, 1e-2, force_tol=1e-12))
        keep(f"{tag}.enthalpy_full", minimize_enthalpy(x, box, D, 1e-2, force_tol=1e-12, box_dof="full"))
        keep(f"{tag}.cg", conjugate_gradient(x, box, D, force_tol=1e-10))
        sd = steepest_descent(x, box, D, dt=0.05, force_tol=1e-8, max_steps=200_000, record=50)
        keep(f"{tag}.sd", sd.result)
        out[f"{tag}.sd.energies"] = sd.energies
        loose = random_packing(n, d, 0.5 if d == 2 else 0.3, "bi", seed=5)
        jam = jam_to_pressure(loose, 1e-3)
        out[f"{tag}.jam.position"] = jam.packing.position
        out[f"{tag}.jam.box"] = jam.packing.box.matrix
        out[f"{tag}.jam.force"] = jam.packing.force
        out[f"{tag}.jam.history"] = np.array([jam.history["phi"], jam.history["pressure"],
                                              jam.history["steps"]], dtype=np.float64)
        jam_full = jam_to_pressure(loose, 1e-3, box_dof="full")
        out[f"{tag}.jam_full.position"] = jam_full.packing.position
        out[f"{tag}.jam_full.box"] = jam_full.packing.box.matrix
        for mode, pressure in (("fixed_volume", None), ("fixed_pressure", 1e-3)):
            series, final = aqs_shear(jam.packing, 0.02, 0.005, pressure=pressure)
            for name in series.data_vars:
                out[f"{tag}.aqs_{mode}.{name}"] = series[name].values
            out[f"{tag}.aqs_{mode}.final"] = final.position
        # a start near jamming (2D phi = 0.83, 3D 0.63) with overlaps the first descent removes
        scale = (start.packing_fraction / (0.83 if d == 2 else 0.63)) ** (1.0 / d) / start.diameter.mean()
        sd_start = start.evolve(position=start.position * scale, diameter=start.diameter / start.diameter.mean(),
                                box=start.box.scaled(scale))
        sd_series = lerner_sd_shear(sd_start, 0.01, 2e-3)
        for name in sd_series.data_vars:
            out[f"{tag}.sd_shear.{name}"] = sd_series[name].values
        m = elastic_moduli(jam.packing.position, jam.packing.box, jam.packing.diameter)
        out[f"{tag}.moduli"] = np.array([m.bulk, m.shear, m.bulk_affine, m.shear_affine, m.pressure])
    np.savez(path, **out)
    print(f"wrote {len(out)} arrays to {path}")


def compare(a: str, b: str) -> int:
    old, new = np.load(a), np.load(b)
    if set(old.files) != set(new.files):
        print("different array sets:", sorted(set(old.files) ^ set(new.files)))
        return 1
    bad = [k for k in old.files
           if old[k].dtype != new[k].dtype or old[k].shape != new[k].shape or old[k].tobytes() != new[k].tobytes()]
    for k in bad:
        print(f"DIFFERENT {k}: max |diff| = {np.max(np.abs(old[k] - new[k])) if old[k].shape == new[k].shape else 'shape'}")
    print(f"{len(old.files) - len(bad)} of {len(old.files)} arrays bitwise identical")
    return 1 if bad else 0


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "run":
        run(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(compare(sys.argv[2], sys.argv[3]))
    else:
        sys.exit(__doc__)
