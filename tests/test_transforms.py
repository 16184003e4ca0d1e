"""JAX transforms: jit == eager, vmap == loop, grad == central finite differences (float64)."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from compiled import fast_value_and_grad_in_everything, jmse_fn
from conftest import FIG1_COEFFICIENTS
from scipy import optimize

import jmse_jax as jj

KEYS = ("w020", "w040", "w131", "w222", "w220")
FIG1_PARAMS = np.array([*(FIG1_COEFFICIENTS[k] for k in KEYS), 0.95, 0.2, 1.0, 5.0, 1e-3])
PARAM_NAMES = [*KEYS, "field", "u", "signal variance", "correlation length", "noise variance"]
# A second point: larger defocus, other field/u/spectra (same compiled function).
OTHER_PARAMS = np.array([4.509, 2.635, -4.158, 4.824, 2.024, 0.48, 0.24, 2.0, 3.0, 3.26e-4])


_FAST = jmse_fn(preset="fast")


def _point(theta):
    """``(ab, p)`` of ``fast_value_and_grad_in_everything`` at the parameter vector
    ``theta``, as Python floats (the types tests/test_merit.py and tests/test_radial.py
    pass: one compiled program serves the three modules)."""
    t = [float(x) for x in theta]
    return (jj.Seidel(**dict(zip(KEYS, t[:5], strict=True))),
            dict(field=t[5], u=t[6], variance=t[7], mu=t[8], noise=t[9]))


def _jmse_theta(theta):
    return fast_value_and_grad_in_everything(*_point(theta))[0]


def _jmse_grad(theta):
    """The gradient in ``theta``'s order (``PARAM_NAMES``)."""
    _, (d_ab, d_p) = fast_value_and_grad_in_everything(*_point(theta))
    return np.array([*(float(getattr(d_ab, k)) for k in KEYS),
                     *(float(d_p[k]) for k in ("field", "u", "variance", "mu", "noise"))])


def _central_difference(fn, theta, steps):
    """Central differences with one Richardson step (error O(h⁴)): the strongly aberrated
    cases vary on a scale of ~1e-2 waves, where a plain O(h²) difference is not 1e-6 exact."""

    def plain(i, h):
        up, down = theta.copy(), theta.copy()
        up[i] += h
        down[i] -= h
        return (float(fn(jnp.asarray(up))) - float(fn(jnp.asarray(down)))) / (2 * h)

    return np.array([(4 * plain(i, h / 2) - plain(i, h)) / 3 for i, h in enumerate(steps)])


@pytest.mark.parametrize("theta", [FIG1_PARAMS, OTHER_PARAMS], ids=["fig1", "other"])
def test_jmse_gradient_matches_finite_differences(theta):
    grad = _jmse_grad(theta)
    assert np.all(np.isfinite(grad))
    steps = 1e-5 * np.maximum(np.abs(theta), 1e-2)  # relative steps; |theta| floor for zeros
    fd = _central_difference(_jmse_theta, theta, steps)
    for name, g, f in zip(PARAM_NAMES, grad, fd, strict=True):
        assert g == pytest.approx(f, rel=1e-6, abs=1e-12), name
    # Every input matters at these points.
    assert np.all(np.abs(grad) > 0)


# -------------------------------------------------------------------------------------
# OTF gradients at singular points
# -------------------------------------------------------------------------------------

OTF_NODES = (48, 48)


@functools.partial(jax.jit, static_argnames=("part",))
def _otf_part(coefficients, nu, field, part):
    """Re or Im of the OTF of Seidel(coefficients over all 7 terms) at nu = (nu_x, nu_y)."""
    ab = jj.Seidel(*coefficients)
    h = jj.otf(ab, nu[0], nu[1], field, nodes=OTF_NODES)
    return jnp.real(h) if part == "re" else jnp.imag(h)


_otf_grads = jax.jit(jax.grad(_otf_part, argnums=(0, 1)), static_argnames=("part",))

ABERRATED = np.array([-1.0, 0.7, 1.5, 1.2, 0.4, 0.2, -0.3])  # all seven Seidel terms


def _grads(coefficients, nu, field=0.95):
    out = {}
    for part in ("re", "im"):
        g_c, g_nu = _otf_grads(jnp.asarray(coefficients), jnp.asarray(nu), field, part=part)
        out[part] = (np.asarray(g_c), np.asarray(g_nu))
    return out


