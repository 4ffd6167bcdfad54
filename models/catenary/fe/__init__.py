"""Finite-element catenary: definition files, form-finding, analysis, ASM fit and time integration."""
