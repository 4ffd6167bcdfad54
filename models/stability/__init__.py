"""Stability of the HIL loop: span maps, one-step maps and characteristic roots (Paper D appendix)."""
