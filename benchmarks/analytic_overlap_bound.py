"""An analytic Bernstein-ellipse bound of the overlap rule's error, in JAX, and its cost.

``overlap_error_bound.py`` bounds the overlap engine's error at each node from the phase ``D``
continued to complex points and sampled densely on each ellipse; it was never below the true
error, and carried to the merit it kept the same designs as the shortcuts' float32 check grid
(``recheck_shortcut.py --probes``). The check costs about 0.45 ms of the default's 1.52 ms at
the paper's Fig. 1 point, so a bound cheaper than that would let the first grid verify itself.
Sparse sampling was not safe (one design's merit-level bound fell to 0.18x the exact probe).

This script builds the bound from ``D``'s Chebyshev coefficients instead, with the engine's own
phase samples (the collocation points of its chords) and host constants, so that what lies
between samples is covered by a margin:

- along each chord ``D`` is a cubic (Seidel), and on the ellipse ``Im T_k = (rho^k - rho^-k)
  sin(k theta) / 2``, so ``-Im D <= sum_k |c_k| (rho^k - rho^-k) / 2``;
- across the chords the same coefficient-wise majorant was 2.5x the exponent of the sampled
  maximum (``Im T_k`` of different ``k`` peak at different angles), and a majorant from the
  trigonometric coefficients of ``D`` in the chord angle was worse (the full-period
  coefficients cancel inside the lens). So the sine polynomial is sampled at a few
  angles and points along the chord, with a second-derivative margin in each
  (``|d^2/dtheta^2 sin k theta| <= k^2``, ``|T_l''| <= l^2 (l^2 - 1) / 3``).

It reports, for each bank case and rule order, the bound over the true error (min, median,
nodes below it) against order (64, 64), and, at the first grid's nodes at the Fig. 1 point,
its time against the overlap engine's OTF at the same nodes (warm, jitted, one process; run
under ``taskset -c 1`` for one core). Usage (from the repository root; about 1 min)::

    taskset -c 1 .venv/bin/python benchmarks/analytic_overlap_bound.py

Writes ``benchmarks/results/analytic_overlap_bound.{json,md}``. Nothing here is in the
library: the bound costs more than the check it would replace (benchmarks/README.md,
optimisation log, session 39).
"""

from __future__ import annotations

import functools
import math
import sys

import _common as common
import jax
import jax.numpy as jnp
import numpy as np
from overlap_error_bound import CASES, FLOOR, NODES, REFERENCE_ORDER, band_frequencies

from jmse_jax._numerics import EXACT, common_dtype, materialise, safe_norm
from jmse_jax._otf import (
    _chord_phase,
    _otf_overlap,
    _overlap_rule,
    along_chord_order,
    diffraction_limited_otf,
)
from jmse_jax._quadrature import polar_panels

#: ``(rhos, thetas, ts)``: the Bernstein-ellipse parameters over which ``overlap_error_bound``
#: minimises its bounds, the points per half ellipse at which the across-chord bound takes
#: ``-Im D``, and the points along each chord at which it takes the largest of those.
SAMPLING = ((1.2, 1.5, 2.0, 2.5, 3.5), 12, 5)
#: Cheaper samplings timed against it (``main``).
SAMPLINGS = (SAMPLING, ((1.5, 2.0, 3.0), 8, 3), ((2.0,), 12, 5))


