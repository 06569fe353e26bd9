"""JSON schema of ``sequence.json`` (``calibproj.sequence/1``), checked with jsonschema.

The schema checks structure and types; :meth:`Sequence.validate` checks what a schema
cannot (frames in order, centres per array, codes that do not overlap).
"""

from __future__ import annotations

KIND = "sequence"
MAJOR = 1

# Integers are ints of the C++ core: larger ones are refused here, the core names its
# own limits (frames, image sides) when the file is loaded.
_MAX_INT = 2**31 - 1


def _integer(minimum: int) -> dict:
    return {"type": "integer", "minimum": minimum, "maximum": _MAX_INT}


_FRAME = _integer(0)
_POSITIVE = {"type": "number", "exclusiveMinimum": 0}
_PAIR_INT = {"type": "array", "items": _integer(1), "minItems": 2, "maxItems": 2}
_POINT = {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2}
_RANGE = {
    "type": "object",
    "required": ["first_frame", "last_frame"],
    "properties": {"first_frame": _FRAME, "last_frame": _FRAME},
}

_CODE = {
    "type": "object",
    "required": ["bits", "frames_per_bit", "first_frame", "last_frame"],
    "properties": {
        "bits": {"type": "array", "items": {"enum": [0, 1]}, "minItems": 2},
        "frames_per_bit": _integer(1),
        "first_frame": _FRAME,
        "last_frame": _FRAME,
    },
}

SEQUENCE_SCHEMA = {
    "$schema": "https://json-schema.org/draft/2020-12/schema",
    "type": "object",
    "required": ["schema", "markers", "projector", "layout", "frames_per_pattern", "frame_count",
                 "centres", "scales", "patterns", "codes", "segments"],
    "properties": {
        "schema": {"type": "string"},
        "markers": {
            "type": "object",
            "required": ["spec", "system", "family", "grid_cells", "quad_cells", "inverted"],
            "properties": {
                "spec": {"type": "string"},
                "system": {"enum": ["aruco", "apriltag"]},
                "family": {"type": "string"},
                "grid_cells": _integer(1),
                "quad_cells": _integer(1),
                "id_count": _integer(0),
                "inverted": {"type": "boolean"},
            },
        },
        "projector": {
            "type": "object",
            "required": ["resolution", "fps"],
            "properties": {"resolution": _PAIR_INT, "fps": _POSITIVE},
        },
        "layout": {
            "type": "object",
            "required": ["grid", "arrays", "scales", "marker_px", "margin_px", "snap_to_pixels",
                         "min_gap_modules", "order"],
            "properties": {
                "grid": _PAIR_INT,
                "arrays": _integer(1),
                "scales": {"type": "array", "items": _POSITIVE, "minItems": 1},
                "marker_px": _POSITIVE,
                "margin_px": {"type": "number"},
                "snap_to_pixels": {"type": "boolean"},
                "min_gap_modules": {"type": "number", "minimum": 0},
                "order": {"const": "array-major"},
            },
        },
        "frames_per_pattern": _integer(1),
        "frame_count": _integer(1),
        "centres": {"type": "array", "minItems": 1, "items": {"type": "array", "minItems": 1, "items": _POINT}},
        "scales": {
            "type": "array",
            "minItems": 1,
            "items": {
                "type": "object",
                "required": ["scale", "marker_side_px", "module_px"],
                "properties": {"scale": _POSITIVE, "marker_side_px": _POSITIVE, "module_px": _POSITIVE},
            },
        },
        "patterns": {
            "type": "array",
            "minItems": 1,
            "items": {
                "type": "object",
                "required": ["array", "scale_index", "scale", "marker_side_px", "first_frame", "last_frame",
                             "omitted"],
                "properties": {
                    "array": _integer(0),
                    "scale_index": _integer(0),
                    "scale": _POSITIVE,
                    "marker_side_px": _POSITIVE,
                    "first_frame": _FRAME,
                    "last_frame": _FRAME,
                    "omitted": {"type": "array", "items": _integer(0)},
                },
            },
        },
        "codes": {
            "type": "object",
            "required": ["start", "end"],
            "properties": {"start": _CODE, "end": _CODE},
        },
        "reference_frames": {
            "type": "object",
            "properties": {"white": {"type": "array", "items": _RANGE}, "black": {"type": "array", "items": _RANGE}},
        },
        "segments": {
            "type": "array",
            "minItems": 1,
            "items": {
                "allOf": [
                    _RANGE,
                    {"required": ["kind"],
                     "properties": {"kind": {"enum": ["white", "black", "start_code", "end_code", "patterns"]}}},
                ]
            },
        },
    },
}
