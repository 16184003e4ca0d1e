"""Imaging simulation and Wiener restoration: the merit must predict the measured MSE.

Statistical checks use fixed seeds and a 3-standard-error tolerance (a false alarm rate of
0.27 % per check for a correct implementation, decided once because the seeds are fixed).
Sizes are small so the whole file runs in well under a minute on two cores; the full study
is ``benchmarks/monte_carlo.py``.
"""

from __future__ import annotations

import math
import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import jmse_jax as jj
from jmse_jax._simulate import _otf_on_grid

jax.config.update("jax_enable_x64", True)

FIG1 = jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
MARKOV = jj.MarkovSignal(1.0, 5.0)
NOISE = jj.WhiteNoise(1e-3)


def _discrete_prediction(aberrations, field, u, signal, noise, n):
    """``Delta nu**2 sum S_e`` on the n x n DFT grid, from ``otf`` on the full grid."""
    nu = np.fft.fftfreq(n, d=1.0 / (2.0 * u))  # pitch 1/(2u) lambda N -> nu = 2 u k / n
    nu_x, nu_y = np.meshgrid(nu, nu, indexing="xy")
    h = _otf_padded(aberrations, nu_x, nu_y, field, (48, 48))
    s_x = np.asarray(signal(jnp.asarray(nu_x), jnp.asarray(nu_y)))
    s_n = np.asarray(noise(jnp.asarray(nu_x), jnp.asarray(nu_y)))
    s_e = s_x * s_n / (np.abs(h) ** 2 * s_x + s_n)
    return (2.0 * u / n) ** 2 * s_e.sum()


def _otf_padded(aberrations, nu_x, nu_y, field, nodes, bucket=2048):
    """``otf`` at every node, called on a flat vector padded to ``bucket`` (one compile)."""
    count = nu_x.size
    flat_x, flat_y = np.zeros(max(bucket, count)), np.zeros(max(bucket, count))
    flat_x[:count], flat_y[:count] = nu_x.ravel(), nu_y.ravel()
    h = jj.otf(aberrations, jnp.asarray(flat_x), jnp.asarray(flat_y), field, nodes=nodes)
    return np.asarray(h)[:count].reshape(nu_x.shape)


def _within(result, prediction, n_se=3.0):
    ratio = float(result.mse / prediction)
    rel_se = float(result.standard_error / prediction)
    return ratio, rel_se, abs(ratio - 1.0) <= n_se * rel_se


# --------------------------------------------------------------------------------------
# Deterministic pieces
# --------------------------------------------------------------------------------------


def test_sensor_frequencies_tile_the_band():
    u, n = 0.2, 9
    nu_x, nu_y = jj.sensor_frequencies((n, n), u)
    step = 2 * u / n
    np.testing.assert_allclose(np.sort(np.asarray(nu_x[0])), step * np.arange(-4, 5), atol=1e-15)
    np.testing.assert_allclose(np.asarray(nu_y[:, 0]), np.asarray(nu_x[0]), atol=1e-15)
    # Cells of side 2u/n centred on the nodes cover exactly [-u, u].
    assert float(jnp.max(nu_x)) + step / 2 == pytest.approx(u, abs=1e-15)


@pytest.mark.parametrize("aberrations, shape", [
    (jj.Zernike([0.0, 0.0, 0.0, 0.4, 0.3, -0.5, 0.7, 0.2], noll=(1, 2, 3, 4, 5, 6, 7, 8)),
     (8, 6)),
    (FIG1, (7, 9)),
])
def test_otf_on_grid_symmetry_bookkeeping_matches_direct_evaluation(aberrations, shape):
    # The grid helper evaluates half (x-asymmetric Zernike, odd Noll terms) or a quarter
    # (Seidel) of the grid and rebuilds the rest by symmetry; compare with every node.
    u = 0.45
    d_y, d_x = 2 * u / shape[0], 2 * u / shape[1]
    k_y = np.fft.fftfreq(shape[0], 1.0 / shape[0])
    k_x = np.fft.fftfreq(shape[1], 1.0 / shape[1])
    nu_x, nu_y = np.meshgrid(d_x * k_x, d_y * k_y, indexing="xy")
    direct = _otf_padded(aberrations, nu_x, nu_y, 0.7, (48, 48), bucket=1024)
    grid = _otf_on_grid(aberrations, jnp.asarray(0.7), (d_y, d_x), shape, (48, 48),
                        jnp.float64)
    np.testing.assert_allclose(np.asarray(grid), np.asarray(direct), rtol=0, atol=1e-13)


