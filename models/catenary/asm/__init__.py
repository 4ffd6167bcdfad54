"""Analytical string model (ASM) of the catenary and its closed-form HIL solution (Paper A)."""
