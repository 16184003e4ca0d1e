"""Closed-form chord integrals (jmse_jax._chords) against SciPy and float64 brute force.

The overlap engine uses the general form (``chord_integral``) only behind the private switch
``_otf._EXACT_CHORDS`` (measured slower than the Gauss chords on CPU; benchmarks/README.md,
optimisation log), so the engine test turns the switch on and compares with the Gauss path.
The even form (``even_chord_integral``) is what the engine's rotationally symmetric path
(the one-ray plans) uses for Seidel wavefronts; its engine checks are in ``test_otf.py``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.special import fresnel, wofz

import jmse_jax as jj
from jmse_jax import _chords, _otf


def _composite_gauss(panels=100, order=40):
    """Composite Gauss–Legendre on [-1, 1] (a single 3000-node rule is not accurate enough)."""
    x, w = np.polynomial.legendre.leggauss(order)
    edges = np.linspace(-1.0, 1.0, panels + 1)
    half = np.diff(edges)[:, None] / 2
    mid = (edges[:-1, None] + edges[1:, None]) / 2
    return (mid + half * x).ravel(), (half * w).ravel()


def _brute(c0, c1, c2):
    """J, int t e^{i phi}, int t^2 e^{i phi} for phi = 2 pi (c0 + c1 t + c2 t^2)."""
    t, w = _composite_gauss()
    e = np.exp(2j * np.pi * (c0[:, None] + c1[:, None] * t + c2[:, None] * t * t))
    return e @ w, (e * t) @ w, (e * t * t) @ w


def _cases():
    """(c0, c1, c2) in waves over 10 decades, with the degenerate and switch-over points."""
    rng = np.random.default_rng(7)
    scales = [0.0, 1e-12, 1e-6, 1e-3, 1e-2, 0.1, 1.0, 5.0, 20.0]
    c0, c1, c2 = [], [], []
    for s1 in scales:
        for s2 in scales + [1e-4]:
            c0.append(rng.uniform(-3, 3, 12))
            c1.append(rng.normal(size=12) * s1)
            c2.append(rng.normal(size=12) * s2)
    two_pi = 2 * np.pi
    g0, b0 = _chords._G_SMALL / two_pi, _chords._B_SMALL / two_pi  # thresholds in waves
    extra_c2 = [g0 * 0.999, g0 * 1.001, g0, 0.3, 0.3, 0.3, 1.0, -1.0, 0.5, 0.0]
    extra_c1 = [b0, b0 + 2 * g0, b0 * 0.999, 0.6, -0.6, 0.6 + 1e-10, 2.0, 2.0, 0.0, 0.0]
    c0.append(np.zeros(len(extra_c1)))
    c1.append(np.array(extra_c1))  # c1 = +-2 c2: stationary point at an end of the chord
    c2.append(np.array(extra_c2))
    return np.concatenate(c0), np.concatenate(c1), np.concatenate(c2)


def _phases(c0, c1, c2):
    return c0 - c1 + c2, c0, c0 + c1 + c2


def test_special_functions_match_scipy_wofz():
    # Ahat(y) = (sqrt(pi) / 2) e^{i pi/4} w(e^{i pi/4} y / 2), K(eps) = -i y Ahat(y).
    y = np.linspace(0.0, 12.0, 61)
    ref = np.sqrt(np.pi) / 2 * np.exp(0.25j * np.pi) * wofz(np.exp(0.25j * np.pi) * y / 2)
    assert np.max(np.abs(_chords.ahat_host(y) - ref)) < 5e-15
    eps = np.linspace(1e-5, 1.0 / _chords._Y**2, 41)
    yy = 1 / np.sqrt(eps)
    ref_k = -1j * yy * np.sqrt(np.pi) / 2 * np.exp(0.25j * np.pi) * wofz(
        np.exp(0.25j * np.pi) * yy / 2)
    assert np.max(np.abs(_chords.k_host(eps) - ref_k)) < 2e-14
    # The device series reproduce the host integrals.
    a = _chords._ahat(jnp.asarray(y[y <= _chords._Y]))
    assert np.max(np.abs(a[0] + 1j * a[1] - ref[y <= _chords._Y])) < 1e-14


def test_pure_quadratic_matches_fresnel():
    # int_{-1}^{1} e^{i 2 pi c2 t^2} dt = (C(2 sqrt c2) + i S(2 sqrt c2)) / sqrt(c2).
    c2 = np.array([1e-3, 0.05, 0.3, 0.5464668, 1.0, 3.0, 12.0])
    s, c = fresnel(2 * np.sqrt(c2))
    ref = (c + 1j * s) / np.sqrt(c2)
    zero = np.zeros_like(c2)
    re, im = jax.jit(_chords.chord_integral)(c2, zero, c2)
    np.testing.assert_allclose(np.asarray(re) + 1j * np.asarray(im), ref, rtol=0, atol=3e-15)
    # Conjugate symmetry (c2 < 0) and the c0 phase factor.
    re, im = jax.jit(_chords.chord_integral)(0.25 - c2, 0.25 + zero, 0.25 - c2)
    np.testing.assert_allclose(np.asarray(re) + 1j * np.asarray(im), 1j * np.conj(ref),
                               rtol=0, atol=3e-15)


def test_values_and_derivatives_against_brute_force():
    c0, c1, c2 = _cases()
    j, m1, m2 = _brute(c0, c1, c2)
    pm, p0, pp = _phases(c0, c1, c2)
    re, im = jax.jit(_chords.chord_integral)(pm, p0, pp)
    assert np.max(np.abs(np.asarray(re) + 1j * np.asarray(im) - j)) < 1e-13

    def total(part):
        return jax.jit(jax.grad(lambda a, b, c: jnp.sum(_chords.chord_integral(a, b, c)[part]),
                                argnums=(0, 1, 2)))(pm, p0, pp)

    g_re, g_im = total(0), total(1)
    # dJ/dc0 = i 2 pi J, dJ/dc1 = i 2 pi M1, dJ/dc2 = i 2 pi M2; c0 = p0,
    # c1 = (pp - pm) / 2, c2 = (pp + pm) / 2 - p0.
    d_c0, d_c1, d_c2 = 2j * np.pi * j, 2j * np.pi * m1, 2j * np.pi * m2
    refs = ((d_c2 - d_c1) / 2, d_c0 - d_c2, (d_c1 + d_c2) / 2)
    for k, ref in enumerate(refs):
        got = np.asarray(g_re[k]) + 1j * np.asarray(g_im[k])
        assert np.all(np.isfinite(got))
        # Near-degenerate chords (g ~ 1e-3 rad) amplify the inputs' rounding: ~1e-9 there.
        assert np.max(np.abs(got - ref)) < 5e-9
        typical = np.abs(got - ref)[np.abs(c2) > 0.05]
        assert np.max(typical) < 1e-11


def test_gradient_finite_at_degenerate_points():
    p = jnp.zeros(4)
    for args in [(p, p, p), (p + 0.3, p + 0.3, p + 0.3), (p, p + 0.0, p + 1e-300)]:
        g = jax.grad(lambda a, b, c: jnp.sum(_chords.chord_integral(a, b, c)[1]),
                     argnums=(0, 1, 2))(*args)
        # Constant phase: dJ/dp0 = i 2 pi * 2 (imag part 4 pi cos), ends share the rest.
        assert all(bool(jnp.all(jnp.isfinite(x))) for x in g)
    g = jax.grad(lambda a, b, c: jnp.sum(_chords.chord_integral(a, b, c)[1]),
                 argnums=(0, 1, 2))(p, p, p)
    _, m1, m2 = _brute(np.zeros(1), np.zeros(1), np.zeros(1))
    # d Im J / d p0 at zero phase = Re(i 2 pi (J - M2)) / i ... = 2 pi (2 - 2/3).
    np.testing.assert_allclose(np.asarray(g[1]), 2 * np.pi * (2 - 2 / 3), rtol=1e-13)
    np.testing.assert_allclose(np.asarray(g[0]), 2 * np.pi * (1 / 3), rtol=1e-13)


def test_perpendicular_chord_degree():
    assert jj.Seidel().perpendicular_chord_degree == 2
    assert jj.Zernike(jnp.ones(2), noll=(4, 11)).perpendicular_chord_degree == 2
    assert jj.Zernike(jnp.ones(2), noll=(4, 12)).perpendicular_chord_degree == 3
    # Numerically: the phase difference along a perpendicular chord is quadratic in t.
    rng = np.random.default_rng(1)
    t = np.linspace(-1, 1, 7)
    nu = np.array([0.3, 0.2])
    e = nu / np.linalg.norm(nu)
    e_perp = np.array([-e[1], e[0]])
    xi = 0.2 * e[:, None] + 0.5 * t * e_perp[:, None]
    for model, quadratic in [
        (jj.Seidel(**dict(zip(("w020", "w040", "w131", "w222", "w220", "w311"),
                              rng.normal(size=6).tolist(), strict=True))), True),
        (jj.Zernike(jnp.asarray(rng.normal(size=3)), noll=(4, 8, 11)), True),
        (jj.Zernike(jnp.asarray(rng.normal(size=2)), noll=(4, 12)), False),
    ]:
        phase = np.asarray(model(xi[0] + nu[0], xi[1] + nu[1], 0.7)
                           - model(xi[0] - nu[0], xi[1] - nu[1], 0.7))
        residual = phase - np.polyval(np.polyfit(t, phase, 2), t)
        assert (np.max(np.abs(residual)) < 1e-12) == quadratic


@pytest.mark.parametrize("coefficients", [
    dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198),
    dict(w020=-8.0, w040=4.0, w131=2.0, w222=2.0, w220=1.0),
    dict(),
])
def test_engine_with_exact_chords_matches_gauss(monkeypatch, coefficients):
    ab = jj.Seidel(**coefficients)
    nu_x = jnp.asarray([0.0, 1e-9, 0.05, 0.3, -0.45, 0.7, 0.999, 1.0])
    nu_y = jnp.asarray([0.0, 0.0, 0.2, -0.1, 0.5, 0.3, 0.0, 0.0])

    def run(exact):
        monkeypatch.setattr(_otf, "_EXACT_CHORDS", exact)
        h = jj.otf(ab, nu_x, nu_y, 0.95, nodes=(48, 48))
        grad = jax.grad(lambda a: jnp.sum(jnp.abs(jj.otf(a, nu_x, nu_y, 0.95,
                                                          nodes=(48, 48))) ** 2))(ab)
        return np.asarray(h), np.array(jax.tree_util.tree_leaves(grad))

    h_exact, g_exact = run(True)
    h_gauss, g_gauss = run(False)
    assert np.max(np.abs(h_exact - h_gauss)) < 1e-13
    assert np.all(np.isfinite(g_exact))
    np.testing.assert_allclose(g_exact, g_gauss, rtol=1e-9, atol=1e-11)


def _even_cases():
    """(p0, gamma) in waves: gamma over 14 decades of both signs, the series' end
    (|gamma| = 1) and zero, p0 over 60 waves."""
    rng = np.random.default_rng(11)
    gamma = np.concatenate([
        rng.uniform(-300.0, 300.0, 400), rng.uniform(-1.5, 1.5, 400),
        10.0 ** rng.uniform(-12, 2.5, 400) * rng.choice([-1.0, 1.0], 400),
        [0.0, 1.0, -1.0, 1.0 + 1e-15, 1.0 - 1e-15, 1e-300],
    ])
    return rng.uniform(-30.0, 30.0, gamma.size), gamma


def test_even_chord_integral_matches_fresnel():
    """``Re int_{-1}^{1} exp(i 2 pi (p0 + gamma t^2)) dt = 2 Re[e^{i 2 pi p0} F(gamma)]`` with
    ``F(gamma) = (C(x) + i S(x)) / x``, ``x = 2 sqrt|gamma|`` (SciPy's Fresnel integrals,
    ``F(-gamma) = conj F(gamma)``)."""
    p0, gamma = _even_cases()
    x = 2.0 * np.sqrt(np.abs(gamma))
    s, c = fresnel(x)
    f = np.where(x > 0, (c + 1j * s) / np.where(x > 0, x, 1.0), 1.0)
    f = np.where(gamma < 0, np.conj(f), f)
    expected = 2.0 * np.real(np.exp(2j * np.pi * p0) * f)
    got = jax.jit(_chords.even_chord_integral)(jnp.asarray(p0), jnp.asarray(p0 + gamma))
    assert np.max(np.abs(np.asarray(got) - expected)) < 3e-13


def test_even_chord_integral_derivatives_against_brute_force():
    """First derivatives in both phases against composite Gauss sums of the differentiated
    integrand (``d/dp1 = Re int 2 pi i t^2 e^{i phi}``, ``d/dp0 = Re int 2 pi i (1 - t^2)
    e^{i phi}``); the Hessian finite everywhere and its ``p1 p1`` entry equal to central
    differences of the gradient."""
    p0, gamma = _even_cases()
    keep = np.abs(gamma) < 120  # the brute-force rule resolves up to ~120 waves
    p0, gamma = p0[keep], gamma[keep]
    t, w = _composite_gauss()
    e = np.exp(2j * np.pi * (p0[:, None] + gamma[:, None] * t * t))
    d1 = np.real((2j * np.pi * e * t * t) @ w)
    d0 = np.real((2j * np.pi * e * (1.0 - t * t)) @ w)
    a, b = jnp.asarray(p0), jnp.asarray(p0 + gamma)
    grad = jax.jit(jax.vmap(jax.grad(_chords.even_chord_integral, (0, 1))))
    g0, g1 = grad(a, b)
    assert np.max(np.abs(np.asarray(g0) - d0)) < 1e-12
    assert np.max(np.abs(np.asarray(g1) - d1)) < 1e-12
    hess = jax.jit(jax.vmap(jax.hessian(_chords.even_chord_integral, (0, 1))))(a, b)
    assert all(np.all(np.isfinite(np.asarray(h))) for h in jax.tree_util.tree_leaves(hess))
    step = 1e-6
    fd = (grad(a, b + step)[1] - grad(a, b - step)[1]) / (2 * step)
    away = np.abs(np.abs(gamma) - 1.0) > 2 * step  # the two forms meet at |gamma| = 1
    np.testing.assert_allclose(np.asarray(hess[1][1])[away], np.asarray(fd)[away],
                               rtol=1e-7, atol=1e-6)


def test_even_chord_series_host_functions():
    """The host functions the series are fitted to: ``F`` on ``|gamma| <= 1`` against SciPy,
    and ``h`` against its definition through ``F``, ``h(x) = (4 pi gamma / i)
    e^{-i 2 pi gamma} ((1 + i) / (4 sqrt gamma) - F(gamma))``, ``x = 1 / (2 pi gamma)``."""
    gamma = np.linspace(0.01, 1.0, 37)
    x = 2.0 * np.sqrt(gamma)
    s, c = fresnel(x)
    np.testing.assert_allclose(_chords.even_f_host(gamma), (c + 1j * s) / x, rtol=0, atol=5e-15)
    gamma = np.linspace(1.0, 40.0, 41)
    x = 2.0 * np.sqrt(gamma)
    s, c = fresnel(x)
    f = (c + 1j * s) / x
    tail = (1 + 1j) / (4 * np.sqrt(gamma)) - f
    h = (4 * np.pi * gamma / 1j) * np.exp(-2j * np.pi * gamma) * tail
    # The right side loses ~4 pi gamma of F's absolute accuracy (about 1e-16).
    np.testing.assert_allclose(_chords.h_host(1.0 / (2 * np.pi * gamma)), h, rtol=0,
                               atol=1e-15 * 4 * np.pi * gamma.max() * 4)
    assert abs(_chords.h_host(np.asarray(0.0)) - 1.0) < 1e-15


def test_even_chord_integral_float32():
    """In float32 the even chords keep float32's accuracy (phases of a few waves)."""
    rng = np.random.default_rng(5)
    p0 = rng.uniform(-3.0, 3.0, 500).astype(np.float32)
    p1 = (p0 + rng.uniform(-20.0, 20.0, 500)).astype(np.float32)
    got = jax.jit(_chords.even_chord_integral)(jnp.asarray(p0), jnp.asarray(p1))
    assert got.dtype == jnp.float32
    expected = _chords.even_chord_integral(jnp.asarray(p0, jnp.float64),
                                           jnp.asarray(p1, jnp.float64))
    assert np.max(np.abs(np.asarray(got, np.float64) - np.asarray(expected))) < 2e-5
