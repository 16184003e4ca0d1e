"""A per-node bound of the overlap rule's error from the Bernstein ellipse (a feasibility study).

The default's shortcut keeps a cheap first grid only when a float32 check grid agrees with it,
and the check costs about a third of the call at the paper's Fig. 1 point
(``grid_frontier.py --components``). What the check sees beyond the first grid's own
interpolation-error estimate is the overlap rule's error and the fine rule's
(``recheck_shortcut.py --probes``). This script asks whether the overlap rule's error at each
frequency node can be bounded from the phase polynomial alone, without new phases.

Gauss–Legendre of order ``n`` on ``[-1, 1]`` integrates a function analytic inside the
Bernstein ellipse ``E_rho`` (foci +-1, semi-axes summing to ``rho``), where ``|f| <= M(rho)``,
to within ``(64/15) M(rho) rho^(-2n) / (rho^2 - 1)`` (Trefethen, *Approximation Theory and
Approximation Practice*, Thm. 19.3). The overlap engine's integrand is ``e^{i 2 pi D}`` with
``D`` the wavefront's difference, a polynomial, so ``|f| = e^{-2 pi Im D}`` on the ellipse is
known in closed form:

- along each chord, with the chord parameter ``t`` on ``E_rho``;
- across the chords, with the chord position on ``E_rho`` and ``|chord integral| <= 2 max_t
  |f|`` (``t`` sampled on [-1, 1]).

Each bound is minimised over ``RHOS``; the node's bound is the along-chord bounds summed
with the chord weights plus the across-chord bound, scaled as the engine scales ``H``. The
true error is the engine's ``H`` at the same order against order (64, 64). Usage (from the
repository root; about 1 min)::

    .venv/bin/python benchmarks/overlap_error_bound.py [--cheap] [CASE ...]

Writes ``benchmarks/results/overlap_error_bound[_cheap].{json,md}`` (``--cheap``: the sparser
sampling ``CHEAP``). The bound as evaluated here
costs more than the quadrature it bounds (a cheap form is sketched in benchmarks/README.md,
optimisation log, session 38).
"""

from __future__ import annotations

import math
import sys

import _common as common
import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

from jmse_jax import _otf  # noqa: E402
from jmse_jax._numerics import gauss_legendre  # noqa: E402

#: Ellipse parameters over which each bound is minimised, and points per ellipse.
RHOS = np.array([1.05, 1.1, 1.2, 1.35, 1.5, 1.75, 2.0, 2.5, 3.0, 4.0, 6.0])
N_THETA = 24
THETA = np.linspace(0.0, 2.0 * np.pi, N_THETA, endpoint=False)
#: Points along each chord at which the across-chord bound takes the largest ``|f|``.
T_SAMPLES = np.linspace(-1.0, 1.0, 9)
ORDERS = ((18, 14), (14, 10), (28, 24))
REFERENCE_ORDER = (64, 64)
CASES = ("fig1", "hypercube_4", "hypercube_3", "coma_6", "hypercube_0", "all_5_field_0.8")
NODES = 300
#: True errors below this are rounding; they are left out of the ratios.
FLOOR = 1e-12


#: A sparser sampling (``--cheap``): what a form inside the library could afford.
CHEAP = dict(rhos=np.array([1.2, 1.5, 2.0, 3.0]), n_theta=8, t_samples=np.array([-1.0, 0.0, 1.0]))


def _ellipse(rho, theta=THETA):
    z = rho * np.exp(1j * theta)
    return 0.5 * (z + 1.0 / z)


def _gauss_bound(log_m, n, rhos=RHOS):
    """``min_rho (64/15) M rho^(-2n) / (rho^2 - 1)`` for ``log M`` on the last axis."""
    log_bound = (math.log(64.0 / 15.0) + log_m - 2 * n * np.log(rhos)
                 - np.log(rhos**2 - 1.0))
    return np.exp(np.min(log_bound, axis=-1))


def node_bounds(aberrations, field, nx, ny, n_phi, n_t, rhos=RHOS, n_theta=N_THETA,
                t_samples=T_SAMPLES):
    """Bounds of the overlap rule's error at each node: ``(along the chords, across)``,
    minimised over ``rhos``, with ``n_theta`` points per ellipse and the across-chord bound's
    largest ``|f|`` taken at ``t_samples``."""
    theta = np.linspace(0.0, 2.0 * np.pi, n_theta, endpoint=False)
    s = np.hypot(nx, ny)
    ex, ey = nx / s, ny / s
    xf, wf = gauss_legendre(n_phi, -1.0, 1.0)
    phi_max = np.arccos(s)
    along_total = np.zeros_like(s)
    across_total = np.zeros_like(s)
    for side in (1.0, -1.0):
        def phase(x, t, side=side):
            """``D`` and ``sin(phi)`` at chord parameter ``x`` (on [-1, 1]), chord point ``t``
            (either may be complex), every node first."""
            phi = phi_max[:, None, None] * (x + 1.0) / 2.0
            a = np.cos(phi) - s[:, None, None]
            sin_phi = np.sin(phi)
            px = side * a * ex[:, None, None] - sin_phi * t * ey[:, None, None]
            py = side * a * ey[:, None, None] + sin_phi * t * ex[:, None, None]
            d = aberrations.difference(px, py, nx[:, None, None], ny[:, None, None], field)
            return np.asarray(d), sin_phi

        log_m = np.stack([np.max(-2 * np.pi * np.imag(
            phase(xf[None, :, None] + 0j, _ellipse(rho, theta)[None, None, :])[0]), axis=-1)
            for rho in rhos], axis=-1)
        along = _gauss_bound(log_m, n_t, rhos)  # (nodes, n_phi)
        sin_real = np.sin(phi_max[:, None] * (xf[None, :] + 1.0) / 2.0)
        along_total += ((phi_max[:, None] / 2.0) * sin_real**2 * along) @ wf
        log_m = []
        for rho in rhos:
            d, sin_phi = phase(_ellipse(rho, theta)[None, :, None],
                               t_samples[None, None, :] + 0j)
            worst = np.max(-2 * np.pi * np.imag(d), axis=-1)
            log_m.append(np.max(np.log(phi_max[:, None] * np.abs(sin_phi[..., 0])**2)
                                + worst, axis=-1))
        across_total += _gauss_bound(np.stack(log_m, axis=-1), n_phi, rhos)
    area = 4.0 * (((phi_max[:, None] / 2.0)
                   * np.sin(phi_max[:, None] * (xf[None, :] + 1.0) / 2.0)**2) @ wf)
    scale = np.asarray(_otf.diffraction_limited_otf(s)) / area
    return along_total * scale, across_total * scale


