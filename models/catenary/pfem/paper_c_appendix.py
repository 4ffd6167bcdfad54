"""Paper C Appendix A: the academic periodic string (two elements and a spring-damper per block), its
FRF, contact operator and a HIL test against a linear spring, computed with the direct PFEM path."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pantohil.models.catenary.pfem.frf import direct_frf, direct_operator, direct_receptance
from pantohil.models.catenary.pfem.blocks import appendix_block


@dataclass(frozen=True)
class AppendixData:
    """Table A.1 and the discretisation of the appendix."""

    speed_m_s: float = 50.0
    dt_s: float = 0.005
    n_fft: int = 10000  # dw = 2 pi / (N dt)
    n_frequencies: int = 5969
    spring_N_m: float = 1e4  # k_z
    spring_offset_m: float = 0.005  # z_0: f = k_z (z_0 - z)


def appendix_hil(op: np.ndarray, k: float, z0: float, tol: float = 1e-10, max_blocks: int = 500):
    """Step-by-step HIL (Paper C eq. 25, no relaxation, no delay) against f = k (z0 - z)."""
    n = op.shape[0]
    z = np.zeros(n)
    f_prev = np.zeros(n)
    forces = []
    for b in range(max_blocks):
        block = np.zeros(n)
        for m in range(n):
            f = k * (z0 - z[m])
            block[m] = f
            forces.append(f)
            z += op[:, m] * (f - f_prev[m])
        if b > 0 and np.max(np.abs(block - f_prev)) < tol:
            return np.array(forces), block, b + 1
        f_prev = block
    return np.array(forces), f_prev, max_blocks


def paper_c_appendix(data: AppendixData = AppendixData()) -> dict:
    """Paper C Appendix A: H(w_3000), I(w_3000), the 6 x 6 operator II and the HIL test against a spring.

    The spring f = k_z (z_0 - z) is iterated with Paper C eq. (25) (no relaxation, no delay); returns the
    printed quantities and the first and steady forces.
    """
    cb = appendix_block()
    blk = cb.block
    T = blk.length_m / data.speed_m_s
    n = int(round(T / data.dt_s))
    dw = 2 * np.pi / (data.n_fft * data.dt_s)
    omega = np.arange(data.n_frequencies) * dw
    shapes = cb.contact_shapes(np.arange(n) * data.speed_m_s * data.dt_s).toarray()
    w3000 = 3000 * dw
    H = direct_frf(blk, w3000, T)
    I3000 = direct_receptance(blk, w3000, T, shapes, shapes)
    op = direct_operator(blk, shapes, data.dt_s, omega)
    forces, steady, blocks = appendix_hil(op, data.spring_N_m, data.spring_offset_m)
    return {
        "example": "Paper C Appendix A (academic periodic string)",
        "contact_points": n, "omega_max_rad_s": float(omega[-1]), "d_omega_rad_s": dw,
        "frf_w3000_first_column_m_per_N": {"re": H[:, 0].real.tolist(), "im": H[:, 0].imag.tolist()},
        "receptance_w3000_real_m_per_N": I3000.real.tolist(),
        "operator_m_per_N": op.tolist(),
        "first_forces_N": forces[:3].tolist(),
        "steady_force_N": steady.tolist(),
        "blocks_to_converge": blocks,
        "force_history_N": forces.tolist(),
    }
