"""Quadrature rules over the sensor band ``[-u, u]**2`` of the frequency plane.

Every rule places its nodes in the first quadrant ``[0, u]**2`` and folds the weights so that
``sum(w * f(nodes))`` approximates ``\\iint_{[-u,u]^2} f`` for integrands even in both
``nu_x`` and ``nu_y``. The Wiener error density ``S_e`` always satisfies
``S_e(-nu) = S_e(nu)``; it is also even in ``nu_x`` when the wavefront is even in ``x``
(every Seidel term). For other wavefronts the merit mirrors the nodes into the second
quadrant itself (see ``_merit``).

The unit rules are built once on the host in NumPy float64 (``gauss_legendre``) and scaled
by ``u`` inside the traced computation, so ``u`` stays differentiable.

Rules (names used by ``jmse(quadrature=...)``; the first four are the paper's Fig. 4 set):

``"rectangle"``  ``p`` equispaced nodes per axis at ``k u / p`` (the FFT grid's rule).
``"trapezoid"``  ``p`` equispaced nodes per axis including both ends.
``"gauss"``      Gauss–Legendre ``p`` nodes per axis (the paper's (a)).
``"gauss_polar"`` Gauss radial (``p`` per ray) times trapezoid angular (``p`` rays) (paper's (b)).
``"polar"``      Gauss–Legendre panels in polar coordinates: the quadrant is split into two
                 triangles at its diagonal (the square's corner), each ray is split at
                 ``|nu| = 1`` when it crosses the cutoff. ``S_e`` has a cone at ``nu = 0`` and
                 a ``(1 - r)^{3/2}`` edge at the cutoff, both smooth along rays, so these
                 panels converge spectrally (the package default).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._numerics import (
    barycentric_matrix,
    check_choice,
    check_count,
    check_range,
    common_dtype,
    gauss_legendre,
)

__all__ = [
    "QUADRATURES",
    "PolarPanels",
    "frequency_quadrature",
    "polar_interpolation_matrices",
    "polar_panels",
    "radial_panel_sizes",
]

#: The names ``frequency_quadrature`` (and ``jmse``'s ``quadrature``) accepts.
QUADRATURES = ("polar", "gauss", "gauss_polar", "trapezoid", "rectangle")


def _axis_rule(rule: str, p: int):
    """Unit 1-D rule on [0, 1] for the tensor rules (nodes, weights), host float64."""
    if rule == "gauss":
        return gauss_legendre(p, 0.0, 1.0)
    if rule == "trapezoid":
        if p < 2:
            raise ValueError(f"p must be >= 2 for the trapezoid rule, got {p}")
        x = np.linspace(0.0, 1.0, p)
        w = np.full(p, 1.0 / (p - 1))
        w[[0, -1]] *= 0.5
        return x, w
    # rectangle: left-anchored at 0 with spacing 1/p (as on an FFT lag grid); node 0
    # carries half a cell because the other half belongs to the mirrored quadrant.
    x = np.arange(p) / p
    w = np.full(p, 1.0 / p)
    w[0] *= 0.5
    return x, w


#: Radial nodes on a ray's part beyond the cutoff (``polar_panels(n_outer=...)`` in the merit,
#: and the one-ray integral's pieces there). There ``S_e = S_x``, smooth and free of the
#: OTF's ridges, so a short Gauss rule is exact to rounding (the inner rule's thousands of
#: nodes would only cost time).
OUTER_NODES = 48

#: Radial panel edges of the polar rule in ``t = r / R`` and the share of nodes in each.
_RADIAL_EDGES = (0.0, 0.15, 0.4, 1.0)
_RADIAL_SHARES = (0.3, 0.3, 0.4)


def _radial_panels() -> list[tuple[float, float]]:
    return list(zip(_RADIAL_EDGES[:-1], _RADIAL_EDGES[1:], strict=True))


def radial_panel_sizes(n: int) -> list[tuple[int, float]]:
    """``(nodes, t_max)`` of each radial panel of the polar rule with ``n`` radial nodes."""
    return [(k, b) for k, (_, b) in zip(_radial_counts(n), _radial_panels(), strict=True)]


def _radial_counts(n: int) -> tuple[int, ...]:
    """Nodes per radial panel for ``n`` in total (each panel gets at least one)."""
    counts = [max(1, round(n * share)) for share in _RADIAL_SHARES[:-1]]
    counts.append(max(1, n - sum(counts)))
    return tuple(counts)


#: Largest Gauss order of one sub-panel of the fine ``S_e`` rule along each ray of a grid
#: with the closed-form peaks of ``jmse_jax._ridges`` (``fine_sub_panels``): each radial
#: panel of the fine rule is split into equal sub-panels. They keep the fine nodes evenly
#: spread (one Gauss rule of hundreds of nodes crowds them at the panel's ends, where ``S_e``
#: has nothing special), and give the peaks exact windows: a few sub-panels around each.
#: The shortcuts' first and check grids, calibrated with one Gauss rule per panel, keep it.
FINE_SUB_PANEL = 16


def _sub_panel_sizes(k: int, sub_panel: int | None) -> list[int]:
    """Node counts of the equal sub-panels of a panel of ``k`` nodes (at most ``sub_panel``
    each, differing by at most one)."""
    pieces = 1 if sub_panel is None else -(-k // sub_panel)
    return [k // pieces + (i < k % pieces) for i in range(pieces)]


def _panel_rule(k: int, a: float, b: float, sub_panel: int | None):
    """``(nodes, weights, sizes, edges)``: a composite Gauss rule of ``k`` nodes on
    ``[a, b]`` whose sub-panels (``sizes`` nodes each, between ``edges``) have lengths in
    proportion to their counts (``sub_panel=None``: one Gauss rule)."""
    sizes = _sub_panel_sizes(k, sub_panel)
    edges = a + (b - a) * np.concatenate([[0], np.cumsum(sizes)]) / k
    rules = [gauss_legendre(c, lo, hi) for c, lo, hi in zip(sizes, edges[:-1], edges[1:],
                                                           strict=True)]
    return (np.concatenate([x for x, _ in rules]), np.concatenate([w for _, w in rules]),
            np.asarray(sizes), edges)


def _radial_rule(n: int, sub_panel: int | None = None):
    """Composite Gauss rule in ``t`` on [0, 1] over ``_RADIAL_EDGES`` (host, float64); with
    ``sub_panel``, each panel's rule is split into sub-panels of at most that many nodes
    (the fine ``S_e`` rule; the coarse OTF rule must stay one Gauss rule per panel, on
    which it is interpolated).

    A strongly aberrated OTF falls from 1 to nearly 0 within a few hundredths of the cutoff
    around ``nu = 0`` and then ripples slowly; a separate inner panel keeps that steep part
    from spoiling the polynomial interpolation over the rest of the ray.
    """
    nodes, weights = [], []
    for (a, b), k in zip(_radial_panels(), _radial_counts(n), strict=True):
        x, w, _, _ = _panel_rule(k, a, b, sub_panel)
        nodes.append(x)
        weights.append(w)
    return np.concatenate(nodes), np.concatenate(weights)


@functools.cache
def fine_sub_panels(n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, starts, edges)`` of the fine radial rule of ``n`` nodes: its nodes in ``t`` and
    its sub-panels; sub-panel ``p`` holds nodes ``starts[p]`` to ``starts[p + 1] - 1`` and
    covers ``[edges[p], edges[p + 1]]`` (``P + 1`` entries each)."""
    nodes, sizes, edges = [], [], [0.0]
    for (a, b), k in zip(_radial_panels(), _radial_counts(n), strict=True):
        x, _, s, e = _panel_rule(k, a, b, FINE_SUB_PANEL)
        nodes.append(x)
        sizes.extend(s)
        edges.extend(e[1:])
    return (np.concatenate(nodes), np.concatenate([[0], np.cumsum(sizes)]),
            np.asarray(edges))