def _fd_check(coefficients, nu, field=0.95, h=1e-6, rtol=1e-6):
    grads = _grads(coefficients, nu, field)
    for part in ("re", "im"):
        g_c, g_nu = grads[part]
        for i in range(len(coefficients)):
            up, down = np.array(coefficients), np.array(coefficients)
            up[i] += h
            down[i] -= h
            fd = (float(_otf_part(jnp.asarray(up), jnp.asarray(nu), field, part=part))
                  - float(_otf_part(jnp.asarray(down), jnp.asarray(nu), field, part=part))
                  ) / (2 * h)
            assert g_c[i] == pytest.approx(fd, rel=rtol, abs=1e-8), (part, "coefficient", i)
        for i in range(2):
            up, down = np.array(nu), np.array(nu)
            up[i] += h
            down[i] -= h
            fd = (float(_otf_part(jnp.asarray(coefficients), jnp.asarray(up), field, part=part))
                  - float(_otf_part(jnp.asarray(coefficients), jnp.asarray(down), field,
                                    part=part))) / (2 * h)
            assert g_nu[i] == pytest.approx(fd, rel=rtol, abs=1e-8), (part, "nu", i)
    return grads


def test_otf_gradient_at_zero_frequency():
    field = 0.95
    grads = _grads(ABERRATED, [0.0, 0.0], field)
    for g in (*grads["re"], grads["im"][0]):
        assert np.all(np.isfinite(g))
        # H(0) = 1 for every pupil; Re H has a cone there (0 chosen), and Im H(0) = 0.
        np.testing.assert_array_equal(g, 0.0)
    # Im H = 4 pi nu . <grad W> + O(|nu|^3): the mean gradient over the disc of the y-odd
    # terms, <d(rho^2 y)/dy> = <x^2> + 3 <y^2> = 1, so 4 pi h (w131 + w311 h^2 + w111).
    w131, w311, w111 = ABERRATED[2], ABERRATED[5], ABERRATED[6]
    slope = 4 * np.pi * field * (w131 + w311 * field**2 + w111)
    np.testing.assert_allclose(grads["im"][1], [0.0, slope], rtol=1e-13, atol=1e-13)
    # ... which central differences confirm. The lens's rim adds a |nu| nu term to Im H
    # (the discs' non-overlapping crescents, of width ~|nu|), so the quotient's error is
    # O(h); one Richardson step for that leaves O(h^2).
    def quotient(h):
        up, down = (_otf_part(jnp.asarray(ABERRATED), jnp.asarray([0.0, v]), field, part="im")
                    for v in (h, -h))
        return (float(up) - float(down)) / (2 * h)

    assert quotient(1e-4) != pytest.approx(slope, rel=1e-4)  # the O(h) term is there
    assert 2 * quotient(5e-5) - quotient(1e-4) == pytest.approx(slope, rel=1e-5)


@pytest.mark.parametrize("nu", [[0.3, -0.2], [0.0, 0.999], [0.706, 0.706]])
def test_otf_gradient_matches_finite_differences(nu):
    grads = _fd_check(ABERRATED, nu)
    assert all(np.all(np.isfinite(g)) for part in grads.values() for g in part)


@pytest.mark.parametrize("nu", [[1.0, 0.0], [0.0, -1.0], [0.6, 0.8]])
def test_otf_gradient_exactly_at_cutoff_is_finite_and_zero(nu):
    # H ~ (1 - |nu|)^(3/2): the one-sided derivative at |nu| = 1 is 0.
    for part, (g_c, g_nu) in _grads(ABERRATED, nu).items():
        assert np.all(np.isfinite(g_c)) and np.all(np.isfinite(g_nu)), part
        np.testing.assert_allclose(g_nu, 0.0, atol=1e-12)
        np.testing.assert_allclose(g_c, 0.0, atol=1e-12)


def test_otf_gradient_at_zero_aberration():
    nu, field = [0.25, 0.3], 0.6
    grads = _fd_check(np.zeros(7), nu, field)
    g_re, _ = grads["re"]
    g_im, _ = grads["im"]
    np.testing.assert_allclose(g_re, 0.0, atol=1e-12)  # first-order phase: purely imaginary
    # Terms quadratic/quartic in the pupil give a phase difference odd over the lens: 0.
    np.testing.assert_allclose(g_im[[0, 1, 3, 4]], 0.0, atol=1e-12)
    # Tilt: dH/dw111 = i 4 pi h nu_y H0 (SPEC §2 sign).
    h0 = float(jj.diffraction_limited_otf(np.hypot(*nu)))
    assert g_im[6] == pytest.approx(4 * np.pi * field * nu[1] * h0, rel=1e-12)


