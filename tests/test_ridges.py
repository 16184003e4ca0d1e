"""Closed-form peaks of ``S_e`` along the polar grid's rays (``jmse_jax._ridges``).

Oracles: SciPy's adaptive quadrature of the same 1-D integrand (an analytic OTF along a
ray), its finite differences, and, for whole designs near the axis, the polar grid with
four times the fine radial nodes and no closed forms.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import integrate

import jmse_jax as jj
from jmse_jax import _merit
from jmse_jax._quadrature import FINE_SUB_PANEL, _radial_rule, fine_sub_panels
from jmse_jax._ridges import ridge_peaks

N = 300  # the fine radial count of the default's first grid
ROOTS = (0.2113, 0.5671)  # zeros of Re H along the ray, between fine nodes


def _otf(t, offset, stretch):
    """An OTF along the ray with two near-zeros: ``Re H`` vanishes at ``ROOTS`` (shifted by
    ``offset``), ``Im H`` is a small smooth ``offset``-independent term."""
    r0, r1 = (r + offset for r in ROOTS)
    re = stretch * (t - r0) * (t - r1) * (1.3 - t)
    im = 1e-4 * (1.0 + t) if stretch > 0 else 0.0 * t
    return re, im


def _spectra(t):
    s_x = 1.0 / (1.0 + (3.0 * t) ** 2) ** 1.5
    return s_x


def _ray(offset, noise, stretch=4.0, peaks=True):
    """``sum bare t S_e`` on one ray of the fine rule of ``N`` nodes (two triangles alike),
    plus the closed-form peaks when ``peaks``."""
    t, starts, edges = fine_sub_panels(N)
    _, w_t = _radial_rule(N, FINE_SUB_PANEL)
    bare = jnp.asarray(t * w_t)
    tj = jnp.asarray(t)
    re, im = _otf(tj, offset, stretch)
    h = jnp.stack([re, im])[None, :, None, :].repeat(2, axis=2)  # (rows, re/im, tri, N)
    s_x = _spectra(tj)[None, None, :]
    s_n = jnp.asarray(noise)
    denominator = (re * re + im * im) * s_x + s_n
    s_e = s_x * s_n / denominator
    total = 2.0 * jnp.sum(s_e * bare)
    if peaks:
        total = total + ridge_peaks(h, jnp.broadcast_to(denominator, (1, 2, N)), s_x, s_n,
                                    t, bare, jnp.ones(1), starts, edges)
    return total


def _exact(offset, noise, stretch=4.0):
    """SciPy's integral of ``2 t S_e`` over [0, 1], with the near-zeros as breakpoints."""
    def f(t):
        re, im = _otf(t, offset, stretch)
        s_x = _spectra(t)
        return 2.0 * t * s_x * noise / ((re * re + im * im) * s_x + noise)

    value, _ = integrate.quad(f, 0.0, 1.0, points=[r + offset for r in ROOTS], limit=2000,
                              epsabs=0.0, epsrel=1e-13)
    return value


@pytest.mark.parametrize(("noise", "rtol"), [(1e-6, 1e-5), (1e-8, 2e-6), (1e-10, 1e-6)])
def test_peaks_match_the_adaptive_integral(noise, rtol):
    # The model's error is of second order in the peak's width c (about 1e-3 to 1e-4 of
    # the ray here; the smallest |H|^2, 1e-8, keeps c from shrinking below 1e-4).
    exact = _exact(0.0, noise)
    plain = float(_ray(0.0, noise, peaks=False))
    corrected = float(_ray(0.0, noise))
    assert abs(plain / exact - 1.0) > 1e3 * rtol  # the fine rule alone misses the peaks
    assert corrected == pytest.approx(exact, rel=rtol)


def test_resolved_peaks_get_no_correction():
    # At a noise of 1e-2 the peaks span many fine nodes: nothing is narrow.
    noise = 1e-2
    assert float(_ray(0.0, noise)) == float(_ray(0.0, noise, peaks=False))
    assert float(_ray(0.0, noise)) == pytest.approx(_exact(0.0, noise), rel=1e-12)