def _radial_interpolation(n_coarse: int, n_fine: int,
                          sub_panel: int | None = None) -> np.ndarray:
    """Block-diagonal interpolation matrix from the composite coarse radial rule to the fine
    one (with its sub-panels of at most ``sub_panel`` nodes, if given), panel by panel."""
    coarse, fine = _radial_counts(n_coarse), _radial_counts(n_fine)
    matrix = np.zeros((n_fine, n_coarse))
    r0 = c0 = 0
    for (a, b), kc, kf in zip(_radial_panels(), coarse, fine, strict=True):
        xc, _ = gauss_legendre(kc, a, b)
        xf, *_ = _panel_rule(kf, a, b, sub_panel)
        matrix[r0:r0 + kf, c0:c0 + kc] = barycentric_matrix(xc, xf)
        r0, c0 = r0 + kf, c0 + kc
    return matrix


#: Fewest angular nodes on either side of a split angular rule (``angular_templates``).
_MIN_SPLIT = 4


def _split_row(n: int, n1: int):
    """One row of a (split) angular rule: ``n1`` Gauss nodes on the first part, ``n - n1``
    on the second (``n1 = n``: the plain rule)."""
    x1, w1 = gauss_legendre(n1, 0.0, 1.0)
    if n1 == n:
        return x1, w1, np.zeros(n, bool)
    x2, w2 = gauss_legendre(n - n1, 0.0, 1.0)
    return np.concatenate([x1, x2]), np.concatenate([w1, w2]), np.arange(n) >= n1


