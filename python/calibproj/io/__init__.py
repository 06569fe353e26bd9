"""File formats: schema-versioned JSON, intrinsics, atomic writes."""