def test_derivative_follows_the_moving_zeros():
    # d/d offset of the corrected sum (through H at the fine nodes) against central
    # differences of the adaptive integral.
    # The model's second-order error moves with the peak against the nodes, so the
    # derivative is good to a few 1e-4 where the value is good to a few 1e-6 (the fine
    # rule alone: 50 and 270 times the derivative, of either sign).
    step = 1e-5
    for noise in (1e-6, 1e-8):
        derivative = float(jax.grad(lambda o, noise=noise: _ray(o, noise))(0.0))
        plain = float(jax.grad(lambda o, noise=noise: _ray(o, noise, peaks=False))(0.0))
        reference = (_exact(step, noise) - _exact(-step, noise)) / (2.0 * step)
        assert derivative == pytest.approx(reference, rel=1e-3)
        assert abs(plain / reference - 1.0) > 10.0


def test_adjoint_equals_autodiff_of_the_value():
    # The adjoint form (the fine rule's derivatives plus the peaks' at their four nodes)
    # against jax.grad of the plain correction.
    t, starts, edges = fine_sub_panels(N)
    rng = np.random.default_rng(0)
    re, im = _otf(jnp.asarray(t), 0.0, 4.0)
    h = jnp.stack([re, im])[None, :, None, :].repeat(2, axis=2)
    s_x = _spectra(jnp.asarray(t))[None, None, :]
    s_n = jnp.asarray(1e-8)
    bare = jnp.asarray(rng.uniform(0.5, 1.0, N) * 1e-3)

    def correction(h):
        d = h[:, 0] ** 2 + h[:, 1] ** 2
        return ridge_peaks(h, d * s_x + s_n, s_x, s_n, t, bare, jnp.ones(1), starts, edges)

    g = [jnp.asarray(rng.normal(size=(1, 2, N))) for _ in range(2)]
    d = h[:, 0] ** 2 + h[:, 1] ** 2
    value, g_re, g_im = ridge_peaks(h, d * s_x + s_n, s_x, s_n, t, bare, jnp.ones(1),
                                    starts, edges, adjoint=g)
    grad = jax.grad(correction)(h)
    assert float(value) == pytest.approx(float(correction(h)), rel=1e-14)
    assert float(value) != 0.0
    np.testing.assert_allclose(g_re - g[0], grad[:, 0], rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(g_im - g[1], grad[:, 1], rtol=1e-12, atol=1e-18)


# A design near the axis: its OTF nearly vanishes on rings (benchmarks/low_noise.py).
NEAR_AXIS = (jj.Seidel(w020=6.0, w222=0.5), 0.1, 0.2)
TIER1 = jj.DEFAULT_TIERS[1][2]


def _grid_value_and_grad(grid, ab, field, u, noise, ridges=True):
    options = {**jj.jmse_options("default", **grid), "tiers": None, "radial": False,
               "peaks": ridges}

    def merit(ab, field):
        return _merit._merit_value(options, jnp.float64, ab, field, jnp.float64(u),
                                   jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(noise))

    return jax.jit(jax.value_and_grad(merit, argnums=(0, 1)))(ab, jnp.float64(field))


def test_minimum_search_converges_before_its_differentiated_steps():
    """Each minimum's model is expanded at the minimum of ``|H|^2`` on the cubics through
    its four nodes, found by Newton's method from the node; the derivatives are exact only
    from a converged minimum (two differentiated steps give the implicit ones). Oracle: the
    real roots of the derivative of ``|p|^2`` (a quintic) by NumPy, and central differences
    of the root in the data. The minima are random, with strong quadratic and cubic terms
    against the linear one, where Newton's first steps are slow: three steps, the search
    until 2026-12-02, left 1123 of these 4000 more than 1e-10 of a node spacing off and
    their derivatives up to 1e-2 off (a random Zernike design's gradient 2.2e-4 off the
    derivative of its value, ``benchmarks/gradient_fuzz.py``)."""
    from jmse_jax import _ridges

    rng = np.random.default_rng(0)
    n, count = 40, 4000
    t = np.linspace(0.2, 0.6, n)
    spacing = t[1] - t[0]
    j = rng.integers(3, n - 4, count)
    centre = t[j] + rng.uniform(-0.5, 0.5, count) * spacing
    a, b, c, f, g = (rng.normal(size=count) * 1e-3 for _ in range(5))
    a *= 10 ** rng.uniform(-2, 1, count)
    e = rng.normal(size=count) * 1e-6
    d = (t - centre[:, None]) / spacing
    re = a[:, None] * d + b[:, None] * d**2 + c[:, None] * d**3
    im = e[:, None] + f[:, None] * d + g[:, None] * d**2
    square = re**2 + im**2
    rows = np.arange(count)
    j = np.array([np.argmin(square[k, j[k] - 1:j[k] + 2]) + j[k] - 1 for k in rows])
    left = square[rows, j - 1] < square[rows, j + 1]
    stencil = np.clip(j - 1 - left, 0, n - 4)[:, None] + np.arange(4)
    y_re, y_im = re[rows[:, None], stencil], im[rows[:, None], stencil]
    spectra = np.full((count, 4), 1e-10), np.full((count, 4), 1e-8)

    def fit(rows, y_re):  # the minima of the rows (a tuple) with the given Re H
        rows = np.asarray(rows)
        return _ridges._fit(y_re, y_im[rows], *(x[rows] for x in spectra), j[rows],
                            np.ones(len(rows), bool), stencil[rows], jnp.asarray(t))

    (t0, *_), live = jax.jit(fit, static_argnums=0)(tuple(range(count)), y_re)
    t0, live = np.asarray(t0), np.asarray(live)

    def stationary(y_re, y_im, k):
        """The real roots of (|p|^2)' in the minimum's interval, p the cubics through the
        stencil (in the local variable s = (t - t_j) / spacing)."""
        s = (t[stencil[k]] - t[j[k]]) / spacing
        p_re, p_im = np.polyfit(s, y_re, 3), np.polyfit(s, y_im, 3)
        slope = np.polyder(np.polyadd(np.polymul(p_re, p_re), np.polymul(p_im, p_im)))
        roots = np.roots(slope)
        roots = roots[np.abs(roots.imag) < 1e-9].real
        return t[j[k]] + spacing * roots[np.abs(roots) <= 1.0]

    inside = live & (t0 > t[j - 1] + 1e-9 * spacing) & (t0 < t[j + 1] - 1e-9 * spacing)
    assert inside.sum() > 3000
    errors = [np.min(np.abs(stationary(y_re[k], y_im[k], k) - t0[k])) / spacing
              for k in np.flatnonzero(inside)]
    assert max(errors) < 1e-10

    # The derivative of the minimum in the data: the implicit one.
    pick = tuple(np.flatnonzero(inside)[:: max(1, inside.sum() // 12)][:12])
    jacobian = jax.jit(jax.jacfwd(lambda y: fit(pick, y)[0][0]))(y_re[list(pick)])
    def root(k, i, h):  # the stationary point nearest t0 with y_re[k, i] moved by h
        y = y_re[k].copy()
        y[i] += h
        found = stationary(y, y_im[k], k)
        return found[np.argmin(np.abs(found - t0[k]))]

    for row, k in enumerate(pick):
        for i in range(4):
            h = 1e-6 * np.max(np.abs(y_re[k]))
            fd = (root(k, i, h) - root(k, i, -h)) / (2 * h)
            assert float(jacobian[row, row, i]) == pytest.approx(fd, rel=1e-5)


def _near_axis_with_and_without_peaks(grid, se_nodes):
    """``NEAR_AXIS`` at noise 1e-4 on ``grid``: (value, gradient in ``w020``, ``w222`` and
    the field) with the closed-form peaks, without them, and without them on the fine rule
    ``se_nodes`` (the same OTF nodes, so only the fine stage differs)."""
    ab, field, u = NEAR_AXIS

    def vector(ridges, grid=grid):
        value, (g_ab, g_field) = _grid_value_and_grad(grid, ab, field, u, 1e-4, ridges=ridges)
        return float(value), np.array([g_ab.w020, g_ab.w222, g_field])

    return vector(True), vector(False), vector(False, {**grid, "se_nodes": se_nodes})


def test_near_axis_design_against_a_finer_grid():
    # 19 200 fine radial nodes without closed forms converge (9600 leave 1e-5 in the
    # gradient).
    (value, grad), (plain_value, plain_grad), (ref_value, ref_grad) = (
        _near_axis_with_and_without_peaks(TIER1, (19200, 160)))
    scale = np.max(np.abs(ref_grad))
    assert value == pytest.approx(ref_value, rel=1e-10)
    assert np.max(np.abs(grad - ref_grad)) < 2e-6 * scale
    # Without the closed forms: 6e-6 in the value, 5e-2 in the gradient.
    assert abs(plain_value / ref_value - 1.0) > 1e-6
    assert np.max(np.abs(plain_grad - ref_grad)) > 1e-2 * scale


def test_peaks_option_reaches_the_grid_the_default_routes_to():
    """``peaks=True`` keeps the default's tiers and gives the grid the design routes to
    its closed-form peaks (here tier 1's own grid, which has none by default); a
    non-boolean is refused."""
    ab, field, u = jj.Seidel(w020=4.0, w222=0.5), 0.1, 0.3
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-4)
    route = _merit._route(ab, field, u, signal, noise, peaks=True)
    assert route["tier"] == 1 and route["path"] == "grid"
    grid = jj.DEFAULT_TIERS[route["tier"]][2]
    assert not grid.get("peaks", False)
    value = float(jj.jmse(ab, field, u, signal, noise, peaks=True))
    plain = float(jj.jmse(ab, field, u, signal, noise))
    oracle, _ = _grid_value_and_grad(grid, ab, field, u, 1e-4)
    assert value == pytest.approx(float(oracle), rel=1e-13)
    assert abs(plain / value - 1.0) > 1e-6
    assert jj.jmse_options("high")["peaks"] and not jj.jmse_options()["peaks"]
    with pytest.raises(ValueError, match="peaks must be True or False"):
        jj.jmse(ab, field, u, signal, noise, peaks="yes")


def test_default_strong_tiers_integrate_the_peaks():
    """The default's tiers 2 and 3 (and the steep tier, tier 3's grid) have the closed-form
    peaks in their own grids (since session 84): without them this near-axis design's value
    is right to 2e-6 but its gradient 8.8e-3 off (at u = 0.3 its sensitivities 4.5e-2,
    ``benchmarks/gradient_accuracy.py``), the peaks of ``S_e`` moving across the fine nodes.
    Oracle: the same grid's fine rule with four times the radial nodes and no closed forms."""
    ab, field, u = NEAR_AXIS
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-4)
    route = _merit._route(ab, field, u, signal, noise)
    assert route["tier"] == 2 and route["path"] == "grid"
    assert all(jj.DEFAULT_TIERS[i][2]["peaks"] for i in (2, 3, 4))
    (value, grad), (_, plain_grad), (ref_value, ref_grad) = (
        _near_axis_with_and_without_peaks(jj.DEFAULT_TIERS[2][2], (19200, 128)))
    assert float(jj.jmse(ab, field, u, signal, noise)) == pytest.approx(value, rel=1e-13)
    scale = np.max(np.abs(ref_grad))
    assert value == pytest.approx(ref_value, rel=1e-9)  # measured 4.3e-11
    assert np.max(np.abs(grad - ref_grad)) < 1e-5 * scale  # measured 5.3e-7
    # Without the closed forms: 2.0e-6 in the value, 8.8e-3 in the gradient.
    assert np.max(np.abs(plain_grad - ref_grad)) > 5e-3 * scale


@pytest.mark.slow
def test_peaks_under_vmap_match_each_design_alone(vectorised_vmap):
    """A batch (``vmap``, vectorised as on a GPU) gives each design what it gets alone, with
    the peaks' closed forms run where one of its designs needs them
    (``batch_skipping_cond``; on CPU one design at a time)."""
    ab, field, u = NEAR_AXIS
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-4)
    mild = jj.Seidel(w020=0.4, w222=0.2)
    batch = jax.tree_util.tree_map(lambda a, b: jnp.stack([a, b]), ab, mild)
    fields = jnp.array([field, 0.3])

    def merit(ab, field):
        return jj.jmse(ab, field, u, signal, noise, preset="fast", peaks=True)

    values, grads = jax.jit(jax.vmap(jax.value_and_grad(merit, argnums=(0, 1))))(batch, fields)
    plain = jax.jit(jax.vmap(merit))(batch, fields)
    for i, (a, f) in enumerate(((ab, field), (mild, 0.3))):
        value, (g_ab, g_field) = jax.jit(jax.value_and_grad(merit, argnums=(0, 1)))(a, f)
        assert float(values[i]) == pytest.approx(float(value), rel=1e-14)
        assert float(plain[i]) == pytest.approx(float(value), rel=1e-14)
        got = np.array([grads[0].w020[i], grads[0].w222[i], grads[1][i]])
        want = np.array([g_ab.w020, g_ab.w222, g_field])
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.max(np.abs(want)))
    # The near-axis design takes its peaks in the batch, too (against the plain rule).
    without = jj.jmse(ab, field, u, signal, noise, preset="fast")
    assert abs(float(plain[0]) / float(without) - 1.0) > 1e-8


