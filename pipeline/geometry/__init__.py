"""Geometry kernels shared by the stages (numba behind validating public wrappers)."""

from .minsphere import min_sphere, min_spheres

__all__ = ["min_sphere", "min_spheres"]
