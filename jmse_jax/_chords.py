"""Exact chord integrals ``J = \\int_{-1}^{1} exp(i 2 pi p(t)) dt`` for quadratic phases ``p``.

The general form (``chord_integral``) is not used by default: the overlap engine calls it
only when ``_otf._EXACT_CHORDS`` is set. When it was written it measured as fast as the Gauss
chords for the value and 35-50 % slower for ``value_and_grad``; the Gauss chords have got
faster since, and in session 99 it was 1.3-5x slower (one core: the default's first grid
0.50 -> 2.55 ms a value, tier 3's grid 71 -> 89 ms; benchmarks/README.md, optimisation log).
It is kept, tested, for devices where the balance may differ. The even form
(``even_chord_integral``, below) is used: the one-ray plans' chords.

Along the chords of the overlap lens that run perpendicular to ``nu``, the phase difference
``W(xi + nu) - W(xi - nu)`` of a Seidel wavefront is a quadratic in the chord parameter ``t``
(its only quartic term, ``rho^4``, is rotationally symmetric). The ``t`` integral then has a
closed form in terms of one smooth special function, and the overlap engine needs one such
evaluation per chord instead of a Gauss rule of 20-60 nodes whose cost grows with the phase
spread across the lens.

Derivation (phase ``phi(t) = c + b t + g t^2`` in radians, ``g >= 0``; ``g < 0`` follows from
``J(p) = conj(J(-p))``). With ``A(beta, g) = \\int_0^inf exp(i (beta s + g s^2)) ds``, the
integral from each end point to infinity of the local quadratic,

    J = e^{i phi(-1)} A(phi'(-1), g) - e^{i phi(1)} A(phi'(1), g),

and ``A(beta, g) = g^{-1/2} Ahat(beta / sqrt(g))``, ``Ahat(y) = \\int_0^inf e^{i (y s + s^2)} ds``.
For ``y < 0``, ``Ahat(y) = sqrt(pi) e^{i pi/4} e^{-i y^2/4} - Ahat(|y|)``; the first part is the
stationary point's contribution, which survives only when the stationary point
``t* = -b / (2 g)`` lies inside the chord. So, with ``T(beta, g) = sign(beta) g^{-1/2}
Ahat(|beta| / sqrt(g))``,

    J = e^{i phi(-1)} T(phi'(-1)) - e^{i phi(1)} T(phi'(1))
        + [phi'(-1) < 0 <= phi'(1)] sqrt(pi / g) e^{i pi/4} e^{i phi(t*)}.

``Ahat`` on ``y >= 0`` is smooth and bounded (``Ahat(0) = sqrt(pi) e^{i pi/4} / 2``,
``Ahat(y) ~ i / y``); it is tabulated once as a Chebyshev series on ``[0, Y]``. Beyond ``Y``
the form ``T = (i / beta) K(g / beta^2)``, ``K(eps) = -i y Ahat(y)`` at ``y = eps^{-1/2}``
(``K(0) = 1``), has no ``1/sqrt(g)`` at all and stays exact as ``g -> 0`` (the linear-phase
limit ``(e^{i phi(1)} - e^{i phi(-1)}) / (i b)``); ``K`` is a second Chebyshev series on
``[0, 1/Y^2]``. Both series are built on the host from the contour integrals

    Ahat(y) = e^{i pi/4} \\int_0^inf exp(-r^2 - y e^{-i pi/4} r) dr,
    K(eps)  = -i e^{i pi/4} \\int_0^inf exp(-eps s^2 - e^{-i pi/4} s) ds

(the path rotated by 45 degrees, where the integrands decay without oscillating), by
composite Gauss–Legendre in float64, accurate to about 1e-15.

When the phase hardly varies along the chord (``g`` and one end point's slope both small),
the two end-point terms are large and nearly cancel; there a 7-node Gauss rule is exact to
rounding instead.

The derivative rule is written by hand (``Ahat' = -(1 + i y Ahat) / 2`` and a series of
``K'`` tabulated the same way) and stays finite at every degenerate point (``g = 0``,
``b = 0``, the stationary point at an end). It needs the third series and about four times
the work of the value.

Even chords (``even_chord_integral``; used by default). On the overlap engine's rotationally
symmetric path the phase along each chord is even, ``p(t) = p0 + gamma t^2`` (waves), and the
chord's integral is ``2 e^{i 2 pi p0} F(gamma)`` with the one-parameter function
``F(gamma) = \\int_0^1 exp(i 2 pi gamma s^2) ds`` (``F(-gamma) = conj F(gamma)``). For
``|gamma| <= 1`` it is a power series, ``F = P(gamma^2) + i gamma Q(gamma^2)``, economised to
degree 12 in ``gamma^2``. For ``|gamma| > 1`` the tail from 1 to infinity, rotated onto the
path ``v = i w / (2 pi gamma)`` of ``s^2 = 1 + v``, leaves

    F(gamma) = (1 + i) / (4 sqrt(gamma)) - e^{i 2 pi gamma} (i x / 2) h(x),
    h(x) = \\int_0^inf e^{-w} (1 + i x w)^{-1/2} dw,   x = 1 / (2 pi gamma) <= 1 / (2 pi),

and ``h``, smooth and close to 1, is a polynomial of degree 14 in ``1 / gamma``. A chord
then costs two phase factors (at ``t = 0`` and ``t = 1``), one reciprocal square root and
three short polynomials, about as much as 15-20 Gauss nodes, whatever ``gamma``; its
derivative is nearly free, ``F' = (e^{i 2 pi gamma} - F) / (2 gamma)`` (and the series'
own derivative for ``|gamma| <= 1``). Absolute error about 1e-14.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from numpy.polynomial import chebyshev as _cheb

from ._numerics import _even_poly, cos_sin_2pi, gauss_legendre, materialise, runtime_one

__all__ = ["chord_integral", "even_chord_integral"]

#: ``|y| = |beta| / sqrt(g)`` below which ``Ahat`` is used, above which ``K``.
_Y = 6.0
_A_DEGREE = 26
_K_DEGREE = 20
#: The small-phase branch (radians): ``g < _G_SMALL`` and an end-point slope ``< _B_SMALL``.
#: There ``|phi(t) - phi(-1)| <= 0.32`` rad over the chord, and the 7-node Gauss rule is exact
#: to rounding. Outside it the closed form's values are
#: exact to ~1e-13 absolute; its derivatives to ~1e-11, and to ~1e-9 for chords just outside
#: the branch (``g ~ 1e-2``), where the end-point terms' cancellation amplifies the inputs'
#: rounding (tests/test_chords.py measures both).
_G_SMALL = 1e-2
_B_SMALL = 0.1
_SMALL_NODES = 7

_SQRT_PI = math.sqrt(math.pi)
_E_PI4 = complex(math.cos(math.pi / 4), math.sin(math.pi / 4))


def _composite_gauss(a, b, panels, order):
    x, w = gauss_legendre(order, 0.0, 1.0)
    edges = np.linspace(a, b, panels + 1)
    h = np.diff(edges)
    return ((edges[:-1, None] + h[:, None] * x).ravel(), (h[:, None] * w).ravel())


def ahat_host(y):
    """``Ahat(y) = \\int_0^inf exp(i (y s + s^2)) ds`` for ``y >= 0`` (NumPy, float64)."""
    y = np.asarray(y, float)
    r, w = _composite_gauss(0.0, 8.0, 64, 24)
    rot = np.exp(-0.25j * np.pi)
    values = np.exp(-(r * r)[None, :] - (y.reshape(-1, 1) * rot) * r[None, :]) @ w
    return (np.exp(0.25j * np.pi) * values).reshape(y.shape)


def k_host(eps, derivative=False):
    """``K(eps) = -i y Ahat(y)`` at ``y = eps^{-1/2}`` (``K(0) = 1``), ``eps >= 0``, or its
    derivative ``K'(eps)`` (NumPy, float64)."""
    eps = np.asarray(eps, float)
    s, w = _composite_gauss(0.0, 64.0, 128, 24)
    if derivative:
        w = -w * s * s
    rot = np.exp(-0.25j * np.pi)
    values = np.exp(-eps.reshape(-1, 1) * (s * s)[None, :] - rot * s[None, :]) @ w
    return (-1j * np.exp(0.25j * np.pi) * values).reshape(eps.shape)


