"""Catenary models: ASM strings, receptances, finite elements and PFEM operators."""
