"""Linked starts shared by the engine tests: 3D chains of four with frozen angles, squeezed."""

from __future__ import annotations

import numpy as np

from jamflow.chains.builders import linked_packing
from jamflow.chains.jamming import linked_volume
from jamflow.state.bodies import Links


def squeezed_chains(kind, mixed: bool, phi: float = 0.66):
    """32 chains of four (frozen angles, seed 2) squeezed to ``phi`` as a model ``kind(box, diameter, links,
    position)``; ``mixed``: every second chain without its first angle link (a flexible chain beside the
    hinged ones). Returns the model and its centres."""
    p = linked_packing(3, 32, "chain", np.random.default_rng(2), chain_length=4)[0]
    links = p.links
    if mixed:
        keep = ~((links.i % 8 == 0) & (links.j == links.i + 2))
        links = Links(links.i[keep], links.j[keep], links.length[keep])
    f = (linked_volume(3, p.diameter, links) / p.box.volume / phi) ** (1 / 3)
    return kind(p.box.scaled(f), p.diameter, links, p.position * f), p.position * f