@functools.cache
def _series():
    """Chebyshev coefficients (real, imag) of ``(1 + y) Ahat`` on [0, Y], ``K`` and ``K'`` on
    [0, 1/Y^2]."""
    eps_max = 1.0 / (_Y * _Y)

    def coefficients(fn, lo, hi, degree):
        x = np.cos(np.pi * (np.arange(degree + 1) + 0.5) / (degree + 1))
        values = fn(lo + (hi - lo) * 0.5 * (x + 1.0))
        return _cheb.chebfit(x, values.real, degree), _cheb.chebfit(x, values.imag, degree)

    # (1 + y) Ahat, so that the series is accurate relative to Ahat's size (~ 1/y).
    a_re, a_im = coefficients(lambda y: (1 + y) * ahat_host(y), 0.0, _Y, _A_DEGREE)
    k_re, k_im = coefficients(k_host, 0.0, eps_max, _K_DEGREE)
    # K' is fitted from its own integral (differentiating K's series would lose ~3 digits).
    kp_re, kp_im = coefficients(functools.partial(k_host, derivative=True), 0.0, eps_max,
                                _K_DEGREE)
    as_tuple = lambda c: tuple(float(v) for v in c)  # noqa: E731
    return tuple(as_tuple(c) for c in (a_re, a_im, k_re, k_im, kp_re, kp_im))