@pytest.mark.parametrize("axis", [0, 1])
def test_capture_of_a_cosine_is_scaled_by_the_hopkins_defocus_otf(axis):
    # SPEC §5 (Hopkins 1955): w020 = 0.5 gives H(0.2) = 0.43481896, H(0.4) = 0.12569082.
    # u = 0.5 -> pitch 1 (lambda N), n = 25 -> nu = 0.04 k: 0.2 and 0.4 are grid frequencies.
    n, u = 25, 0.5
    pos = np.arange(n, dtype=np.float64)
    for nu, expected in ((0.2, 0.43481896), (0.4, 0.12569082)):
        wave = np.cos(2 * np.pi * nu * pos)
        scene = wave[:, None] * np.ones(n) if axis == 0 else np.ones(n)[:, None] * wave
        capture = jj.simulate_capture(scene, jj.Seidel(w020=0.5), 0.0, u, jj.WhiteNoise(1e-30),
                                      jax.random.key(0))
        gain = float(np.sum(np.asarray(capture) * scene) / np.sum(scene * scene))
        assert gain == pytest.approx(expected, abs=2e-8)


def test_capture_blur_is_the_diffraction_limited_otf_on_a_random_scene():
    # Independent route: NumPy FFT with the closed-form aberration-free OTF (SPEC §5).
    n, u = 21, 0.6
    scene = np.asarray(jj.random_scene(MARKOV, (n, n), u, jax.random.key(3)))
    nu = np.fft.fftfreq(n, d=1.0 / (2 * u))
    r = np.minimum(np.hypot(nu[None, :], nu[:, None]), 1.0)
    h = (2 / np.pi) * (np.arccos(r) - r * np.sqrt(1 - r * r))
    expected = np.real(np.fft.ifft2(h * np.fft.fft2(scene)))
    capture = jj.simulate_capture(scene, jj.Seidel(), 0.0, u, jj.WhiteNoise(1e-30),
                                  jax.random.key(1))
    np.testing.assert_allclose(np.asarray(capture), expected, rtol=0, atol=1e-12)


def test_restore_inverts_the_blur_when_noise_is_negligible():
    # G H = |H|^2 S_x / (|H|^2 S_x + S_n) -> 1 as S_n -> 0 wherever H != 0 (w020 = 0.5 has
    # no OTF zero inside |nu| < 0.25 sqrt 2), so restore(blur(scene)) = scene.
    n, u = 33, 0.25
    ab, tiny = jj.Seidel(w020=0.5), jj.WhiteNoise(1e-20)
    scene = jj.random_scene(MARKOV, (n, n), u, jax.random.key(7))
    capture = jj.simulate_capture(scene, ab, 0.0, u, tiny, jax.random.key(8))
    assert float(jnp.max(jnp.abs(capture - scene))) > 1e-2  # the blur did something
    restored = jj.restore(np.asarray(capture), ab, 0.0, u, MARKOV, tiny)
    assert isinstance(restored, jax.Array)
    np.testing.assert_allclose(np.asarray(restored), np.asarray(scene), rtol=0, atol=1e-8)
    # NumPy and JAX inputs give the same result.
    np.testing.assert_array_equal(np.asarray(jj.restore(capture, ab, 0.0, u, MARKOV, tiny)),
                                  np.asarray(restored))


def test_restore_float32_follows_the_input_dtype():
    n, u = 17, 0.3
    scene = jj.random_scene(MARKOV, (n, n), u, jax.random.key(0))
    ab = jj.Seidel(w020=-1.0)
    restored64 = jj.restore(scene, ab, 0.0, u, MARKOV, NOISE)
    restored32 = jj.restore(np.asarray(scene, np.float32), ab, 0.0, u, MARKOV, NOISE)
    assert restored32.dtype == jnp.float32
    scale = float(jnp.max(jnp.abs(restored64)))
    np.testing.assert_allclose(np.asarray(restored32), np.asarray(restored64), rtol=0,
                               atol=1e-4 * scale)


