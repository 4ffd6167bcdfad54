"""The two-pantograph closed form of Paper A eqs. (24)-(25), written apart from pantohil's
(models/catenary/asm/closed_form.py): the poles of the string from its own cubic (Paper A eq. 9), the receptances
from their residues (eqs. 15-17), the chain's receptance from its own matrices (eq. 18), and the pair's two
equations per harmonic solved for both forces. The reference of the tests of two pantographs."""
import numpy as np


def _poles(cat, omega, speed):
    """Roots of lambda k^3 + eta k^2 + tau k + sigma (Paper A eq. 9) and P'(k) at each."""
    T, mu, kbar = cat.tension_N, cat.density_kg_m, cat.support_stiffness_N_m2
    c = cat.alpha_1_s * mu + cat.beta_s * kbar
    lam = 1j * cat.beta_s * T * speed
    eta = T - mu * speed ** 2 + 1j * cat.beta_s * T * omega
    tau = 1j * c * speed - 2 * mu * speed * omega
    sigma = kbar + 1j * c * omega - mu * omega ** 2
    roots = np.roots([lam, eta, tau, sigma])
    return [(k, 3 * lam * k ** 2 + 2 * eta * k + tau) for k in roots]


def _string(cat, omega, speed, spacing_m):
    """(H11, H at the point spacing_m ahead, H at the point spacing_m behind), Paper A eqs. (15)-(17)."""
    poles = _poles(cat, omega, speed)
    below = [(k, d) for k, d in poles if k.imag < 0]
    above = [(k, d) for k, d in poles if k.imag > 0]
    direct = -1j * sum(1 / d for _, d in below)
    ahead = -1j * sum(np.exp(-1j * k * spacing_m) / d for k, d in below)
    behind = 1j * sum(np.exp(1j * k * spacing_m) / d for k, d in above)
    return direct, ahead, behind


def _chain(pan, omega):
    """H_p = 1/k_c + [K - w^2 M + i w C]^-1 (1, 1) of the masses in a chain, head first (Paper A eq. 18)."""
    m, k, c = (np.asarray(a, dtype=float) for a in (pan.masses_kg, pan.stiffnesses_N_m, pan.dampings_Ns_m))
    n = len(m)
    K, C = np.zeros((n, n)), np.zeros((n, n))
    for i in range(n):  # element i joins mass i to mass i + 1, the last to the ground
        nodes = [i, i + 1] if i + 1 < n else [i]
        for a in nodes:
            for b in nodes:
                sign = 1.0 if a == b else -1.0
                K[a, b] += sign * k[i]
                C[a, b] += sign * c[i]
    return np.linalg.inv(K - omega ** 2 * np.diag(m) + 1j * omega * C)[0, 0] + 1 / pan.contact_stiffness_N_m


def _harmonics(x):
    spec = np.fft.rfft(x) / len(x)
    spec[1:] *= 2
    return spec


def closed_form_pair(case):
    """Each pantograph's steady force at the N samples of a span (first, second), Paper A eqs. (24)-(25)."""
    second = case.sections.second_pantograph
    n, L = case.samples_per_span, second.spacing_m
    x = np.arange(n) * case.speed_m_s * case.dt_s
    offset = -L if second.position == "trailing" else L
    z1, z2 = _harmonics(case.profile.heights(x)), _harmonics(case.profile.heights(x + offset))
    f1 = np.zeros(n // 2 + 1, dtype=complex)
    f2 = np.zeros(n // 2 + 1, dtype=complex)
    f1[0] = f2[0] = case.pantograph.uplift_force_N
    for j in range(1, case.n_harmonics):
        omega = 2 * np.pi * j / (n * case.dt_s)
        direct, ahead, behind = _string(case.catenary, omega, case.speed_m_s, L)
        h12, h21 = (ahead, behind) if offset < 0 else (behind, ahead)  # at 1 from 2, at 2 from 1
        hp = _chain(case.pantograph, omega)
        # contact: the head's height -hp f equals the wire's z0 + H f at each point
        f1[j], f2[j] = np.linalg.solve([[hp + direct, h12], [h21, hp + direct]], [-z1[j], -z2[j]])
    series = [np.fft.irfft(np.concatenate([f[:1], f[1:] / 2]) * n, n=n) for f in (f1, f2)]
    return np.array(series)
