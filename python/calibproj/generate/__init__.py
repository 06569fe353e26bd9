"""Projection sequence generation: MSM layout, marker images, light codes, projector video."""

from calibproj.generate.builder import SequenceOptions, build_sequence, default_frames_per_pattern, generate
from calibproj.generate.codes import LightCode
from calibproj.generate.layout import MsmLayout
from calibproj.generate.sequence import MarkerSystem, Pattern, Segment, Sequence

__all__ = [
    "LightCode",
    "MarkerSystem",
    "MsmLayout",
    "Pattern",
    "Segment",
    "Sequence",
    "SequenceOptions",
    "build_sequence",
    "default_frames_per_pattern",
    "generate",
]
