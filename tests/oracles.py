"""Independent NumPy/SciPy float64 oracles, written from SPEC §2 (not from the package code).

Nothing here imports ``jmse_jax``: each oracle transcribes a formula of the specification
or integrates it by a different method than the package does.
"""

from __future__ import annotations

import math

import numpy as np
from scipy import integrate

SEIDEL_KEYS = ("w020", "w040", "w131", "w222", "w220", "w311", "w111")


def seidel_wavefront(coefficients: dict, x, y, field):
    """SPEC §2: ``W = w020 rho² + w040 rho⁴ + w131 h rho² y + w222 h² y² + w220 h² rho²
    + w311 h³ y + w111 h y`` in waves."""
    c = {k: float(coefficients.get(k, 0.0)) for k in SEIDEL_KEYS}
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    h = float(field)
    rho2 = x**2 + y**2
    return (
        c["w020"] * rho2
        + c["w040"] * rho2**2
        + c["w131"] * h * rho2 * y
        + c["w222"] * h**2 * y**2
        + c["w220"] * h**2 * rho2
        + c["w311"] * h**3 * y
        + c["w111"] * h * y
    )


def diffraction_limited_otf(r):
    """``H(r) = (2/pi)(arccos r - r sqrt(1 - r²))`` for ``r < 1``, else 0."""
    r = np.abs(np.asarray(r, dtype=np.float64))
    rc = np.minimum(r, 1.0)
    value = (2.0 / math.pi) * (np.arccos(rc) - rc * np.sqrt(1.0 - rc**2))
    return np.where(r < 1.0, value, 0.0)


def otf(coefficients: dict, nu_x: float, nu_y: float, field: float, *, n_inner: int = 200,
        tol: float = 1e-13) -> complex:
    """OTF by direct integration of ``(1/pi) ∫∫ P(xi + nu) P*(xi - nu) d²xi`` (SPEC §2).

    Cartesian coordinates rotated so that ``a`` runs along ``nu`` and ``b`` across it: the
    overlap of the discs ``|xi ± nu| <= 1`` is ``|b| <= sqrt(1 - s²)``,
    ``|a| <= sqrt(1 - b²) - s`` with ``s = |nu|``. The outer ``b`` integral is adaptive
    (``scipy.integrate.quad``, tolerance ``tol``); the inner ``a`` integral of the entire
    integrand over its finite interval is Gauss–Legendre with ``n_inner`` nodes
    (``numpy.polynomial.legendre``), exact to rounding for the phase variations used here.
    """
    s = math.hypot(nu_x, nu_y)
    if s >= 1.0:
        return 0.0 + 0.0j
    if s == 0.0:
        return 1.0 + 0.0j
    ex, ey = nu_x / s, nu_y / s
    t, wt = np.polynomial.legendre.leggauss(n_inner)
    b_max = math.sqrt(1.0 - s * s)

    def inner(b):
        half = math.sqrt(1.0 - b * b) - s
        a = half * t
        xi_x = a * ex - b * ey
        xi_y = a * ey + b * ex
        w_plus = seidel_wavefront(coefficients, xi_x + nu_x, xi_y + nu_y, field)
        w_minus = seidel_wavefront(coefficients, xi_x - nu_x, xi_y - nu_y, field)
        return half * np.sum(wt * np.exp(2j * math.pi * (w_plus - w_minus)))

    value, _ = integrate.quad(inner, -b_max, b_max, epsabs=tol, epsrel=tol, limit=400,
                              complex_func=True)
    return complex(value / math.pi)


def otf_dblquad(coefficients: dict, nu_x: float, nu_y: float, field: float,
                tol: float = 1e-11) -> complex:
    """The same integral by ``scipy.integrate.dblquad`` in unrotated Cartesian coordinates
    (``xi_y`` outer over the lens's extent, ``xi_x`` between the two circles). Slow; used
    to check ``otf`` itself, only for ``nu`` along ``nu_y``."""
    if nu_x != 0.0:
        raise ValueError("otf_dblquad handles nu = (0, nu_y) only")
    s = abs(nu_y)
    if s >= 1.0:
        return 0.0 + 0.0j
    y_max = 1.0 - s  # xi_y in [-(1 - s), 1 - s]; xi_x between the circles

    def half_width(yy):
        return math.sqrt(max(0.0, 1.0 - (abs(yy) + s) ** 2))

    def phase(xx, yy):
        w = seidel_wavefront(coefficients, xx, yy + nu_y, field) - seidel_wavefront(
            coefficients, xx, yy - nu_y, field)
        return 2.0 * math.pi * float(w)

    parts = []
    for fn in (math.cos, math.sin):
        value, _ = integrate.dblquad(lambda xx, yy, fn=fn: fn(phase(xx, yy)), -y_max, y_max,
                                     lambda yy: -half_width(yy), half_width,
                                     epsabs=tol, epsrel=tol)
        parts.append(value / math.pi)
    return complex(parts[0], parts[1])