@functools.cache
def _bound_constants(n_phi: int, n_t: int, chord_points: int, sampling):
    """Host constants of ``overlap_error_bound`` (float64, cached): see its body."""
    rhos, THETAS, TS = sampling  # noqa: N806
    rhos = np.asarray(rhos)
    frac, _, t_colloc, _, _ = _overlap_rule(n_phi, n_t, chord_points)

    def to_chebyshev(points, degree):
        return np.linalg.inv(np.polynomial.chebyshev.chebvander(points, degree - 1))

    def growth(degree):  # |Im T_k| <= (rho^k - rho^-k) / 2 on E_rho
        k = np.arange(degree)
        return 0.5 * (rhos[:, None] ** k - rhos[:, None] ** (-k))

    def log_gauss(n):
        return math.log(64.0 / 15.0) - 2 * n * np.log(rhos) - np.log(rhos**2 - 1.0)

    along = to_chebyshev(t_colloc, chord_points)  # (l, q): values -> coefficients in t
    # Across: values at the chord positions -> Chebyshev coefficients in the chord position
    # (k), then Im T_k on the ellipse at the sampled angles, per rho: (k, rho * theta).
    theta = np.pi * (np.arange(THETAS) + 0.5) / THETAS
    k = np.arange(n_phi)
    im_t = (growth(n_phi)[:, :, None] * np.sin(np.outer(k, theta))[None]).transpose(1, 0, 2)
    # Samples along the chord (with the ends) and the margin of a sampled maximum:
    # |p(t*) - p(t_j)| <= (h^2 / 8) max |p''| at the maximum t* of |p|, h the spacing, with
    # max |T_l''| = l^2 (l^2 - 1) / 3; in theta likewise with |d^2/dtheta^2 sin k theta| <= k^2.
    t_samples = np.linspace(-1.0, 1.0, TS)
    to_t = np.polynomial.chebyshev.chebvander(t_samples, chord_points - 1) @ along  # (ts, q)
    l = np.arange(chord_points)
    margin_t = (2.0 / (TS - 1)) ** 2 / 8.0 * (l**2 * (l**2 - 1) / 3.0)  # (l,)
    margin_theta = (np.pi / THETAS) ** 2 / 8.0 * (k**2 * growth(n_phi))  # (rho, k)
    half_a = 0.5 * (rhos + 1.0 / rhos)  # the ellipse's semi-axes
    half_b = 0.5 * (rhos - 1.0 / rhos)
    return (along, to_chebyshev(2.0 * frac - 1.0, n_phi), growth(chord_points),
            im_t.reshape(n_phi, -1), to_t, margin_t, margin_theta, growth(n_phi),
            log_gauss(n_t), log_gauss(n_phi), half_a, half_b)