@pytest.mark.slow
def test_second_derivatives_with_the_peaks():
    """The Hessian (forward over reverse) against central differences of the gradient: the
    Newton minimum's last two steps are differentiated, whose second derivatives are the
    implicit ones (with one step the Hessian's first entry came out -7.9e-4 against 1.48e-3)."""
    ab, field, u = NEAR_AXIS
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-4)

    def merit(x):
        return jj.jmse(jj.Seidel(w020=x[0], w222=x[1]), field, u, signal, noise,
                       preset="fast", peaks=True)

    x = jnp.array([ab.w020, ab.w222])
    hessian = np.asarray(jax.jit(jax.hessian(merit))(x))
    grad = jax.jit(jax.grad(merit))
    h = 1e-5
    columns = [(grad(x + h * e) - grad(x - h * e)) / (2.0 * h) for e in jnp.eye(2)]
    differences = np.stack([np.asarray(c) for c in columns], axis=1)
    np.testing.assert_allclose(hessian, differences, rtol=1e-5,
                               atol=1e-6 * np.max(np.abs(hessian)))
    np.testing.assert_allclose(hessian, hessian.T, rtol=1e-12)


def test_reverse_over_a_derivative_says_what_to_use():
    """Reverse mode over a derivative of ``jmse`` with the peaks (``jax.grad`` of
    ``jax.grad``) fails inside JAX; ``jmse``'s error says to take second derivatives
    forward over reverse (``jax.hessian``) instead, also behind a ``jit`` between the two
    derivatives, where JAX's own error came before."""

    def merit(u):
        return jj.jmse(jj.Seidel(w020=1.0, w131=0.5), 0.7, u, jj.MarkovSignal(1.0, 5.0),
                       jj.WhiteNoise(1e-3), preset="fast", peaks=True)

    for form in (jax.grad(jax.grad(merit)),
                 # A jit between the two derivatives hides the outer one from jmse, and
                 # JAX's own error came (refuse_reverse_over).
                 jax.grad(jax.jit(jax.grad(merit))),
                 jax.jacrev(jax.jit(jax.jacrev(merit)))):
        with pytest.raises(ValueError, match=r"reverse mode through one of its own "
                                             r"derivatives.*jax\.hessian\(f\)"):
            jax.make_jaxpr(form)(0.3)


