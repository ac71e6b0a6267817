"""Pair queries (k-d tree, cells, sheared boxes) and the one Verlet list every model uses."""