def overlap_error_bound(aberrations, nu_x, nu_y, field, nodes, sampling=SAMPLING):
    """A bound of the overlap engine's error ``|H_rule - H|`` at each node, for the rule of
    order ``nodes = (n_phi, n_t)`` (no gradient; the shape of the nodes).

    Gauss-Legendre of order ``n`` on ``[-1, 1]`` integrates a function analytic inside the
    Bernstein ellipse ``E_rho`` (foci +-1, semi-axes summing to ``rho``), where it is at most
    ``M``, to within ``(64/15) M rho^(-2n) / (rho^2 - 1)`` (Trefethen, *Approximation
    Theory and Approximation Practice*, Thm. 19.3). The integrand is ``exp(i 2 pi D)`` with
    ``D`` the wavefront's difference, so ``M = exp(2 pi max(-Im D))``. ``D``'s Chebyshev
    coefficients ``c_k`` are real and ``Im T_k = (rho^k - rho^-k) sin(k theta) / 2`` on
    ``E_rho``, so ``-Im D`` there is a sine polynomial in the ellipse's angle:

    - along each chord ``D`` is a polynomial of the degree the engine assumes
      (``chord_degree``; its coefficients exact), majorised by ``sum |c_k| (rho^k -
      rho^-k) / 2``;
    - across the chords the coefficients are those of the interpolant through the engine's
      ``n_phi`` chord positions (``D`` is a trigonometric polynomial of degree 3 in the
      chord angle, resolved to rounding), and the sine polynomial, a polynomial in ``t``
      along the chords, is maximised over ``thetas`` angles and ``ts`` points
      along the chord with a second-derivative margin for what lies between the samples.
      The chord's ``t`` integral is at most twice that maximum, and its weight
      ``sin(phi)^2`` at most ``min(cosh(Im phi), sinh|phi|)^2``.

    Both bounds are minimised over the ``rhos`` of ``sampling``, summed over the lens's two
    halves with the engine's chord weights and scaled as the engine scales ``H``.
    """
    n_phi, n_t = nodes
    dtype = common_dtype(aberrations, nu_x, nu_y, field)
    n_t = along_chord_order(n_t, dtype)
    aberrations, nu_x, nu_y, field = jax.lax.stop_gradient((aberrations, nu_x, nu_y, field))
    nu_x, nu_y = jnp.broadcast_arrays(jnp.asarray(nu_x, dtype), jnp.asarray(nu_y, dtype))
    shape = nu_x.shape
    nu_x, nu_y = nu_x.reshape(-1), nu_y.reshape(-1)
    field = jnp.asarray(field, dtype)
    degree = aberrations.chord_degree
    chord_points = n_t if degree is None or degree + 1 >= n_t else degree + 1
    frac, w_frac, t_colloc, _, _ = (jnp.asarray(a, dtype)
                                    for a in _overlap_rule(n_phi, n_t, chord_points))
    constants = _bound_constants(n_phi, n_t, chord_points, sampling)
    rhos, THETAS, TS = sampling  # noqa: N806
    along_np, _, along_g_np, _, to_t_np, margin_t_np, _, _, log_n_t_np, _, _, _ = constants
    (_, across_c, _, im_t, _, _, margin_theta, growth_k, _, log_n_phi, half_a, half_b) = (
        jnp.asarray(a, dtype) for a in constants)
    across_c_t = across_c.T
    s = safe_norm(nu_x, nu_y)
    interior = (s > 0) & (s < 1)
    s_safe = jnp.where(interior, s, 0.5)
    nx = jnp.where(interior, nu_x, 0.5)
    ny = jnp.where(interior, nu_y, 0.0)
    ex, ey = nx / s_safe, ny / s_safe
    phi_max = jnp.arccos(s_safe)
    phi = phi_max[:, None] * frac[None, :]
    sin_phi = jnp.sin(phi)
    a = jnp.cos(phi) - s_safe[:, None]
    chord_w = phi_max[:, None] * w_frac[None, :] * sin_phi**2  # (N, n_phi)
    phase = _chord_phase(aberrations, field, nx, ny, ex, ey, a, sin_phi, t_colloc)
    two_pi = 2.0 * math.pi
    n_rho = len(rhos)
    # The contractions over the few collocation points, samples and rhos are written out
    # term by term: XLA fuses them into element-wise loops, where products with a
    # dimension of 4 or 5 went to library calls at several times the cost.
    # Stored once (``materialise``): each term below would otherwise re-evaluate the
    # wavefront at every collocation point.
    (phase,) = materialise(phase)
    points = [phase[..., q] for q in range(chord_points)]  # each (N, 2, n_phi)

    def combine(matrix, values):
        """``sum_q matrix[i, q] values[q]`` for each row ``i`` (host matrix)."""
        return [sum(float(m_iq) * v for m_iq, v in zip(row, values, strict=True))
                for row in matrix]

    # Along the chords: per chord, -Im D <= sum_k |c_k| (rho^k - rho^-k) / 2 (k >= 1).
    along_abs = [jnp.abs(c) for c in combine(along_np, points)[1:]]
    log_along = [two_pi * sum(float(g) * c for g, c in zip(along_g_np[r, 1:], along_abs,
                                                             strict=True))
                 + float(log_n_t_np[r]) for r in range(n_rho)]
    # The sums as products: a reduction would take the element-wise chain into a YNNPACK
    # fusion, which evaluates it many times slower than XLA's own loop.
    along = jnp.exp(functools.reduce(jnp.minimum, log_along))  # (N, 2, n_phi)
    along = jnp.matmul((along * chord_w[:, None, :]).reshape(along.shape[0], -1),
                       jnp.ones(2 * n_phi, dtype), precision=EXACT)
    # Across the chords: Chebyshev coefficients in the chord position (k) at the samples
    # along the chord (s), then Im D on the ellipse at the sampled angles, per rho.
    at_t = jnp.stack(combine(to_t_np, points), axis=2)  # (N, 2, s, n_phi)
    coef = jnp.matmul(at_t, across_c_t, precision=EXACT)  # (N, 2, s, k)
    n = coef.shape[0]
    im = jnp.matmul(coef.reshape(-1, n_phi), im_t, precision=EXACT)
    # The largest |Im D| over the angles and the samples along the chord, as element-wise
    # maxima of slices (a max-reduction went to a YNNPACK fusion at ten times the cost).
    im = jnp.abs(im).reshape(n, 2, TS, n_rho, THETAS)
    im = functools.reduce(jnp.maximum, [im[:, :, i, :, j] for i in range(TS)
                                        for j in range(THETAS)])  # (N, 2, rhos)
    # The margins of the sampled maximum, from the coefficients in t (l): |a_k(t)| <=
    # sum_l |a_kl| in theta, |p''(t)| <= sum_l |v_l| l^2 (l^2 - 1) / 3 in t.
    by_point = jnp.matmul(phase.swapaxes(-1, -2), across_c_t, precision=EXACT)  # (N,2,q,k)
    by_point = [by_point[:, :, q] for q in range(chord_points)]
    tcoef = [jnp.abs(c) for c in combine(along_np, by_point)]  # each (N, 2, k)
    size_k = sum(tcoef)
    curve_k = sum(float(m) * c for m, c in zip(margin_t_np, tcoef, strict=True))
    margin = (jnp.matmul(size_k, margin_theta.T, precision=EXACT)
              + jnp.matmul(curve_k, growth_k.T, precision=EXACT))
    worst = two_pi * (im + margin)  # (N, 2, rhos)
    # |sin(phi)|^2 on the ellipse, phi = phi_max (z + 1) / 2: at most cosh(Im phi)^2 and
    # sinh(|phi|)^2.
    im_phi = 0.5 * phi_max[:, None] * half_b[None, :]
    abs_phi = 0.5 * phi_max[:, None] * (half_a[None, :] + 1.0)
    sin2 = jnp.minimum(jnp.cosh(im_phi), jnp.sinh(abs_phi)) ** 2  # (N, rhos)
    log_across = worst + (jnp.log(phi_max[:, None] * sin2) + log_n_phi)[:, None, :]
    across = jnp.sum(jnp.exp(jnp.min(log_across, axis=-1)), axis=-1)
    rule_area = 4.0 * jnp.sum(chord_w, axis=1)
    scale = diffraction_limited_otf(s_safe) / rule_area
    bound = jnp.where(interior, (along + across) * scale, 0.0)
    return bound.reshape(shape)




