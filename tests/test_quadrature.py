"""Frequency quadratures over the sensor band [-u, u]²: exactness and order of convergence."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import oracles
import pytest
from scipy import integrate

from jmse_jax._quadrature import frequency_quadrature

RULES = ("polar", "gauss", "gauss_polar", "trapezoid", "rectangle")


def _markov(x, y):
    return oracles.markov_psd(np.hypot(x, y), 1.0, 5.0)


def _dl_otf2_plus_markov(x, y):
    """A band integrand with the OTF's cutoff edge and S_x's cone-like peak at 0."""
    return oracles.diffraction_limited_otf(np.hypot(x, y)) ** 2 + _markov(x, y)


def _rule_integral(rule, u, p, f):
    nu_x, nu_y, w = (np.asarray(a) for a in frequency_quadrature(rule, u, p))
    return float(np.sum(w * f(nu_x, nu_y)))


@pytest.fixture(scope="module")
def markov_reference():
    return {u: oracles.square_integral(_markov, u) for u in (0.2, 0.5)}


@pytest.mark.parametrize("rule", RULES)
@pytest.mark.parametrize("u", [0.2, 1.5])
def test_nodes_in_first_quadrant_with_positive_weights(rule, u):
    p = (6, 5) if rule == "polar" else 6
    nu_x, nu_y, w = (np.asarray(a) for a in frequency_quadrature(rule, u, p))
    assert nu_x.shape == nu_y.shape == w.shape
    assert np.all(nu_x >= 0) and np.all(nu_y >= 0)
    assert np.all(nu_x <= u * (1 + 1e-14)) and np.all(nu_y <= u * (1 + 1e-14))
    assert np.all(w >= 0)


@pytest.mark.parametrize("u", [0.1, 0.2, 0.9, 1.5])
def test_constant_gives_band_area(u):
    area = 4 * u * u
    one = lambda x, y: np.ones_like(x)  # noqa: E731
    assert _rule_integral("gauss", u, 3, one) == pytest.approx(area, rel=1e-14)
    assert _rule_integral("trapezoid", u, 2, one) == pytest.approx(area, rel=1e-14)
    assert _rule_integral("polar", u, (16, 16), one) == pytest.approx(area, rel=1e-13)
    # Rectangle rule on the lag grid k u / p, k = 0..p-1 (half cell at 0): first order.
    p = 10
    assert _rule_integral("rectangle", u, p, one) == pytest.approx(area * (1 - 0.5 / p) ** 2,
                                                                    rel=1e-14)
    # A float32 u gives float32 nodes and weights (they were float64), summing to the area.
    for rule, nodes in (("gauss", 3), ("polar", (16, 16))):
        arrays = frequency_quadrature(rule, np.float32(u), nodes)
        assert {a.dtype for a in arrays} == {np.dtype(np.float32)}
        assert float(jnp.sum(arrays[2])) == pytest.approx(area, rel=1e-6)


def test_gauss_exact_for_even_polynomials():
    u = 0.37

    def f(x, y):
        return 1 + 3 * x**2 + x**2 * y**4 - 2 * y**6

    exact = 4 * u**2 + 3 * (2 * u**3 / 3) * 2 * u + (2 * u**3 / 3) * (2 * u**5 / 5) \
        - 2 * (2 * u**7 / 7) * 2 * u
    assert _rule_integral("gauss", u, 4, f) == pytest.approx(exact, rel=1e-14)
    assert _rule_integral("polar", u, (24, 24), f) == pytest.approx(exact, rel=1e-12)
    assert oracles.square_integral(f, u) == pytest.approx(exact, rel=1e-12)  # the oracle too


@pytest.mark.parametrize("u", [0.2, 0.5])
@pytest.mark.parametrize("rule", ["gauss", "polar"])
def test_spectral_convergence_on_markov_spectrum(markov_reference, rule, u):
    reference = markov_reference[u]
    # p = 48: the polar rule's rays are composite (three radial panels, see _quadrature),
    # so it needs a few more nodes than a single panel on this smooth integrand.
    errors = [abs(_rule_integral(rule, u, p, _markov) - reference) / reference
              for p in (8, 16, 48)]
    assert errors[2] < 1e-8
    assert errors[2] < 1e-4 * errors[0]  # faster than any fixed power of 1/p


@pytest.mark.parametrize(("rule", "p_coarse", "order"),
                         [("trapezoid", 17, 2), ("gauss_polar", 17, 2), ("rectangle", 16, 1)])
def test_algebraic_order(markov_reference, rule, p_coarse, order):
    u = 0.2
    reference = markov_reference[u]
    coarse = abs(_rule_integral(rule, u, p_coarse, _markov) - reference)
    fine = abs(_rule_integral(rule, u, 2 * p_coarse - (p_coarse % 2), _markov) - reference)
    ratio = coarse / fine
    assert 2**order * 0.8 < ratio < 2**order * 1.25, ratio


@pytest.mark.parametrize("u", [0.9, 1.2, 1.5])
def test_polar_past_the_cutoff(u):
    """Corners of the band past |nu| = 1: rays split at the cutoff, still convergent."""
    if u >= 1:  # the whole disc lies in the band: its part reduces to a radial integral
        disc, _ = integrate.quad(lambda r: oracles.diffraction_limited_otf(r) ** 2 * r, 0, 1,
                                 epsabs=1e-15, epsrel=1e-14)
        reference = 2 * math.pi * disc + oracles.square_integral(_markov, u)
    else:
        reference = oracles.square_integral(_dl_otf2_plus_markov, u)
    errors = [abs(_rule_integral("polar", u, (p, p), _dl_otf2_plus_markov) - reference)
              / reference for p in (16, 32)]
    # The edge of H0**2 at |nu| = 1 ((1 - r)**3) converges algebraically; the composite
    # radial rule leaves 40 % of the nodes to the outer panel (8e-6 at p = 32).
    assert errors[1] < 1e-5
    assert errors[1] < errors[0] / 10


@pytest.mark.parametrize("u", [0.3, 0.8])
def test_weights_are_differentiable_in_u(u):
    """At u = 0.8 the polar rule's angular rule is split at arccos(u), a traced point."""
    for rule in ("gauss", "polar"):
        p = (12, 12) if rule == "polar" else 5
        area = jax.grad(lambda u, rule=rule, p=p: frequency_quadrature(rule, u, p)[2].sum())
        # The split point moves with u: its parts' rules are exact only to their order.
        assert float(area(u)) == pytest.approx(8 * u, rel=1e-12 if u < 0.7 else 1e-9)


