"""Signal and noise spectra, the Wiener filter and its error spectral density (SPEC §2)."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import oracles
import problems
import pytest
from compiled import fast_value_and_grad_in_everything
from scipy import integrate

import jmse_jax as jj
from jmse_jax import _merit

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


# --------------------------------------------------------------------------------------
# Spectra that depend on the direction of nu (models of one's own)
# --------------------------------------------------------------------------------------

FIG1 = (jj.Seidel(**problems.FIG1), 0.95, 0.2)


class _SkewNoise(jj.AbstractNoise):
    """Noise of an oriented texture: even (``S(-nu) = S(nu)``, as every real field's
    spectrum), but not mirror symmetric in ``nu_x``."""

    variance: float
    tilt: float
    u: float

    def __call__(self, nu_x, nu_y):
        return self.variance * (1.0 + self.tilt * nu_x * nu_y / self.u**2)


class _SkewSignal(jj.AbstractSignal):
    """A signal spectrum tilted the same way."""

    base: jj.AbstractSignal
    tilt: float
    u: float

    def radial(self, r):
        return self.base.radial(r)

    def __call__(self, nu_x, nu_y):
        return self.base(nu_x, nu_y) * (1.0 + self.tilt * nu_x * nu_y / self.u**2)


class _StretchedNoise(jj.AbstractNoise):
    """Anisotropic but mirror symmetric; ``declared`` says so (``x_symmetric``)."""

    variance: float
    stretch: float
    u: float
    declared: bool = eqx.field(static=True)

    def __call__(self, nu_x, nu_y):
        return self.variance * (1.0 + self.stretch * (nu_x**2 - nu_y**2) / self.u**2)

    @property
    def x_symmetric(self):
        return self.declared


def _whole_band(aberrations, field, u, signal, noise, n=100):
    """``(1 / 2 pi) iint S_e`` over the whole band ``[-u, u]^2``, nothing folded: a tensor
    Gauss rule of ``n`` nodes per half axis on ``jj.otf``'s OTF with overlap nodes (64, 64)
    (float64 brute force)."""
    x, w = np.polynomial.legendre.leggauss(n)
    axis = np.concatenate([(x - 1.0) * u / 2, (x + 1.0) * u / 2])
    weights = np.concatenate([w, w]) * u / 2
    nu_x, nu_y = (jnp.asarray(a) for a in np.meshgrid(axis, axis, indexing="ij"))
    s_e = jj.error_spectral_density(jj.otf(aberrations, nu_x, nu_y, field, nodes=(64, 64)),
                                    signal(nu_x, nu_y), noise(nu_x, nu_y))
    return float(np.sum(np.asarray(s_e) * np.outer(weights, weights))) / (2.0 * math.pi)


@pytest.mark.parametrize("skewed", ["noise", "signal"])
def test_spectra_not_mirror_symmetric_are_integrated_over_both_quadrants(skewed):
    """A spectrum tilted along a diagonal: ``jmse`` folded the band onto its first quadrant
    and was 20 % off (0.003064 and 0.002055 for the two tilts against 0.002559); both tilts
    now give the whole band's integral, and the same value (the wavefront is even in x)."""
    ab, field, u = FIG1
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
    values = []
    for tilt in (0.9, -0.9):
        if skewed == "noise":
            noise = _SkewNoise(1e-3, tilt, u)
        else:
            signal = _SkewSignal(jj.MarkovSignal(1.0, 5.0), tilt, u)
        assert not (signal.x_symmetric and noise.x_symmetric)
        values.append(float(jj.jmse(ab, field, u, signal, noise)))
        assert values[-1] == pytest.approx(_whole_band(ab, field, u, signal, noise), rel=2e-6)
    assert values[0] == pytest.approx(values[1], rel=1e-12)