def _clenshaw(x, c_re, c_im):
    """Chebyshev series with real coefficient lists ``c_re``, ``c_im`` at ``x`` in [-1, 1]."""
    two_x = 2.0 * x
    zero = jnp.zeros_like(x)
    b1r = b2r = b1i = b2i = zero
    for cr, ci in zip(c_re[:0:-1], c_im[:0:-1], strict=True):
        b1r, b2r = two_x * b1r - b2r + cr, b1r
        b1i, b2i = two_x * b1i - b2i + ci, b1i
    return x * b1r - b2r + c_re[0], x * b1i - b2i + c_im[0]


def _ahat(y):
    """``Ahat(y)`` on [0, Y]."""
    c_re, c_im, *_ = _series()
    re, im = _clenshaw(y * (2.0 / _Y) - 1.0, c_re, c_im)
    # A division (not a multiplication by the reciprocal): XLA counts it as expensive and
    # then computes the series once instead of fusing (recomputing) it into every consumer.
    return re / (1.0 + y), im / (1.0 + y)


def _k(eps, derivative):
    _, _, k_re, k_im, kp_re, kp_im, *_ = _series()
    x = eps * (2.0 * _Y * _Y) - 1.0
    return _clenshaw(x, kp_re, kp_im) if derivative else _clenshaw(x, k_re, k_im)


@functools.cache
def _small_rule():
    t, w = gauss_legendre(_SMALL_NODES, -1.0, 1.0)
    return tuple(float(v) for v in t), tuple(float(v) for v in w)


class _C:
    """Minimal complex arithmetic on (real, imag) pairs of arrays (keeps the dtype real)."""

    __slots__ = ("re", "im")

    def __init__(self, re, im):
        self.re, self.im = re, im

    def __add__(self, o):
        return _C(self.re + o.re, self.im + o.im)

    def __sub__(self, o):
        return _C(self.re - o.re, self.im - o.im)

    def __mul__(self, o):
        if isinstance(o, _C):
            return _C(self.re * o.re - self.im * o.im, self.re * o.im + self.im * o.re)
        return _C(self.re * o, self.im * o)

    def times_i(self):
        return _C(-self.im, self.re)

    def conj(self):
        return _C(self.re, -self.im)

    def where(self, cond, other):
        """``self`` where ``cond``, else ``other``."""
        return _C(jnp.where(cond, self.re, other.re), jnp.where(cond, self.im, other.im))


