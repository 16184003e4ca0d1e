"""Wavefront models: Seidel formula (SPEC §2) and Noll-indexed Zernike polynomials."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from oracles import SEIDEL_KEYS, seidel_wavefront

import jmse_jax as jj

# Noll (1976) table: j -> (n, m), m > 0 the cos(m theta) term, m < 0 the sin term.
NOLL_TABLE = {
    1: (0, 0), 2: (1, 1), 3: (1, -1), 4: (2, 0), 5: (2, -2), 6: (2, 2), 7: (3, -1), 8: (3, 1),
    9: (3, -3), 10: (3, 3), 11: (4, 0), 12: (4, 2), 13: (4, -2), 14: (4, 4), 15: (4, -4),
}


def test_seidel_wavefront_matches_spec_formula():
    rng = np.random.default_rng(1)
    for _ in range(5):
        coefficients = dict(zip(SEIDEL_KEYS, rng.uniform(-6, 6, len(SEIDEL_KEYS)), strict=True))
        field = rng.uniform(0, 1)
        x, y = rng.uniform(-1, 1, (2, 50))
        got = jj.wavefront(jj.Seidel(**coefficients), jnp.asarray(x), jnp.asarray(y), field)
        np.testing.assert_allclose(got, seidel_wavefront(coefficients, x, y, field),
                                   rtol=1e-13, atol=1e-12)


def test_seidel_terms_individually():
    # Pupil point on +y at rho = 1, field 1: every term equals its coefficient.
    for key in SEIDEL_KEYS:
        ab = jj.Seidel(**{key: 0.7})
        assert float(jj.wavefront(ab, 0.0, 1.0, 1.0)) == pytest.approx(0.7, rel=1e-15)
    # The field point is on +y: at the pupil point (1, 0) every y-dependent term vanishes.
    ab = jj.Seidel(w131=1.0, w222=1.0, w111=1.0, w311=1.0)
    assert float(jj.wavefront(ab, 1.0, 0.0, 1.0)) == 0.0
    assert float(jj.wavefront(ab, 0.0, -0.5, 1.0)) == pytest.approx(-0.125 + 0.25 - 0.5 - 0.5)


def _closed_sum(ab, h, points):
    weights, x, y, dx, dy = points
    return jnp.sum(weights * ab.difference(x, y, dx, dy, h))


def _twice_sum(ab, h, points):
    weights, x, y, dx, dy = points
    return jnp.sum(weights * (ab(x + dx, y + dy, h) - ab(x - dx, y - dy, h)))


def test_seidel_difference_matches_two_evaluations():
    """The closed-form ``W(xi + d) - W(xi - d)`` against the SPEC formula evaluated twice
    (the float64 NumPy oracle), with its derivatives in every coefficient and the field
    against the two-evaluation form's."""
    rng = np.random.default_rng(3)
    for _ in range(4):
        coefficients = dict(zip(SEIDEL_KEYS, rng.uniform(-8, 8, len(SEIDEL_KEYS)), strict=True))
        field = rng.uniform(0, 1)
        x, y = rng.uniform(-1, 1, (2, 64))
        dx, dy = rng.uniform(-0.7, 0.7, (2, 64))
        ab = jj.Seidel(**coefficients)
        got = ab.difference(jnp.asarray(x), jnp.asarray(y), jnp.asarray(dx), jnp.asarray(dy),
                            field)
        want = (seidel_wavefront(coefficients, x + dx, y + dy, field)
                - seidel_wavefront(coefficients, x - dx, y - dy, field))
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)

        points = (jnp.asarray(rng.standard_normal(64)), x, y, dx, dy)
        g_closed = jax.grad(_closed_sum, argnums=(0, 1))(ab, jnp.asarray(field), points)
        g_twice = jax.grad(_twice_sum, argnums=(0, 1))(ab, jnp.asarray(field), points)
        for a, b in zip(jax.tree_util.tree_leaves(g_closed), jax.tree_util.tree_leaves(g_twice),
                        strict=True):
            np.testing.assert_allclose(a, b, rtol=1e-11, atol=1e-11)