@pytest.mark.parametrize("u", [0.6, 0.75, 0.95, 1.1])
def test_split_angular_rule(u):
    """For 1/sqrt(2) < u < 1 the angular rule is split at arccos(u), where the rays start
    to reach the cutoff, with nodes shared in proportion; otherwise the plain Gauss rule."""
    from jmse_jax._quadrature import angular_rule

    frac, w_frac = (np.asarray(a) for a in angular_rule(u, 12, jnp.float64))
    assert np.all(np.diff(frac) > 0) and frac[0] > 0 and frac[-1] < 1
    assert w_frac.sum() == pytest.approx(1.0, rel=1e-14)
    plain, _ = np.polynomial.legendre.leggauss(12)
    if not math.sqrt(0.5) < u < 1:
        np.testing.assert_allclose(frac, (plain + 1) / 2, rtol=1e-14)
        return
    split = math.acos(u) / (math.pi / 4)
    n1 = int(np.sum(frac < split))
    assert n1 == min(max(round(split * 12), 4), 8)
    # Each part holds a Gauss rule of its own: it integrates x**(2 n - 1) exactly.
    x1, x2 = frac[:n1], frac[n1:]
    w1, w2 = w_frac[:n1], w_frac[n1:]
    k = 2 * min(n1, 12 - n1) - 1
    assert np.sum(w1 * x1**k) == pytest.approx(split ** (k + 1) / (k + 1), rel=1e-12)
    assert np.sum(w2 * x2**k) == pytest.approx((1 - split ** (k + 1)) / (k + 1), rel=1e-12)


@pytest.mark.parametrize(
    ("rule", "p", "match"),
    [
        ("bogus", 4, r"quadrature must be one of 'polar', .*, got 'bogus'"),
        ("gauss", 0, r"p must be an integer >= 1, got 0"),
        ("rectangle", -2, r"p must be an integer >= 1, got -2"),
        ("polar", (0, 4), r"nodes \(radial\) must be an integer >= 3, got 0"),
        ("polar", (4, 0), r"nodes \(angular\) must be an integer >= 1, got 0"),
        ("trapezoid", 1, r"p must be >= 2 for the trapezoid rule, got 1"),
    ],
)
def test_bad_rule_or_count_raises(rule, p, match):
    with pytest.raises(ValueError, match=match):
        frequency_quadrature(rule, 0.2, p)


@pytest.mark.parametrize("coarse, fine, drop", [((18, 10), (300, 40), (1, 0)),
                                                ((18, 10), (300, 40), (0, 1)),
                                                ((24, 12), (60, 20), (2, 2))])
