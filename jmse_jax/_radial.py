"""The band integral along one ray, for rotationally symmetric wavefronts.

When the wavefront less its tilt depends on ``rho`` only (any design on the axis, or a
Zernike set of ``m = 0`` terms) and both spectra are isotropic, ``S_e`` depends on
``r = |nu|`` only, and the integral over the square band ``[-u, u]**2`` is one-dimensional:

    \\iint_band S_e d^2 nu = \\int_0^{sqrt(2) u} S_e(r) Theta(r) r dr,

where ``Theta(r)`` is the angle of the circle of radius ``r`` that lies inside the square:
``2 pi`` for ``r <= u`` and ``2 pi - 8 arccos(u / r)`` for ``u < r <= sqrt(2) u``. The OTF is
then needed at a few dozen radii instead of thousands of nodes over the quadrant, and ``S_e``
at a few thousand radii instead of a polar grid (``_merit``).

The ray is cut at the two points where the integrand is not smooth: ``r = u`` (``Theta`` has
a square-root corner there) and the cutoff ``r = 1`` (beyond it ``H = 0`` and ``S_e = S_x``).
The pieces, for any ``u``:

- ``A``: ``r in [0, min(u, 1)]``, ``Theta = 2 pi``, ``S_e`` from the OTF, on the radial
  panels of the polar rule (``_quadrature._RADIAL_EDGES``) scaled to the piece;
- ``B``: ``r in [u, min(sqrt(2) u, 1)]`` (empty when ``u >= 1``), ``S_e`` from the OTF, with
  ``r = u + L v**2`` so that the corner at ``r = u`` becomes smooth in ``v``;
- ``C``: beyond the cutoff, ``S_x`` alone: ``r in [1, u]`` (``u > 1``) and
  ``r in [max(u, 1), sqrt(2) u]`` (again with ``r = lo + L v**2``).

Where a piece ends at the cutoff, ``H`` behaves like ``(1 - r)**(3/2)``. A map that makes
``sqrt(1 - r)`` smooth there helped only the aberration-free lens (1e-10 -> 1e-15 at 24
nodes) and cost aberrated ones more (defocus -5 at ``u = 1``: 1e-8 -> 8e-7 at 40 nodes, the
ripples near the panel's start losing nodes), so the pieces are not mapped.
Empty pieces have zero length, hence zero weights, so one static program serves every ``u``.
The OTF is evaluated on coarse Gauss nodes of ``A`` and ``B`` (per panel, as along the polar
rule's rays) by the overlap engine (along ``nu_x``) and interpolated polynomially, panel by
panel, to fine nodes on evenly spread sub-panels (``_fine_rule``).

At high SNR ``S_e`` has a peak of height ``S_x`` and half-width ``sqrt(S_n / S_x) / |H'|`` at
each zero of the (real) OTF along the ray, narrower than the fine nodes above a peak ratio
``S_x / S_n`` of about 1e8: the plain fine rule was 7.4e-5, 1.6e-3 and 2.6e-2 off at 1.6e8,
1.6e9 and 1.6e10 on 6 waves of defocus, and its gradient 30 times off at 1.6e8.
``_zero_peaks`` finds each such zero and integrates a model of its peak in closed form
(4e-10 at 1.6e10; ``benchmarks/low_noise.py``). It costs about 0.1 ms of the value and
0.1-0.3 ms of ``value_and_grad`` per design (one core; the ray alone takes 0.35-0.5 / 0.6-0.9
ms), and a few seconds of each program's compile.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._numerics import EXACT, barycentric_matrix, gauss_legendre, safe_arccos
from ._otf import _otf_overlap
from ._quadrature import _RADIAL_EDGES, OUTER_NODES, _radial_counts

__all__ = ["radial_band_integral", "radial_counts"]

#: Largest Gauss order of the fine rule's sub-panels (see ``_fine_rule``).
_SUB_PANEL = 48


#: Floors of the fine S_e counts along the ray on ``A`` and ``B`` (``radial_counts``).
_MIN_FINE = (12800, 3200)

#: Smallest overlap order along the chords on the ray (``radial_band_integral``). The ray has
#: a hundred OTF nodes, so a higher order costs little, and symmetric designs need it where
#: a polar grid may not: ``fast``'s 16 held on the bank's off-axis cases but moved the one-ray
#: value of ``spherical_6_balanced`` from 6e-7 to 1.6e-4 (24: 6e-7).
_MIN_ALONG = 24

#: Private switch for studies (benchmarks/low_noise.py, test_radial): False drops the
#: closed-form peaks of ``_zero_peaks``.
_SUBTRACT = True


class _SubPanels(NamedTuple):
    """Host description of a fine rule's sub-panels: ``sizes`` (P,), their node counts, and
    ``edges`` (P + 1,), their ends in the rule's variable."""

    sizes: np.ndarray
    edges: np.ndarray


