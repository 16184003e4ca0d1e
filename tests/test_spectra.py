"""Signal and noise spectra, the Wiener filter and its error spectral density (SPEC §2)."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import oracles
import pytest
from compiled import fast_value_and_grad_in_everything
from scipy import integrate

import jmse_jax as jj

RNG = np.random.default_rng(7)
NU_X, NU_Y = RNG.uniform(-1.5, 1.5, (2, 40))
R = np.hypot(NU_X, NU_Y)


@pytest.mark.parametrize(("variance", "mu"), [(1.0, 5.0), (2.5, 0.3), (0.01, 40.0)])
def test_markov_integrates_to_variance(variance, mu):
    signal = jj.MarkovSignal(variance, mu)
    radial = lambda r: 2 * math.pi * r * float(signal.radial(jnp.asarray(r)))  # noqa: E731
    total, _ = integrate.quad(radial, 0, np.inf, epsabs=0, epsrel=1e-12, limit=400)
    assert total == pytest.approx(variance, rel=1e-9)


def test_markov_formula():
    signal = jj.MarkovSignal(2.0, 3.0)
    np.testing.assert_allclose(signal(jnp.asarray(NU_X), jnp.asarray(NU_Y)),
                               oracles.markov_psd(R, 2.0, 3.0), rtol=1e-14)
    assert float(signal.radial(0.0)) == pytest.approx(2.0 * 2 * math.pi * 9.0, rel=1e-15)


def test_power_law_formula():
    signal = jj.PowerLawSignal(amplitude=1e-3, exponent=2.5, knee=0.02)
    np.testing.assert_allclose(signal(jnp.asarray(NU_X), jnp.asarray(NU_Y)),
                               oracles.power_law_psd(R, 1e-3, 2.5, 0.02), rtol=1e-14)
    assert float(signal(0.0, 0.0)) == pytest.approx(1e-3 / 0.02**2.5, rel=1e-14)


def test_white_spectra_are_constant():
    np.testing.assert_array_equal(jj.WhiteSignal(3.0)(jnp.asarray(NU_X), jnp.asarray(NU_Y)), 3.0)
    noise = jj.WhiteNoise(1e-3)(jnp.asarray(NU_X), jnp.asarray(NU_Y))
    assert noise.shape == NU_X.shape
    np.testing.assert_array_equal(noise, 1e-3)


def test_signal_gradient_at_zero_frequency_is_finite():
    for signal in (jj.MarkovSignal(1.0, 5.0), jj.PowerLawSignal(1e-3, 2.0, 0.01)):
        g = jax.grad(lambda x, s=signal: s(x, jnp.asarray(0.0)))(jnp.asarray(0.0))
        assert float(g) == 0.0  # S_x is even and smooth in r² at the origin


def test_error_spectral_density_and_wiener_filter_formulas():
    h = RNG.normal(size=20) + 1j * RNG.normal(size=20)
    s_x, s_n = RNG.uniform(0.1, 10, 20), RNG.uniform(1e-4, 1e-1, 20)
    s_e = jj.error_spectral_density(jnp.asarray(h), jnp.asarray(s_x), jnp.asarray(s_n))
    np.testing.assert_allclose(s_e, oracles.error_spectral_density(h, s_x, s_n), rtol=1e-14)
    g = jj.wiener_filter(jnp.asarray(h), jnp.asarray(s_x), jnp.asarray(s_n))
    np.testing.assert_allclose(g, np.conj(h) * s_x / (np.abs(h) ** 2 * s_x + s_n), rtol=1e-14)
    # The Wiener identity: S_e = S_x (1 - G H) for the optimal filter.
    np.testing.assert_allclose(s_e, np.real(s_x * (1 - np.asarray(g) * h)), rtol=1e-12)


def test_limits_at_zero_and_unit_otf():
    s_x, s_n = 4.0, 1e-3
    zero, one = jnp.asarray(0.0 + 0.0j), jnp.asarray(1.0 + 0.0j)
    assert float(jj.error_spectral_density(zero, s_x, s_n)) == pytest.approx(s_x, rel=1e-15)
    assert complex(jj.wiener_filter(zero, s_x, s_n)) == 0
    assert float(jj.error_spectral_density(one, s_x, s_n)) == pytest.approx(
        s_x * s_n / (s_x + s_n), rel=1e-15)
    assert complex(jj.wiener_filter(one, s_x, s_n)) == pytest.approx(s_x / (s_x + s_n),
                                                                     rel=1e-15)


def test_error_density_gradient_at_otf_zero():
    def s_e(re, im):
        return jj.error_spectral_density(jax.lax.complex(re, im), 4.0, 1e-3)

    g = jax.grad(s_e, argnums=(0, 1))(jnp.asarray(0.0), jnp.asarray(0.0))
    assert [float(v) for v in g] == [0.0, 0.0]  # S_e is even in H: a smooth maximum at 0
    g = jax.grad(s_e)(jnp.asarray(0.01), jnp.asarray(0.0))
    expected = -4.0 * 1e-3 * 4.0 * 2 * 0.01 / (1e-4 * 4.0 + 1e-3) ** 2
    assert float(g) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: jj.WhiteNoise(0.0), r"noise variance must be in \(0\.0, inf\], got 0\.0"),
        (lambda: jj.WhiteNoise(-1.0), r"noise variance must be in \(0\.0, inf\], got -1\.0"),
        (lambda: jj.WhiteNoise(float("nan")), r"noise variance must be finite"),
        (lambda: jj.WhiteNoise(1e-310), r"noise variance must be at least float64's smallest "
                                        r"normal number \(2\.23e-308.*got 1e-310"),
        (lambda: jj.MarkovSignal(variance=0.0), r"variance must be in \(0\.0, inf\], got 0\.0"),
        (lambda: jj.MarkovSignal(1.0, correlation_length=-1.0),
         r"correlation_length must be in \(0\.0, inf\], got -1\.0"),
        (lambda: jj.PowerLawSignal(knee=0.0), r"knee must be in \(0\.0, inf\], got 0\.0"),
        (lambda: jj.PowerLawSignal(amplitude=-1.0), r"amplitude must be in \(0\.0, inf\]"),
        (lambda: jj.PowerLawSignal(exponent=0.0), r"exponent must be in \(0\.0, inf\]"),
        (lambda: jj.WhiteSignal(0.0), r"level must be in \(0\.0, inf\], got 0\.0"),
        # S_x(0) = 2 pi variance mu^2 and amplitude knee^-exponent past float64: S_e would
        # be inf / inf (NaN) at the low frequencies.
        (lambda: jj.MarkovSignal(1.0, 1e155), r"S_x\(0\) = inf overflows float64"),
        (lambda: jj.PowerLawSignal(1.0, 400.0, 0.01), r"S_x\(0\) = inf overflows float64"),
        (lambda: jj.PowerLawSignal(1.0, 2.0, 1e-200), r"S_x\(0\) = inf overflows float64"),
    ],
)
def test_bad_spectrum_parameters_raise(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_overflowing_spectrum_under_jit_is_inf_not_nan():
    """A traced parameter whose S_x(0) overflows cannot raise: valid() is False, so the
    merit is +inf with a zero gradient (it was NaN), and a sane value is unchanged. (The
    spectra are built inside the shared program of tests/compiled.py, so they are traced.)"""
    ab = jj.Seidel(w020=1.0)
    p = dict(field=0.0, u=0.2, noise=1e-3, variance=1.0, mu=1e155)
    value, (grad_ab, grad_p) = fast_value_and_grad_in_everything(ab, p)
    assert float(value) == float("inf")
    assert float(grad_p["mu"]) == 0.0 and float(grad_ab.w020) == 0.0
    subnormal = dict(p, u=1.2, noise=1e-310, mu=5.0)
    assert float(fast_value_and_grad_in_everything(ab, subnormal)[0]) == float("inf")  # was NaN
    sane = fast_value_and_grad_in_everything(ab, dict(p, mu=5.0))[0]
    assert float(sane) == pytest.approx(
        float(jj.jmse(ab, 0.0, 0.2, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3),
                      preset="fast")), rel=1e-14)
