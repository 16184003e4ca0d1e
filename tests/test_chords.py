"""Closed-form chord integrals (jmse_jax._chords) against SciPy and float64 brute force.

The overlap engine uses the general form (``chord_integral``) off the symmetric path from
``_otf._CLOSED_FORM_ORDER`` Gauss nodes along the chords, so the engine test lowers that
order and compares with the Gauss path. The even form (``even_chord_integral``) is what the
engine's rotationally symmetric path (the one-ray plans) uses for Seidel wavefronts; its
engine checks are in ``test_otf.py``.
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
    # The Taylor rectangle's edges and corners, just inside and just outside.
    g_t, b_t = _chords._TAYLOR_G, _chords._TAYLOR_B
    for fg, fb in [(1.0, 1.0), (0.999, 1.001), (1.001, 0.999), (1.001, 1.001), (0.5, 1.001),
                   (1.001, 0.5), (1.0, 0.0), (0.0, 1.0)]:
        for sg, sb in [(1, 1), (1, -1), (-1, 1), (-1, -1)]:
            c0.append(rng.uniform(-3, 3, 1))
            c1.append(np.array([sb * fb * b_t]))
            c2.append(np.array([sg * fg * g_t]))
    # An end slope s = c1 + 2 c2 at the far / near border s^2 = 4 |c2|, and at t* = +-1.
    g = 10.0 ** rng.uniform(-2.2, 1.5, 40) * rng.choice([-1.0, 1.0], 40)
    for f in (1.0 - 1e-12, 1.0, 1.0 + 1e-12):
        c0.append(rng.uniform(-3, 3, 40))
        c1.append(f * 2.0 * np.sqrt(np.abs(g)) - 2.0 * g)
        c2.append(g)
    c0.append(np.zeros(8))
    c1.append(np.array([0.6, -0.6, 2.0, -2.0, 0.01, -0.01, 40.0, -40.0]))
    c2.append(np.array([0.3, 0.3, 1.0, 1.0, 0.005, 0.005, 20.0, 20.0]))
    return np.concatenate(c0), np.concatenate(c1), np.concatenate(c2)


def _phases(c0, c1, c2):
    return c0 - c1 + c2, c0, c0 + c1 + c2


def test_h_and_its_derivative_match_scipy_wofz():
    # h(x) = int_0^inf e^{-w} (1 + i x w)^{-1/2} dw = sqrt(pi / (i x)) w(e^{i pi/4} / sqrt(x)).
    x = np.linspace(1e-4, 1.0 / (2.0 * np.pi), 60)
    ref = np.sqrt(np.pi) / (np.sqrt(x) * np.exp(0.25j * np.pi)) * wofz(
        np.exp(0.25j * np.pi) / np.sqrt(x))
    assert np.max(np.abs(_chords.h_host(x) - ref)) < 2e-14
    # h' integrates to h's increments.
    for lo, hi in [(0.0, 0.05), (0.05, 1.0 / (2.0 * np.pi))]:
        t, w = np.polynomial.legendre.leggauss(40)
        t, w = lo + (hi - lo) * (t + 1) / 2, w * (hi - lo) / 2
        increment = _chords.h_host(np.array(hi)) - _chords.h_host(np.array(lo))
        assert abs(_chords.h_host(t, derivative=True) @ w - increment) < 1e-15
    # The device series reproduce the host functions (u = 2 pi x on [0, 1]).
    u = np.linspace(0.0, 1.0, 101)
    h_re, h_im, hp_re, hp_im = _chords._h_series()
    poly = np.polynomial.polynomial.polyval
    assert np.max(np.abs(poly(u, h_re) + 1j * poly(u, h_im)
                         - _chords.h_host(u / (2 * np.pi)))) < 1e-13
    assert np.max(np.abs(poly(u, hp_re) + 1j * poly(u, hp_im)
                         - _chords.h_host(u / (2 * np.pi), derivative=True) / (2 * np.pi))) < 1e-13


def test_taylor_tables_are_the_moments():
    # On the rectangle's corner the tables give the moments to rounding.
    b, g = _chords._TAYLOR_B, -_chords._TAYLOR_G
    t, w = _composite_gauss()
    e = np.exp(2j * np.pi * (b * t + g * t * t))
    for q, table in enumerate(_chords._taylor_tables()):
        got = _chords._taylor_moment(table, b, g, b * b, g * g)
        assert abs(got[0] + 1j * got[1] - (e * t**q) @ w) < 1e-15


def test_pure_quadratic_matches_fresnel():
    # int_{-1}^{1} e^{i 2 pi c2 t^2} dt = (C(2 sqrt c2) + i S(2 sqrt c2)) / sqrt(c2).
    c2 = np.array([1e-3, 0.05, 0.3, 0.5464668, 1.0, 3.0, 12.0])
    s, c = fresnel(2 * np.sqrt(c2))
    ref = (c + 1j * s) / np.sqrt(c2)
    zero = np.zeros_like(c2)
    re, im = jax.jit(_chords.chord_integral)(c2, zero, c2)
    np.testing.assert_allclose(np.asarray(re) + 1j * np.asarray(im), ref, rtol=0, atol=1e-14)
    # Arguments broadcast against each other, in the value and the derivative.
    re, im = _chords.chord_integral(c2, 0.0, c2)
    np.testing.assert_allclose(np.asarray(re) + 1j * np.asarray(im), ref, rtol=0, atol=1e-14)
    d = jax.grad(lambda p: jnp.sum(_chords.chord_integral(c2, p, c2)[0]))(0.0)
    np.testing.assert_allclose(float(d), np.sum(-2 * np.pi * (ref.imag - (
        _brute(np.zeros_like(c2), np.zeros_like(c2), c2)[2]).imag)), rtol=1e-11)
    # Conjugate symmetry (c2 < 0) and the c0 phase factor.
    re, im = jax.jit(_chords.chord_integral)(0.25 - c2, 0.25 + zero, 0.25 - c2)
    np.testing.assert_allclose(np.asarray(re) + 1j * np.asarray(im), 1j * np.conj(ref),
                               rtol=0, atol=1e-14)


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
    # Chords of little phase outside the Taylor rectangle: there the identities lose up to
    # (|b| / |g|)^2, about 1e-10 next to the rectangle.
    small_phase = (np.abs(c2) < 0.1) & (np.abs(c1) < 1.0)
    for k, ref in enumerate(refs):
        got = np.asarray(g_re[k]) + 1j * np.asarray(g_im[k])
        assert np.all(np.isfinite(got))
        assert np.max(np.abs(got - ref)) < 3e-10
        assert np.max(np.abs(got - ref)[~small_phase]) < 3e-12


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


def test_second_derivatives_finite_at_degenerate_points():
    g_t, b_t = _chords._TAYLOR_G, _chords._TAYLOR_B
    c1 = np.array([0.0, 0.0, 0.6, -0.6, b_t, b_t, 2.0 * np.sqrt(0.3) - 0.6, 1e-300, 3.0])
    c2 = np.array([0.0, 0.3, 0.3, 0.3, g_t, 0.0, 0.3, 0.0, 0.0])
    pm, p0, pp = _phases(np.full(c1.size, 0.2), c1, c2)
    hess = jax.jit(jax.vmap(jax.hessian(lambda a, b, c: _chords.chord_integral(a, b, c)[0],
                                        (0, 1, 2))))(pm, p0, pp)
    assert all(bool(jnp.all(jnp.isfinite(x))) for x in jax.tree_util.tree_leaves(hess))


@pytest.mark.parametrize("coefficients", [
    dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198),
    dict(w020=-8.0, w040=4.0, w131=2.0, w222=2.0, w220=1.0),
    dict(),
])
def test_engine_with_closed_form_chords_matches_gauss(monkeypatch, coefficients):
    ab = jj.Seidel(**coefficients)
    nu_x = jnp.asarray([0.0, 1e-9, 0.05, 0.3, -0.45, 0.7, 0.999, 1.0])
    nu_y = jnp.asarray([0.0, 0.0, 0.2, -0.1, 0.5, 0.3, 0.0, 0.0])

    def run(order):
        monkeypatch.setattr(_otf, "_CLOSED_FORM_ORDER", order)
        jax.clear_caches()  # the engine's jitted programs do not see the switch
        h = jj.otf(ab, nu_x, nu_y, 0.95, nodes=(48, 48))
        grad = jax.grad(lambda a: jnp.sum(jnp.abs(jj.otf(a, nu_x, nu_y, 0.95,
                                                          nodes=(48, 48))) ** 2))(ab)
        return np.asarray(h), np.array(jax.tree_util.tree_leaves(grad))

    h_exact, g_exact = run(48)
    h_gauss, g_gauss = run(49)
    jax.clear_caches()
    assert np.max(np.abs(h_exact - h_gauss)) < 1e-13
    assert np.all(np.isfinite(g_exact))
    np.testing.assert_allclose(g_exact, g_gauss, rtol=1e-11, atol=1e-13)
    # With the engine's own threshold, a long rule along the chords takes the closed form.
    assert _otf._CLOSED_FORM_ORDER == 49
    monkeypatch.undo()
    assert _otf._CLOSED_FORM_ORDER <= 64
    h_long = np.asarray(jj.otf(ab, nu_x, nu_y, 0.95, nodes=(48, 64)))
    assert np.max(np.abs(h_long - h_gauss)) < 1e-13


def test_recomputed_closed_form_blocks_match_stored_and_gauss(monkeypatch):
    """Blocks of closed-form chords recomputed in the reverse pass (``_remat_otf``, as the
    default's steep and balanced grids run them since session 101) give the stored blocks'
    value and gradient, and the Gauss chords' (the three phases along each chord enter the
    kernel as three arrays, and its weighted sum has its own derivative rule)."""
    ab = jj.Seidel(w020=-6.0, w131=4.0, w222=3.0, w040=2.0)
    rng = np.random.default_rng(5)
    radius, angle = np.sqrt(rng.uniform(0.0, 1.1, 1100)), rng.uniform(0.0, np.pi, 1100)
    nu_x, nu_y = jnp.asarray(radius * np.cos(angle)), jnp.asarray(radius * np.sin(angle))

    def run(order, remat):
        monkeypatch.setattr(_otf, "_CLOSED_FORM_ORDER", order)
        jax.clear_caches()

        def loss(a, field):
            h = _otf._otf_overlap(a, nu_x, nu_y, field, (16, 64), remat=remat)
            return jnp.sum(jnp.abs(h) ** 2 * (1.0 + nu_x))

        value, grads = jax.jit(jax.value_and_grad(loss, argnums=(0, 1)))(ab, 0.9)
        return float(value), np.array(jax.tree_util.tree_leaves(grads))

    assert 1100 > _otf._OVERLAP_BLOCK * 1024 // (16 * _otf._CLOSED_FORM_BLOCK_ORDER)
    v_remat, g_remat = run(64, True)
    v_stored, g_stored = run(64, False)
    v_gauss, g_gauss = run(65, True)
    jax.clear_caches()
    assert v_remat == pytest.approx(v_stored, rel=1e-14)
    np.testing.assert_allclose(g_remat, g_stored, rtol=1e-13, atol=1e-15)
    assert v_remat == pytest.approx(v_gauss, rel=1e-12)
    np.testing.assert_allclose(g_remat, g_gauss, rtol=1e-12, atol=1e-13)


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