def _endpoint(beta, g, derivatives):
    """``T(beta, g)`` and, if asked, ``dT/dbeta``, ``dT/dg`` (``g >= 0``)."""
    abs_b = jnp.abs(beta)
    sq = jnp.sqrt(g)
    use_a = abs_b < _Y * sq  # False whenever g == 0
    # Ahat branch (safe stand-ins where not selected: g > 0 there).
    g_a = jnp.where(use_a, g, 1.0)
    sq_a = jnp.where(use_a, sq, 1.0)
    y = jnp.where(use_a, abs_b / sq_a, 0.0)
    sign = jnp.where(beta < 0, -1.0, 1.0)
    a = _C(*_ahat(y))
    # K branch (beta != 0 there; stand-in 1 elsewhere).
    b_k = jnp.where(use_a, 1.0, beta)
    inv_b = 1.0 / b_k
    eps = jnp.where(use_a, 0.0, g * inv_b * inv_b)
    # Divisions, not multiplications by 1/beta: see _ahat.
    k = _C(*_k(eps, False))
    kb = _C(k.re / b_k, k.im / b_k)  # K / beta
    t = (a * (sign / sq_a)).where(use_a, kb.times_i())
    if not derivatives:
        return t, None, None
    kp = _C(*_k(eps, True))
    kpb = _C(kp.re / b_k, kp.im / b_k)  # K' / beta
    # Ahat' = -(1 + i y Ahat) / 2 and D = (y Ahat)' = Ahat + y Ahat' (both lose up to y^2 <= 36
    # in relative accuracy: about 1e-9 absolute on dT/dg in the worst, near-degenerate case).
    iya = a.times_i() * y
    ap = _C(-0.5 * (1.0 + iya.re), -0.5 * iya.im)
    d = a + ap * y
    dt_db_a = ap * (1.0 / g_a)
    dt_dg_a = d * (-0.5 * sign / (g_a * sq_a))
    dt_db_k = (kb + kpb * (2.0 * eps)).times_i() * -inv_b
    dt_dg_k = kpb.times_i() * (inv_b * inv_b)
    return t, dt_db_a.where(use_a, dt_db_k), dt_dg_a.where(use_a, dt_dg_k)


