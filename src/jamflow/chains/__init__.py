"""Chains and clusters of spheres (``soft-chains-of-spheres-packings.md``).

:mod:`~jamflow.chains.builders` (rigid clusters, chains, cementing, link files, start
checks), jamming, shear stabilisation, the constrained Hessian, certificates and
moduli. The energy model with its constraint projection is
:class:`jamflow.models.links.LinkedSpheresModel`; rattling clusters, danglers and the
isostatic count of clusters are counted by the network core,
:func:`jamflow.network.count_bodies`.
"""
