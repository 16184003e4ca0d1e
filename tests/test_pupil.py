"""Pupil grids, OPD sampling and the exact Zernike projection on the polar grid."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
import pytest
from oracles import seidel_wavefront

import jmse_jax as jj

SEIDEL = dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198, w311=0.3,
              w111=-0.45)


@pytest.mark.parametrize(("rings", "arms"), [(1, 1), (3, 10), (6, 40)])
def test_polar_grid_weights_sum_to_pi(rings, arms):
    grid = jj.PolarGrid(rings, arms)
    assert grid.x.shape == grid.weights.shape == (rings, arms)
    assert np.sum(grid.weights) == pytest.approx(math.pi, rel=1e-14)
    assert np.all(np.hypot(grid.x, grid.y) < 1.0)


@pytest.mark.parametrize("rings", [1, 3, 6])
def test_polar_grid_integrates_even_radial_powers_exactly(rings):
    grid = jj.PolarGrid(rings, 8)
    rho2 = grid.x**2 + grid.y**2
    for k in range(2 * rings):  # Gauss in rho²: exact to degree 2 L - 1
        assert np.sum(grid.weights * rho2**k) == pytest.approx(math.pi / (k + 1), rel=1e-13)
    k = 2 * rings  # one degree too many: no longer exact
    assert abs(np.sum(grid.weights * rho2**k) - math.pi / (k + 1)) > 1e-8


def test_polar_grid_arm_zero_on_plus_y():
    grid = jj.PolarGrid(2, 4)
    np.testing.assert_allclose(grid.x[:, 0], 0.0, atol=1e-15)
    assert np.all(grid.y[:, 0] > 0)
    assert np.all(grid.x[:, 1] > 0)  # theta = pi/2 from +y is +x


def test_square_grid_weights_approximate_pi_to_first_order():
    errors = []
    for B in (32, 64, 128, 256):
        grid = jj.SquareGrid(B)
        assert grid.x.shape == (B, B)
        np.testing.assert_allclose(grid.x[0, :2], [-1 + 1 / B, -1 + 3 / B], rtol=1e-14)
        errors.append(abs(np.sum(grid.weights) - math.pi) / math.pi)
    assert errors[0] < 3e-2 and errors[-1] < 5e-3
    assert errors[-1] < errors[0] / 3  # staircase edge: no better than first order, but converging


@pytest.mark.parametrize("grid", [jj.PolarGrid(3, 10), jj.PolarGrid(6, 40)], ids=repr)
def test_zernike_orthonormal_under_polar_quadrature(grid):
    basis = np.stack([np.asarray(jj.wavefront(jj.Zernike([1.0], noll=(j,)), grid.x, grid.y))
                      for j in range(1, 16)])
    gram = np.einsum("iab,jab,ab->ij", basis, basis, grid.weights) / math.pi
    np.testing.assert_allclose(gram, np.eye(15), atol=1e-13)


def test_sample_opd_equals_wavefront_on_grid():
    grid = jj.PolarGrid(6, 40)
    ab = jj.Seidel(**SEIDEL)
    np.testing.assert_allclose(jj.sample_opd(ab, grid, 0.8),
                               seidel_wavefront(SEIDEL, grid.x, grid.y, 0.8), rtol=1e-13,
                               atol=1e-13)


def test_zernike_fit_analytic_coefficients():
    # w020 rho² + w040 rho⁴: c1 = w020/2 + w040/3, c4 = (w020 + w040)/(2 sqrt 3),
    # c11 = w040/(6 sqrt 5), everything else 0.
    w020, w040 = -1.3, 2.1
    grid = jj.PolarGrid(3, 10)
    fit = jj.zernike_fit(jj.sample_opd(jj.Seidel(w020=w020, w040=w040), grid), grid)
    expected = np.zeros(15)
    expected[0] = w020 / 2 + w040 / 3
    expected[3] = (w020 + w040) / (2 * math.sqrt(3))
    expected[10] = w040 / (6 * math.sqrt(5))
    assert fit.noll == tuple(range(1, 16))
    np.testing.assert_allclose(fit.coefficients, expected, atol=1e-14)
    # Integer samples fit in JAX's default float (float64 here), not float32: piston 1.
    ones = jj.zernike_fit(np.ones(np.shape(grid.x), int), grid).coefficients
    assert ones.dtype == jnp.float64
    np.testing.assert_allclose(ones, np.eye(15)[0], atol=1e-14)


@pytest.mark.parametrize("grid", [jj.PolarGrid(3, 10), jj.PolarGrid(6, 40)], ids=repr)
def test_zernike_fit_recovers_seidel_wavefront_exactly(grid):
    field = 0.95
    fit = jj.zernike_fit(jj.sample_opd(jj.Seidel(**SEIDEL), grid, field), grid)
    rng = np.random.default_rng(3)
    rho, theta = np.sqrt(rng.uniform(0, 1, 200)), rng.uniform(0, 2 * np.pi, 200)
    x, y = rho * np.sin(theta), rho * np.cos(theta)
    np.testing.assert_allclose(jj.wavefront(fit, jnp.asarray(x), jnp.asarray(y)),
                               seidel_wavefront(SEIDEL, x, y, field), atol=1e-12)


def test_zernike_fit_on_square_grid_is_approximate():
    grid = jj.SquareGrid(64)
    fit = jj.zernike_fit(jj.sample_opd(jj.Seidel(w040=1.0), grid), grid)
    # Staircase edge: right to about 10 %, not to rounding as on the polar grid.
    c11 = float(fit.coefficients[10])
    assert c11 == pytest.approx(1 / (6 * math.sqrt(5)), rel=0.15)
    assert abs(c11 - 1 / (6 * math.sqrt(5))) > 1e-4


def test_zernike_fit_rejects_underresolving_grid():
    grid = jj.PolarGrid(2, 10)
    with pytest.raises(ValueError, match="rings=2, arms=10 cannot resolve Zernike terms up to n=4"):
        jj.zernike_fit(jj.sample_opd(jj.Seidel(), grid), grid)
    with pytest.raises(ValueError, match="samples must have the grid's shape"):
        jj.zernike_fit(np.zeros(3), jj.PolarGrid(3, 10))


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: jj.PolarGrid(0, 4), "rings must be an integer >= 1, got 0"),
        (lambda: jj.PolarGrid(3, 0), "arms must be an integer >= 1, got 0"),
        (lambda: jj.SquareGrid(0), "B must be an integer >= 1, got 0"),
        (lambda: jj.SquareGrid(-3), "B must be an integer >= 1, got -3"),
    ],
)
def test_grid_sizes_below_one_raise(call, match):
    with pytest.raises(ValueError, match=match):
        call()
