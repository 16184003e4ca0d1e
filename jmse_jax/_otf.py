"""Optical transfer function at arbitrary frequency nodes: three engines.

``H(nu) = (1/pi) \\iint P(xi + nu) P*(xi - nu) d^2 xi`` with ``P = circ(rho) exp(i 2 pi W)``
(SPEC §2), so ``H(0) = 1``, ``H = 0`` for ``|nu| >= 1``, and a tilt ``W = a y`` gives
``H = exp(i 4 pi a nu_y) H_0``.

Engines
-------
``"overlap"``
    The autocorrelation integral evaluated directly at each node by Gauss quadrature over
    the lens-shaped overlap of the two shifted discs. With ``s = |nu|``, ``e = nu / s`` and
    ``e_perp`` the unit vector 90 degrees from ``e``, each half of the lens is parametrised as
    ``xi = +-(cos(phi) - s) e + t sin(phi) e_perp`` with ``phi in [0, arccos s]``,
    ``t in [-1, 1]`` and area element ``sin(phi)**2 dphi dt``. The map is analytic and the
    integrand is entire, so Gauss–Legendre converges spectrally for every ``s`` (no square
    root at the lens tips, no PSF window). The rule is rescaled to the exact lens area, so the
    aberration-free OTF is exact to rounding at any order.
    Where the phase is quadratic along the chords (Seidel wavefronts, Zernike terms up to
    ``Z11``), each chord's ``t`` integral has a closed form (``_chords``): on the
    rotationally symmetric path, whose chords' phases are even, always (1.6-4x faster than
    the Gauss chords there); elsewhere from ``_CLOSED_FORM_ORDER`` Gauss nodes along the
    chords, where it costs less than the Gauss rule it replaces.
``"nudft"``
    Pupil on a ``B x B`` square grid, PSF by a ``2B``-padded FFT, then the OTF at each node by
    an explicit (non-uniform) DFT of the PSF. First order in ``1/B`` (staircase pupil edge).
``"fft"``
    The baseline: OTF on the uniform FFT lag grid (``nu = k / B``), bilinearly interpolated
    to the nodes (exact at lag-grid nodes).
"""

from __future__ import annotations

import functools
import math
import warnings

import jax
import jax.numpy as jnp
import numpy as np

from ._aberrations import AbstractAberrations, Seidel
from ._chords import chord_integral, even_chord_integral
from ._numerics import (
    EXACT,
    AccuracyWarning,
    all_finite,
    barycentric_matrix,
    check_choice,
    check_count,
    check_finite_tree,
    check_range,
    common_dtype,
    cos_2pi,
    cos_sin_2pi,
    cos_sin_2pi_stacked,
    gauss_legendre,
    is_concrete,
    is_single_precision,
    materialise,
    safe_arccos,
    safe_norm,
    safe_sqrt,
)
from ._pupil import SquareGrid

__all__ = ["OTF_METHODS", "diffraction_limited_otf", "otf", "otf_fft_grid", "pupil_psf"]

OTF_METHODS = ("overlap", "nudft", "fft")

# Frequency nodes processed per block by the overlap engine (bounds the working memory to
# about 8 * 2 * block * n_phi * n_t bytes per temporary).
_OVERLAP_BLOCK = 128

#: The Gauss order along the chords from which ``_chords.chord_integral`` replaces the
#: Gauss rule off the symmetric path (float64, phases quadratic along the chords). The
#: closed form costs about 65 ns a chord (value) and 90 ns (``value_and_grad``) on one core
#: of the 2-core AMD EPYC host, a Gauss node about 1.5 and 2.1 ns in place. Measured in
#: ``jmse`` on ``Seidel(-4, 3, -3, 2.5, 2)`` at field 0.9, u 0.4 (value / value_and_grad,
#: Gauss -> closed form, one core): the steep tier's grid, order 64, 182 / 373 -> 131 / 340
#: ms; the balanced grid, 96, 402 / 792 -> 237 / 544 ms; ``HIGH_STEEP_GRID``, 80, 443 / 1119
#: -> 390 / 1082 ms; but tier 3's grid, 40, 74 / 183 -> 79 / 196 ms, and ``"high"``'s own,
#: 48, 67 / 156 -> 66 / 203 ms (benchmarks/README.md, optimisation log, session 100).
#: The switch at 32, measured in the default with the blocks as they now are (recomputed
#: in the reverse pass; one core, ``ab_compare.py``, 64 -> 32): tier 3 ``hypercube_2``
#: 80.9 / 225 -> 81.9 / 241 ms, tier 2 ``fig1_u_0.5`` 32.3 / 86.3 -> 33.4 / 92.4 ms (log,
#: sessions 100-101), so 64 stands.
_CLOSED_FORM_ORDER = 64
#: The order along the chords that sizes the overlap engine's blocks when the chords are
#: integrated in closed form.
_CLOSED_FORM_BLOCK_ORDER = 16

# The lens's two halves (``_chord_phase``'s ``sides``).
_BOTH = (1.0, -1.0)


