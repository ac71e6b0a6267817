"""Analyses of packings and flow runs; each returns an ``xarray.Dataset``."""