def pupil_otf_lag_grid(coefficients: dict, field: float, B: int) -> np.ndarray:
    """Baseline OTF on the ``2B x 2B`` lag grid (NumPy FFT order, rows ``nu_y = k/B``).

    Pupil sampled at the cell centres of a ``B x B`` grid over ``[-1, 1]²`` (inside the unit
    disc), zero-padded to ``2B``, ``|fft2|²`` is the PSF, ``ifft2`` of the PSF is the pupil
    autocorrelation, normalised to 1 at lag 0.
    """
    centres = (np.arange(B) + 0.5) * (2.0 / B) - 1.0
    x, y = np.meshgrid(centres, centres)  # rows y, columns x
    inside = x**2 + y**2 <= 1.0
    pupil = np.where(inside, np.exp(2j * np.pi * seidel_wavefront(coefficients, x, y, field)), 0)
    padded = np.zeros((2 * B, 2 * B), dtype=np.complex128)
    padded[:B, :B] = pupil
    psf = np.abs(np.fft.fft2(padded)) ** 2
    autocorrelation = np.fft.ifft2(psf)
    return autocorrelation / autocorrelation[0, 0].real


def markov_psd(r, variance: float, correlation_length: float):
    """SPEC §2: ``variance 2 pi mu² / (1 + (2 pi mu r)²)^(3/2)``."""
    mu = correlation_length
    return variance * 2.0 * np.pi * mu**2 / (1.0 + (2.0 * np.pi * mu * np.asarray(r)) ** 2) ** 1.5


def power_law_psd(r, amplitude: float, exponent: float, knee: float):
    """SPEC §2: ``amplitude / (knee² + r²)^(exponent/2)``."""
    return amplitude / (knee**2 + np.asarray(r) ** 2) ** (exponent / 2.0)


def error_spectral_density(h, s_x, s_n):
    """SPEC §2: ``S_x S_n / (|H|² S_x + S_n)``."""
    return s_x * s_n / (np.abs(h) ** 2 * s_x + s_n)


def baseline_jmse(coefficients: dict, field: float, u: float, signal_psd, noise_variance: float,
                  B: int) -> float:
    """The paper's baseline: lag-grid OTF, rectangle rule over the lags strictly inside
    ``|nu_x|, |nu_y| < u``, ``sum S_e / B² / (2 pi)``. ``signal_psd(r)`` is ``S_x``. For
    ``u > 1`` the lags run past the ``2B`` grid (``-B .. B - 1``), where ``H = 0``."""
    inner = np.fft.fftshift(pupil_otf_lag_grid(coefficients, field, B))  # lags -B .. B-1
    reach = max(B, int(np.ceil(u * B)))
    k = np.arange(-reach, reach + 1)
    h = np.zeros((k.size, k.size), complex)
    h[reach - B:reach + B, reach - B:reach + B] = inner
    nu_x, nu_y = np.meshgrid(k / B, k / B)
    band = (np.abs(nu_x) < u) & (np.abs(nu_y) < u)
    s_x = signal_psd(np.hypot(nu_x, nu_y))
    s_e = error_spectral_density(h, s_x, noise_variance)
    return float(np.sum(s_e[band]) / B**2 / (2.0 * np.pi))


def square_integral(f, u: float, tol: float = 1e-12) -> float:
    """``∫∫_{[-u, u]²} f(nu_x, nu_y)`` for ``f`` even in both arguments, by
    ``scipy.integrate.dblquad`` over the first quadrant (times 4)."""
    value, _ = integrate.dblquad(lambda y, x: f(x, y), 0.0, u, 0.0, u, epsabs=tol, epsrel=tol)
    return 4.0 * value


def markov_no_transfer_jmse(u: float, variance: float, correlation_length: float) -> float:
    """``(1 / 2 pi) ∫∫_{[-u, u]²} S_x`` for the Markov spectrum in closed form: the JMSE with
    no transfer at all (``H = 0``, so ``S_e = S_x``), an upper bound of every lens's.

    With ``c = 1 / (2 pi mu)``, ``S_x = (variance mu / k²) (c² + r²)^(-3/2)`` (``k = 2 pi mu``)
    and ``∫_0^X ∫_0^Y (c² + x² + y²)^(-3/2) = arctan(X Y / (c sqrt(c² + X² + Y²))) / c``
    (the solid angle of a rectangle)."""
    c = 1.0 / (2.0 * np.pi * correlation_length)
    angle = np.arctan(u * u / (c * np.sqrt(c * c + 2.0 * u * u)))
    return float(4.0 * variance / (2.0 * np.pi) * angle / (2.0 * np.pi))


def richardson_difference(fn, x, i: int, h: float) -> float:
    """Central difference of ``fn`` along coordinate ``i`` of ``x`` (a float array), with one
    Richardson step: ``(4 D(h/2) - D(h)) / 3``, error of order ``h^4``."""
    def plain(step):
        e = np.zeros_like(x)
        e[i] = step
        return (float(fn(x + e)) - float(fn(x - e))) / (2 * step)
    return (4 * plain(h / 2) - plain(h)) / 3