def diffraction_limited_otf(r):
    """Aberration-free OTF ``(2/pi)(arccos r - r sqrt(1 - r^2))`` (0 for ``r >= 1``)."""
    r = jnp.abs(r)
    value = (2.0 / math.pi) * (safe_arccos(r) - r * safe_sqrt(1.0 - r * r))
    # NaN stays NaN (r < 1 is false for it).
    return jnp.where((r < 1) | jnp.isnan(r), value, jnp.zeros_like(value))


def _check_aberrations(aberrations, field):
    if not isinstance(aberrations, AbstractAberrations):
        raise TypeError(
            f"aberrations must be a jmse_jax.Seidel or jmse_jax.Zernike, got {type(aberrations)}"
        )
    check_finite_tree("aberrations", aberrations)
    check_range("field", field, 0.0, 1.0)
    check_scalars(aberrations, [("field", field)],
                  "the frequencies may be arrays; for many designs use jax.vmap")


def check_scalars(aberrations, named, hint: str) -> None:
    """``TypeError`` for a ``None`` and ``ValueError`` for an array among ``named`` (pairs of
    name and value) and the Seidel coefficients of ``aberrations``: one design per call
    (``hint`` says where batches go)."""
    if isinstance(aberrations, Seidel):
        named = [*named, *((f"aberrations.{name}", getattr(aberrations, name))
                           for name in Seidel.__dataclass_fields__)]
    for name, value in named:
        if value is None:  # an empty pytree: no other check would see it
            raise TypeError(f"{name} must be a real number, got None")
        shape = tuple(value.shape) if hasattr(value, "shape") else np.shape(value)
        if shape != ():
            raise ValueError(f"{name} must be a scalar (one design), got shape {shape}; {hint}")


# --------------------------------------------------------------------------------------
# "overlap": direct autocorrelation quadrature
# --------------------------------------------------------------------------------------


@functools.cache
def _overlap_rule(n_phi: int, n_t: int, chord_points: int):
    """Host constants of the overlap rule (float64, cached).

    Returns ``frac, w_frac`` (Gauss on [0, 1] for ``phi / phi_max``), ``t_colloc`` (Chebyshev
    points on [-1, 1] where the phase is evaluated along each chord), ``interp``
    (``n_t x chord_points`` Lagrange matrix from those points to the Gauss nodes ``t_j``) and
    ``moment`` (``n_t x chord_points``: ``w_j * interp[j, q]``).
    """
    frac, w_frac = gauss_legendre(n_phi, 0.0, 1.0)
    t, w_t = gauss_legendre(n_t, -1.0, 1.0)
    q = np.arange(chord_points)
    t_colloc = np.cos(np.pi * (q + 0.5) / chord_points)[::-1].copy()
    interp = barycentric_matrix(t_colloc, t)
    return frac, w_frac, t_colloc, interp, interp * w_t[:, None]


@functools.cache
def _even_overlap_rule(n_phi: int, n_t: int, chord_points: int):
    """``_overlap_rule`` for integrands even in ``t``: the Gauss nodes ``t_j >= 0`` alone,
    each weight doubled but the middle node's (odd ``n_t``), so that the half rule sums
    what the whole rule sums. Returns ``frac, w_frac, t_colloc, interp, moment`` with
    ``interp`` and ``moment`` of ``ceil(n_t / 2)`` rows."""
    frac, w_frac, t_colloc, interp, _ = _overlap_rule(n_phi, n_t, chord_points)
    t, w_t = gauss_legendre(n_t, -1.0, 1.0)
    keep = np.flatnonzero(t >= -1e-14)  # the middle node of an odd rule sits at 0
    w_half = np.where(np.abs(t[keep]) > 1e-14, 2.0 * w_t[keep], w_t[keep])
    half = interp[keep]
    return frac, w_frac, t_colloc, half, half * w_half[:, None]


@jax.custom_jvp
def _phase_integral(phase, weights, interp, moment):
    """``sum_i weights_i sum_j w_j exp(i 2 pi (interp @ phase_i)_j)`` as (real, imag).

    ``phase`` (..., chords, Q) holds the phase difference in waves at the collocation points
    of each chord and ``weights`` (..., chords) the chord weights; the sum runs over the last
    two axes of ``phase``. The derivative rule forms the cosine and sine moments per
    collocation point once and takes both the value and the tangent from them, so the
    backward pass costs almost nothing (no array of quadrature-node size is stored or
    recomputed).

    The value alone (no derivative) needs no moments: it contracts the stacked cosine and
    sine at the Gauss nodes with the Gauss weights ``w_j = sum_q moment[j, q]``.

    Both paths take the cosine and sine from ``cos_sin_2pi_stacked`` (one polynomial per
    entry, one loop for both): with ``cos_sin_2pi`` XLA computed the two outputs in two
    loops, each evaluating both half-angle polynomials (benchmarks/README.md).
    """
    trig = cos_sin_2pi_stacked(_phase_at_nodes(phase, interp))  # (..., chords, 2, J)
    parts = jnp.einsum("...kj,j->...k", trig, jnp.sum(moment, axis=-1), precision=EXACT)
    return _sum_pair(weights[..., None] * parts[..., :1], weights[..., None] * parts[..., 1:])


def _phase_at_nodes(phase, interp):
    """The phase at the Gauss nodes along each chord from its values at the collocation
    points."""
    return jnp.einsum("...q,jq->...j", phase, interp, precision=EXACT)