def _chord(pm, p0, pp, derivatives):
    """``J`` (and ``dJ/db``, ``dJ/dg``) for phases in waves at ``t = -1, 0, 1``."""
    pm, p0, pp = materialise(pm, p0, pp)
    c2_waves = 0.5 * (pp + pm) - p0
    flip = c2_waves < 0
    sgn = jnp.where(flip, -1.0, 1.0)
    pm, p0, pp = sgn * pm, sgn * p0, sgn * pp
    two_pi = 2.0 * math.pi
    c1 = 0.5 * (pp - pm)
    c2 = jnp.abs(c2_waves)
    b, g = two_pi * c1, two_pi * c2
    beta1, beta2 = b - 2.0 * g, b + 2.0 * g
    one = runtime_one(g)  # dividing by it makes XLA store a value once (see materialise)
    e1 = _C(*(v / one for v in cos_sin_2pi(pm)))
    e2 = _C(*(v / one for v in cos_sin_2pi(pp)))

    small = (g < _G_SMALL) & (jnp.minimum(jnp.abs(beta1), jnp.abs(beta2)) < _B_SMALL)
    # Closed form (stand-ins on the small branch keep it finite).
    g_c = jnp.where(small, 1.0, g)
    t1, t1_b, t1_g = _endpoint(beta1, g_c, derivatives)
    t2, t2_b, t2_g = _endpoint(beta2, g_c, derivatives)
    # beta = 0 counts as positive in T (sign +1), so a stationary point exactly at t = 1
    # (beta2 = 0) is inside and one at t = -1 (beta1 = 0) is not: J stays continuous.
    inside = (beta1 < 0) & (beta2 >= 0) & ~small
    g_s = jnp.where(inside, g_c, 1.0)
    t_star = jnp.where(inside, -c1 / (2.0 * jnp.where(inside, c2, 1.0)), 0.0)
    phase_star = p0 + 0.5 * c1 * t_star  # = p0 - c1^2 / (4 c2)
    es = _C(*(v / one for v in cos_sin_2pi(phase_star)))
    s = (es * _C(_SQRT_PI * _E_PI4.real, _SQRT_PI * _E_PI4.imag)) * jnp.where(
        inside, 1.0 / jnp.sqrt(g_s), 0.0)
    e1t1, e2t2 = e1 * t1, e2 * t2
    j_closed = e1t1 - e2t2 + s

    # Small-phase branch: expand about t = -1.
    nodes, weights = _small_rule()
    beta1_s = jnp.where(small, beta1, 0.0)
    g_sm = jnp.where(small, g, 0.0)
    sums = [_C(jnp.zeros_like(g), jnp.zeros_like(g)) for _ in range(3 if derivatives else 1)]
    for t_j, w_j in zip(nodes, weights, strict=True):
        s_j = t_j + 1.0
        e_j = _C(*cos_sin_2pi((beta1_s * s_j + g_sm * (s_j * s_j)) / two_pi))
        sums[0] = sums[0] + e_j * w_j
        if derivatives:
            sums[1] = sums[1] + e_j * (w_j * t_j)
            sums[2] = sums[2] + e_j * (w_j * t_j * t_j)
    sums = [_C(v.re / one, v.im / one) for v in sums]
    j_small = e1 * sums[0]
    j = j_small.where(small, j_closed)
    if not derivatives:
        j = j.where(~flip, j.conj())
        return _C(j.re / one, j.im / one), None

    # Derivatives in b and g [radians]; dJ/dc0 = i J needs nothing more.
    dj_db_closed = ((e1t1.times_i() * -1.0) + e1 * t1_b
                    - (e2t2.times_i() + e2 * t2_b) + s.times_i() * t_star)
    dj_dg_closed = ((e1t1.times_i() + e1 * (t1_b * -2.0 + t1_g))
                    - (e2t2.times_i() + e2 * (t2_b * 2.0 + t2_g))
                    + s * _C(-0.5 / g_s, t_star * t_star))
    dj_db = (e1 * sums[1]).times_i().where(small, dj_db_closed)
    dj_dg = (e1 * sums[2]).times_i().where(small, dj_dg_closed)
    # Undo the flip: J(c) = conj(J~(-c)), so dJ/dc = -conj(dJ~/dc~) (and dJ/dc0 = i J).
    j = j.where(~flip, j.conj())
    dj_db = dj_db.where(~flip, dj_db.conj() * -1.0)
    dj_dg = dj_dg.where(~flip, dj_dg.conj() * -1.0)
    return j, (dj_db, dj_dg)


@jax.custom_jvp
def chord_integral(pm, p0, pp):
    """``\\int_{-1}^{1} exp(i 2 pi p(t)) dt`` for the quadratic ``p`` with ``p(-1) = pm``,
    ``p(0) = p0``, ``p(1) = pp`` (waves, broadcast arrays). Returns ``(real, imag)``.

    Exact (closed form, see the module docstring) to about 1e-14 absolute for any
    coefficients; differentiable with a hand-written rule that stays finite everywhere.
    """
    pm, p0, pp = jnp.broadcast_arrays(pm, p0, pp)
    j, _ = _chord(pm, p0, pp, derivatives=False)
    return j.re, j.im


