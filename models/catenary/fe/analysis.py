"""Everything `pantohil catenary` reports about a catenary file: form-finding of a multi-span section,
the vertical stiffness along its central span (Paper A Fig. 7), the wavelengths under a fixed harmonic
force and the ASM2 fit (Paper A sec. 4, Table 1), and the contact-wire profile z0 with its harmonics."""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pantohil.models.catenary.asm.string import AsmParameters
from pantohil.models.catenary.fe.asm_fit import (attenuation, dominant_wavelength, fit_density, is_propagating,
    support_stiffness_from)
from pantohil.models.catenary.fe.definition import CatenaryDefinition, CatenaryError, load_definition
from pantohil.models.catenary.asm.closed_form import one_sided_harmonics
from pantohil.models.catenary.fe.model import contact_wire_profile, form_find, harmonic_responses, vertical_stiffness
from pantohil.models.input_files import InputFileError, read_input_bytes, read_input_text
from pantohil.models.storage import cache_folder, cache_root, write_text_atomic

FIT_BANDS_HZ = ((5.0, 20.0), (10.0, 20.0), (10.0, 40.0))
ANALYSIS_VERSION = 2


@dataclass
class AnalysisSettings:
    """Section lengths, profile step, wave frequencies and fit bands of a catenary analysis."""
    static_spans: int = 5  # form-finding and stiffness: the central span of a 5-span section
    wave_spans: int = 12  # wavelengths: a long section with absorbing ends
    profile_step_m: float = 0.05
    # every 0.25 Hz: between the periodic structure's stop bands (every ~4 Hz here) the FE wavelength swings
    # from about +5 % to -6 % of the string's; 1 Hz steps alias that swing into the fitted density (3 %)
    wave_frequencies_hz: tuple = tuple(np.arange(5.0, 40.01, 0.25))
    fit_bands_hz: tuple = FIT_BANDS_HZ


@dataclass
class CatenaryAnalysis:
    """A catenary file's analysis: form-found droppers, profile z0, stiffness along a span, wavelengths, fits."""
    name: str
    span_m: float
    dropper_positions_m: list
    dropper_lengths_m: list
    dropper_tensions_N: list
    steady_arm_forces_N: list
    max_height_error_m: float
    profile_x_m: list
    profile_z_m: list
    stiffness_x_m: list
    stiffness_N_m: list
    wave_frequencies_hz: list
    wavelengths_m: list
    propagating: list  # False where the frequency lies in a stop band (evanescent response)
    fits: list  # [{band_hz, density_kg_m, frequencies_used}]
    contact_tension_N: float
    alpha_1_s: float
    beta_s: float
    harmonics: list = field(default_factory=list)

    @property
    def mean_stiffness_N_m(self) -> float:
        """Mean vertical contact-wire stiffness k_z,FEM over the central span [N/m] (Paper A sec. 4.1)."""
        return float(np.mean(self.stiffness_N_m))

    @property
    def support_stiffness_N_m2(self) -> float:
        """ASM2 support stiffness kbar = k_z,FEM^2 / (4 T) [N/m^2] (Paper A eq. 32)."""
        return support_stiffness_from(self.mean_stiffness_N_m, self.contact_tension_N)

    @property
    def fitted_density_kg_m(self) -> float:
        """The 10-40 Hz fit (Paper A's choice)."""
        return next(f["density_kg_m"] for f in self.fits if tuple(f["band_hz"]) == (10.0, 40.0))

    def summary(self) -> dict:
        """The analysis as catenary.json: droppers, stiffness, the ASM2 fit per band, profile harmonics."""
        return {
            "name": self.name, "span_m": self.span_m, "dropper_positions_m": self.dropper_positions_m,
            "dropper_lengths_m": self.dropper_lengths_m, "dropper_tensions_N": self.dropper_tensions_N,
            "max_height_error_m": self.max_height_error_m, "min_dropper_tension_N": float(min(self.dropper_tensions_N)),
            "steady_arm_forces_N": self.steady_arm_forces_N,
            "mean_vertical_stiffness_N_m": self.mean_stiffness_N_m,
            "min_vertical_stiffness_N_m": float(min(self.stiffness_N_m)),
            "max_vertical_stiffness_N_m": float(max(self.stiffness_N_m)),
            "asm_fit": {"support_stiffness_N_m2": self.support_stiffness_N_m2,
                        "density_kg_m": self.fitted_density_kg_m, "band_hz": [10.0, 40.0],
                        "tension_N": self.contact_tension_N, "bands": self.fits,
                        "wave_frequencies_hz": self.wave_frequencies_hz, "wavelengths_m": self.wavelengths_m,
                        "propagating": self.propagating},
            "z0_harmonics": self.harmonics,
        }