def _coarse_splits(n: int) -> list[int]:
    """``n1`` of each template row: the plain rule, then ``_MIN_SPLIT .. n - _MIN_SPLIT``."""
    return [n] + list(range(_MIN_SPLIT, n - _MIN_SPLIT + 1))


@functools.cache
def angular_templates(n: int, fine: int | None = None):
    """Host templates ``(local, weights, second)``, each ``(rows, m)``, of the angular rule
    of a polar triangle (cached): positions and weights on [0, 1] within their part and
    whether a node lies in the second part. Row 0 is the plain Gauss rule; row ``k >= 1``
    splits ``n`` nodes into ``n1 = _MIN_SPLIT + k - 1`` and ``n - n1``. With ``fine``, the
    rows of the fine rule of ``fine`` nodes that match those of ``n`` (nodes shared in the
    same proportion), ``m = fine``; otherwise ``m = n``.
    """
    m = n if fine is None else fine
    rows = []
    for k, n1 in enumerate(_coarse_splits(n)):
        m1 = m if k == 0 else int(np.clip(round(n1 * m / n), _MIN_SPLIT, m - _MIN_SPLIT))
        rows.append(_split_row(m, m1))
    return tuple(np.stack(a) for a in zip(*rows, strict=True))


def angular_split(u, n: int, dtype):
    """``(row, f)``: the template row of ``angular_templates(n)`` for Nyquist ratio ``u`` and
    the split point ``f`` (a fraction of the triangle's ``pi/4``; traced).

    For ``1/sqrt(2) < u < 1`` a ray at angle ``alpha`` reaches the cutoff only for
    ``alpha > arccos u``, and the angular integrand has a kink there; the rule is split at
    ``f = arccos(u) / (pi/4)`` with nodes shared in proportion to the parts' lengths.
    Otherwise the plain rule (row 0, ``f = 1``).
    """
    if n < 2 * _MIN_SPLIT:  # too few nodes for two parts: always the plain rule
        return jnp.zeros((), jnp.int32), jnp.ones((), dtype)
    u = jnp.asarray(u, dtype)
    inside = (u > math.sqrt(0.5)) & (u < 1.0)
    u_safe = jnp.where(inside, u, 0.85)
    f = jnp.where(inside, jnp.arccos(u_safe) / (math.pi / 4), 1.0)
    n1 = jnp.clip(jnp.round(jax.lax.stop_gradient(f) * n), _MIN_SPLIT, n - _MIN_SPLIT)
    row = jnp.where(inside, (n1 - _MIN_SPLIT + 1).astype(jnp.int32), 0)
    return row, f