@chord_integral.defjvp
def _chord_integral_jvp(primals, tangents):
    pm, p0, pp = jnp.broadcast_arrays(*primals)
    j, (dj_db, dj_dg) = _chord(pm, p0, pp, derivatives=True)
    d_pm, d_p0, d_pp = (jnp.broadcast_to(t, pm.shape) for t in tangents)
    # c0 = 2 pi p0, b = pi (pp - pm), g = pi (pp + pm) - 2 pi p0 (radians).
    d_c0 = (2.0 * math.pi) * d_p0
    d_b = math.pi * (d_pp - d_pm)
    d_g = math.pi * (d_pp + d_pm) - d_c0
    d_re = -j.im * d_c0 + dj_db.re * d_b + dj_dg.re * d_g
    d_im = j.re * d_c0 + dj_db.im * d_b + dj_dg.im * d_g
    return (j.re, j.im), (d_re, d_im)


#: ``even_chord_integral``: ``|gamma|`` (waves) up to which ``F`` is the series in
#: ``gamma^2``, beyond which the end-point form with ``h(x)`` at ``x = 1 / (2 pi |gamma|)``.
_EVEN_SPLIT = 1.0
#: Degrees of the power series (economised on the unit interval): ``h`` in ``1 / |gamma|``
#: (error in ``F`` about 3e-14 at degree 14, 4e-13 at 12) and the small-``gamma`` parts of
#: ``F`` and ``F'`` in ``gamma^2`` (about 4e-15 and 2e-14 at degree 12).
_H_DEGREE = 14
_EVEN_SERIES_DEGREE = 12


def h_host(x):
    """``h(x) = \\int_0^inf e^{-w} (1 + i x w)^{-1/2} dw`` for ``x >= 0`` (NumPy, float64)."""
    x = np.asarray(x, float)
    w, weights = _composite_gauss(0.0, 48.0, 96, 24)  # e^{-48}: below 1e-20
    values = (np.exp(-w)[None, :] * (1.0 + 1j * x.reshape(-1, 1) * w[None, :]) ** -0.5) @ weights
    return values.reshape(x.shape)


def even_f_host(gamma, derivative=False):
    """``F(gamma) = \\int_0^1 exp(i 2 pi gamma s^2) ds`` or ``F'(gamma)`` for ``|gamma| <=
    1`` (NumPy, float64; a 40-node Gauss rule, exact to rounding for a phase of at most one
    wave)."""
    gamma = np.asarray(gamma, float)
    s, w = gauss_legendre(40, 0.0, 1.0)
    if derivative:
        w = 2j * np.pi * w * s * s
    values = np.exp(2j * np.pi * gamma.reshape(-1, 1) * (s * s)[None, :]) @ w
    return values.reshape(gamma.shape)


def _power_series(fn, degree):
    """Coefficients, lowest first, of the degree-``degree`` Chebyshev interpolant of ``fn`` on
    ``u`` in [0, 1], written in powers of ``u`` (for Horner's rule; they stay of order 10
    here, so little is lost to cancellation)."""
    u = 0.5 * (np.cos(np.pi * (np.arange(4 * degree) + 0.5) / (4 * degree)) + 1.0)
    series = np.polynomial.Chebyshev.fit(u, fn(u), degree, domain=[0.0, 1.0])
    return tuple(float(c) for c in series.convert(kind=np.polynomial.Polynomial).coef)


@functools.cache
def _even_series():
    """``(h_re, h_im)`` in ``u = 1 / |gamma|`` and ``(p, q, r, s)`` in ``v = gamma^2``, with
    ``F = p(v) + i gamma q(v)`` and ``F' = gamma r(v) + i s(v)`` for ``|gamma| <= 1``."""
    x_of = lambda u: u / (2.0 * math.pi)  # noqa: E731
    g_of = np.sqrt  # gamma >= 0 from v (both parts are even or odd in gamma)
    odd = lambda fn: (lambda v: fn(v) / np.where(v > 0, g_of(v), 1.0))  # noqa: E731
    return (
        _power_series(lambda u: h_host(x_of(u)).real, _H_DEGREE),
        _power_series(lambda u: h_host(x_of(u)).imag, _H_DEGREE),
        _power_series(lambda v: even_f_host(g_of(v)).real, _EVEN_SERIES_DEGREE),
        _power_series(odd(lambda v: even_f_host(g_of(v)).imag), _EVEN_SERIES_DEGREE),
        _power_series(odd(lambda v: even_f_host(g_of(v), True).real), _EVEN_SERIES_DEGREE),
        _power_series(lambda v: even_f_host(g_of(v), True).imag, _EVEN_SERIES_DEGREE),
    )