def analyse(cat: CatenaryDefinition, settings: AnalysisSettings | None = None) -> CatenaryAnalysis:
    """Form-find a catenary file, then its profile z0, stiffness k_z(x), wavelengths and ASM2 fit (Paper A sec. 4)."""
    s = settings or AnalysisSettings()
    L = cat.span_m
    mid = s.static_spans // 2
    ff = form_find(cat, s.static_spans)
    central = [i for i, d in enumerate(ff.section.droppers) if mid * L < d[0] < (mid + 1) * L]
    x_prof = np.arange(0.0, L + 1e-9, s.profile_step_m)
    z_prof = contact_wire_profile(ff, mid, x_prof)
    x_k, kz = vertical_stiffness(ff, mid)
    # harmonics of z0 over one period (the last point repeats the first)
    amps = one_sided_harmonics(z_prof[:-1])
    order = np.argsort(-np.abs(amps[1:41])) + 1
    harmonics = [{"harmonic": int(h), "wavelength_m": L / h, "amplitude_m": float(abs(amps[h]))} for h in order[:10]]
    # wavelengths on a long section with absorbing ends, load in the middle of its central span
    fw = form_find(cat, s.wave_spans)
    x_load = (s.wave_spans // 2 + 0.5) * L
    x_load = float(fw.section.x[np.argmin(np.abs(fw.section.x - x_load))])
    kbar = support_stiffness_from(float(np.mean(kz)), cat.contact.tension_N)
    guess = AsmParameters(cat.contact.tension_N, cat.contact.mass_kg_m, kbar, cat.alpha_1_s, cat.beta_s)
    waves, moving = [], []
    responses = harmonic_responses(fw, 2 * np.pi * np.array(s.wave_frequencies_hz), x_load)
    for f, u in zip(s.wave_frequencies_hz, responses, strict=False):
        waves.append(dominant_wavelength(fw.section.x, u, x_load, L))
        moving.append(is_propagating(attenuation(fw.section.x, u, x_load, L), guess, 2 * np.pi * f))
    freqs, waves_a, ok = np.array(s.wave_frequencies_hz), np.array(waves), np.array(moving)
    fits = []
    for lo, hi in s.fit_bands_hz:
        sel = (freqs >= lo - 1e-9) & (freqs <= hi + 1e-9) & ok
        fits.append({"band_hz": [lo, hi], "frequencies_used": int(sel.sum()),
                     "density_kg_m": fit_density(freqs[sel], waves_a[sel], cat.contact.tension_N, kbar,
                                                 cat.alpha_1_s, cat.beta_s)})
    return CatenaryAnalysis(
        cat.name, L, list(cat.dropper_positions_m), [float(v) for v in ff.dropper_lengths_m[central]],
        [float(v) for v in ff.dropper_tensions_N[central]], [float(v) for v in ff.steady_arm_forces_N],
        ff.max_height_error_m, x_prof.tolist(), z_prof.tolist(), x_k.tolist(), kz.tolist(),
        [float(f) for f in freqs], [float(w) for w in waves], [bool(m) for m in moving], fits,
        cat.contact.tension_N, cat.alpha_1_s, cat.beta_s, harmonics)


def cache_dir() -> Path:
    """Folder of the cached catenary analyses ($PANTOHIL_CACHE or ~/.cache/pantohil, then catenaries/)."""
    return cache_root() / "catenaries"


def cached_analysis(path: Path) -> CatenaryAnalysis:
    """The analysis of a catenary file, from the cache when the file has not changed (atomic writes)."""
    path = Path(path)
    cat = load_definition(path)
    try:
        data = read_input_bytes(path, "catenary file")  # the bytes whose analysis is cached, read as checked
    except InputFileError as exc:
        raise CatenaryError(str(exc)) from None
    key = hashlib.sha256(f"{ANALYSIS_VERSION}".encode() + data).hexdigest()[:20]
    entry = cache_dir() / f"{key}.json"
    if entry.exists():
        try:  # a regular file of bounded size (a FIFO or a device planted in the cache does not hang)
            return CatenaryAnalysis(**json.loads(read_input_text(entry, "catenary cache entry")))
        except (ValueError, TypeError):  # InputFileError included: an unreadable entry is recomputed and replaced
            pass
    result = analyse(cat)
    cache_folder(entry.parent)
    write_text_atomic(entry, json.dumps(result.__dict__))
    return result