def test_reverse_over_a_derivative_of_a_one_ray_plan_with_peaks_says_what_to_use():
    """Reverse mode over a derivative of a one-ray plan with the peaks failed outside
    ``jmse``, in the outer derivative's backward pass, with JAX's ``AssertionError``, and
    the process's memory then grew until it was killed: on the axis without ``jit`` (where
    the design takes its one-ray plan alone) and for a Zernike set of radial terms alone
    (the program then holds the one-ray plans alone). Without ``jit`` ``jmse`` recognises
    such calls by their tracers (``reverse_over_derivative``) and refuses them before
    tracing anything; the traced program carries ``refuse_reverse_over``, which the outer
    derivative meets before its backward pass. Both raise the error that says what to
    use."""
    from jmse_jax._numerics import reverse_over_derivative

    seen = []

    def probe(u):
        seen.append(reverse_over_derivative(u))
        return u * u

    jax.grad(probe)(0.3)
    jax.hessian(probe)(0.3)
    jax.jvp(jax.grad(probe), (0.3,), (1.0,))
    jax.grad(jax.grad(probe))(0.3)
    jax.jit(jax.jacrev(jax.jacrev(probe)))(0.3)
    jax.grad(lambda u: jax.jvp(probe, (u,), (1.0,))[1])(0.3)
    assert seen == [False, False, False, True, True, True]

    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)

    def on_the_axis(u):
        return jj.jmse(jj.Seidel(w020=1.0, w131=0.5), 0.0, u, signal, noise, preset="fast",
                       peaks=True)

    def radial_terms(c):
        return jj.jmse(jj.Zernike(c, noll=(4, 11)), 0.3, 0.2, signal, noise)

    with pytest.raises(ValueError, match=r"reverse mode through one of its own "
                                         r"derivatives.*jax\.hessian\(f\)") as raised:
        jax.grad(jax.grad(on_the_axis))(0.3)
    assert "one-ray plan with the closed-form peaks" in str(raised.value.__cause__)
    # The program of radial terms alone carries refuse_reverse_over, which the outer
    # derivative meets before its backward pass, with or without a jit between the two.
    first = jax.grad(lambda c: jax.grad(radial_terms)(c)[0])
    between = jax.grad(jax.jit(lambda c: jax.grad(radial_terms)(c)[0]))
    for call in (jax.jit(first), between):
        with pytest.raises(ValueError, match=r"reverse mode through one of its own "
                                             r"derivatives.*jax\.hessian\(f\)"):
            call(jnp.asarray([0.8, 0.3]))


