"""Lumped-mass pantograph models and their linear one-step maps."""
