"""The incremental registration, driven step by step over the core's steps."""