def test_gradient_with_a_tilted_noise_is_the_finite_difference():
    """The mirrored quadrant's spectra carry the noise's parameters: the gradient in a
    coefficient, the noise variance and the tilt is the central difference's (float64)."""
    _, field, u = FIG1
    signal = jj.MarkovSignal(1.0, 5.0)

    def merit(w020, variance, tilt):
        ab = jj.Seidel(**{**problems.FIG1, "w020": w020})
        return jj.jmse(ab, field, u, signal, _SkewNoise(variance, tilt, u))

    point = (-2.75, 1e-3, 0.6)
    grad = jax.grad(merit, argnums=(0, 1, 2))(*point)
    for i, step in enumerate((1e-5, 1e-8, 1e-5)):
        up, down = list(point), list(point)
        up[i] += step
        down[i] -= step
        difference = (float(merit(*up)) - float(merit(*down))) / (2 * step)
        assert np.isfinite(float(grad[i]))
        assert float(grad[i]) == pytest.approx(difference, rel=1e-5), i


@pytest.mark.slow
def test_tilted_noise_on_a_wavefront_not_even_in_x():
    """Both halves differ there (the OTF and the spectra; the whole band's integral with
    200 nodes per half axis is itself about 1e-6 from the converged value on this design).
    Slow: 10 s, most of it the brute force's 160 000 OTF nodes with overlap rule (64, 64)."""
    ab = jj.Zernike([0.8, -0.6, 0.5, -0.4], noll=(5, 6, 7, 8))
    assert not ab.x_symmetric
    u, signal, noise = 0.3, jj.MarkovSignal(1.0, 3.0), _SkewNoise(3e-3, 0.8, 0.3)
    whole = _whole_band(ab, 0.5, u, signal, noise, n=200)
    assert float(jj.jmse(ab, 0.5, u, signal, noise)) == pytest.approx(whole, rel=3e-6)


def test_tilted_noise_under_another_quadrature():
    """The Gauss product rule's mirrored half takes the mirrored spectra too: both tilts
    give the same value, within the rule's own error of the whole band's integral."""
    ab, field, u = FIG1
    signal = jj.MarkovSignal(1.0, 5.0)
    gauss = [float(jj.jmse(ab, field, u, signal, _SkewNoise(1e-3, tilt, u), quadrature="gauss",
                           nodes=32)) for tilt in (0.9, -0.9)]
    assert gauss[0] == pytest.approx(gauss[1], rel=1e-14)
    assert gauss[0] == pytest.approx(
        _whole_band(ab, field, u, signal, _SkewNoise(1e-3, 0.9, u)), rel=1e-2)


def test_a_mirror_symmetric_model_may_say_so():
    """Declared ``x_symmetric``, the model takes one quadrant; undeclared, both: the same
    value."""
    ab, field, u = FIG1
    signal = jj.MarkovSignal(1.0, 5.0)
    declared, undeclared = (_StretchedNoise(1e-3, 0.5, u, flag) for flag in (True, False))
    assert declared.x_symmetric and not undeclared.x_symmetric
    value = float(jj.jmse(ab, field, u, signal, declared))
    assert value == pytest.approx(float(jj.jmse(ab, field, u, signal, undeclared)), rel=1e-13)


class _BandWhiteNoise(jj.AbstractNoise):
    """``WhiteNoise(variance)`` inside the band ``[-u, u]^2``, louder beyond it along
    ``nu_x``, where the merit never looks."""

    variance: float
    u: float

    def __call__(self, nu_x, nu_y):
        beyond = jnp.maximum(nu_x * nu_x - self.u**2, 0.0) / self.u**2
        return self.variance * (1.0 + 250.0 * beyond * beyond)


