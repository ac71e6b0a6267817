"""Soft repulsive spheres: potentials, minimisers, jamming onset, quasistatic shear, Hessian.

Modules: :mod:`~jamflow.soft.potential` (pair potential, forces, stress, Verlet list),
:mod:`~jamflow.soft.minimize` (FIRE, steepest descent, CG, enthalpy minimisation; for any
energy model of :mod:`jamflow.models`),
:mod:`~jamflow.soft.jamming` (compress/decompress bisection to a target pressure),
:mod:`~jamflow.soft.shear` (athermal quasistatic shear; Lerner et al.'s steepest-descent
protocol), :mod:`~jamflow.soft.hessian` (dynamical matrix, modes, elastic moduli).
"""

from .minimize import (
    DescentResult,
    FireParameters,
    MinimizeResult,
    conjugate_gradient,
    fire,
    minimize,
    minimize_cg,
    minimize_enthalpy,
    minimize_enthalpy_model,
    minimize_fire,
    minimize_sd,
    steepest_descent,
)
from .potential import NeighborList, PowerLawPotential, evaluate, overlapping_pairs

__all__ = [
    "DescentResult",
    "FireParameters",
    "MinimizeResult",
    "NeighborList",
    "PowerLawPotential",
    "conjugate_gradient",
    "evaluate",
    "fire",
    "minimize",
    "minimize_cg",
    "minimize_enthalpy",
    "minimize_enthalpy_model",
    "minimize_fire",
    "minimize_sd",
    "overlapping_pairs",
    "steepest_descent",
]