def _phase_moments(phase, interp, moment):
    """Cosine and sine moments per collocation point, each ``(..., chords, Q)``."""
    trig = cos_sin_2pi_stacked(_phase_at_nodes(phase, interp))
    moments = jnp.einsum("...kj,jq->...kq", trig, moment, precision=EXACT)
    return moments[..., 0, :], moments[..., 1, :]


def _contract(weights, moments):
    return jnp.sum(weights * jnp.sum(moments, axis=-1), axis=-1)


@jax.custom_jvp
def _sum_pair(a, b):
    """``(sum(a), sum(b))`` over the last two axes in one variadic reduction.

    XLA's CPU backend hands a plain sum, with its element-wise producers, to a YNNPACK
    fusion that evaluates them several times slower than XLA's own loops; YNNPACK takes no
    variadic reduction, so this one stays an XLA loop, in every program alike. The
    derivative rule keeps the variadic reduction for the value and sums the tangents
    plainly: JAX's own rule for a general reduction builds it as a tree of slices and
    adds, into each of which XLA fused the producers of both parts again.
    """
    zero = jnp.zeros((), a.dtype)
    return jax.lax.reduce((a, b), (zero, zero),
                          lambda x, y: (x[0] + y[0], x[1] + y[1]), (a.ndim - 2, a.ndim - 1))


@_sum_pair.defjvp
def _sum_pair_jvp(primals, tangents):
    da, db = tangents
    return _sum_pair(*primals), (jnp.sum(da, axis=(-2, -1)), jnp.sum(db, axis=(-2, -1)))


@_phase_integral.defjvp
def _phase_integral_jvp(primals, tangents):
    phase, weights, interp, moment = primals
    d_phase, d_weights, _, _ = tangents
    cos_m, sin_m = _phase_moments(phase, interp, moment)
    w = weights[..., None]
    re, im = _sum_pair(w * cos_m, w * sin_m)
    two_pi_w = (2.0 * math.pi) * weights[..., None]
    d_re = _contract(d_weights, cos_m) - jnp.sum(two_pi_w * sin_m * d_phase, axis=(-2, -1))
    d_im = _contract(d_weights, sin_m) + jnp.sum(two_pi_w * cos_m * d_phase, axis=(-2, -1))
    return (re, im), (d_re, d_im)


@jax.custom_jvp
def _even_phase_integral(phase, weights, interp, moment):
    """The real part of ``_phase_integral`` for phases whose cosine part is all there is
    (the rotationally symmetric path of ``_otf_overlap_flat``): the value takes the cosine
    alone, one polynomial per node; the derivative rule forms both moments, since the
    tangent needs the sine's."""
    trig = cos_2pi(_phase_at_nodes(phase, interp))  # (..., chords, J)
    parts = jnp.einsum("...kj,j->...k", trig, jnp.sum(moment, axis=-1), precision=EXACT)
    return jnp.sum(weights * parts, axis=-1)


@_even_phase_integral.defjvp
def _even_phase_integral_jvp(primals, tangents):
    # ``_phase_integral``'s rule, real part (XLA drops the imaginary part's unused sums).
    (re, _), (d_re, _) = _phase_integral_jvp(primals, tangents)
    return re, d_re


def _gauss_chords(phase, chord_w, n_phi, chord_points, interp, moment):
    """Chord integrals by the Gauss rule in ``t`` (phase given at the collocation points)."""
    weights = jnp.broadcast_to(chord_w[:, None, :], (chord_w.shape[0], 2, n_phi))
    return _phase_integral(
        phase.reshape(phase.shape[0], 2 * n_phi, chord_points),
        weights.reshape(-1, 2 * n_phi),
        interp,
        moment,
    )


def _quadratic_chords(aberrations) -> bool:
    degree = aberrations.perpendicular_chord_degree
    return degree is not None and degree <= 2


def _closed_form_chords(aberrations, n_t: int, dtype, symmetric: bool) -> bool:
    """Whether ``_otf_overlap_flat`` integrates the chords off the symmetric path in closed
    form (``_chords.chord_integral``): quadratic along them, a Gauss rule of at least
    ``_CLOSED_FORM_ORDER`` nodes asked for, float64."""
    return (not symmetric and _quadratic_chords(aberrations) and n_t >= _CLOSED_FORM_ORDER
            and not is_single_precision(dtype))


@functools.partial(jax.checkpoint, static_argnums=(9,))
def _chord_phase(aberrations, field, nx, ny, ex, ey, a, sin_phi, t_colloc, sides):
    """Phase difference ``W(xi + nu) - W(xi - nu)`` [waves] at the collocation points of
    every chord, ``(N, halves, n_phi, Q)`` with one entry of ``halves`` per entry of ``sides``
    (``nu`` in cutoff units shifts each copy of the unit-radius pupil by ``nu``).

    Under ``jax.checkpoint``: reverse mode recomputes these few polynomial evaluations
    instead of storing the wavefront's terms at every collocation point (one array of the
    phase's size per term, tens of MB per call in all, which XLA's CPU runtime maps afresh
    and page-faults on every call). ``(nx, ny)`` is ``nu``, ``(ex, ey)`` its direction,
    ``a`` each chord's distance from the lens's mid-line and ``sin_phi`` its half-length;
    ``sides``: the lens's halves to take (the symmetric path takes one).
    """
    # Chord points xi = side * a * e + t sin(phi) * e_perp, e_perp = (-ey, ex), on each half.
    side = jnp.asarray(sides, a.dtype)
    along = side[None, :, None, None] * a[:, None, :, None]  # (N, halves, n_phi, 1)
    across = (sin_phi[:, :, None] * t_colloc[None, None, :])[:, None, :, :]  # (N, 1, n_phi, Q)
    ex4, ey4 = ex[:, None, None, None], ey[:, None, None, None]
    xi_x = along * ex4 - across * ey4
    xi_y = along * ey4 + across * ex4
    dx, dy = nx[:, None, None, None], ny[:, None, None, None]
    return aberrations.difference(xi_x, xi_y, dx, dy, field)


