"""NaN-safe primitives: values and gradients at and around their singular points."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jmse_jax import _numerics as nm


def _grad(fn, x):
    return float(jax.grad(fn)(jnp.asarray(x, jnp.float64)))


def test_safe_sqrt_values_and_gradients():
    x = np.array([-2.0, -1e-300, 0.0, 1e-12, 0.25, 4.0])
    np.testing.assert_allclose(nm.safe_sqrt(jnp.asarray(x)), np.sqrt(np.maximum(x, 0.0)),
                               rtol=1e-15)
    # Singular point and beyond: finite, documented one-sided value 0.
    for point in (-1.0, 0.0):
        assert _grad(nm.safe_sqrt, point) == 0.0
    for point in (1e-12, 0.25, 4.0):
        assert _grad(nm.safe_sqrt, point) == pytest.approx(0.5 / math.sqrt(point), rel=1e-14)
    # A NaN stays NaN (it came out as a plausible 0, which made the RMS merit of a NaN
    # design its best value); in safe_norm too.
    assert math.isnan(float(nm.safe_sqrt(jnp.asarray(np.nan))))
    assert math.isnan(float(nm.safe_norm(jnp.asarray(np.nan), jnp.asarray(1.0))))


def test_safe_norm_values_and_gradients():
    x, y = 3.0, -4.0
    assert float(nm.safe_norm(jnp.asarray(x), jnp.asarray(y))) == 5.0
    gx, gy = jax.grad(nm.safe_norm, argnums=(0, 1))(jnp.asarray(x), jnp.asarray(y))
    np.testing.assert_allclose([gx, gy], [0.6, -0.8], rtol=1e-15)
    # At the origin the norm has a cone: the gradient returned is the finite value 0.
    g0 = jax.grad(nm.safe_norm, argnums=(0, 1))(jnp.asarray(0.0), jnp.asarray(0.0))
    assert [float(g) for g in g0] == [0.0, 0.0]
    assert float(nm.safe_norm(jnp.asarray(0.0), jnp.asarray(0.0))) == 0.0


def test_safe_arccos_values_and_gradients():
    x = np.array([-1.5, -1.0, -0.3, 0.0, 0.7, 1.0, 2.0])
    np.testing.assert_allclose(nm.safe_arccos(jnp.asarray(x)), np.arccos(np.clip(x, -1, 1)),
                               rtol=1e-15, atol=1e-15)
    for point in (-1.5, -1.0, 1.0, 2.0):  # singular (infinite) slope: finite 0 by design
        g = _grad(nm.safe_arccos, point)
        assert np.isfinite(g) and g == 0.0
    for point in (-0.3, 0.0, 0.7, 0.999999):
        assert _grad(nm.safe_arccos, point) == pytest.approx(
            -1 / math.sqrt((1 - point) * (1 + point)), rel=1e-12)


def test_abs2_values_and_gradients():
    def f(re, im):
        return nm.abs2(jax.lax.complex(re, im))

    assert float(f(jnp.asarray(3.0), jnp.asarray(-4.0))) == 25.0
    g = jax.grad(f, argnums=(0, 1))(jnp.asarray(3.0), jnp.asarray(-4.0))
    np.testing.assert_allclose(g, [6.0, -8.0], rtol=1e-15)
    g0 = jax.grad(f, argnums=(0, 1))(jnp.asarray(0.0), jnp.asarray(0.0))  # |z| is singular here
    assert [float(v) for v in g0] == [0.0, 0.0]
    # Real input works too.
    assert _grad(nm.abs2, -2.0) == -4.0


def test_gauss_legendre_exactness():
    x, w = nm.gauss_legendre(5, 0.0, 2.0)
    for degree in range(10):
        assert np.sum(w * x**degree) == pytest.approx(2.0 ** (degree + 1) / (degree + 1),
                                                      rel=1e-14)


@pytest.mark.parametrize("n", [1, 2, 7, 8, 1025, 3001])
def test_large_gauss_legendre_rules_by_newton(n):
    """Rules above ``NEWTON_GAUSS_ABOVE`` nodes come from Newton's method (``leggauss`` is
    O(n^3)); checked against ``leggauss`` and against closed-form integrals, including one
    whose integrand is near a pole just past the end (the end weights matter)."""
    x, w = nm._gauss_legendre_newton(n)
    xr, wr = np.polynomial.legendre.leggauss(n)
    np.testing.assert_allclose(x, xr, rtol=0, atol=5e-16)
    np.testing.assert_allclose(w, wr, rtol=0, atol=1e-13)
    assert np.all(np.diff(x) > 0) and np.allclose(x, -x[::-1], rtol=0, atol=0)
    if n > 8:
        for f, integral in ((np.exp, math.e - 1 / math.e),
                            (lambda t: np.sqrt(1.5 - t), (2.5**1.5 - 0.5**1.5) * 2 / 3),
                            (lambda t: 1 / (1.01 - t), math.log(2.01 / 0.01))):
            assert np.dot(w, f(x)) == pytest.approx(integral, rel=1e-14)
    # The package's rules: Newton's above the threshold, leggauss's (bit for bit) below it.
    used = nm._gauss_legendre_unit(n)
    expected = (x, w) if n > nm.NEWTON_GAUSS_ABOVE else (xr, wr)
    np.testing.assert_array_equal(used[0], expected[0])
    np.testing.assert_array_equal(used[1], expected[1])


def test_barycentric_matrix_reproduces_polynomials():
    source, _ = nm.gauss_legendre(8, 0.0, 1.0)
    target = np.linspace(0.0, 1.0, 13)
    matrix = nm.barycentric_matrix(source, target)
    poly = np.polynomial.Polynomial([0.3, -1.0, 2.0, 0.5, -0.7, 1.1, 0.2, -0.9])
    np.testing.assert_allclose(matrix @ poly(source), poly(target), atol=1e-13)
    # A target on a source node is copied exactly.
    exact = nm.barycentric_matrix(source, source[2:3])
    np.testing.assert_array_equal(exact[0], np.eye(8)[2])


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: nm.check_range("u", 2.0, 0.0, 1.5, low_inclusive=False),
         r"u must be in \(0\.0, 1\.5\], got 2\.0"),
        (lambda: nm.check_range("u", float("nan"), 0.0, 1.5), r"u must be finite.*got nan"),
        (lambda: nm.check_count("B", 0), r"B must be an integer >= 1, got 0"),
        (lambda: nm.check_count("B", 2.0), r"B must be an integer >= 1, got 2\.0"),
        (lambda: nm.check_choice("method", "x", ("a", "b")),
         r"method must be one of 'a', 'b', got 'x'"),
    ],
)
def test_checks_raise_with_name_value_and_range(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_checks_are_silent_under_tracing():
    jax.jit(lambda v: nm.check_range("u", v, 0.0, 1.0) or v)(jnp.asarray(5.0))


def test_cos_sin_2pi_values_and_derivative():
    x = np.concatenate([np.linspace(-3.0, 3.0, 601), [0.25, 0.5, -0.75, 1e3 + 0.125, -57.3]])
    reduced = x - np.round(x)  # exact: phases are in waves
    c, s = nm.cos_sin_2pi(jnp.asarray(x))
    np.testing.assert_allclose(c, np.cos(2 * np.pi * reduced), atol=3e-15)
    np.testing.assert_allclose(s, np.sin(2 * np.pi * reduced), atol=3e-15)
    dc, ds = jax.jvp(nm.cos_sin_2pi, (jnp.asarray(x),), (jnp.ones_like(jnp.asarray(x)),))[1]
    np.testing.assert_allclose(dc, -2 * np.pi * np.sin(2 * np.pi * reduced), atol=2e-14)
    np.testing.assert_allclose(ds, 2 * np.pi * np.cos(2 * np.pi * reduced), atol=2e-14)
    g = jax.grad(lambda v: nm.cos_sin_2pi(v)[1])(jnp.asarray(0.5))  # at a rounding tie
    assert float(g) == pytest.approx(-2 * np.pi, rel=1e-14)


def test_cos_sin_2pi_stacked_values_and_derivative():
    x = np.concatenate([np.linspace(-3.0, 3.0, 601), [0.25, 0.5, -0.75, 1e3 + 0.125, -57.3]])
    reduced = x - np.round(x)
    xs = jnp.asarray(np.stack([x, x[::-1]]))  # batch axes are kept
    e = nm.cos_sin_2pi_stacked(xs)
    assert e.shape == (2, 2, x.size)
    for row, r in ((e[0], reduced), (e[1], reduced[::-1])):
        np.testing.assert_allclose(row[0], np.cos(2 * np.pi * r), atol=2e-15)
        np.testing.assert_allclose(row[1], np.sin(2 * np.pi * r), atol=2e-15)
    de = jax.jvp(nm.cos_sin_2pi_stacked, (xs,), (jnp.ones_like(xs),))[1][0]
    np.testing.assert_allclose(de[0], -2 * np.pi * np.sin(2 * np.pi * reduced), atol=2e-14)
    np.testing.assert_allclose(de[1], 2 * np.pi * np.cos(2 * np.pi * reduced), atol=2e-14)
    g = jax.grad(lambda v: nm.cos_sin_2pi_stacked(v)[0, 0])(jnp.asarray([0.5]))  # a tie
    assert float(g[0]) == pytest.approx(0.0, abs=1e-13)
    g = jax.grad(lambda v: nm.cos_sin_2pi_stacked(v)[1, 0])(jnp.asarray([0.5]))
    assert float(g[0]) == pytest.approx(-2 * np.pi, rel=1e-14)
    # float32 stays float32 and accurate to its rounding
    e32 = nm.cos_sin_2pi_stacked(jnp.asarray(x, jnp.float32))
    assert e32.dtype == jnp.float32
    # (its own, shorter polynomial: error about 2e-7 in sin(pi r), below float32's rounding
    # of the reduced phase for |x| of a few waves)
    x32 = np.float32(x)
    reduced32 = x32.astype(np.float64) - np.round(x32.astype(np.float64))
    np.testing.assert_allclose(e32[0], np.cos(2 * np.pi * reduced32), atol=1.5e-6)
    np.testing.assert_allclose(e32[1], np.sin(2 * np.pi * reduced32), atol=1.5e-6)


def test_cos_2pi_is_the_stacked_cosine():
    """The cosine alone (the overlap engine's symmetric path): the stacked function's cosine
    entry, bit for bit, in float64 and float32, and cos(2 pi x) to rounding."""
    x = np.concatenate([np.linspace(-3.0, 3.0, 601), [0.25, 0.5, -0.75, 1e3 + 0.125, -57.3]])
    for dtype, atol in ((jnp.float64, 2e-15), (jnp.float32, 1.5e-6)):
        xs = jnp.asarray(x, dtype)
        c = nm.cos_2pi(xs)
        assert c.dtype == dtype
        np.testing.assert_array_equal(c, nm.cos_sin_2pi_stacked(xs)[0])
        xd = np.asarray(xs).astype(np.float64)
        np.testing.assert_allclose(c, np.cos(2 * np.pi * (xd - np.round(xd))), atol=atol)


_PI = np.longdouble("3.14159265358979323846264338327950288")


def _chebyshev_in_powers(f, b, degree, n=40):
    """Chebyshev series of f on z in [0, b] in extended precision, cut at ``degree`` and
    written in powers of z (how ``_COS_H``, ``_SIN_H`` and ``_SIN_PI_R`` were made)."""
    ld, pi = np.longdouble, _PI
    a = ld(0)
    theta = pi * (np.arange(n, dtype=ld) + ld(0.5)) / n
    z = (a + b) / 2 + (b - a) / 2 * np.cos(theta)
    values = f(z)
    series = [2 * np.sum(values * np.cos(j * theta)) / n for j in range(degree + 1)]
    series[0] /= 2
    scale, offset = ld(2) / (b - a), -(a + b) / (b - a)  # Chebyshev variable = scale z + offset
    powers = [np.array([ld(1)]), np.array([offset, scale])]
    for _ in range(2, degree + 1):
        nxt = 2 * np.convolve(powers[-1], np.array([offset, scale]))
        nxt[: powers[-2].size] -= powers[-2]
        powers.append(nxt)
    out = np.zeros(degree + 1, dtype=ld)
    for c, p in zip(series, powers, strict=True):
        out[: p.size] += c * p
    return out


@pytest.mark.skipif(np.finfo(np.longdouble).eps > 1e-18,
                    reason="the fit needs extended precision (x86 long double)")
def test_trigonometric_coefficients_are_the_documented_chebyshev_fit():
    def sin_over_root(scale):
        def f(z):
            r = np.sqrt(z)
            return np.where(r > 0, np.sin(scale * r) / np.where(r > 0, r, 1), scale)
        return f

    half_turn = (_PI / 2) ** 2
    for fitted, f, b in ((nm._COS_H, lambda z: np.cos(np.sqrt(z)), half_turn),
                         (nm._SIN_H, sin_over_root(1), half_turn),
                         (nm._SIN_PI_R, sin_over_root(_PI), np.longdouble(0.25))):
        np.testing.assert_allclose(np.asarray(fitted),
                                   _chebyshev_in_powers(f, b, 8).astype(float),
                                   rtol=1e-12, atol=0)
    # float32's polynomial: the same fit cut at degree 4
    np.testing.assert_allclose(np.asarray(nm._SIN_PI_R_F32),
                               _chebyshev_in_powers(sin_over_root(_PI), np.longdouble(0.25),
                                                    4).astype(float),
                               rtol=1e-12, atol=0)


def test_materialise_changes_values_and_derivatives_by_at_most_an_ulp():
    # Division by the run-time 1 m / m must leave the numbers as they are: XLA rewrites
    # a / (m / m) as (a m) / m (a 1-ulp change, seen at |x| ~ 1e9), nothing more; the
    # derivative of the stored array is the identity (no term through the run-time 1).
    x = jnp.asarray(np.linspace(-1e3, 1e3, 101) ** 3)
    y = jnp.asarray(np.geomspace(1e-300, 1e290, 101))  # |y| (|x| + 1) inside the range
    for fn in (nm.materialise, jax.jit(nm.materialise)):
        a, b = fn(x, y)
        np.testing.assert_allclose(np.asarray(a), np.asarray(x), rtol=2.3e-16, atol=0)
        np.testing.assert_allclose(np.asarray(b), np.asarray(y), rtol=2.3e-16, atol=0)
    grad = jax.grad(lambda v: jnp.sum(nm.materialise(v, 3.0 * v)[1] ** 2))(x)
    np.testing.assert_allclose(np.asarray(grad), np.asarray(18.0 * x), rtol=7e-16, atol=0)
    np.testing.assert_allclose(np.asarray(nm.runtime_one(x)), np.ones(101), rtol=2.3e-16)


def _counting_branches(calls):
    def costly(x):
        jax.debug.callback(lambda: calls.append(1))
        return jnp.sin(x) * x, x + 1.0

    def cheap(x):
        return jnp.zeros_like(x), x

    return costly, cheap


@pytest.mark.parametrize("sequential", [True, False])
def test_batch_skipping_cond_skips_the_branch_no_member_takes(sequential):
    calls = []
    costly, cheap = _counting_branches(calls)

    def skipping(x):
        return nm.batch_skipping_cond(x > 1.0, costly, cheap, x, sequential=sequential)

    def plain(x):
        return jax.lax.cond(x > 1.0, costly, cheap, x)

    none = jnp.array([0.1, 0.5, 0.9])
    some = jnp.array([0.1, 1.5, 0.9, 2.5])
    for fn, expect_calls in ((skipping, 0), (plain, 1)):
        calls.clear()
        jax.block_until_ready(jax.jit(jax.vmap(fn))(none))
        assert (len(calls) > 0) == bool(expect_calls)  # plain cond: a select runs both
    # Where some members take it: one member at a time, only those two run the branch
    # (each its own callback); vectorised, it runs once for the whole batch.
    calls.clear()
    jax.block_until_ready(jax.jit(jax.vmap(skipping))(some))
    assert len(calls) == (2 if sequential else 1)
    # Each member gets its own branch's result, bit for bit as alone, in either batch and
    # with an unbatched predicate (the operands batched or not).
    for xs in (none, some):
        out = jax.jit(jax.vmap(skipping))(xs)
        alone = [jax.jit(plain)(x) for x in xs]
        for i in range(len(xs)):
            assert float(out[0][i]) == float(alone[i][0])
            assert float(out[1][i]) == float(alone[i][1])
    flag = jax.vmap(lambda x: nm.batch_skipping_cond(True, costly, cheap, x,
                                                     sequential=sequential))(some)
    np.testing.assert_array_equal(flag[0], jnp.sin(some) * some)
    flag = jax.vmap(lambda p: nm.batch_skipping_cond(p, costly, cheap, jnp.float64(2.0),
                                                     sequential=sequential))(
        jnp.array([True, False]))
    np.testing.assert_array_equal(flag[0], [jnp.sin(2.0) * 2.0, 0.0])


def test_batch_skipping_cond_picks_the_loop_by_backend():
    # sequential=None: member by member on the backends listed (CPU here), where the
    # vectorised branch measured slower.
    calls = []
    costly, cheap = _counting_branches(calls)
    some = jnp.array([0.1, 1.5, 0.9, 2.5])
    jax.block_until_ready(jax.jit(jax.vmap(
        lambda x: nm.batch_skipping_cond(x > 1.0, costly, cheap, x)))(some))
    expected = 2 if jax.default_backend() in nm.SEQUENTIAL_BRANCH_BACKENDS else 1
    assert len(calls) == expected


@pytest.mark.parametrize("sequential", [True, False])
def test_batch_skipping_cond_derivatives(sequential):
    # Forward and reverse mode, and vmap of them, as those of lax.cond (the branch taken).
    _, cheap = _counting_branches([])

    def costly(x):
        return jnp.sin(x) * x, x * x

    def fn(x):
        value, other = nm.batch_skipping_cond(x > 1.0, costly, cheap, x, sequential=sequential)
        return value + 0.5 * other

    def exact(x):
        return jnp.where(x > 1.0, jnp.sin(x) * x + 0.5 * x * x, 0.5 * x)

    def slope(x):
        return jnp.where(x > 1.0, jnp.cos(x) * x + jnp.sin(x) + x, 0.5)

    xs = jnp.array([0.3, 1.2, 2.7])
    np.testing.assert_allclose(jax.vmap(jax.grad(fn))(xs), slope(xs), rtol=1e-14)
    np.testing.assert_allclose(jax.vmap(lambda x: jax.jvp(fn, (x,), (1.0,))[1])(xs),
                               slope(xs), rtol=1e-14)
    np.testing.assert_allclose(jax.jit(jax.vmap(jax.value_and_grad(fn)))(xs)[0], exact(xs),
                               rtol=1e-14)
    for x in xs:
        assert float(jax.grad(fn)(x)) == pytest.approx(float(slope(x)), rel=1e-14)