def test_otf_gradient_near_an_otf_zero():
    """Defocus w020 = 1: H(nu, 0) crosses zero near nu = 0.19 (SPEC §5 gives H(0.2) < 0)."""
    coefficients = np.array([1.0, 0, 0, 0, 0, 0, 0])

    def re_h(nu_x):
        return float(_otf_part(jnp.asarray(coefficients), jnp.asarray([nu_x, 0.0]), 0.0,
                               part="re"))

    zero = optimize.brentq(re_h, 0.15, 0.2, xtol=1e-14)
    assert 0.17 < zero < 0.2
    for nu in ([zero, 0.0], [zero * 0.6, zero * 0.8]):
        grads = _fd_check(coefficients, nu, field=0.0)
        assert abs(grads["re"][1][0]) > 0.1  # a transversal zero crossing


# -------------------------------------------------------------------------------------
# jit == eager, vmap == loop
# -------------------------------------------------------------------------------------

BATCH = {k: np.array([FIG1_COEFFICIENTS[k], 0.5 * FIG1_COEFFICIENTS[k], -0.3])
         for k in KEYS}
FIELDS = np.array([0.0, 0.5, 0.95])


def _batched_seidel():
    return jj.Seidel(**{k: jnp.asarray(v) for k, v in BATCH.items()}, w311=jnp.zeros(3),
                     w111=jnp.zeros(3))


def _member(i):
    return jj.Seidel(**{k: float(v[i]) for k, v in BATCH.items()})


def test_wavefront_jit_and_vmap():
    x, y = jnp.linspace(-0.7, 0.7, 9), jnp.linspace(0.6, -0.6, 9)
    ab = _member(0)
    eager = jj.wavefront(ab, x, y, 0.95)
    np.testing.assert_allclose(jax.jit(jj.wavefront)(ab, x, y, 0.95), eager, rtol=1e-15)
    batched = jax.vmap(jj.wavefront, in_axes=(0, None, None, 0))(_batched_seidel(), x, y,
                                                                  jnp.asarray(FIELDS))
    loop = np.stack([jj.wavefront(_member(i), x, y, FIELDS[i]) for i in range(3)])
    np.testing.assert_allclose(batched, loop, rtol=1e-14, atol=1e-15)


@pytest.mark.parametrize("method", ["overlap", "nudft", "fft"])
def test_otf_jit_and_vmap(method):
    nu_x, nu_y = jnp.asarray([0.1, -0.3, 0.45]), jnp.asarray([0.2, 0.05, -0.5])

    def fn(ab, field):
        return jj.otf(ab, nu_x, nu_y, field, method, nodes=(28, 28), B=32)

    eager = fn(_member(0), 0.95)
    np.testing.assert_allclose(jax.jit(fn)(_member(0), 0.95), eager, atol=1e-13)
    batched = jax.vmap(fn)(_batched_seidel(), jnp.asarray(FIELDS))
    loop = np.stack([jax.jit(fn)(_member(i), FIELDS[i]) for i in range(3)])
    np.testing.assert_allclose(batched, loop, atol=1e-13)


def test_jmse_jit_and_vmap(fig1):
    _, _, u, signal, noise = fig1
    eager = float(jj.jmse(_member(0), 0.95, u, signal, noise, preset="fast"))
    assert float(_FAST(_member(0), 0.95, u, signal, noise)) == pytest.approx(eager, rel=1e-12)
    batched = jax.vmap(_FAST, in_axes=(0, 0, None, None, None))(
        _batched_seidel(), jnp.asarray(FIELDS), u, signal, noise)
    loop = [float(_FAST(_member(i), FIELDS[i], u, signal, noise)) for i in range(3)]
    np.testing.assert_allclose(batched, loop, rtol=1e-12)


def test_baseline_jit_and_vmap(fig1):
    _, _, u, signal, noise = fig1

    def fn(ab, field, u):
        return jj.baseline_jmse(ab, field, u, signal, noise, B=32)

    eager = float(fn(_member(0), 0.95, u))
    jitted = jax.jit(fn)
    assert float(jitted(_member(0), 0.95, u)) == pytest.approx(eager, rel=1e-12)
    us = jnp.asarray([0.2, 0.3, 0.45])
    batched = jax.vmap(jitted)(_batched_seidel(), jnp.asarray(FIELDS), us)
    loop = [float(jitted(_member(i), FIELDS[i], float(us[i]))) for i in range(3)]
    np.testing.assert_allclose(batched, loop, rtol=1e-12)