def angular_rule(u, n: int, dtype, split=None, fine: int | None = None):
    """Angle fractions and weights of the (possibly split) angular rule of ``n`` nodes, or
    of its matching ``fine`` rule (traced)."""
    local, weights, second = angular_templates(n, fine)
    row, f = angular_split(u, n, dtype) if split is None else split
    local, weights, second = (jnp.asarray(a)[row] for a in (local, weights, second))
    local, weights = local.astype(dtype), weights.astype(dtype)
    frac = jnp.where(second, f + (1.0 - f) * local, f * local)
    w_frac = jnp.where(second, (1.0 - f) * weights, f * weights)
    return frac, w_frac


@functools.cache
def split_interpolation(coarse: int, fine: int) -> np.ndarray:
    """Host matrices ``(rows, fine, coarse)`` from each template row of the coarse angular
    rule to the matching fine row (block-diagonal in the two parts)."""
    c_local, _, c_second = angular_templates(coarse)
    f_local, _, f_second = angular_templates(coarse, fine)
    out = np.zeros((len(c_local), fine, coarse))
    for row in range(len(c_local)):
        for part in (False, True):
            ci = np.flatnonzero(c_second[row] == part)
            fi = np.flatnonzero(f_second[row] == part)
            if len(ci) and len(fi):
                out[row][np.ix_(fi, ci)] = barycentric_matrix(c_local[row][ci],
                                                              f_local[row][fi])
    return out


#: Above this many bytes the angular interpolation matrices of ``split_interpolation`` (one
#: dense ``fine x coarse`` matrix per template row, picked by the traced ``u``) are not made
#: constants of the program: ``polar_interpolation_matrices`` gives the tables of
#: ``angular_interpolation_tables`` instead and ``angular_interpolation_block`` builds the
#: rows of a block in the program. Every grid of the presets stays below it, with
#: ``se_angular_for``'s largest count too (the Zernike balanced grid's 96 coarse angular
#: nodes with 5760 fine ones: 380 MB), so their programs are unchanged; a Zernike reference
#: with 7680 (``benchmarks/default_climb.py``) had 0.92 GB of them, which a
#: ``value_and_grad`` captured four times and which exhausted a 24 GB host (session 87).
BUILT_ANGULAR_BYTES = 512 * 2**20


class AngularTables(NamedTuple):
    """Host tables from which ``angular_interpolation_block`` builds the angular
    interpolation matrix of a template row (``split_interpolation``'s, to rounding): the
    coarse rule's positions on [0, 1] within their part, parts and barycentric weights
    (``(rows, coarse)``), and the fine rule's positions and parts (``(rows, fine)``)."""

    coarse_local: np.ndarray
    coarse_second: np.ndarray
    coarse_bary: np.ndarray
    fine_local: np.ndarray
    fine_second: np.ndarray


@functools.cache
def angular_interpolation_tables(coarse: int, fine: int) -> AngularTables:
    """``AngularTables`` of the angular rules of ``coarse`` and ``fine`` nodes."""
    c_local, _, c_second = angular_templates(coarse)
    f_local, _, f_second = angular_templates(coarse, fine)
    bary = np.zeros(c_local.shape)
    for row in range(len(c_local)):
        for part in (False, True):
            ci = np.flatnonzero(c_second[row] == part)
            if not len(ci):
                continue  # the plain rule (row 0) has no second part
            diff = c_local[row][ci, None] - c_local[row][None, ci]
            np.fill_diagonal(diff, 1.0)
            weights = 1.0 / np.prod(diff, axis=1)
            # A common factor cancels; scaled to at most 1 (float32 would overflow).
            bary[row, ci] = weights / np.max(np.abs(weights))
    return AngularTables(c_local, c_second, bary, f_local, f_second)


