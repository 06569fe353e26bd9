"""Projection sequence generation: MSM layout, marker images, light codes, projector video."""

from calibproj.sequence.builder import SequenceOptions, build_sequence, default_frames_per_pattern, generate
from calibproj.sequence.codes import LightCode
from calibproj.sequence.layout import MsmLayout
from calibproj.sequence.sequence import MarkerSystem, Pattern, Segment, Sequence

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
