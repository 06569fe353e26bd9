"""Projection sequence generation: MSM layout, marker images, light codes, projector video."""

from calibproj.generate.layout import MsmLayout

__all__ = ["MsmLayout"]