# --------------------------------------------------------------------------------------
# Monte-Carlo agreement
# --------------------------------------------------------------------------------------


def test_public_pipeline_mse_matches_the_discrete_prediction():
    # Only public functions (random_scene -> simulate_capture -> restore), vmapped over
    # keys; the prediction is computed here from otf on the full grid.
    n, u, field, trials = 33, 0.2, 0.95, 48

    def one_trial(key):
        k_scene, k_noise = jax.random.split(key)
        scene = jj.random_scene(MARKOV, (n, n), u, k_scene)
        capture = jj.simulate_capture(scene, FIG1, field, u, NOISE, k_noise)
        restored = jj.restore(capture, FIG1, field, u, MARKOV, NOISE)
        return jnp.mean((restored - scene) ** 2)

    per_trial = np.asarray(jax.jit(jax.vmap(one_trial))(jax.random.split(jax.random.key(11),
                                                                          trials)))
    predicted = _discrete_prediction(FIG1, field, u, MARKOV, NOISE, n)
    ratio = per_trial.mean() / predicted
    rel_se = per_trial.std(ddof=1) / math.sqrt(trials) / predicted
    assert rel_se < 0.02
    assert abs(ratio - 1) <= 3 * rel_se, (ratio, rel_se)
    # The library's estimator predicts the same expectation.
    res = jj.monte_carlo_mse(FIG1, field, u, MARKOV, NOISE, jax.random.key(0), size=n, trials=2,
                             jmse_preset=None)
    assert float(res.discrete_prediction) == pytest.approx(predicted, rel=1e-12)


def test_monte_carlo_fig1_matches_discrete_and_continuous_predictions():
    n = 65
    res = jj.monte_carlo_mse(FIG1, 0.95, 0.2, MARKOV, NOISE, jax.random.key(2024), size=n,
                             trials=64, batch=16, jmse_preset="fast")
    # 2 pi JMSE with the SPEC §5 reference JMSE = 2.6539432e-3.
    assert float(res.continuous_prediction) == pytest.approx(2 * math.pi * 2.6539432e-3,
                                                             rel=1e-4)
    # Midpoint rule on 65 x 65 cells is within 1e-3 of the integral for this smooth S_e.
    assert float(res.discrete_prediction / res.continuous_prediction) == pytest.approx(1, abs=1e-3)
    ratio, rel_se, ok = _within(res, res.discrete_prediction)
    assert rel_se <= 0.01
    assert ok, (ratio, rel_se)
    _, _, ok_continuous = _within(res, res.continuous_prediction)
    assert ok_continuous
    # The sample standard error agrees with the Gaussian-mode theory (the std of a std
    # estimate from 64 trials is about 9 %, so 30 % is more than 3 sigma).
    assert float(res.standard_error / res.predicted_standard_error) == pytest.approx(1, abs=0.3)


@pytest.mark.parametrize("case", ["defocus_m6", "powerlaw_fig1"])
def test_monte_carlo_far_from_focus_and_power_law(case):
    if case == "defocus_m6":
        ab, field, signal = jj.Seidel(w020=-6.0), 0.0, MARKOV
    else:
        ab, field, signal = FIG1, 0.95, jj.PowerLawSignal(1e-3, 2.0, 0.01)
    res = jj.monte_carlo_mse(ab, field, 0.2, signal, NOISE, jax.random.key(5), size=65,
                             trials=32, batch=16, jmse_preset=None)
    ratio, rel_se, ok = _within(res, res.discrete_prediction)
    assert rel_se <= 0.01
    assert ok, (ratio, rel_se)


def test_aliasing_breaks_the_prediction_and_the_alias_model_explains_it():
    # u = 0.4 with a 3x finer grid covers the optics' support (3u = 1.2 >= 1). Diffraction-
    # limited optics pass a lot of signal between u and the cutoff, which aliases.
    kwargs = dict(size=33, trials=32, batch=16, oversample=3, jmse_preset=None)
    ab, u = jj.Seidel(w020=-0.5), 0.4
    ideal = jj.monte_carlo_mse(ab, 0.0, u, MARKOV, NOISE, jax.random.key(1), sampling="ideal",
                               **kwargs)
    assert float(ideal.model_prediction / ideal.discrete_prediction) == pytest.approx(1, abs=1e-12)
    assert _within(ideal, ideal.discrete_prediction)[2]
    for sampling in ("point", "pixel"):
        broken = jj.monte_carlo_mse(ab, 0.0, u, MARKOV, NOISE, jax.random.key(1),
                                    sampling=sampling, **kwargs)
        ratio, rel_se, ok = _within(broken, broken.discrete_prediction)
        assert not ok and ratio > 1.05, (sampling, ratio, rel_se)
        assert _within(broken, broken.model_prediction)[2], sampling


