"""Protocols that make and drive packings: random starts, LS, CALiPPSO, certificates, soft jamming,
quasistatic shear and the event-driven overdamped dynamics."""