def _otf_overlap_flat(aberrations, nu_x, nu_y, field, n_phi, n_t, dtype, zero_slope=None,
                      symmetric=False):
    """Overlap-quadrature OTF at a flat vector of nodes; returns (real, imag).

    ``zero_slope``: the wavefront's mean gradient (``_mean_gradient``), which gives ``Im H``
    its derivative at ``nu = 0`` (``Re H`` has a cone there: derivative 0); without it both
    derivatives there are 0 (``jmse`` never evaluates ``nu = 0``).

    ``symmetric``: the wavefront is rotationally symmetric, in its value and in every
    tangent (the one-ray plans' ``symmetric_part``). Its phase difference is then odd
    through the lens's centre and even along each chord, so ``H`` is real and the rule
    takes one half of the lens, the nodes ``t >= 0`` of each chord and the cosine alone: a
    quarter of the nodes, each one polynomial instead of two. The sum is the whole rule's
    to rounding; the imaginary part is returned as exact zeros. Where the phase is also
    quadratic along the chords (``perpendicular_chord_degree <= 2``: Seidel wavefronts and
    radial Zernike terms up to ``Z11``), it is ``p0 + gamma t^2`` there and each chord is
    integrated in closed form (``_chords.even_chord_integral``, from the phase at ``t = 0``
    and ``t = 1``): exact along the chords, so ``n_t`` is not used.

    Off the symmetric path, for such wavefronts in float64 with ``n_t >=
    _CLOSED_FORM_ORDER``, each chord is likewise integrated in closed form
    (``_chords.chord_integral``, from the phase at ``t = -1, 0, 1``) instead of by the Gauss
    rule of order ``n_t``."""
    # Off the symmetric path, quadratic along the chords and a long Gauss rule asked for:
    # each chord in closed form (``_chords.chord_integral``, from the phase at t = -1, 0, 1).
    exact = _closed_form_chords(aberrations, n_t, dtype, symmetric)
    # Symmetric and quadratic along the chords (Seidel's and the radial Zernike terms to
    # rho^4): each chord's phase is p0 + gamma t^2, integrated in closed form.
    even_exact = symmetric and _quadratic_chords(aberrations)
    degree = aberrations.chord_degree
    chord_points = n_t if degree is None or degree + 1 >= n_t else degree + 1
    rule = _even_overlap_rule if symmetric else _overlap_rule
    frac, w_frac, t_colloc, interp, moment = (
        jnp.asarray(a, dtype) for a in rule(n_phi, n_t, chord_points)
    )
    if even_exact:  # the phase at t = 0 and 1 fixes p0 + gamma t^2
        t_colloc = jnp.asarray([0.0, 1.0], dtype)
    s = safe_norm(nu_x, nu_y)
    interior = (s > 0) & (s < 1)
    # Double-where: the singular points s = 0 (direction undefined) and s >= 1 (empty
    # overlap, infinite d arccos/ds) are computed at a harmless stand-in and selected away.
    s_safe = jnp.where(interior, s, 0.5)
    nx = jnp.where(interior, nu_x, 0.5)
    ny = jnp.where(interior, nu_y, 0.0)
    ex, ey = nx / s_safe, ny / s_safe  # unit vector along nu
    phi_max = jnp.arccos(s_safe)
    phi = phi_max[:, None] * frac[None, :]  # (N, n_phi)
    cos_phi, sin_phi = cos_sin_2pi(phi * (0.5 / math.pi))  # faster than jnp.cos, jnp.sin
    a = cos_phi - s_safe[:, None]  # distance of the chord from the lens's mid-line
    # Stored once: XLA would otherwise recompute sin(phi) and cos(phi) at every collocation
    # point of the chord phase, in each of the fusions that use them (the wavefront and,
    # under reverse mode, each coefficient's derivative).
    a, sin_phi = materialise(a, sin_phi)
    chord_w = phi_max[:, None] * w_frac[None, :] * sin_phi**2  # (N, n_phi)
    if symmetric:  # one half, twice: its mirror image through the centre is its conjugate
        phase = _chord_phase(aberrations, field, nx, ny, ex, ey, a, sin_phi, t_colloc, (1.0,))
        if even_exact:
            chords = even_chord_integral(phase[:, 0, :, 0], phase[:, 0, :, 1])
            re = jnp.sum((2.0 * chord_w) * chords, axis=1)
        else:
            re = _even_phase_integral(phase[:, 0], 2.0 * chord_w, interp, moment)
        im = jnp.zeros_like(re)
    elif exact:
        # The phase at t = -1, 0, 1 (which fixes the quadratic) as three arrays: sliced
        # from one (..., 3) array, their cotangents met in one loop over that short axis,
        # into which XLA fused the derivative rule's moments and evaluated them for each
        # entry (a recomputed block's reverse pass 4x slower).
        pm, p0, pp = (
            _chord_phase(aberrations, field, nx, ny, ex, ey, a, sin_phi,
                         jnp.asarray([t], dtype), _BOTH)[..., 0] for t in (-1.0, 0.0, 1.0))
        j_re, j_im = chord_integral(pm, p0, pp)
        w = chord_w[:, None, :]
        # One variadic sum, so that the kernel is evaluated once for both parts.
        re, im = _sum_pair(w * j_re, w * j_im)
    else:
        phase = _chord_phase(aberrations, field, nx, ny, ex, ey, a, sin_phi, t_colloc, _BOTH)
        re, im = _gauss_chords(phase, chord_w, n_phi, chord_points, interp, moment)
    # Rescale by exact lens area / rule's lens area: exact for the unaberrated pupil.
    rule_area = 4.0 * jnp.sum(chord_w, axis=1)
    scale = diffraction_limited_otf(s_safe) / rule_area
    re = jnp.where(interior, re * scale, jnp.where(s == 0, 1.0, 0.0))
    if zero_slope is None:
        im = jnp.where(interior, im * scale, 0.0)
    else:  # Im H = 4 pi nu . <grad W> + O(|nu|^3) at nu = 0: value 0, the right slope
        gx, gy = zero_slope
        im = jnp.where(interior, im * scale,
                       jnp.where(s == 0, (4.0 * math.pi) * (nu_x * gx + nu_y * gy), 0.0))
    return re, im