def test_lowered_interpolation_drops_the_top_legendre_degrees(coarse, fine, drop):
    """``polar_interpolation_matrices(..., drop)``: on each radial panel (and angular rule)
    a polynomial of degree below ``k - d`` at the coarse nodes is interpolated exactly, as
    by the full matrices, and the top Legendre polynomial ``P_{k-1}`` is interpolated as
    zero (``d >= 1``). Oracle: NumPy's Legendre polynomials on the panels' Gauss nodes."""
    from numpy.polynomial import legendre

    from jmse_jax._numerics import gauss_legendre
    from jmse_jax._quadrature import (
        _radial_counts,
        _radial_panels,
        angular_templates,
        polar_interpolation_matrices,
    )

    full_r, full_a = polar_interpolation_matrices(coarse, fine)
    low_r, low_a = polar_interpolation_matrices(coarse, fine, drop)
    start = 0
    for (a, b), k in zip(_radial_panels(), _radial_counts(coarse[0]), strict=True):
        x, _ = gauss_legendre(k, a, b)
        s = (2 * x - a - b) / (b - a)
        for degree, kept in ((k - 1 - drop[0], True), (k - 1, drop[0] == 0)):
            values = np.zeros(coarse[0])
            values[start:start + k] = legendre.legval(s, np.eye(k)[degree])
            expected = full_r @ values if kept else np.zeros(fine[0])
            np.testing.assert_allclose(low_r @ values, expected, atol=1e-9)
        start += k
    x = angular_templates(coarse[1])[0][0]  # the plain angular rule's nodes on [0, 1]
    k = coarse[1]
    for degree, kept in ((k - 1 - drop[1], True), (k - 1, drop[1] == 0)):
        values = legendre.legval(2 * x - 1, np.eye(k)[degree])
        expected = full_a[0] @ values if kept else np.zeros(fine[1])
        np.testing.assert_allclose(low_a[0] @ values, expected, atol=1e-9)


@pytest.mark.parametrize("coarse, fine", [(40, 960), (64, 1000), (16, 48)])
def test_built_angular_interpolation_is_the_host_matrices(coarse, fine):
    """``angular_interpolation_block`` (the program's build of the angular interpolation
    above ``BUILT_ANGULAR_BYTES``) gives ``split_interpolation``'s matrix of every template
    row to rounding, zero rows for padding (part -1), and within each part interpolates a
    polynomial of the part's degree exactly (oracle: the polynomial at the fine nodes)."""
    from jmse_jax._quadrature import (
        angular_interpolation_block,
        angular_interpolation_tables,
        split_interpolation,
    )

    tables = angular_interpolation_tables(coarse, fine)
    host = split_interpolation(coarse, fine)
    for row in range(len(tables.coarse_local)):
        coarse_row = tuple(jnp.asarray(a[row], float) for a in tables[:3])
        part = np.asarray(tables.fine_second[row], float)
        built = np.asarray(angular_interpolation_block(
            coarse_row, jnp.asarray(np.append(tables.fine_local[row], 0.5)),
            jnp.asarray(np.append(part, -1.0))))
        np.testing.assert_allclose(built[:-1], host[row], rtol=0, atol=1e-13)
        assert not built[-1].any()
        second = tables.coarse_second[row]
        for side in (False, True):
            k = int(np.sum(second == side))
            if k == 0:
                continue
            values = np.where(second == side, (tables.coarse_local[row] - 0.3) ** (k - 1), 0.0)
            chosen = tables.fine_second[row] == side
            np.testing.assert_allclose(
                (built[:-1] @ values)[chosen], (tables.fine_local[row][chosen] - 0.3) ** (k - 1),
                rtol=0, atol=1e-11)


def test_jmse_with_built_angular_interpolation(monkeypatch):
    """With every grid's angular interpolation built in the program
    (``BUILT_ANGULAR_BYTES = 0``), ``jmse``'s value and gradient in the coefficients (the
    fine stage's adjoint) and in ``u`` (its ordinary derivative) are those with the host
    matrices, on a split angular rule (u = 0.85)."""
    import jmse_jax as jj
    from jmse_jax import _merit, _quadrature

    c = jnp.array([1.5, -0.8, 0.7, 0.5, -0.3])
    calls = []

    def counted(*args):
        calls.append(1)
        return _quadrature.angular_interpolation_block(*args)

    monkeypatch.setattr(_merit, "angular_interpolation_block", counted)

    def merit(c, u):
        return jj.jmse(jj.Seidel(*c), 0.7, u, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-4),
                       preset="fast")

    def run():
        jax.clear_caches()
        value, (g_c, g_u) = jax.value_and_grad(merit, argnums=(0, 1))(c, 0.85)
        return float(value), np.append(np.asarray(g_c), float(g_u))

    value, grad = run()
    assert not calls
    monkeypatch.setattr(_quadrature, "BUILT_ANGULAR_BYTES", 0)
    built_value, built_grad = run()
    assert calls  # the build was traced
    assert built_value == pytest.approx(value, rel=1e-13)
    np.testing.assert_allclose(built_grad, grad, rtol=0, atol=1e-12 * np.max(np.abs(grad)))