def test_refuse_reverse_over_lets_every_other_derivative_through():
    """``refuse_reverse_over`` changes no value and no derivative of first order, nor
    forward over reverse, forward over forward or a third order with forward outside, and
    refuses reverse mode over a derivative in each form, a ``jit`` between the two
    included (analytic derivatives of ``x^3 y``)."""
    from jmse_jax._numerics import refuse_reverse_over

    def f(x, y):
        x, y, label = refuse_reverse_over((x, y, "kept"), "no reverse over reverse")
        assert label == "kept"
        return x ** 3 * y

    x, y = 1.5, 0.7
    assert float(jax.jit(f)(x, y)) == x ** 3 * y
    assert float(jax.grad(f)(x, y)) == pytest.approx(3 * x ** 2 * y, rel=1e-15)
    assert float(jax.jvp(f, (x, y), (1.0, 0.0))[1]) == pytest.approx(3 * x ** 2 * y,
                                                                       rel=1e-15)
    hessian = jax.jit(jax.hessian(f, argnums=(0, 1)))(x, y)
    np.testing.assert_allclose(np.array(hessian, dtype=float),
                               [[6 * x * y, 3 * x ** 2], [3 * x ** 2, 0.0]], rtol=1e-15)
    forward = jax.jacfwd(jax.jacfwd(f))(x, y)
    assert float(forward) == pytest.approx(6 * x * y, rel=1e-15)
    third = jax.jacfwd(jax.jacfwd(jax.jit(jax.grad(f))))(x, y)
    assert float(third) == pytest.approx(6 * y, rel=1e-15)
    # Operands without a tangent keep a symbolic zero, so that the derivative rules behind
    # take gradients only in those that carry one (a first form instantiated zeros, and
    # the tier switch's rule then formed the gradient in every operand).
    from jax.custom_derivatives import SymbolicZero

    seen = []

    @jax.custom_jvp
    def product(x, y):
        return x * y

    def product_jvp(primals, tangents):
        seen.append(tuple(isinstance(t, SymbolicZero) for t in tangents))
        (x, y), (dx, dy) = primals, tangents
        dx, dy = (jnp.zeros_like(p) if isinstance(t, SymbolicZero) else t
                  for p, t in ((x, dx), (y, dy)))
        return x * y, dx * y + x * dy

    product.defjvp(product_jvp, symbolic_zeros=True)

    def g(x, y):
        return product(*refuse_reverse_over((x, y), "no reverse over reverse"))

    assert float(jax.grad(g)(x, y)) == y
    assert float(jax.jvp(lambda x: g(x, y), (x,), (1.0,))[1]) == y
    assert float(jax.jit(lambda y: jax.jvp(lambda y: g(x, y), (y,), (1.0,))[1])(y)) == x
    assert seen == [(False, True), (False, True), (True, False)]
    grad_of = jax.grad(f)
    for form in (jax.grad(grad_of), jax.grad(jax.jit(grad_of)), jax.jit(jax.grad(grad_of)),
                 jax.grad(lambda x, y: jax.jvp(f, (x, y), (1.0, 0.0))[1]),
                 jax.grad(jax.jit(jax.hessian(f)))):
        with pytest.raises(ValueError, match="no reverse over reverse"):
            form(x, y)
