"""Chains and clusters of spheres (``soft-chains-of-spheres-packings.md``).

:mod:`~jamflow.chains.builders` (rigid clusters, chains, cementing, link files, start
checks), :mod:`~jamflow.chains.clusters` (rattling clusters, danglers, the isostatic
count of clusters). The energy model with its constraint projection is
:class:`jamflow.models.links.LinkedSpheresModel`.
"""
