"""Soft repulsive spheres: the power-law potential, its compiled kernels, Hessian and fast minimisers."""
