"""Geometry stage (paper §5): depth preparation, warps, Jacobians, visibility, weights."""

from .samples import Samples

__all__ = ["Samples"]
