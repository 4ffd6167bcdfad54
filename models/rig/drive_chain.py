"""The thesis's rig chains, stepped at the model's dt (Paper B sec. 4, Paper D sec. 2).

Height path: a pure delay (the link to the drive), one height of every N_com reaches the drive
(`decimation`), which ramps linearly from its previous reference to the new one over `ramp_s`,
emitting a sub-reference every `sub_step_s` (0.3125 ms on Paper B's LinMot E1400); each
sub-reference passes the drive's acceleration/velocity-limited motion profile (`RigLimits`) and a
position loop, modelled as a second-order closed loop (natural frequency, damping) integrated
exactly between sub-references. The actuator height of a step is the position at the step's end.

Force path: the load cells' amplifier low-pass (a Butterworth of `filter_order` at `filter_hz`,
discretised by the bilinear transform at dt), a pure delay, then the offset and noise.

The decimation and the sub-references make the chain periodically time-varying; `RigChain` is
exact, and `frequency_response` gives its response at the kept harmonics as the fundamental of a
multisine run of the chain itself (what an identification measures); `analytic_response` is the
closed form of its linear time-invariant approximation (an independent check).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from pantohil.models.schema import param

from .actuator import ActuatorLimits, Limiter


MAX_DELAY_STEPS = 100_000  # a delay is shorter than a span, and a span holds at most this many (MAX_SAMPLES_PER_SPAN)
MAX_DECIMATION = 10_000  # as the case's rig.comm_decimation


@dataclass(frozen=True)
class HeightPath:
    """[height] of a rig file: the path of the commanded height to the actuator (Paper B sec. 4, Paper D
    sec. 2)."""

    delay_steps: int = param(0, "1", "pure delay to the drive [steps] (shorter than the longest span)", 0,
                             MAX_DELAY_STEPS)
    decimation: int = param(1, "1", "N_com: one height of every N_com sent reaches the drive", 1, MAX_DECIMATION)
    ramp_s: float = param(0.0, "s", "the drive's ramp from the old to the new reference (0: N_com dt)", 0.0)
    sub_step_s: float = param(0.0, "s", "the drive's sub-reference period (0: the ramp read at every model step)",
                              0.0)
    servo_frequency_hz: float = param(0.0, "Hz", "position loop natural frequency (0: ideal tracking)", 0.0)
    servo_damping: float = param(0.7, "1", "position loop damping ratio", 0.0, low_open=True)


@dataclass(frozen=True)
class ForcePath:
    """[force] of a rig file: the true to the measured force (amplifier low-pass, then acquisition delay)."""

    filter_hz: float = param(0.0, "Hz", "amplifier low-pass cut-off (0: none; below the Nyquist frequency)", 0.0)
    filter_order: int = param(2, "1", "Butterworth order", 1, 8)
    delay_steps: int = param(0, "1", "acquisition delay [steps] (shorter than the longest span)", 0, MAX_DELAY_STEPS)


@dataclass(frozen=True)
class MeasuredResponse:
    """A rig's frequency response measured at given frequencies (written by `pantohil rig-identify`)."""

    frequencies_hz: tuple
    height: tuple  # complex gains, command -> actuator height
    force: tuple  # complex gains, true -> measured force

    def at(self, freqs_hz: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The gains at `freqs_hz`, each of which must be one of the measured frequencies."""
        known = np.asarray(self.frequencies_hz)
        idx = []
        for f in np.atleast_1d(freqs_hz):
            j = int(np.argmin(np.abs(known - f)))
            if abs(known[j] - f) > 1e-6 * max(1.0, f):
                raise ValueError(f"the measured response has no point at {f:.6g} Hz (identify the rig for this case)")
            idx.append(j)
        return np.asarray(self.height)[idx], np.asarray(self.force)[idx]


@dataclass(frozen=True)
class RigSpec:
    """A rig file: the chain between the catenary model and the pantograph."""

    name: str
    model_step_s: float
    height: HeightPath = field(default_factory=HeightPath)
    force: ForcePath = field(default_factory=ForcePath)
    limits: ActuatorLimits = field(default_factory=ActuatorLimits)
    stated_delay_s: float = 0.0  # the total delay the paper states (for the report only)
    description: str = ""
    measured: MeasuredResponse | None = None

    @property
    def ramp_s(self) -> float:
        """Duration of the drive's ramp to a new reference: as given, or N_com model steps [s]."""
        return self.height.ramp_s or self.height.decimation * self.model_step_s


class DiscreteFilter:
    """A digital filter (b, a) run one sample at a time (transposed direct form II), started at rest
    at a constant input."""

    def __init__(self, b, a, initial: float):
        # scipy is imported where it is used in this module, not at its top: scipy.signal takes 0.7 s to
        # import, and every command of the CLI imports this module (refusing a bad input needs none of it)
        from scipy import signal

        a0 = float(a[0])
        self.b = [float(v) / a0 for v in b]
        self.a = [float(v) / a0 for v in a]
        order = max(len(self.a), len(self.b)) - 1
        self.state = [float(v) for v in signal.lfilter_zi(self.b, self.a) * initial] if order else []

    def __call__(self, x: float) -> float:
        b, a, s = self.b, self.a, self.state
        if not s:  # a pure gain (no filter)
            return b[0] * x
        y = b[0] * x + s[0]
        last = len(s) - 1
        for i in range(len(s)):
            s[i] = b[i + 1] * x - a[i + 1] * y + (s[i + 1] if i < last else 0.0)
        return y


def force_filter_coefficients(path: ForcePath, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Analog Butterworth low-pass at filter_hz, bilinear transform at dt (identity if none)."""
    from scipy import signal  # imported where used: see DiscreteFilter

    if path.filter_hz <= 0:
        return np.array([1.0]), np.array([1.0])
    b, a = signal.butter(path.filter_order, 2 * math.pi * path.filter_hz, analog=True)
    bz, az = signal.bilinear(b, a, fs=1.0 / dt_s)
    return bz, az


@lru_cache(maxsize=256)
def _servo_transition(wn: float, zeta: float, h_ns: int) -> tuple[np.ndarray, np.ndarray]:
    """Exact transition of x' = A x + B u over h with u held (zero-order hold)."""
    from scipy import linalg  # imported where used: see DiscreteFilter

    h = h_ns * 1e-12
    m = np.zeros((3, 3))
    m[0, 1] = 1.0
    m[1, 0], m[1, 1], m[1, 2] = -wn * wn, -2 * zeta * wn, wn * wn
    e = linalg.expm(m * h)
    return e[:2, :2].copy(), e[:2, 2].copy()


class _Drive:
    """Decimated references, the linear ramp at sub-steps, the motion profile and the position loop.

    With `limited` False the motion profile is left out: the drive is then linear in its inputs and its
    signals may be arrays (the rows of a state basis, for the stability map)."""

    def __init__(self, spec: RigSpec, dt_s: float, z0, limited: bool = True):
        hp = spec.height
        self.hp, self.dt, self.ramp = hp, dt_s, spec.ramp_s
        self.tau = hp.sub_step_s
        self.z_old = self.z_new = self.u = z0
        self.t_arrival = -1.0
        self.k = 0
        self.limiter = Limiter(spec.limits, self.tau or dt_s, z0) if limited else None
        self.wn = 2 * math.pi * hp.servo_frequency_hz
        self.pos, self.vel = z0, 0.0 * z0  # the position loop's state
        self.tick = 0  # sub-references emitted so far (the drive's own clock)

    STATE = ("z_old", "z_new", "u", "pos", "vel")  # what the drive remembers between steps (linear part)

    def state_names(self) -> tuple:
        """The drive's state variables that its next steps use (the position loop's only if there is one)."""
        return self.STATE if self.wn > 0 else self.STATE[:3]

    def _ramp_at(self, t: float):
        frac = min(max((t - self.t_arrival) / self.ramp, 0.0), 1.0)
        return self.z_old + (self.z_new - self.z_old) * frac

    def _reference(self, z):
        return z if self.limiter is None else self.limiter(z)[0]

    def _advance(self, h: float) -> None:
        if self.wn > 0 and h > 0:
            phi, gam = _servo_transition(self.wn, self.hp.servo_damping, int(round(h * 1e12)))
            self.pos, self.vel = (phi[0, 0] * self.pos + phi[0, 1] * self.vel + gam[0] * self.u,
                                  phi[1, 0] * self.pos + phi[1, 1] * self.vel + gam[1] * self.u)

    def step(self, z):
        t0 = self.k * self.dt
        if self.k % self.hp.decimation == 0:  # a new reference reaches the drive (Paper B sec. 4)
            self.z_old, self.z_new, self.t_arrival = self.z_new, z, t0
        self.k += 1
        t1 = self.k * self.dt
        if self.tau <= 0:
            self._advance(t1 - t0)
            self.u = self._reference(self._ramp_at(t1))
        else:
            t = t0
            while (self.tick + 1) * self.tau <= t1 + 1e-12:  # sub-references inside this step
                self.tick += 1
                ts = self.tick * self.tau
                self._advance(ts - t)
                self.u, t = self._reference(self._ramp_at(ts)), ts
            self._advance(t1 - t)
        return self.pos if self.wn > 0 else self.u


class RigChain:
    """A rig file's chain at the model's dt. `step(z_command, f_true)` -> (actuator height, measured force).

    `linear=True`: without the motion profile's limits, the offset and the noise, the chain is linear and
    its signals may be arrays; `state()` and `set_state()` then read and write everything it remembers
    between steps (its clocks aside), for the span-to-span map of models/stability/rig_map.py."""

    def __init__(self, spec: RigSpec, dt_s: float, initial_height: float = 0.0, initial_force: float = 0.0,
                 force_offset_N: float = 0.0, noise_std_N: float = 0.0, noise_seed: int = 0, linear: bool = False):
        self.spec, self.dt = spec, dt_s
        hp, fp = spec.height, spec.force
        self._zdelay = deque([initial_height] * hp.delay_steps)
        self._fdelay = deque([initial_force] * fp.delay_steps)
        self._drive = _Drive(spec, dt_s, initial_height, limited=not linear)
        b, a = force_filter_coefficients(fp, dt_s)
        self._filter = DiscreteFilter(b, a, initial_force)
        self.offset, self.noise = (0.0, 0.0) if linear else (force_offset_N, noise_std_N)
        self._rng = np.random.default_rng(noise_seed)

    def state(self) -> list:
        """Every value the chain remembers between steps: delay lines, drive, filter (its clocks aside)."""
        d = self._drive
        return [*self._zdelay, *self._fdelay, *(getattr(d, k) for k in d.state_names()), *self._filter.state]

    def set_state(self, values) -> None:
        """Write the values `state()` lists, in its order."""
        values = list(values)
        if len(values) != len(self.state()):
            raise ValueError(f"the rig chain has {len(self.state())} state values, got {len(values)}")
        nz, nf = len(self._zdelay), len(self._fdelay)
        self._zdelay = deque(values[:nz])
        self._fdelay = deque(values[nz:nz + nf])
        names = self._drive.state_names()
        for k, v in zip(names, values[nz + nf:nz + nf + len(names)], strict=True):
            setattr(self._drive, k, v)
        self._filter.state = values[nz + nf + len(names):]

    @staticmethod
    def _through(line: deque, x: float) -> float:
        if not line:
            return x
        line.append(x)
        return line.popleft()

    def height(self, z_command: float) -> float:
        """Height path of one model step: delay, then the drive (interpolation, position loop, limits) [m]."""
        return self._drive.step(self._through(self._zdelay, z_command))

    def force(self, f_true: float) -> float:
        """Force path of one model step: load-cell filter, delay, offset and noise [N]."""
        f = self._through(self._fdelay, self._filter(f_true)) + self.offset
        if self.noise > 0:
            f += float(self._rng.normal(0.0, self.noise))
        return f

    def step(self, z_command: float, f_true: float) -> tuple[float, float]:
        """One model step of the rig: (actuator height, measured force)."""
        return self.height(z_command), self.force(f_true)


def analytic_response(spec: RigSpec, dt_s: float, freqs_hz) -> tuple[np.ndarray, np.ndarray]:
    """Closed form of the chain's linear time-invariant approximation (command -> height, true -> measured).

    Sampling every T = N_com dt and ramping over T_r is, averaged over the sampling phase, the kernel
    w(s) = r(s) - r(s - T) with r the unit ramp of length T_r, over T: W(w) = (1 - e^{-iwT})
    (1 - e^{-iwT_r}) / (T T_r (iw)^2); read at the step's end (e^{iw dt}); sub-references every tau
    held: e^{-iw tau/2} sinc(w tau/2); position loop w_n^2 / (w_n^2 - w^2 + 2 i zeta w_n w); pure
    delays e^{-iw d dt}; the force filter exactly (its bilinear form at dt).
    """
    from scipy import signal  # imported where used: see DiscreteFilter

    w = 2 * np.pi * np.asarray(freqs_hz, dtype=float)
    hp, fp = spec.height, spec.force
    gz = np.exp(-1j * w * hp.delay_steps * dt_s)
    if hp.decimation > 1 or hp.ramp_s > 0:
        T, Tr = hp.decimation * dt_s, spec.ramp_s
        iw = 1j * np.where(w == 0, 1.0, w)
        ramp = (1 - np.exp(-iw * T)) * (1 - np.exp(-iw * Tr)) / (T * Tr * iw**2)
        gz = gz * np.where(w == 0, 1.0, ramp) * np.exp(1j * w * dt_s)
    if hp.sub_step_s > 0:
        x = w * hp.sub_step_s / 2
        gz = gz * np.exp(-1j * x) * np.sinc(x / np.pi)
    if hp.servo_frequency_hz > 0:
        wn = 2 * np.pi * hp.servo_frequency_hz
        gz = gz * wn**2 / (wn**2 - w**2 + 2j * hp.servo_damping * wn * w)
    b, a = force_filter_coefficients(fp, dt_s)
    _, gf = signal.freqz(b, a, worN=w * dt_s)
    gf = gf * np.exp(-1j * w * fp.delay_steps * dt_s)
    return gz, gf


def record_spans(spec: RigSpec | None, dt_s: float, samples_per_span: int, minimum: int = 4) -> int:
    """Spans of a multisine record: whole periods of the rig's clocks against the span (`pattern_spans`
    unlimited), doubled until there are at least `minimum` (a rig of unknown clocks: `minimum`)."""
    spans = 1
    if spec is not None:
        pattern = pattern_steps(spec, dt_s)
        spans = max(1, pattern // math.gcd(pattern, samples_per_span))
    while spans < minimum:
        spans *= 2
    return spans


def multisine(samples_per_span: int, n_harmonics: int, total: int, dt_s: float) -> np.ndarray:
    """A Schroeder multisine of unit amplitude per harmonic over `sqrt(N_h - 1)`, at the harmonics
    1..N_h-1 of the span (Paper D eqs. 4-8: the kept harmonics), `total` samples from t = 0."""
    k = np.arange(1, n_harmonics)
    if not len(k):
        return np.zeros(total)
    phase = -np.pi * k * (k - 1) / len(k)  # Schroeder phases: low crest factor
    t = np.arange(total) * dt_s
    omega = 2 * np.pi * k / (samples_per_span * dt_s)
    return np.cos(np.outer(t, omega) + phase).sum(axis=1) / len(k) ** 0.5


def harmonic_gains(x: np.ndarray, y: np.ndarray, spans: int, n_harmonics: int) -> np.ndarray:
    """y / x at the harmonics 1..N_h-1 of the span, from a record of `spans` whole spans (the
    harmonic k of the span is bin k * spans); 1 at DC (a rig has no drift to compensate)."""
    g = np.ones(n_harmonics, complex)
    if n_harmonics > 1:
        bins = np.arange(1, n_harmonics) * spans
        g[1:] = np.fft.rfft(y)[bins] / np.fft.rfft(x)[bins]
    return g


def frequency_response(spec: RigSpec, dt_s: float, samples_per_span: int, n_harmonics: int,
                       amplitude_m: float = 1e-3, amplitude_N: float = 10.0) -> tuple[np.ndarray, np.ndarray]:
    """The chain's response at harmonics 0..N_h-1 of the span: the fundamental of a Schroeder multisine
    run through `RigChain` itself, over whole spans after a settling span; at DC the gain is 1 (no drift).

    Exact for the linear time-invariant parts; for the decimation and the sub-references it is the
    response averaged over their phase within the record (the aliased parts fall above the kept band
    when N_com dt < 1 / (2 f_max))."""
    n = samples_per_span
    spans = record_spans(spec, dt_s, n)
    total = (spans + 1) * n
    shape = multisine(n, n_harmonics, total, dt_s)
    z_in, f_in = amplitude_m * shape, amplitude_N * shape
    chain = RigChain(spec, dt_s)
    out = np.array([chain.step(z, f) for z, f in zip(z_in, f_in, strict=False)])
    rec = slice(n, total)
    return (harmonic_gains(z_in[rec], out[rec, 0], spans, n_harmonics),
            harmonic_gains(f_in[rec], out[rec, 1], spans, n_harmonics))


def pattern_steps(spec: RigSpec, dt_s: float) -> int:
    """Steps after which the decimation and the sub-reference clock repeat."""
    p = max(1, spec.height.decimation)
    tau = spec.height.sub_step_s
    if tau > 0:
        ratio = dt_s / tau
        for q in range(1, 1001):  # dt / tau = p'/q: the clocks align every q steps
            if abs(ratio * q - round(ratio * q)) < 1e-9:
                p = p * q // math.gcd(p, q)
                break
    return p


def pattern_spans(spec: RigSpec, dt_s: float, samples_per_span: int, limit: int = 8) -> int:
    """Spans after which the rig's clocks are back at the same phase within the span (at most `limit`;
    beyond it the pattern is treated as unrelated to the span and the steady state as span-periodic)."""
    p = pattern_steps(spec, dt_s)
    spans = p // math.gcd(p, samples_per_span)
    return spans if spans <= limit else 1


def group_delay_s(spec: RigSpec, dt_s: float) -> dict:
    """Low-frequency group delays of the two paths and their sum (the rig's latency)."""
    f = np.array([0.05])
    gz, gf = analytic_response(spec, dt_s, f)
    w = 2 * np.pi * f[0]
    hz, hf = -float(np.angle(gz[0])) / w, -float(np.angle(gf[0])) / w
    return {"height_s": hz, "force_s": hf, "total_s": hz + hf}


def latency_steps(spec: RigSpec, dt_s: float) -> int:
    """The rig's latency rounded to whole steps (the pure delay advance of Paper D sec. 3.4)."""
    return int(round(group_delay_s(spec, dt_s)["total_s"] / dt_s))
