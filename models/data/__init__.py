"""Data shipped with pantohil: cases, catenaries, sweeps and rigs (TOML)."""
from pathlib import Path

DATA_DIR = Path(__file__).parent
CASES_DIR = DATA_DIR / "cases"
CATENARIES_DIR = DATA_DIR / "catenaries"
SWEEPS_DIR = DATA_DIR / "sweeps"
RIGS_DIR = DATA_DIR / "rigs"
