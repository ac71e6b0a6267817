"""Event-driven overdamped dynamics of frictionless hard spheres (Lerner, Düring & Wyart).

Modules: :mod:`.network` (S, N = S S^T, forces, velocities), :mod:`.collisions`
(next-collision prediction, the integrator's Verlet list), :mod:`.skin` (the list's
validity bound), :mod:`.rewiring` (Sec. IV B),
:mod:`.starts` (dense starts by decompressing a jammed packing),
:mod:`.jamming` (Sec. IV D), :mod:`.driving` (modes), :mod:`.integrate` (the loop,
dt rule, drift correction), :mod:`.run` (a whole run and its datasets),
:mod:`.checkpoint` (checkpoint and resume).
"""
