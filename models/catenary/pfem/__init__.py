"""Periodic finite-element method (PFEM): FRFs, blocks, operators and their file (Papers C-D)."""