def angular_interpolation_block(coarse_row, fine_local, fine_part):
    """The rows of ``split_interpolation``'s matrix for fine nodes at ``fine_local`` (``(m,)``)
    in parts ``fine_part`` (0 or 1; any other value gives a zero row, for padding), from the
    coarse rule's ``coarse_row = (local, second, bary)`` of one template row (traced): the
    barycentric formula of ``_numerics.barycentric_matrix`` within each part."""
    c_local, c_second, c_bary = coarse_row
    same = fine_part[:, None] == c_second.astype(fine_part.dtype)[None, :]
    delta = fine_local[:, None] - c_local[None, :]
    exact = same & (jnp.abs(delta) <= 1e-15)
    terms = jnp.where(same, c_bary[None, :] / jnp.where(exact, 1.0, delta), 0.0)
    total = jnp.sum(terms, axis=1, keepdims=True)
    matrix = terms / jnp.where(total == 0.0, 1.0, total)
    return jnp.where(jnp.any(exact, axis=1, keepdims=True), exact.astype(matrix.dtype), matrix)


class PolarPanels(NamedTuple):
    """Nodes of the polar panel rule, shaped ``(2 triangles, n_angles, n_radial)``.

    ``inner`` nodes cover ``|nu| <= min(r_max, 1)`` (where the OTF is needed); ``outer``
    nodes cover the part of each ray beyond the cutoff (``H = 0``, so ``S_e = S_x``).
    Weights include the polar Jacobian ``r`` and the factor 4 of the folded quadrants.
    ``radius`` and ``outer_radius`` are ``|nu|`` at the nodes (shaped ``(n_angles, n)``, the
    same for both triangles). The inner weights factor as
    ``row_weights[:, None] * radial_weights[None, :]`` (``(n_angles,)`` and ``(n_radial,)``).
    """

    nu_x: jax.Array
    nu_y: jax.Array
    weights: jax.Array
    outer_nu_x: jax.Array
    outer_nu_y: jax.Array
    outer_weights: jax.Array
    radius: jax.Array
    outer_radius: jax.Array
    row_weights: jax.Array | None = None
    radial_weights: jax.Array | None = None


def polar_panels(u, n_radial: int, n_angular: int, dtype=None, n_outer: int | None = None,
                 angles=None, sub_panel: int | None = None) -> PolarPanels:
    """Polar Gauss panel rule over the folded band for Nyquist ratio ``u`` (traced).

    Triangle 1 holds angles ``alpha in [0, pi/4]`` from the ``nu_x`` axis, where a ray ends at
    ``r_max = u / cos(alpha)``; triangle 2 is its mirror image in the diagonal. Along each ray
    ``r = t R`` with ``R = min(r_max, 1)`` and ``t`` on a composite Gauss rule (panels
    ``_RADIAL_EDGES``), and the part beyond the cutoff ``[R, r_max]`` has its own nodes.
    ``n_outer`` sets a separate Gauss rule of that many nodes for the part beyond the cutoff
    (default: the inner rule), where the integrand is the smooth ``S_x`` alone.
    The ``n_angular`` rays follow ``angular_rule``: one Gauss rule in the angle, split at
    ``arccos u`` for ``1/sqrt(2) < u < 1`` (where the rays start to reach the cutoff, a kink
    in the angular integrand that one Gauss rule resolves only algebraically: 1e-5 to 1e-4
    at the presets' counts, ``benchmarks/wide_band_check.py``).
    ``sub_panel`` splits the radial rule's panels into sub-panels (``_radial_rule``; the fine
    ``S_e`` rule's ``FINE_SUB_PANEL``).
    ``angles = (frac, w_frac)`` replaces them by the given angle fractions (of the triangle's
    ``pi/4``) and weights, e.g. one block of rows inside a loop.
    """
    dtype = dtype or jnp.result_type(float)
    t, w_t = (jnp.asarray(a, dtype) for a in _radial_rule(n_radial, sub_panel))
    if n_outer is None:
        t_out, w_t_out = t, w_t
    else:
        t_out, w_t_out = (jnp.asarray(a, dtype) for a in gauss_legendre(n_outer, 0.0, 1.0))
    u = jnp.asarray(u, dtype)
    frac, w_frac = angular_rule(u, n_angular, dtype) if angles is None else angles
    frac, w_frac = jnp.asarray(frac, dtype), jnp.asarray(w_frac, dtype)
    alpha = (math.pi / 4) * frac  # (n_a,)
    w_alpha = (math.pi / 4) * w_frac
    r_max = u / jnp.cos(alpha)
    inner = jnp.minimum(r_max, 1.0)
    r = inner[:, None] * t[None, :]  # (n_a, n_r)
    w = 4.0 * w_alpha[:, None] * inner[:, None] * w_t[None, :] * r
    r_out = inner[:, None] + (r_max - inner)[:, None] * t_out[None, :]
    w_out = 4.0 * w_alpha[:, None] * (r_max - inner)[:, None] * w_t_out[None, :] * r_out
    cos_a, sin_a = jnp.cos(alpha)[:, None], jnp.sin(alpha)[:, None]
    # Triangle 2 (alpha in [pi/4, pi/2]) is triangle 1 with nu_x and nu_y swapped.
    nu_x = jnp.stack([r * cos_a, r * sin_a])
    nu_y = jnp.stack([r * sin_a, r * cos_a])
    out_x = jnp.stack([r_out * cos_a, r_out * sin_a])
    out_y = jnp.stack([r_out * sin_a, r_out * cos_a])
    # The inner weights factor as row_weights[a] * radial_weights[i] (both triangles alike).
    row_weights = 4.0 * w_alpha * inner * inner
    return PolarPanels(nu_x, nu_y, jnp.stack([w, w]), out_x, out_y, jnp.stack([w_out, w_out]),
                       r, r_out, row_weights, t * w_t)