# --------------------------------------------------------------------------------------
# Input validation
# --------------------------------------------------------------------------------------


class _ZeroNoise(jj.AbstractNoise):
    def __call__(self, nu_x, nu_y):
        return jnp.zeros_like(nu_x * nu_y)


@pytest.mark.parametrize("image", [np.zeros(8), np.zeros((2, 8, 8))])
def test_restore_rejects_non_2d_images(image):
    with pytest.raises(ValueError, match=r"image must be a 2-D array.*shape"):
        jj.restore(image, FIG1, 0.95, 0.2, MARKOV, NOISE)


@pytest.mark.parametrize("pixel", [float("nan"), float("inf")])
def test_non_finite_pixels_are_rejected(pixel):
    image = np.zeros((8, 8))
    image[2, 5] = pixel
    with pytest.raises(ValueError, match=r"image must be finite, got .* at pixel \(y=2, x=5\)"):
        jj.restore(image, FIG1, 0.95, 0.2, MARKOV, NOISE)
    with pytest.raises(ValueError, match=r"scene must be finite"):
        jj.simulate_capture(image, FIG1, 0.95, 0.2, NOISE, jax.random.key(0))


@pytest.mark.parametrize("u", [0.0, -0.1, 2.0, float("nan")])
def test_restore_rejects_u_outside_range(u):
    with pytest.raises(ValueError, match=r"u must be .*\(0\.0, 1\.5\]"):
        jj.restore(np.zeros((8, 8)), FIG1, 0.95, u, MARKOV, NOISE)


def test_non_positive_noise_is_rejected():
    with pytest.raises(ValueError, match="noise PSD must be > 0"):
        jj.restore(np.zeros((8, 8)), FIG1, 0.95, 0.2, MARKOV, _ZeroNoise())
    with pytest.raises(ValueError, match="noise PSD must be > 0"):
        jj.simulate_capture(np.zeros((8, 8)), FIG1, 0.95, 0.2, _ZeroNoise(), jax.random.key(0))
    with pytest.raises(ValueError, match="noise variance"):
        jj.WhiteNoise(0.0)


@pytest.mark.parametrize("kwargs, message", [
    (dict(size=64), "size must be an odd integer"),
    (dict(size=1), "size must be an integer >= 3"),
    (dict(trials=1), "trials must be an integer >= 2"),
    (dict(oversample=2), "oversample must be an odd integer"),
    (dict(sampling="point"), "oversample must be an odd integer >= 3"),
    (dict(sampling="box"), "sampling must be one of"),
    (dict(jmse_preset="slow"), "jmse_preset must be one of 'fast', 'default', 'high', got "
                               "'slow'"),
])
def test_monte_carlo_rejects_bad_settings(kwargs, message):
    with pytest.raises(ValueError, match=message):
        jj.monte_carlo_mse(FIG1, 0.95, 0.2, MARKOV, NOISE, jax.random.key(0), **kwargs)


def test_predicted_pixel_mse_names_its_preset_argument():
    with pytest.raises(ValueError, match="jmse_preset must be one of 'fast', 'default', 'high'"):
        jj.predicted_pixel_mse(FIG1, 0.95, 0.2, MARKOV, NOISE, jmse_preset="slow")


def test_random_scene_rejects_bad_shape():
    with pytest.raises(ValueError, match="shape must be a pair"):
        jj.random_scene(MARKOV, (8,), 0.2, jax.random.key(0))
    with pytest.raises(ValueError, match=r"shape\[1\] \(n_x\) must be an integer >= 1"):
        jj.random_scene(MARKOV, (8, 0), 0.2, jax.random.key(0))