def band_frequencies(u, nodes=NODES):
    """``nodes`` random frequencies ``(nu_x, nu_y)`` spread over the band of ``u`` (up to
    ``min(sqrt(2) u, 0.999)``), the same for every call."""
    rng = np.random.default_rng(1)
    reach = min(0.999, u * math.sqrt(2.0))
    r = reach * np.sqrt(rng.uniform(0.01, 1.0, nodes))
    theta = rng.uniform(0.0, 2.0 * math.pi, nodes)
    return r * np.cos(theta), r * np.sin(theta)


def study(case, sampling=None) -> list[dict]:
    aberrations, field, u, _, _ = case.arguments
    nx, ny = band_frequencies(u)
    reference = np.asarray(_otf._otf_overlap(aberrations, nx, ny, field, REFERENCE_ORDER))
    rows = []
    for order in ORDERS:
        h = np.asarray(_otf._otf_overlap(aberrations, nx, ny, field, order))
        true = np.abs(h - reference)
        along, across = node_bounds(aberrations, float(field), nx, ny, *order,
                                    **(sampling or {}))
        bound = along + across
        resolved = true > FLOOR
        ratio = bound[resolved] / true[resolved]
        rows.append(dict(
            case=case.name, order=order, true_max=float(true.max()),
            bound_max=float(bound.max()), along_max=float(along.max()),
            across_max=float(across.max()), nodes_resolved=int(resolved.sum()),
            ratio_min=float(ratio.min()) if resolved.any() else None,
            ratio_median=float(np.median(ratio)) if resolved.any() else None,
            below_true=int(np.sum(bound[resolved] < true[resolved]))))
    return rows


def main(argv=None) -> int:
    argv = list(argv if argv is not None else sys.argv[1:])
    cheap = "--cheap" in argv
    names = [a for a in argv if a != "--cheap"] or list(CASES)
    sampling = CHEAP if cheap else None
    cases = {c.name: c for c in common.load_bank()}
    report = dict(machine=common.machine_info(), nodes=NODES, orders=ORDERS,
                  reference_order=REFERENCE_ORDER, rhos=RHOS.tolist(), rows=[])
    lines = ["# A Bernstein-ellipse bound of the overlap rule's error per node", "",
             f"`python benchmarks/overlap_error_bound.py{' --cheap' if cheap else ''}`", "",
             ("Sparse sampling: rho in " + str(CHEAP["rhos"].tolist()) + f", "
              f"{CHEAP['n_theta']} points per ellipse, the across-chord bound's |f| at t in "
              + str(CHEAP["t_samples"].tolist()) + "." if cheap else
              f"rho in {RHOS.tolist()}, {len(THETA)} points per ellipse, the across-chord "
              f"bound's |f| at {len(T_SAMPLES)} points along each chord."), "",
             f"Commit {report['machine'].get('commit')}. {NODES} random frequencies per case "
             f"in the band (up to min(sqrt(2) u, 0.999)); true error: `|H|` at the order "
             f"against order {REFERENCE_ORDER}; ratios over the nodes whose true error "
             f"exceeds {FLOOR:g} (below it the error is rounding).", "",
             "| case | order | true error (largest) | bound (largest; along / across the "
             "chords) | bound / true: min | median | nodes below the true error |",
             "|---|---|---|---|---|---|---|"]
    for name in names:
        for row in study(cases[name], sampling):
            report["rows"].append(row)

            def fmt(x, spec):
                return "–" if x is None else format(x, spec)

            lines.append(
                f"| {row['case']} | {row['order']} | {row['true_max']:.1e} | "
                f"{row['bound_max']:.1e} ({row['along_max']:.1e} / {row['across_max']:.1e}) "
                f"| {fmt(row['ratio_min'], '.2g')} | {fmt(row['ratio_median'], '.2g')} | "
                f"{row['below_true']} of {row['nodes_resolved']} |")
            print(lines[-1], flush=True)
    common.write_report("overlap_error_bound" + ("_cheap" if cheap else ""), report, lines)
    return 0


if __name__ == "__main__":
    sys.exit(main())