def polar_interpolation_matrices(coarse: tuple[int, int], fine: tuple[int, int],
                                 drop: tuple[int, int] = (0, 0),
                                 sub_panel: int | None = None):
    """Host matrices ``(L_radial, L_angular)`` taking polar-panel values from ``coarse``
    ``(n_radial, n_angular)`` Gauss nodes to ``fine`` ones (polynomial interpolation in ``t``
    and in the angle fraction, each on [0, 1]). ``L_angular`` is ``(rows, fine, coarse)``, one
    matrix per template row of the (split) angular rule (``split_interpolation``; row 0: the
    plain Gauss rules), or, above ``BUILT_ANGULAR_BYTES`` (and without ``drop``'s angular
    part), the ``AngularTables`` the program builds it from.

    ``sub_panel``: the fine radial rule's sub-panels (``_radial_rule``).

    ``drop = (d_r, d_a)`` lowers the interpolants' degree: on every panel (and part of a
    split angular rule) the coarse values' top ``d`` Legendre coefficients are set to zero
    before interpolating (``_lowered``). The difference between the merit on the lowered and
    on the full interpolants estimates the full one's interpolation error (the error
    estimate of ``TierShortcut.first``).
    """
    l_r = _radial_interpolation(coarse[0], fine[0], sub_panel)
    rows = len(angular_templates(coarse[1])[0])
    if not drop[1] and rows * fine[1] * coarse[1] * 8 > BUILT_ANGULAR_BYTES:
        return l_r, angular_interpolation_tables(coarse[1], fine[1])
    l_a = split_interpolation(coarse[1], fine[1])
    if drop[0]:
        l_r = l_r @ _radial_lowering(coarse[0], drop[0])
    if drop[1]:
        l_a = np.einsum("rfc,rcd->rfd", l_a, _angular_lowering(coarse[1], drop[1]))
    return l_r, l_a


def _lowered(x, a: float, b: float, drop: int) -> np.ndarray:
    """Matrix that removes the top ``drop`` Legendre coefficients of the polynomial through
    values at the nodes ``x`` on ``[a, b]`` (the identity when ``drop >= len(x)``)."""
    k = len(x)
    if drop >= k:
        return np.eye(k)
    vander = np.polynomial.legendre.legvander((2.0 * np.asarray(x) - a - b) / (b - a), k - 1)
    return vander[:, :k - drop] @ np.linalg.inv(vander)[:k - drop, :]