@pytest.mark.parametrize("size", [None, 33])
def test_predicted_pixel_mse_under_jit_is_inf_for_bad_noise(size):
    """Traced values cannot raise: a noise variance <= 0 gives +inf (not NaN, nor a negative
    MSE), on the DFT grid as through jmse."""
    merit = jax.jit(lambda v: jj.predicted_pixel_mse(FIG1, 0.95, 0.2, MARKOV, jj.WhiteNoise(v),
                                                     size=size, jmse_preset="fast"))
    assert np.isposinf(float(merit(-1e-3))) and np.isposinf(float(merit(0.0)))
    expected = jj.predicted_pixel_mse(FIG1, 0.95, 0.2, MARKOV, NOISE, size=size,
                                      jmse_preset="fast")
    assert float(merit(float(NOISE.variance))) == pytest.approx(float(expected), rel=1e-12)


def _runtime_error_message(call):
    """The message of the runtime error ``call()`` raises (equinox's error under jax.jit
    arrives as an XLA runtime error whose text carries it)."""
    with pytest.raises(Exception) as info:  # noqa: PT011 - the class depends on the jit
        jax.block_until_ready(call())
    return str(info.value)


def test_images_under_jit_raise_for_bad_traced_input():
    """Traced values cannot raise a ValueError at trace time, and an image has no +inf
    convention: restore, simulate_capture and random_scene raise a runtime error naming
    the argument instead of returning NaN pixels (before: NaN or silently wrong images)."""
    image = np.zeros((9, 9))
    image[4, 4] = 1.0
    restore = jax.jit(lambda v, u, field: jj.restore(image, FIG1, field, u, MARKOV,
                                                     jj.WhiteNoise(v)))
    good = restore(1e-3, 0.2, 0.95)
    np.testing.assert_allclose(good, jj.restore(image, FIG1, 0.95, 0.2, MARKOV, NOISE),
                               rtol=1e-12, atol=1e-15)
    for args, message in [((-1e-3, 0.2, 0.95), "restore: noise parameters must be finite"),
                          ((1e-3, float("nan"), 0.95), r"restore: u must be in \(0, 1.5\]"),
                          ((1e-3, 2.0, 0.95), r"restore: u must be in \(0, 1.5\]"),
                          ((1e-3, 0.2, 1.5), r"restore: field must be in \[0, 1\]")]:
        assert re.search(message, _runtime_error_message(lambda args=args: restore(*args))), args

    capture = jax.jit(jax.vmap(lambda field: jj.simulate_capture(
        image, FIG1, field, 0.2, NOISE, jax.random.key(0))))
    assert capture(jnp.array([0.1, 0.5])).shape == (2, 9, 9)
    assert "simulate_capture: field must be in [0, 1]" in _runtime_error_message(
        lambda: capture(jnp.array([0.1, 1.5])))
    pixels = jax.jit(lambda x: jj.restore(x, FIG1, 0.95, 0.2, MARKOV, NOISE))
    assert "restore: image must be finite" in _runtime_error_message(
        lambda: pixels(jnp.asarray(image).at[1, 1].set(jnp.nan)))

    scene = jax.jit(lambda mu: jj.random_scene(jj.MarkovSignal(1.0, mu), (9, 9), 0.2,
                                               jax.random.key(0)))
    np.testing.assert_allclose(scene(5.0), jj.random_scene(MARKOV, (9, 9), 0.2,
                                                           jax.random.key(0)), rtol=1e-12)
    assert "random_scene: signal parameters must be finite and > 0" in (
        _runtime_error_message(lambda: scene(-5.0)))


def test_gradient_of_restore_under_jit_is_finite_and_guarded():
    """The runtime checks do not disturb derivatives: d(sum restored)/d(noise variance)
    under jit equals a central difference, and a bad variance still raises."""
    image = np.zeros((9, 9))
    image[4, 4] = 1.0
    image[2, 6] = -0.5

    def total(v):
        return jnp.sum(jj.restore(image, FIG1, 0.95, 0.2, MARKOV, jj.WhiteNoise(v)) ** 2)

    grad = jax.jit(jax.grad(total))
    step = 1e-7
    fd = (total(1e-3 + step) - total(1e-3 - step)) / (2 * step)
    assert float(grad(1e-3)) == pytest.approx(float(fd), rel=1e-6)
    assert "noise parameters must be finite" in _runtime_error_message(lambda: grad(-1.0))
