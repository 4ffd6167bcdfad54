"""The periodic HIL iteration on the virtual catenary (Paper B, Paper D)."""