@functools.cache
def _radial_lowering(n: int, drop: int) -> np.ndarray:
    """Block-diagonal ``_lowered`` over the radial panels of the rule of ``n`` nodes."""
    out = np.zeros((n, n))
    start = 0
    for (a, b), k in zip(_radial_panels(), _radial_counts(n), strict=True):
        x, _ = gauss_legendre(k, a, b)
        out[start:start + k, start:start + k] = _lowered(x, a, b, drop)
        start += k
    return out


@functools.cache
def _angular_lowering(n: int, drop: int) -> np.ndarray:
    """``_lowered`` for each template row of the angular rule of ``n`` nodes, per part,
    ``(rows, n, n)``."""
    local, _, second = angular_templates(n)
    out = np.zeros((len(local), n, n))
    for row in range(len(local)):
        for part in (False, True):
            i = np.flatnonzero(second[row] == part)
            if len(i):
                out[row][np.ix_(i, i)] = _lowered(local[row][i], 0.0, 1.0, drop)
    return out


def frequency_quadrature(rule: str, u, p, dtype=None):
    """Nodes and folded weights of ``rule`` over the band ``[-u, u]**2``.

    Parameters
    ----------
    rule : one of ``QUADRATURES``
    u : float [cutoff units], traced allowed
    p : int, or (int, int) for ``"polar"`` (radial, angular nodes per triangle)
        Nodes per axis (tensor rules) or per ray and rays (``"gauss_polar"``).

    Returns
    -------
    nu_x, nu_y, weights : flat arrays; ``sum(weights) = 4 u**2`` up to the rule's error.
    """
    check_choice("quadrature", rule, QUADRATURES)
    check_range("u", u, 0.0, None, low_inclusive=False)
    dtype = dtype or common_dtype(u)  # float32 u: float32 nodes, as jnp would give
    u = jnp.asarray(u, dtype)
    if rule == "polar":
        if isinstance(p, np.ndarray):
            p = p.tolist()
        if isinstance(p, (int, np.integer)) and not isinstance(p, bool):
            p = (p, p)
        if not (isinstance(p, (tuple, list)) and len(p) == 2):
            raise ValueError(f"p must be an int or a pair (radial, angular) for 'polar', "
                             f"got {p!r}")
        n_r, n_a = p
        check_count("nodes (radial)", n_r, 3)
        check_count("nodes (angular)", n_a)
        panels = polar_panels(u, int(n_r), int(n_a), dtype)
        return (
            jnp.concatenate([panels.nu_x.ravel(), panels.outer_nu_x.ravel()]),
            jnp.concatenate([panels.nu_y.ravel(), panels.outer_nu_y.ravel()]),
            jnp.concatenate([panels.weights.ravel(), panels.outer_weights.ravel()]),
        )
    check_count("p", p)
    if rule == "gauss_polar":
        t, w_t = gauss_legendre(p, 0.0, 1.0)
        alpha = np.linspace(0.0, math.pi / 2, p) if p > 1 else np.array([math.pi / 4])
        w_alpha = np.full(p, (math.pi / 2) / max(p - 1, 1))
        if p > 1:
            w_alpha[[0, -1]] *= 0.5
        else:
            w_alpha[:] = math.pi / 2
        alpha_j = jnp.asarray(alpha, dtype)
        r_max = u / jnp.maximum(jnp.cos(alpha_j), jnp.sin(alpha_j))  # ray length in the square
        r = r_max[:, None] * jnp.asarray(t, dtype)[None, :]
        w_ray = jnp.asarray(w_alpha, dtype)[:, None] * r_max[:, None]
        w = 4.0 * w_ray * jnp.asarray(w_t, dtype)[None, :] * r
        return (
            (r * jnp.cos(alpha_j)[:, None]).ravel(),
            (r * jnp.sin(alpha_j)[:, None]).ravel(),
            w.ravel(),
        )
    x, w = _axis_rule(rule, p)
    x, w = jnp.asarray(x, dtype) * u, jnp.asarray(w, dtype) * u
    nu_x, nu_y = jnp.meshgrid(x, x, indexing="xy")
    weights = 4.0 * w[None, :] * w[:, None]
    return nu_x.ravel(), nu_y.ravel(), weights.ravel()