def test_the_tiers_read_anisotropic_spectra_inside_the_band():
    """The default's tiers read ``S_x / S_n`` at the band's corner and on a ring; for
    isotropic spectra at ``(r, 0)``, which for ``r > u`` lies outside the band. A noise
    equal to white noise inside the band read 251 times lower there and sent this design
    (a band whose corner is near the cutoff at high SNR, ``test_tiers.py``'s
    ``CORNER_DESIGN``) to tier 2 instead of the steep tier 4, 1.2e-3 off the converged
    value (white noise's, the same in the band) where tier 4 is 6e-7 off. It now reads the
    white noise's values and takes its plan."""
    ab = jj.Seidel(w020=1.4338, w040=-0.2546, w131=-0.7411, w222=-1.5247, w220=-1.19)
    field, u, signal = 0.827, 0.703, jj.PowerLawSignal(0.88, 2.638, 0.643)
    white, band_white = jj.WhiteNoise(1.97e-6), _BandWhiteNoise(1.97e-6, u)
    assert float(band_white(jnp.sqrt(2.0) * u, 0.0)) > 250 * 1.97e-6  # (r, 0) is louder
    for probe in (_merit._edge_snr(u, signal, white),
                  _merit._ring_snr(jnp.asarray(0.5), u, signal, white)):
        assert float(probe) > 1e4
    assert float(_merit._edge_snr(u, signal, band_white)) == pytest.approx(
        float(_merit._edge_snr(u, signal, white)), rel=1e-12)
    # The ring of a strength-0.5 design reaches past u: 0.3 u / 0.5 = 0.42 < u, so the
    # ring inside the band, and at strength 0.2 past it (1.05 > u).
    for strength in (0.5, 0.2):
        assert float(_merit._ring_snr(jnp.asarray(strength), u, signal, band_white)) == \
            pytest.approx(float(_merit._ring_snr(jnp.asarray(strength), u, signal, white)),
                          rel=1e-12)
    plans = []
    for noise in (white, band_white):
        static, _ = _merit._prepare((ab, field, u, signal, noise), jj.jmse_options())
        plans.append(int(_merit._tier_of(static, ab, field, u, signal, noise)[0]))
    assert plans == [4, 4]


def test_peak_snr_looks_at_both_quadrants_of_spectra_not_mirror_symmetric():
    """The quietest point of the tilted noise lies in the second quadrant's corner, where
    ``S_n`` is a tenth of its value on the axes."""
    u = 0.3
    peak = float(_merit._peak_snr(u, jj.WhiteSignal(1.0), _SkewNoise(1e-3, 0.9, u)))
    assert peak == pytest.approx(1e4, rel=1e-12)
    assert float(_merit._peak_snr(u, jj.WhiteSignal(1.0), _SkewNoise(1e-3, -0.9, u))) == peak


class _OddNoise(jj.AbstractNoise):
    """Not even: no real field has this spectrum."""

    variance: float

    def __call__(self, nu_x, nu_y):
        return self.variance * (1.0 + 0.5 * jnp.tanh(nu_x))


class _MisdeclaredNoise(_SkewNoise):
    """Says it is mirror symmetric and is not."""

    @property
    def x_symmetric(self):
        return True


class _OddSignal(jj.AbstractSignal):
    def radial(self, r):
        return 1.0 / (1.0 + r * r)

    def __call__(self, nu_x, nu_y):
        return self.radial(jnp.hypot(nu_x, nu_y)) * (1.0 + 0.5 * jnp.tanh(nu_y))


@pytest.mark.parametrize("signal, noise, match", [
    (jj.MarkovSignal(1.0, 5.0), _OddNoise(1e-3),
     r"noise must be even, S\(-nu\) = S\(nu\).*_OddNoise gives 0\.00101949\d* at nu = "
     r"\(0\.039, 0\.213\) and 0\.00098050\d* at -nu"),
    (jj.MarkovSignal(1.0, 5.0), _MisdeclaredNoise(1e-3, 0.5, 0.3),
     r"noise must be mirror symmetric, S\(-nu_x, nu_y\) = S\(nu_x, nu_y\), as its "
     r"x_symmetric says"),
    (_OddSignal(), jj.WhiteNoise(1e-3), r"signal must be even"),
])
def test_spectra_that_break_their_symmetries_are_refused(signal, noise, match):
    """The merit integrates half the band (and, for ``x_symmetric`` models, one quadrant)
    and doubles it: a spectrum that is not even, or not the mirror image it says it is,
    would give a wrong number, so a concrete call refuses it (the baseline and sweeps
    too)."""
    ab = jj.Seidel(w020=1.0)
    with pytest.raises(ValueError, match=match):
        jj.jmse(ab, 0.5, 0.3, signal, noise)
    with pytest.raises(ValueError, match=match):
        jj.baseline_jmse(ab, 0.5, 0.3, signal, noise)
    with pytest.raises(ValueError, match=match):
        jj.sweep_jmse(jj.Seidel(w020=jnp.asarray([1.0, 2.0])), 0.5, 0.3, signal, noise,
                      progress=False)