def _mean_gradient(aberrations, field, dtype):
    """The wavefront's mean gradient over the pupil, ``(<dW/dx>, <dW/dy>)``, from the
    divergence theorem: ``(1/pi) oint W n ds``, by the trapezoid rule on the rim (exact for
    polynomials of degree below 64)."""
    theta = jnp.asarray(2.0 * math.pi * np.arange(64) / 64, dtype)
    cos_t, sin_t = jnp.cos(theta), jnp.sin(theta)
    rim = aberrations(cos_t, sin_t, field)
    return (2.0 / 64) * jnp.sum(rim * cos_t), (2.0 / 64) * jnp.sum(rim * sin_t)


def along_chord_order(n_t: int, dtype) -> int:
    """The Gauss order along the chords that the overlap engine uses for a requested
    ``n_t``: ``n_t`` in float64, rounded up to a multiple of 8 in float32.

    The nodes along a chord are the minor axis of the engine's arrays. In float32 XLA's CPU
    loops over that axis fill their 16-lane vectors only at multiples of 8 (one core, 224
    frequencies x 40 chords, value / value_and_grad: order 13-14 0.50-0.53 / 0.76-0.78 ms,
    16 0.19 / 0.39 ms, 17 0.25 / 0.54 ms, 20 0.31 / 0.50 ms, 24 0.25 / 0.45 ms), so the
    rounded order is both cheaper and more accurate. In float64 the cost steps at multiples
    of 4 and 8 are small (13-16 alike, 17-20 alike) and the order is kept as asked, so
    float64 results do not move.
    """
    if is_single_precision(dtype):
        return -(-n_t // 8) * 8
    return n_t


def _otf_overlap(aberrations, nu_x, nu_y, field, nodes, remat=False, zero_slope=False,
                 symmetric=False):
    """Overlap-engine OTF at ``(nu_x, nu_y)``; ``remat``: when the nodes span several blocks,
    reverse mode recomputes each block instead of storing its chord moments (less memory,
    more time); ``zero_slope``: give ``Im H`` its derivative at ``nu = 0`` (``otf``);
    ``symmetric``: the wavefront is rotationally symmetric in value and tangents, so a
    quarter of the rule serves (``_otf_overlap_flat``)."""
    n_phi, n_t = nodes
    dtype = common_dtype(aberrations, nu_x, nu_y, field)
    n_t = along_chord_order(n_t, dtype)
    nu_x, nu_y = jnp.broadcast_arrays(jnp.asarray(nu_x, dtype), jnp.asarray(nu_y, dtype))
    shape = nu_x.shape
    flat_x, flat_y = nu_x.reshape(-1), nu_y.reshape(-1)
    field = jnp.asarray(field, dtype)
    n = flat_x.shape[0]
    slope = _mean_gradient(aberrations, field, dtype) if zero_slope else None
    closed_form = _closed_form_chords(aberrations, n_t, dtype, symmetric)
    # Closed-form chords hold a few arrays per chord, not one per Gauss node along it.
    block = max(1, min(n, _OVERLAP_BLOCK * 1024 // (n_phi * (_CLOSED_FORM_BLOCK_ORDER
                                                            if closed_form else n_t))))
    if n <= block:
        re, im = _otf_overlap_flat(aberrations, flat_x, flat_y, field, n_phi, n_t, dtype,
                                   slope, symmetric)
    else:
        # Equal blocks no larger than the cap: the fewest blocks, padded by < n_blocks nodes
        # (a fixed block size padded the last block by up to a whole block of dead work).
        n_blocks = -(-n // block)
        block = -(-n // n_blocks)
        pad = n_blocks * block - n
        px = jnp.pad(flat_x, (0, pad)).reshape(n_blocks, block)
        py = jnp.pad(flat_y, (0, pad)).reshape(n_blocks, block)

        def one_block(xy):
            return _otf_overlap_flat(aberrations, xy[0], xy[1], field, n_phi, n_t, dtype,
                                     slope, symmetric)

        # Closed-form blocks are recomputed too. Stored (session 100), they raised the
        # scratch of the default's value_and_grad program, which every tier shares, from 24
        # to 177 MB, and the Fig. 1 point's value_and_grad from 2.1 to 4.2-5.1 ms (one
        # core): XLA's CPU runtime maps scratch afresh on every call (merit._REMAT_OTF).
        if remat:
            one_block = jax.checkpoint(one_block)

        re, im = jax.lax.map(one_block, (px, py))
        re, im = re.reshape(-1)[:n], im.reshape(-1)[:n]
    return jax.lax.complex(re, im).reshape(shape)


# --------------------------------------------------------------------------------------
# Square-grid engines: "nudft" and "fft"
# --------------------------------------------------------------------------------------


def pupil_psf(aberrations, field, B: int, dtype=None):
    """PSF of the ``B x B`` sampled pupil on the ``2B x 2B`` FFT grid (unnormalised).

    Returns ``|FFT2(P_padded)|**2`` in NumPy FFT order, rows along ``y``, columns along ``x``.
    """
    grid = SquareGrid(B)
    dtype = dtype or common_dtype(aberrations, field)
    x, y = jnp.asarray(grid.x, dtype), jnp.asarray(grid.y, dtype)
    inside = jnp.asarray(grid.weights > 0)
    angle = (2.0 * math.pi) * aberrations(x, y, jnp.asarray(field, dtype))
    pupil = jnp.where(inside, jax.lax.complex(jnp.cos(angle), jnp.sin(angle)), 0.0)
    padded = jnp.zeros((2 * B, 2 * B), pupil.dtype).at[:B, :B].set(pupil)
    spectrum = jnp.fft.fft2(padded)
    return jnp.real(spectrum) ** 2 + jnp.imag(spectrum) ** 2


def otf_fft_grid(aberrations, field, B: int, dtype=None):
    """Baseline OTF on the ``2B x 2B`` lag grid: ``H[k_y, k_x]`` at ``nu = k / B`` (FFT order).

    Berkner & Shroff Sec. III-A: pupil ``B x B`` -> zero-pad to ``2B`` -> FFT -> PSF -> FFT.
    Normalised so that ``H[0, 0] = 1``.
    """
    _check_aberrations(aberrations, field)
    check_count("B", B)
    psf = pupil_psf(aberrations, field, B, dtype)
    lag = jnp.fft.ifft2(psf)
    return lag / jnp.real(lag[0, 0])


def _otf_nudft(aberrations, nu_x, nu_y, field, B):
    dtype = common_dtype(aberrations, nu_x, nu_y, field)
    nu_x, nu_y = jnp.broadcast_arrays(jnp.asarray(nu_x, dtype), jnp.asarray(nu_y, dtype))
    psf = pupil_psf(aberrations, field, B, dtype)
    m = jnp.asarray(np.fft.fftfreq(2 * B, 1.0 / (2 * B)), dtype)  # integer PSF frequencies
    # Continuous lag tau = nu * B pupil samples; A(tau) = sum_m PSF_m exp(2 pi i m.tau / 2B).
    scale = (2.0 * math.pi / (2 * B)) * B
    flat_x, flat_y = nu_x.reshape(-1), nu_y.reshape(-1)
    ang_x = scale * flat_x[:, None] * m[None, :]  # (N, 2B)
    ang_y = scale * flat_y[:, None] * m[None, :]
    ex = jax.lax.complex(jnp.cos(ang_x), jnp.sin(ang_x))
    ey = jax.lax.complex(jnp.cos(ang_y), jnp.sin(ang_y))
    rows = jnp.matmul(ey, psf.astype(ex.dtype), precision=EXACT)  # (N, 2B): sum over y
    values = (jnp.sum(rows * ex, axis=1) / jnp.sum(psf)).reshape(nu_x.shape)
    # The sum is periodic in nu (period 2); the OTF vanishes past the cutoff.
    return jnp.where(safe_norm(nu_x, nu_y) >= 1, jnp.zeros_like(values), values)


def _otf_fft(aberrations, nu_x, nu_y, field, B):
    dtype = common_dtype(aberrations, nu_x, nu_y, field)
    nu_x, nu_y = jnp.broadcast_arrays(jnp.asarray(nu_x, dtype), jnp.asarray(nu_y, dtype))
    grid = jnp.fft.fftshift(otf_fft_grid(aberrations, field, B, dtype))  # lags -B .. B-1
    # Bilinear interpolation in lag units; lag index k maps to array index k + B.
    kx = jnp.clip(nu_x * B + B, 0.0, 2 * B - 1.0)
    ky = jnp.clip(nu_y * B + B, 0.0, 2 * B - 1.0)
    ix0 = jnp.clip(jnp.floor(kx).astype(jnp.int32), 0, 2 * B - 2)
    iy0 = jnp.clip(jnp.floor(ky).astype(jnp.int32), 0, 2 * B - 2)
    fx, fy = kx - ix0, ky - iy0
    g00 = grid[iy0, ix0]
    g01 = grid[iy0, ix0 + 1]
    g10 = grid[iy0 + 1, ix0]
    g11 = grid[iy0 + 1, ix0 + 1]
    value = (1 - fy) * ((1 - fx) * g00 + fx * g01) + fy * ((1 - fx) * g10 + fx * g11)
    outside = safe_norm(nu_x, nu_y) >= 1
    return jnp.where(outside, jnp.zeros_like(value), value)


#: Overlap nodes per axis that ``otf`` asks for before it warns: ``1.25 E + 2.5 R + 12``,
#: with ``E`` the largest spread (max - min, in waves) of the phase difference
#: ``W(p + nu) - W(p - nu)`` across an overlap lens over the frequencies asked for, and ``R``
#: that of its residual after the best-fitting plane (``_phase_spread``). A phase
#: difference linear across the lens (defocus, astigmatism) needs about ``E + 12`` nodes for
#: 1e-6; a curved one (coma's is quadratic) about ``4.5 R`` (10 waves of coma at field 1:
#: ``E = R = 8.9``, 40 nodes, where the former rule ``2 E + 14``, fitted on |nu| up to 0.3,
#: 0.6 or 1, asked for 32 and let a 5.2e-5 error pass; session 79). Fitted on single Seidel
#: terms of 2-12 waves and random mixtures at |nu| up to 0.999 against (192, 192).
_SPREAD_LINEAR, _SPREAD_CURVED, _SPREAD_OFFSET = 1.25, 2.5, 12.0


@jax.jit
def _phase_spread(aberrations, field, s_max):
    """``(E, R)``: largest ``max - min`` of ``D = W(p + s e) - W(p - s e)`` over points ``p``
    of the overlap lens, and of ``D`` less its least-squares plane over the same points, on
    12 shifts ``s`` up to ``s_max`` x 12 directions ``e`` x 15 x 15 points (a sampled
    estimate, for ``otf``'s warning)."""
    dtype = common_dtype(aberrations, field, s_max)
    s = jnp.minimum(s_max, 0.999) * jnp.asarray(np.arange(1, 13) / 12, dtype)[:, None, None]
    angle = jnp.asarray(np.arange(12) * math.pi / 12, dtype)[None, :, None]
    ex, ey = jnp.cos(angle), jnp.sin(angle)
    g = np.linspace(-1.0, 1.0, 15)
    gu, gv = (jnp.asarray(a.ravel(), dtype)[None, None, :] for a in np.meshgrid(g, g))
    along, across = gu * (1 - s), gv * jnp.sqrt(1 - s * s)  # the lens's bounding box
    px, py = along * ex - across * ey, along * ey + across * ex
    inside = ((px + s * ex) ** 2 + (py + s * ey) ** 2 <= 1) & (
        (px - s * ex) ** 2 + (py - s * ey) ** 2 <= 1)
    diff = (aberrations(px + s * ex, py + s * ey, field)
            - aberrations(px - s * ex, py - s * ey, field))
    # The plane in the lens's scaled coordinates (gu, gv in [-1, 1]: the same planes as in
    # along, across, and well conditioned in float32 when the lens is thin).
    one = jnp.ones_like(diff)
    basis = jnp.stack([one, gu * one, gv * one], -1)
    weight = inside.astype(dtype)
    normal = (jnp.einsum("...pi,...pj,...p->...ij", basis, basis, weight)
              + 1e-12 * jnp.eye(3, dtype=dtype))
    plane = jnp.linalg.solve(normal, jnp.einsum("...pi,...p,...p->...i", basis, diff,
                                                weight)[..., None])[..., 0]
    residual = diff - jnp.einsum("...pi,...i->...p", basis, plane)

    def spread(d):
        high = jnp.max(jnp.where(inside, d, -jnp.inf), axis=-1)
        low = jnp.min(jnp.where(inside, d, jnp.inf), axis=-1)
        return jnp.max(jnp.where(high >= low, high - low, 0.0))

    return spread(diff), spread(residual)


def _warn_if_coarse(aberrations, nu_x, nu_y, field, nodes):
    """An ``AccuracyWarning`` when the overlap ``nodes`` look too few for the design at the
    frequencies asked for (concrete input only)."""
    if not is_concrete((aberrations, nu_x, nu_y, field)):
        return
    s_max = float(np.max(np.hypot(np.asarray(nu_x), np.asarray(nu_y)), initial=0.0))
    if s_max <= 0.0:
        return
    # Evaluated now even inside a caller's jit (constant inputs there).
    with jax.ensure_compile_time_eval():
        spread, curved = (float(x) for x in _phase_spread(
            aberrations, jnp.asarray(field, float), min(s_max, 1.0)))
    need = math.ceil(_SPREAD_LINEAR * spread + _SPREAD_CURVED * curved + _SPREAD_OFFSET)
    if min(nodes) < need:
        warnings.warn(
            f"otf: nodes={tuple(nodes)} may be too few for this design at |nu| up to "
            f"{s_max:.3g}: the phase difference across the overlap spreads over "
            f"{spread:.3g} waves; about nodes=({need}, {need}) holds 1e-6 (compare two "
            f"counts)", AccuracyWarning, stacklevel=3)


def otf(
    aberrations: AbstractAberrations,
    nu_x,
    nu_y,
    field=0.0,
    method: str = "overlap",
    *,
    nodes: tuple[int, int] = (32, 32),
    B: int = 64,
):
    """Complex OTF ``H`` of the aberrated pupil at arbitrary frequency nodes.

    Parameters
    ----------
    aberrations : Seidel or Zernike [waves]
    nu_x, nu_y : array [units of the incoherent cutoff 1/(lambda N)]
        Frequency nodes; broadcast against each other.
    field : float in [0, 1] [fraction of full field]
    method : {"overlap", "nudft", "fft"}
        Engine (see module docstring). ``"overlap"`` is the accurate one.
    nodes : (int, int)
        ``(n_phi, n_t)`` Gauss nodes across/along each half of the overlap lens
        (``"overlap"``). About ``n >= pi * |2 s grad W|_max + 12`` per axis reaches 1e-10.
        When the inputs are concrete, an ``AccuracyWarning`` says when they look too few for
        1e-6 (``_phase_spread``); with frequencies up to the cutoff the default (32, 32)
        is quiet up to 8 waves of defocus or 6 of coma at full field (cautious: they hold
        1e-6 at (32, 32) up to 10 and 8 waves). For Seidel wavefronts in float64, ``n_t >=
        64`` integrates each chord in closed form instead (exact along the chords, and
        cheaper than so long a Gauss rule).
    B : int
        Square pupil grid size (``"nudft"``, ``"fft"``).

    Returns
    -------
    complex array, the broadcast shape of ``nu_x`` and ``nu_y``; ``H(0) = 1``.

    Notes
    -----
    Differentiable in every float input (coefficients, ``field``, ``nu``); the gradient is
    finite at ``nu = 0`` (where ``Re H`` has a cone and its gradient returned is 0, while
    ``Im H`` has the slope ``4 pi <grad W>``, the mean wavefront gradient: a tilt's) and at
    ``|nu| = 1``. Under ``jit`` or ``vmap``, where values cannot be checked, a non-finite
    input or a ``field`` outside [0, 1] gives NaN (at the frequencies concerned, or
    everywhere for a bad design) with a zero gradient.

    Examples
    --------
    >>> import jmse_jax
    >>> h = jmse_jax.otf(jmse_jax.Seidel(), 0.5, 0.0)
    >>> round(float(h.real), 8)  # (2/pi)(arccos 0.5 - 0.5 sqrt(0.75))
    0.39100222
    """
    check_choice("method", method, OTF_METHODS)
    _check_aberrations(aberrations, field)
    check_range("nu_x", nu_x)
    check_range("nu_y", nu_y)
    if method == "overlap":
        if not (isinstance(nodes, (tuple, list)) and len(nodes) == 2):
            raise ValueError(f"nodes must be a pair (n_phi, n_t), got {nodes!r}")
        check_count("nodes[0] (n_phi)", nodes[0])
        check_count("nodes[1] (n_t)", nodes[1])
        _warn_if_coarse(aberrations, nu_x, nu_y, field, nodes)
        return _compiled_otf(method, (int(nodes[0]), int(nodes[1])), aberrations, nu_x, nu_y,
                             field)
    check_count("B", B)
    return _compiled_otf(method, int(B), aberrations, nu_x, nu_y, field)


@functools.partial(jax.jit, static_argnums=(0, 1))
def _compiled_otf(method, setting, aberrations, nu_x, nu_y, field):
    """The engine ``method`` (``setting``: its nodes or ``B``), compiled once per input shape
    (outside ``jit`` the engines would otherwise run primitive by primitive).

    Traced input that the checks could not see (a non-finite coefficient, ``field`` or
    ``nu``, or ``field`` outside [0, 1]) gives NaN at the nodes concerned (every node, for a
    bad design) instead of a plausible number; the engines then run on a harmless stand-in,
    so the gradient at the good nodes stays finite.
    """
    design_ok = all_finite((aberrations, field)) & (field >= 0) & (field <= 1)
    nu_x, nu_y = jnp.broadcast_arrays(nu_x, nu_y)
    ok = design_ok & jnp.isfinite(nu_x) & jnp.isfinite(nu_y)
    aberrations, field = jax.tree_util.tree_map(
        lambda leaf: jnp.where(design_ok, leaf, jnp.zeros_like(leaf)), (aberrations, field))
    nu_x = jnp.where(ok, nu_x, jnp.zeros_like(nu_x))
    nu_y = jnp.where(ok, nu_y, jnp.zeros_like(nu_y))
    if method == "overlap":
        h = _otf_overlap(aberrations, nu_x, nu_y, field, setting, zero_slope=True)
    elif method == "nudft":
        h = _otf_nudft(aberrations, nu_x, nu_y, field, setting)
    else:
        h = _otf_fft(aberrations, nu_x, nu_y, field, setting)
    return jnp.where(ok, h, jnp.full_like(h, complex(math.nan, math.nan)))
