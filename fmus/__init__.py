"""Thin pythonfmu wrappers around pantohil.models: one script per FMU, each with a unique name."""
