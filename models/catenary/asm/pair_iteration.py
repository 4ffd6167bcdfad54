"""The pair's HIL iteration on ASM2, built alike by the in-process loop (models/hil/pair_loop.py) and the
catenary FMU (from its staged resources): the four operators, each point's frequency-reduced static height,
and the coupling compensation from the pantograph receptance (models/hil/pair.py)."""
from __future__ import annotations

import numpy as np

from pantohil.models.catenary.asm.pair import PairSpec, circulant_blocks, coupling_compensation, pair_spectra
from pantohil.models.catenary.asm.string import AsmParameters
from pantohil.models.catenary.grid import SpanGrid
from pantohil.models.catenary.receptance import reduce_harmonics
from pantohil.models.hil.loop import HilSettings
from pantohil.models.hil.pair import PairedHil


def pair_iteration(cat: AsmParameters, grid: SpanGrid, z0_pair_m: np.ndarray, settings: HilSettings,
                   delay_steps: tuple[int, int], pair: PairSpec, receptance_m_N: np.ndarray | None) -> PairedHil:
    """PairedHil on ASM2; `z0_pair_m` the static heights at the N samples of both points (2, N) [m];
    `receptance_m_N` the pantograph's at harmonics 0..N_h-1, for the coupling compensation (pair.compensated)."""
    n = grid.samples_per_span
    spectra = pair_spectra(cat, grid.speed_m_s, n, grid.dt_s, grid.n_harmonics, pair.spacing_m, pair.position)
    z0 = np.array([reduce_harmonics(z, grid.n_harmonics) for z in z0_pair_m])
    compensation = None
    if pair.compensated:
        q = coupling_compensation(spectra, receptance_m_N)
        compensation = (circulant_blocks(q, n, np.eye(2)), circulant_blocks(spectra @ q, n))
    return PairedHil(circulant_blocks(spectra, n), z0, settings, delay_steps, compensation)