def test_zernike_difference_is_two_evaluations():
    ab = jj.Zernike(jnp.asarray([0.0, 0.0, 0.3, -0.5, 0.8, 0.2, -0.4, 0.6, 0.1, 0.7, -0.2]))
    x, y, dx, dy = (jnp.asarray(v) for v in np.random.default_rng(4).uniform(-0.6, 0.6, (4, 9)))
    np.testing.assert_array_equal(ab.difference(x, y, dx, dy, 0.4),
                                  ab(x + dx, y + dy, 0.4) - ab(x - dx, y - dy, 0.4))


def test_seidel_is_even_in_x():
    ab = jj.Seidel(w020=1.1, w040=-2.0, w131=0.7, w222=1.3, w220=-0.4, w311=0.2, w111=0.9)
    x, y = np.linspace(-0.9, 0.9, 7), np.linspace(0.8, -0.8, 7)
    np.testing.assert_array_equal(jj.wavefront(ab, x, y, 0.6), jj.wavefront(ab, -x, y, 0.6))
    assert ab.x_symmetric


@pytest.mark.parametrize("j", range(1, 16))
def test_noll_to_nm_standard_table(j):
    assert jj.noll_to_nm(j) == NOLL_TABLE[j]


def test_noll_to_nm_beyond_table():
    # n = 5, 6 rows, checked against counting: j in n(n+1)/2 + 1 .. (n+1)(n+2)/2.
    assert jj.noll_to_nm(16) == (5, 1)
    assert jj.noll_to_nm(21) == (5, -5)
    assert jj.noll_to_nm(22) == (6, 0)
    with pytest.raises(ValueError, match="noll index must be an integer >= 1, got 0"):
        jj.noll_to_nm(0)


