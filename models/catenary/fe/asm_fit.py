"""Fitting ASM2 to a finite-element catenary (Paper A sec. 4): kbar from the mean vertical stiffness
(eq. 32), and the string density mu by least squares of the wavelengths a fixed harmonic force
radiates along the contact wire (eq. 36)."""
from __future__ import annotations

import numpy as np
from scipy import optimize

from pantohil.models.catenary.asm.string import AsmParameters, wavelength_at_rest


def support_stiffness_from(kz_mean_N_m: float, tension_N: float) -> float:
    """kbar = k_z^2 / (4 T), Paper A eq. (32)."""
    return kz_mean_N_m**2 / (4.0 * tension_N)


def dominant_wavelength(x: np.ndarray, u: np.ndarray, x_load: float, span_m: float,
                        windows_spans=(2, 3, 4, 5, 6)) -> float:
    """The most dominant wavelength of the contact-wire response (Paper A sec. 4.2): the peak of the
    spatial DFT of the complex response over windows of several spans, starting one span from the
    load on either side; the median over windows and sides. The complex field makes a wave travelling
    away from the load a one-sided peak."""
    out = []
    for side in (+1, -1):
        d = side * (x - x_load)
        for w in windows_spans:
            sel = (d >= span_m) & (d <= (1 + w) * span_m)
            if sel.sum() < 16:
                continue
            order = np.argsort(d[sel])
            dd, uu = d[sel][order], u[sel][order]
            grid = np.linspace(dd[0], dd[-1], len(dd))  # the mesh is near-uniform; make it exact
            field = np.interp(grid, dd, uu.real) + 1j * np.interp(grid, dd, uu.imag)
            field = field * np.hanning(len(field))
            pad = 16 * len(field)
            spec = np.abs(np.fft.fft(field, n=pad))
            k = 2 * np.pi * np.fft.fftfreq(pad, d=grid[1] - grid[0])
            spec[np.abs(k) < 2 * np.pi / (w * span_m)] = 0.0  # longer than the window: not a wave here
            kp = k[int(np.argmax(spec))]
            if kp != 0:
                out.append(2 * np.pi / abs(kp))
    if not out:
        raise ValueError("the section is too short to measure a wavelength")
    return float(np.median(out))


def attenuation(x: np.ndarray, u: np.ndarray, x_load: float, span_m: float, spans=(1, 5)) -> float:
    """Decay rate [1/m] of the response amplitude between 1 and 5 spans from the load (both sides):
    the slope of log|u| against distance."""
    rates = []
    for side in (+1, -1):
        d = side * (x - x_load)
        sel = (d >= spans[0] * span_m) & (d <= spans[1] * span_m) & (np.abs(u) > 0)
        if sel.sum() > 8:
            rates.append(-np.polyfit(d[sel], np.log(np.abs(u[sel])), 1)[0])
    return float(np.mean(rates)) if rates else float("nan")


STOP_BAND_RATIO = 8.0  # measured on paper_a_stitched: stop bands decay 12-67x faster than ASM2's wave,
                       # propagating waves 0.5-5.3x (the FE's Rayleigh beta also damps its bending)
STOP_BAND_FLOOR_1_M = 0.002


def is_propagating(fe_attenuation_1_m: float, asm: AsmParameters, omega: float) -> bool:
    """A wave propagates unless it decays far faster than the string's own damping explains (ASM2's
    Im k of the radiated wave): in a stop band of the periodic catenary the response is evanescent
    and has no wavelength to fit."""
    from pantohil.models.catenary.asm.string import poles

    k2 = poles(asm, omega, 0.0).upper[0]
    return fe_attenuation_1_m <= STOP_BAND_RATIO * abs(k2.imag) + STOP_BAND_FLOOR_1_M


def fit_density(frequencies_hz: np.ndarray, wavelengths_m: np.ndarray, tension_N: float, kbar_N_m2: float,
                alpha_1_s: float, beta_s: float, bounds=(0.3, 6.0)) -> float:
    """mu minimising sum (lambda_ASM(w; mu) - lambda_FE(w))^2 over the band, Paper A eq. (36) and Table 1."""
    w = 2 * np.pi * np.asarray(frequencies_hz, dtype=float)
    target = np.asarray(wavelengths_m, dtype=float)

    def cost(mu):
        p = AsmParameters(tension_N, mu, kbar_N_m2, alpha_1_s, beta_s)
        model = np.array([wavelength_at_rest(p, wi) for wi in w])
        return float(np.sum((model - target) ** 2))

    res = optimize.minimize_scalar(cost, bounds=bounds, method="bounded", options={"xatol": 1e-6})
    return float(res.x)