ORDERS = ((18, 14), (14, 10))


def tightness(case, order, sampling) -> dict:
    """The bound over the true error at ``NODES`` random band frequencies of ``case``."""
    aberrations, field, u, _, _ = case.arguments
    nx, ny = band_frequencies(u)
    reference = np.asarray(_otf_overlap(aberrations, nx, ny, field, REFERENCE_ORDER))
    true = np.abs(np.asarray(_otf_overlap(aberrations, nx, ny, field, order)) - reference)
    bound = np.asarray(overlap_error_bound(aberrations, nx, ny, field, order, sampling))
    resolved = true > FLOOR
    ratio = bound[resolved] / true[resolved]
    return dict(case=case.name, order=order, true_max=float(true.max()),
                bound_max=float(bound.max()), nodes_resolved=int(resolved.sum()),
                ratio_min=float(ratio.min()), ratio_median=float(np.median(ratio)),
                below_true=int(np.sum(ratio < 1.0)))


def _phase_only(aberrations, nu_x, nu_y, field, nodes):
    """The phase at the engine's collocation points, the part a bound inside the engine
    would share with it."""
    n_phi, n_t = nodes
    frac, _, t_colloc, _, _ = _overlap_rule(n_phi, n_t, aberrations.chord_degree + 1)
    s = safe_norm(nu_x, nu_y)
    phi = jnp.arccos(s)[:, None] * frac[None, :]
    return _chord_phase(aberrations, field, nu_x, nu_y, nu_x / s, nu_y / s,
                        jnp.cos(phi) - s[:, None], jnp.sin(phi), jnp.asarray(t_colloc))