def radial_counts(nodes: tuple[int, int], se_nodes: tuple[int, int]):
    """``(coarse A, coarse B, fine A, fine B)`` node counts along the ray for a polar grid.

    The coarse counts are 1.5 times the grid's radial count on ``A`` and the grid's count on
    ``B``, and the fine counts twice the grid's radial S_e count on ``A`` and once on ``B``
    (a third of ``A``'s length or less), at least ``_MIN_FINE``. With these the one-ray
    result is at least as accurate as the polar grid it stands in for, for every preset:

    - coarse: the OTF's ripples set the accuracy on ``A``. On 6 waves of defocus at
      ``u = 0.2``, 36 nodes (the fast grid's 1.5 x 24) leave 1.3e-5 (the fast polar grid:
      3.6e-4), 48 leave 2.7e-9 and 60 (the default's) 3e-13. A floor of 60 would cost the
      fast preset 0.7 ms per design (1.0 -> 1.7 ms) for accuracy its polar grid lacks;
    - fine: ``S_e`` has narrow ridges along the OTF's zeros, the narrower the higher the SNR and the
      stronger the aberration (the floor costs the fast preset 0.35 ms). With noise 1e-4 and 6 waves
      of defocus at ``u = 0.2``, 3200 nodes on ``A`` leave 1.4e-4, 4800 leave 8e-7, 6400 leave 1e-9
      and 9600 leave 8e-11; on a design of strength 23 at ``u = 0.84`` (noise 1.5e-3), 6400 leave
      5.8e-5, 12800 leave 2.2e-7 and 25600 leave 3e-9. The polar grids of the presets are 1e-3 to
      1e-2 off on such designs: the polar grid integrates each ray at its own node positions, so its
      rays' errors partly cancel, but it cannot afford thousands of nodes per ray.
    """
    n_r, n_fine = int(nodes[0]), int(se_nodes[0])
    return (-(-3 * n_r // 2), n_r, max(2 * n_fine, _MIN_FINE[0]),
            max(OUTER_NODES, n_fine, _MIN_FINE[1]))


def _fine_rule(edges, coarse_counts, fine_counts):
    """Host rules on ``[edges[0], edges[-1]]``: the coarse composite Gauss rule (``counts``
    per panel), a fine one whose panels split each coarse panel into equal sub-panels of at
    most ``_SUB_PANEL`` Gauss nodes, and per coarse panel the interpolation matrix from its
    coarse nodes to its fine ones (polynomial on the panel).

    Sub-panels keep the fine nodes evenly spread (one Gauss rule of thousands of nodes
    crowds them at the panel ends, and costs seconds to build).
    """
    coarse, fine, weights, blocks, sub_edges, sub_sizes = [], [], [], [], [edges[0]], []
    for a, b, k_c, k_f in zip(edges[:-1], edges[1:], coarse_counts, fine_counts, strict=True):
        x_c, _ = gauss_legendre(k_c, a, b)
        pieces = -(-k_f // _SUB_PANEL)
        cuts = np.linspace(a, b, pieces + 1)
        rules = [gauss_legendre(-(-k_f // pieces), lo, hi)
                 for lo, hi in zip(cuts[:-1], cuts[1:], strict=True)]
        x_f = np.concatenate([x for x, _ in rules])
        coarse.append(x_c)
        fine.append(x_f)
        weights.append(np.concatenate([w for _, w in rules]))
        blocks.append(barycentric_matrix(x_c, x_f))
        sub_edges.extend(cuts[1:])
        sub_sizes.extend(len(x) for x, _ in rules)
    return (np.concatenate(coarse), np.concatenate(fine), np.concatenate(weights),
            tuple(blocks), _SubPanels(np.asarray(sub_sizes), np.asarray(sub_edges)))


def _interpolate(blocks, h, dtype):
    """The coarse values ``h`` (panels' nodes in order) at the fine nodes, panel by panel."""
    parts, start = [], 0
    for block in blocks:
        stop = start + block.shape[1]
        parts.append(jnp.matmul(jnp.asarray(block, dtype), h[start:stop], precision=EXACT))
        start = stop
    return jnp.concatenate(parts)


@functools.cache
def _ray_rules(n_a: int, n_b: int, m_a: int, m_b: int):
    """Host rules of pieces ``A`` (in ``t = r / min(u, 1)``, on the polar rule's radial
    panels) and ``B`` (in ``v``, one panel): ``(coarse, fine, fine weights, interpolation blocks)``
    for each."""
    piece_a = _fine_rule(_RADIAL_EDGES, _radial_counts(n_a), _radial_counts(m_a))
    piece_b = _fine_rule((0.0, 1.0), (n_b,), (m_b,))
    return piece_a, piece_b


#: ``_zero_peaks`` looks for the OTF's zeros in blocks of this many fine intervals along the
#: ray, and integrates the first narrow peak in each of the first ``_PEAKS`` blocks that
#: hold one in closed form, nearest the axis first, where ``S_x`` is largest. On the axis the
#: zeros are hundreds of fine nodes apart (6 waves of defocus at u = 0.2 have 7 along the
#: ray; 20 waves at u = 1 about 40, of which the outer ones keep the fine rule's sum).
_BLOCK = 64
_PEAKS = 24

#: ``_zero_peaks`` leaves a peak to the fine rule when its half-width exceeds this fraction
#: of its sub-panel (48 Gauss nodes integrate such a peak to rounding).
_RESOLVED = 0.25


def _model_integral(r0, c, k, z):
    """``int M(z) (r0 + c z) dz`` at ``z`` (an antiderivative) for ``_zero_peaks``' model
    ``M(z) = 1 / U + k_s z / U - k_q z^3 / U^2 - k_t z / U^2``, ``U = 1 + z^2``
    (``k = (k_s, k_q, k_t)``)."""
    k_s, k_q, k_t = k
    arctan = jnp.arctan(z)
    u = 1.0 + z * z
    log_u = 0.5 * jnp.log(u)
    at_r0 = arctan + k_s * log_u - k_q * (log_u + 0.5 / u) + k_t * 0.5 / u
    at_z = (log_u + k_s * (z - arctan) - k_q * (z - 1.5 * arctan + 0.5 * z / u)
            - k_t * (0.5 * arctan - 0.5 * z / u))
    return r0 * at_r0 + c * at_z


def _window_change(x, bare, begin, end, lower, upper, x0, c, k, span):
    """Per peak (``(P,)`` each but ``x`` and ``bare``, the fine nodes and bare weights): the
    closed-form integral of the model ``M((x - x0) / c) (x0 + c z)`` of ``_model_integral``
    over the window ``[lower, upper]`` less the fine rule's sum of ``M`` over the window's
    nodes ``begin .. end - 1`` (at most ``span``): what replaces the rule's sum there."""
    index = begin[:, None] + jnp.arange(span)
    inside = index < end[:, None]
    index = jnp.minimum(index, x.shape[0] - 1)
    z = (x[index] - x0[:, None]) / c[:, None]
    u = 1.0 + z * z
    k_s, k_q, k_t = (a[:, None] for a in k)
    model = (1.0 + k_s * z) / u - (k_q * z * z + k_t) * z / (u * u)
    summed = jnp.sum(jnp.where(inside, bare[index] * model, 0.0), axis=-1)
    exact = c * (_model_integral(x0, c, k, (upper - x0) / c)
                 - _model_integral(x0, c, k, (lower - x0) / c))
    return exact - summed


def _cubic(x, y, z):
    """Value, first and second derivative at ``z`` of the cubic through ``(x, y)`` (last axis
    4), from Newton's divided differences."""
    c = [y[..., i] for i in range(4)]
    for level in range(1, 4):
        for i in range(3, level - 1, -1):
            c[i] = (c[i] - c[i - 1]) / (x[..., i] - x[..., i - level])
    p, dp, d2p = c[3], jnp.zeros_like(z), jnp.zeros_like(z)
    for i in (2, 1, 0):
        step = z - x[..., i]
        d2p = d2p * step + 2.0 * dp
        dp = dp * step + p
        p = p * step + c[i]
    return p, dp, d2p


def _zero_peaks(h, r, bare, s_x, s_n, rule, edges, theta, signal, noise):
    """Correction to the fine rule's ``sum(theta(r) w S_e)`` for the peaks of ``S_e`` at the
    zeros of the real OTF ``h`` along the ray, too narrow for the fine nodes at high SNR.

    ``h, r, bare, s_x, s_n`` are the fine nodes of both pieces of the ray in ascending ``r``,
    with bare weights (``sum bare f(r) ~ int f(r) r dr``); ``rule`` is their ``_RayRule``,
    ``edges`` the sub-panels' ends in ``r`` (``(lower, upper)``) and ``theta(r)`` the
    angular factor of the integrand. One call serves both pieces (each call adds to every
    program's compile time).

    Near a zero ``r0`` of ``h``, with ``h = g d + q d^2`` (``d = r - r0``), and the spectra
    and ``theta`` linear in ``d`` about their values at ``r0``,
    ``theta S_e = theta S_n / (h^2 + S_n / S_x)`` is, to first order in ``d``,

        ``theta0 S_x0 M(z)``, ``M(z) = 1 / U + k_s z / U - k_q z^3 / U^2 - k_t z / U^2``,

    with ``z = d / c``, ``U = 1 + z^2``, half-width ``c = sqrt(S_n / S_x) / |g|`` and
    ``k_s = c (ln S_n theta)'``, ``k_q = c 2 q / g`` and ``k_t = c (ln S_n / S_x)'``: a
    Lorentzian of height ``S_x`` and its first asymmetric terms (the three terms took 6 waves
    of defocus at a peak ratio of 1.6e10 from 5e-6 with the Lorentzian alone to 4e-10). The
    correction replaces the fine rule's sum of that model over the zero's sub-panel and one
    on each side by its integral in closed form, so that the fine rule integrates only the
    difference, which has no peak of width ``c``. The zero, ``g`` and ``q`` come from the
    cubic through the four fine nodes around the sign change. Far from the zero the model
    is smooth and the sub-panels' Gauss rules integrate it as well as the closed form does,
    so a peak wide enough for the fine rule gets a correction of rounding size (and none
    past ``_RESOLVED``). Written in ``z`` so that no power of ``c`` underflows in float32.
    """
    n = h.shape[0]
    ids, starts = jnp.asarray(rule.ids), jnp.asarray(rule.starts)
    lower, upper = edges
    crossing = ((h[:-1] < 0) != (h[1:] < 0)) & jnp.asarray(rule.intervals)
    secant = (h[1:] - h[:-1]) / jnp.where(crossing, r[1:] - r[:-1], 1.0)
    secant = jnp.where(crossing, secant, 1.0)
    half_width = jnp.sqrt(s_n[:-1] / s_x[:-1]) / jnp.abs(secant)
    narrow = crossing & (half_width < _RESOLVED * (upper - lower)[ids[:-1]])

    # The first narrow zero in each of the first _PEAKS blocks of _BLOCK intervals that
    # hold one (a search over all N intervals cost 0.1 ms per piece). Nothing is skipped
    # when no peak is narrow: a lax.cond saved no measurable time and added to every
    # program's compile.
    blocks = -(-(n - 1) // _BLOCK)
    flags = jnp.pad(jax.lax.stop_gradient(narrow), (0, blocks * _BLOCK - (n - 1)))
    flags = flags.reshape(blocks, _BLOCK)
    held = jnp.any(flags, axis=1)
    (chosen,) = jnp.nonzero(held, size=min(_PEAKS, blocks), fill_value=0)
    j = chosen * _BLOCK + jnp.argmax(flags[chosen], axis=1)
    live = held[chosen]
    # The zero from the cubic through four fine nodes: two Newton steps from the secant's.
    # Entries without a live zero get a harmless cubic, so that no derivative is NaN.
    stencil = jnp.clip(j - 1, 0, n - 4)[:, None] + jnp.arange(4)
    dummy = jnp.arange(4, dtype=h.dtype)
    x = jnp.where(live[:, None], r[stencil], dummy)
    y = jnp.where(live[:, None], h[stencil], dummy - 1.5)
    lo, hi = jnp.where(live, r[j], 1.0), jnp.where(live, r[j + 1], 2.0)
    r0 = lo - jnp.where(live, h[j] / secant[j], -0.5)
    for _ in range(2):
        p, dp, _ = _cubic(x, y, r0)
        ok = dp != 0.0
        r0 = jnp.clip(r0 - jnp.where(ok, p / jnp.where(ok, dp, 1.0), 0.0), lo, hi)
    _, g, d2p = _cubic(x, y, r0)
    live = live & (g != 0.0)
    g = jnp.where(live, g, 1.0)
    r0 = jnp.where(live, r0, lo)
    # The spectra and the angular factor at r0, with their logarithmic slopes.
    ones = jnp.ones_like(r0)
    s_x0, ds_x = jax.jvp(signal.radial, (r0,), (ones,))
    s_n0, ds_n = jax.jvp(lambda r: noise(r, jnp.zeros_like(r)), (r0,), (ones,))
    theta0, dtheta = jax.jvp(theta, (r0,), (ones,))
    c = jnp.sqrt(s_n0 / s_x0) / jnp.abs(g)
    k = (c * (ds_n / s_n0 + dtheta / theta0),  # slope of the numerator
         c * d2p / g,  # 2 q / g with q = p'' / 2
         c * (ds_n / s_n0 - ds_x / s_x0))  # slope of S_n / S_x
    # Window: the sub-panel that holds r0, and its neighbours in the same piece.
    home = jnp.where(r0 < upper[ids[j]], ids[j], ids[j + 1])
    first = jnp.maximum(home - 1, jnp.asarray(rule.piece_first)[home])
    last = jnp.minimum(home + 1, jnp.asarray(rule.piece_last)[home])
    span = 3 * int(np.max(np.diff(rule.starts)))
    change = _window_change(r, bare, starts[first], starts[last + 1], lower[first],
                            upper[last], r0, c, k, span)
    peak = s_x0 * theta0
    return jnp.sum(jnp.where(live, peak * change, 0.0))


class _RayRule(NamedTuple):
    """Host description of both pieces' fine rules joined (``_zero_peaks``): ``ids`` (N,),
    the sub-panel of each node; ``starts`` (P + 1,), each sub-panel's first node (then N);
    ``piece_first`` and ``piece_last`` (P,), the first and last sub-panel of each one's
    piece; ``intervals`` (N - 1,), False for the gap between the pieces."""

    ids: np.ndarray
    starts: np.ndarray
    piece_first: np.ndarray
    piece_last: np.ndarray
    intervals: np.ndarray


@functools.cache
def _joined_rule(n_a: int, n_b: int, m_a: int, m_b: int) -> _RayRule:
    (*_, sub_a), (*_, sub_b) = _ray_rules(n_a, n_b, m_a, m_b)
    sizes = np.concatenate([sub_a.sizes, sub_b.sizes])
    p_a, p_b = len(sub_a.sizes), len(sub_b.sizes)
    intervals = np.ones(int(sizes.sum()) - 1, bool)
    intervals[int(sub_a.sizes.sum()) - 1] = False
    return _RayRule(np.repeat(np.arange(p_a + p_b), sizes),
                    np.concatenate([[0], np.cumsum(sizes)]),
                    np.repeat([0, p_a], [p_a, p_b]),
                    np.repeat([p_a - 1, p_a + p_b - 1], [p_a, p_b]), intervals)


def _theta(u, r):
    """Angle of the circle of radius ``r`` inside ``[-u, u]**2`` (for ``r >= u``)."""
    return 2.0 * math.pi - 8.0 * safe_arccos(u / r)


def radial_band_integral(aberrations, field, u, signal, noise, options, dtype):
    """``\\iint_{[-u, u]^2} S_e d^2 nu`` for a rotationally symmetric wavefront and isotropic
    ``signal`` and ``noise`` (traced; differentiable in every float input).

    ``options`` is a polar grid (``nodes``, ``se_nodes``, ``overlap_nodes``); the counts
    along the ray follow from it (``radial_counts``), with at least ``_MIN_ALONG`` overlap
    nodes along the chords.
    """
    n_a, n_b, m_a, m_b = radial_counts(options["nodes"], options["se_nodes"])
    overlap = (options["overlap_nodes"][0], max(options["overlap_nodes"][1], _MIN_ALONG))
    u = jnp.asarray(u, dtype)
    one = jnp.ones((), dtype)
    a = jnp.minimum(u, one)  # end of piece A
    length_b = jnp.maximum(jnp.minimum(math.sqrt(2.0) * u, one) - u, 0.0)
    two_pi = 2.0 * math.pi

    (t_c, t_f, w_t, interp_a, sub_a), (v_c, v_f, w_v, interp_b, sub_b) = _ray_rules(
        n_a, n_b, m_a, m_b)
    # One call of the overlap engine for both pieces' coarse nodes (A: r = t min(u, 1);
    # B: r = u + L v^2), at the grid's full order: the ray has a few dozen nodes, and one
    # call keeps the program (and its compile time) small.
    r_coarse = jnp.concatenate([a * jnp.asarray(t_c, dtype),
                                u + length_b * jnp.asarray(v_c * v_c, dtype)])
    # H is real for these wavefronts: the phase difference is odd under xi -> -xi and even
    # along each chord of the overlap lens, so the engine takes a quarter of its rule and
    # the cosine alone (``symmetric``), and real products interpolate H to the fine nodes
    # (half the work of complex ones).
    h = jnp.real(_otf_overlap(aberrations, r_coarse, jnp.zeros_like(r_coarse), field, overlap,
                              symmetric=True))
    h_a = _interpolate(interp_a, h[:n_a], dtype)
    h_b = _interpolate(interp_b, h[n_a:], dtype)
    t_f, w_t, v_f, w_v = (jnp.asarray(x, dtype) for x in (t_f, w_t, v_f, w_v))

    def theta(r):  # the angular factor of either piece
        return jnp.where(r > u, _theta(u, r), two_pi)

    r_a = a * t_f
    r_b = u + length_b * v_f * v_f
    bare_a = a * w_t * r_a
    bare_b = (2.0 * length_b) * w_v * v_f * r_b
    spectra = [(signal.radial(r), noise(r, jnp.zeros_like(r))) for r in (r_a, r_b)]
    # The weights keep their former order of products (A's is 2 pi bare_a), so that the sum
    # is bit for bit what it was: on the axis d/dfield is exactly 0 (test_radial).
    total = sum(jnp.sum(w * (s_x * s_n / (h * h * s_x + s_n)))
                for w, h, (s_x, s_n) in zip(((two_pi * a) * w_t * r_a, bare_b * _theta(u, r_b)),
                                            (h_a, h_b), spectra, strict=True))
    if _SUBTRACT:
        e_a, e_b = (jnp.asarray(x.edges, dtype) for x in (sub_a, sub_b))
        edges = (jnp.concatenate([a * e_a[:-1], u + length_b * e_b[:-1] ** 2]),
                 jnp.concatenate([a * e_a[1:], u + length_b * e_b[1:] ** 2]))
        total = total + _zero_peaks(
            jnp.concatenate([h_a, h_b]), jnp.concatenate([r_a, r_b]),
            jnp.concatenate([bare_a, bare_b]),
            *(jnp.concatenate(x) for x in zip(*spectra, strict=True)),
            _joined_rule(n_a, n_b, m_a, m_b), edges, theta, signal, noise)

    # Beyond the cutoff: S_e = S_x.
    x, w_x = (jnp.asarray(c, dtype) for c in gauss_legendre(OUTER_NODES, 0.0, 1.0))
    length_c1 = jnp.maximum(u - one, 0.0)  # r in [1, u]: the whole circle is in the band
    r_c1 = one + length_c1 * x
    total = total + jnp.sum(two_pi * length_c1 * w_x * r_c1 * signal.radial(r_c1))
    lo = jnp.maximum(u, one)  # r in [max(u, 1), sqrt(2) u]: the corners, past the cutoff
    length_c2 = jnp.maximum(math.sqrt(2.0) * u - lo, 0.0)
    r_c2 = lo + length_c2 * x * x
    w_c2 = (2.0 * length_c2) * w_x * x * r_c2 * _theta(u, r_c2)
    return total + jnp.sum(w_c2 * signal.radial(r_c2))