def _even_parts(p0, p1):
    """``Z = e^{i 2 pi p0} F(p1 - p0)`` as ``(re, im)``, and what the derivative rule needs."""
    # Stored once: XLA would otherwise recompute the chord phases (a polynomial in the
    # wavefront's terms) for each of their uses here (3x the kernel's time in place).
    p0, p1 = materialise(p0, p1)
    h_re, h_im, p, q, _, _ = _even_series()
    gamma = p1 - p0
    big = jnp.abs(gamma) > _EVEN_SPLIT
    sign = jnp.where(gamma < 0, -1.0, 1.0)
    c0, s0 = cos_sin_2pi(p0)
    c1, s1 = cos_sin_2pi(p1)
    # |gamma| > 1: Z = e^{i 2 pi p0} (1 + i sign) / (4 sqrt|gamma|) + e^{i 2 pi p1} (a + i b),
    # a + i b = -(x / 2) (i h) for gamma > 0 and its conjugate for gamma < 0.
    inv_sqrt = jax.lax.rsqrt(jnp.where(big, jnp.abs(gamma), 1.0))
    u = inv_sqrt * inv_sqrt  # 1 / |gamma|
    half_x = u * (0.25 / math.pi)
    a = half_x * _even_poly(h_im, u)
    b = -sign * half_x * _even_poly(h_re, u)
    quarter = 0.25 * inv_sqrt
    re_big = quarter * (c0 - sign * s0) + (c1 * a - s1 * b)
    im_big = quarter * (s0 + sign * c0) + (s1 * a + c1 * b)
    # |gamma| <= 1: Z = e^{i 2 pi p0} (p(v) + i gamma q(v)).
    v = jnp.where(big, 0.0, gamma * gamma)
    f_re, f_im = _even_poly(p, v), gamma * _even_poly(q, v)
    re = jnp.where(big, re_big, c0 * f_re - s0 * f_im)
    im = jnp.where(big, im_big, s0 * f_re + c0 * f_im)
    return re, im, (gamma, big, v, c0, s0, c1)


@jax.custom_jvp
def even_chord_integral(p0, p1):
    """``Re \\int_{-1}^{1} exp(i 2 pi (p0 + (p1 - p0) t^2)) dt``: a chord whose phase is
    even in ``t``, given in waves at ``t = 0`` (``p0``) and ``t = 1`` (``p1``), as on the
    overlap engine's rotationally symmetric path (whose imaginary parts cancel). Arrays of
    one shape; closed form (module docstring), absolute error about 1e-14, with a derivative
    rule that is finite everywhere (``p0 = p1`` included)."""
    return 2.0 * _even_parts(p0, p1)[0]


@even_chord_integral.defjvp
def _even_chord_integral_jvp(primals, tangents):
    p0, p1 = primals
    d0, d1 = tangents
    re, im, (gamma, big, v, c0, s0, c1) = _even_parts(p0, p1)
    _, _, _, _, r, s = _even_series()
    # Re e^{i 2 pi p0} F'(gamma): (cos 2 pi p1 - Re Z) / (2 gamma) for |gamma| > 1, the
    # series' own derivative below.
    far = (c1 - re) / (2.0 * jnp.where(big, gamma, 1.0))
    near = c0 * (gamma * _even_poly(r, v)) - s0 * _even_poly(s, v)
    slope = jnp.where(big, far, near)
    # value 2 Re Z: d/dp1 = 2 Re(e F'), d/dp0 = -4 pi Im Z - 2 Re(e F').
    return 2.0 * re, 2.0 * slope * (d1 - d0) - (4.0 * math.pi) * im * d0