def timings(order=(18, 14)) -> list[dict]:
    """Warm jitted times at the first grid's coarse nodes (24, 8) at the Fig. 1 point."""
    aberrations, field, u = common.jj.Seidel(**common.FIG1), common.FIG1_FIELD, common.FIG1_U
    coarse = polar_panels(u, 24, 8, jnp.float64)
    x, y = coarse.nu_x.reshape(-1), coarse.nu_y.reshape(-1)
    rows = []

    def warm(fn):
        return common.time_compiled(fn, (aberrations, x, y), max_repeats=31)["warm_s"]

    otf_s = warm(lambda a, x, y: _otf_overlap(a, x, y, field, order))
    phase_s = warm(lambda a, x, y: _phase_only(a, x, y, field, order))
    for sampling in SAMPLINGS:
        bound_s = warm(lambda a, x, y, s=sampling: overlap_error_bound(a, x, y, field, order, s))
        rows.append(dict(sampling=sampling, nodes=int(x.shape[0]), order=order,
                         bound_s=bound_s, otf_s=otf_s, phase_s=phase_s))
    return rows


def main() -> int:
    cases = {c.name: c for c in common.load_bank()}
    report = dict(machine=common.machine_info(), nodes=NODES, orders=ORDERS,
                  reference_order=REFERENCE_ORDER, tightness=[], timings=[])
    lines = ["# An analytic Bernstein-ellipse bound of the overlap rule's error, and its cost",
             "", "`taskset -c 1 .venv/bin/python benchmarks/analytic_overlap_bound.py`", "",
             f"Commit {report['machine'].get('commit')}. {NODES} random frequencies per case "
             f"in the band; true error: `|H|` at the order against {REFERENCE_ORDER}; ratios "
             f"over the nodes whose true error exceeds {FLOOR:g}.", "",
             "| sampling (rhos, angles, points along a chord) | case | order | true error "
             "(largest) | bound (largest) | bound / true: min | median | nodes below |",
             "|---|---|---|---|---|---|---|---|"]
    for sampling in SAMPLINGS:
        for name in CASES:
            for order in ORDERS:
                row = dict(sampling=sampling, **tightness(cases[name], order, sampling))
                report["tightness"].append(row)
                lines.append(f"| {sampling} | {name} | {order} | {row['true_max']:.1e} | "
                             f"{row['bound_max']:.1e} | {row['ratio_min']:.3g} | "
                             f"{row['ratio_median']:.3g} | {row['below_true']} of "
                             f"{row['nodes_resolved']} |")
                print(lines[-1], flush=True)
    lines += ["", "Time at the first grid's 384 coarse nodes at the Fig. 1 point, order "
              "(18, 14), warm and jitted (median):", "",
              "| sampling | bound | the OTF at the same nodes | the phase alone | bound / OTF |",
              "|---|---|---|---|---|"]
    for row in timings():
        report["timings"].append(row)
        lines.append(f"| {row['sampling']} | {row['bound_s'] * 1e6:.0f} us | "
                     f"{row['otf_s'] * 1e6:.0f} us | {row['phase_s'] * 1e6:.0f} us | "
                     f"{row['bound_s'] / row['otf_s']:.2f} |")
        print(lines[-1], flush=True)
    common.write_report("analytic_overlap_bound", report, lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