def _zernike_reference(j, x, y):
    """Noll-normalised Z_j from the explicit formulas (theta measured from +y)."""
    rho = np.hypot(x, y)
    theta = np.arctan2(x, y)
    n, m = NOLL_TABLE[j]
    radial = sum((-1) ** k * math.factorial(n - k)
                 / (math.factorial(k) * math.factorial((n + abs(m)) // 2 - k)
                    * math.factorial((n - abs(m)) // 2 - k)) * rho ** (n - 2 * k)
                 for k in range((n - abs(m)) // 2 + 1))
    if m == 0:
        return math.sqrt(n + 1) * radial
    trig = np.cos(m * theta) if m > 0 else np.sin(-m * theta)
    return math.sqrt(2 * (n + 1)) * radial * trig


@pytest.mark.parametrize("j", range(1, 16))
def test_zernike_polynomials_match_explicit_formula(j):
    rng = np.random.default_rng(j)
    rho, theta = np.sqrt(rng.uniform(0, 1, 40)), rng.uniform(0, 2 * np.pi, 40)
    x, y = rho * np.sin(theta), rho * np.cos(theta)
    got = jj.wavefront(jj.Zernike([1.0], noll=(j,)), x, y)
    np.testing.assert_allclose(got, _zernike_reference(j, x, y), atol=1e-13)


def test_zernike_wavefront_is_a_sum_and_x_symmetry_flag():
    coefficients = [0.1, -0.2, 0.3, 0.5, -0.4]
    ab = jj.Zernike(coefficients, noll=(1, 2, 3, 4, 5))
    x, y = 0.3, -0.6
    expected = sum(c * _zernike_reference(j, np.array(x), np.array(y))
                   for c, j in zip(coefficients, (1, 2, 3, 4, 5), strict=True))
    assert float(jj.wavefront(ab, x, y, 0.5)) == pytest.approx(float(expected), rel=1e-13)
    assert not ab.x_symmetric
    assert jj.Zernike([1.0, 1.0], noll=(4, 11)).x_symmetric


def test_zernike_bad_input():
    with pytest.raises(ValueError, match="noll must list one index per coefficient"):
        jj.Zernike([1.0, 2.0], noll=(4,))
    with pytest.raises(ValueError, match="noll index must be an integer >= 1, got 0"):
        jj.Zernike([1.0], noll=(0,))


def test_zernike_seidel_like_terms_sum_to_the_wavefront_less_piston_and_tilt():
    """``Zernike.seidel_like_terms`` (the split by which ``jmse`` measures how much terms
    cancel) loses nothing but piston and tilt: the terms of a design of Noll 1-22 sum to its
    wavefront less its best-fit tilt (Zernike polynomials are orthogonal to tilt, so that is
    ``Z2`` and ``Z3``), up to a constant; and defocus with spherical aberration becomes
    Seidel's two terms, ``rho^2`` and ``rho^4``, each its own."""
    rng = np.random.default_rng(7)
    ab = jj.Zernike(rng.normal(size=22))
    x, y = (jnp.asarray(v) for v in rng.uniform(-0.7, 0.7, size=(2, 50)))
    origin = jnp.zeros(1)

    def total(x, y):
        return sum(term(x, y) for term in ab.seidel_like_terms())

    flat = ab.without_tilt()
    np.testing.assert_allclose(total(x, y) - total(origin, origin),
                               flat(x, y, 0.0) - flat(origin, origin, 0.0), rtol=0, atol=1e-12)
    assert ab.beyond_seidel_degree()  # Noll 12-22 hold radial orders 5 and 6
    w020, w040 = 3.0, -2.0  # W = 3 rho^2 - 2 rho^4 = a4 Z4 + a11 Z11 + piston
    a11 = w040 / (6 * math.sqrt(5))
    ab = jj.Zernike([(w020 + w040) / (2 * math.sqrt(3)), a11], noll=(4, 11))
    rho = jnp.linspace(0.0, 1.0, 7)
    got = [term(0.6 * rho, 0.8 * rho) for term in ab.seidel_like_terms()]
    np.testing.assert_allclose(got[0], w020 * rho**2, atol=1e-14)
    np.testing.assert_allclose(got[1], w040 * rho**4, atol=1e-14)
    assert not ab.beyond_seidel_degree()
    assert not bool(jj.Zernike([1.0, 0.0], noll=(4, 22)).beyond_seidel_degree())
    # Rounding left by a fit of a Seidel wavefront does not count; a part of 1e-5 does.
    assert not bool(jj.Zernike([1.0, 1e-13], noll=(4, 22)).beyond_seidel_degree())
    assert bool(jj.Zernike([1.0, 1e-5], noll=(4, 22)).beyond_seidel_degree())
    assert not jj.Seidel(w040=1.0).beyond_seidel_degree()
    # Angular order 3 or more (trefoil Z9/Z10, quadrafoil Z14/Z15) is not a Seidel shape
    # either: such designs were up to 5.4e-3 off in the tiers (session 79).
    for j in (9, 10, 14, 15):
        assert bool(jj.Zernike([0.5, 1e-5], noll=(4, j)).beyond_seidel_degree())
        assert not bool(jj.Zernike([0.5, 1e-13], noll=(4, j)).beyond_seidel_degree())
    assert not bool(jj.Zernike([0.5, 1.0, 1.0], noll=(4, 12, 13)).beyond_seidel_degree())


def test_zernike_coefficients_of_programs_whose_angle_runs_from_x_give_the_same_merit():
    """docs/conventions.md: with the polar angle from +x, the same Noll coefficients describe
    this package's wavefront reflected across x = y; the square band and isotropic spectra
    map onto themselves under that reflection, so the JMSE is the same, and the OTF's axes
    swap."""
    noll = (4, 5, 6, 7, 8, 9, 10, 11)
    ab = jj.Zernike([0.3, 0.2, -0.15, 0.25, -0.1, 0.12, -0.08, 0.2], noll=noll)
    grid = jj.PolarGrid(6, 40)
    theirs = np.asarray(jj.wavefront(ab, grid.y, grid.x))  # W(y, x): theta from +x
    reflected = jj.zernike_fit(theirs, grid, noll=noll)
    # Their cosine and sine partners trade places (Z5 <-> Z6 with a sign, Z7 <-> Z8, ...).
    np.testing.assert_allclose(reflected.coefficients,
                               [0.3, 0.2, 0.15, -0.1, 0.25, 0.08, -0.12, 0.2], atol=1e-12)
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
    assert float(jj.jmse(reflected, 0.0, 0.3, signal, noise, preset="fast")) == pytest.approx(
        float(jj.jmse(ab, 0.0, 0.3, signal, noise, preset="fast")), rel=1e-12)
    assert complex(jj.otf(reflected, 0.05, 0.1)) == pytest.approx(
        complex(jj.otf(ab, 0.1, 0.05)), abs=1e-13)
