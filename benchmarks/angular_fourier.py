"""Would a trigonometric angular interpolation of the coarse OTF need fewer OTF nodes?

The polar grid (``jmse_jax._quadrature.polar_panels``) splits the first quadrant into two
triangles at the diagonal, each with its own Gauss rule in the angle, and interpolates the
coarse OTF to the fine ``S_e`` nodes by a polynomial in the angle per triangle. For a
wavefront even in ``x`` (every Seidel design: the field lies on the y axis) the OTF on a
circle ``|nu| = r`` is, over the whole turn, ``Re H = sum_k a_k cos(2 k theta)`` and
``Im H = sum_k b_k sin((2 k + 1) theta)`` (``H(-nu_x, nu_y) = H(nu)`` and
``H(-nu) = conj H(nu)``). So ``N`` equally spaced angles over the quadrant determine the
first ``N`` terms of both series, and a periodic band-limited function is interpolated with
about ``pi / 2`` fewer nodes per oscillation than by polynomials on Gauss nodes.

The catch is geometry: the triangles' rays end at the square's edge, ``u / cos(alpha)``, a
radius that is not smooth at the diagonal, so trigonometric rows must lie on circles
(radius ``min(u sqrt(2), 1)``) and cover more of the plane than the band.

This script measures both layouts on the same fine ``S_e`` rule, everything but the coarse
grid equal (overlap order (64, 64), the library's fine rule and spectra):

* ``triangles``: ``jmse`` with ``nodes=(R, A)``, ``2 R A`` OTF nodes;
* ``circles``: ``R`` radial nodes on the library's composite radial panels over
  ``[0, min(u sqrt(2), 1)]`` times ``N`` equally spaced angles over the quadrant (``R N``
  OTF nodes); interpolated to the fine nodes by the two series in the angle, then by the
  panels' polynomials along each fine ray;
* ``envelope``: the same with rows on ``r = t R(theta)``, ``R`` a smooth envelope of the
  square's edge (``ENVELOPE``) instead of a circle.

and prints the relative error of each against the bank case's converged reference. Run:

    .venv/bin/python benchmarks/angular_fourier.py   # ~46 min on 2 cores; --summarise: table only

Bands with ``u > 1/sqrt(2)`` are skipped (the circles would cross the cutoff).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

import _common  # float64, paths, machine_info
import jax
import jax.numpy as jnp
import numpy as np

import jmse_jax as jj
from jmse_jax._numerics import barycentric_matrix, gauss_legendre
from jmse_jax._otf import _otf_overlap
from jmse_jax._quadrature import (
    OUTER_NODES,
    _radial_counts,
    _radial_panels,
    _radial_rule,
    polar_panels,
)

sys.path.insert(0, str(_common.TESTS))
from problems import PROBLEMS_BY_NAME  # noqa: E402

ORDER = (64, 64)
FINE = (2400, 160)
CASES = ("fig1", "fig1_defocus_m6", "fig1_noise_1e-4", "fig1_u_0.5", "coma_6",
         "astigmatism_m6", "all_5_field_0.8", "hypercube_0", "hypercube_2", "hypercube_4",
         "hypercube_5", "hypercube_6", "powerlaw_defocus_m3_u_0.4")


def angular_matrices(theta_coarse, theta_fine):
    """Matrices taking ``Re H`` and ``Im H`` at the coarse angles to the fine ones."""
    n = len(theta_coarse)
    k = np.arange(n)
    cos_c = np.cos(2 * np.outer(theta_coarse, k))
    sin_c = np.sin(np.outer(theta_coarse, 2 * k + 1))
    cos_f = np.cos(2 * np.outer(theta_fine, k))
    sin_f = np.sin(np.outer(theta_fine, 2 * k + 1))
    return cos_f @ np.linalg.inv(cos_c), sin_f @ np.linalg.inv(sin_c)


def radial_matrix(n_coarse, t_fine):
    """Interpolation from the composite coarse radial rule (``n_coarse`` nodes, in ``t`` on
    [0, 1]) to arbitrary ``t_fine``, panel by panel."""
    out = np.zeros((len(t_fine), n_coarse))
    start = 0
    for (a, b), k in zip(_radial_panels(), _radial_counts(n_coarse), strict=True):
        xc, _ = gauss_legendre(k, a, b)
        inside = (t_fine >= a) & ((t_fine < b) | (b == 1.0))
        if inside.any():
            out[np.ix_(inside, np.arange(start, start + k))] = barycentric_matrix(
                xc, t_fine[inside])
        start += k
    return out


#: ``R(theta) = u (A + B cos(4 theta))``: the smooth envelope of the square's edge that
#: touches it at ``theta = 0`` and ``pi / 4`` (``u / cos(theta)`` there) and lies outside it
#: in between (at most 12 % at 22.5 degrees).
ENVELOPE = ((1 + math.sqrt(2)) / 2, (1 - math.sqrt(2)) / 2)


def ray_length(u, theta, envelope):
    """Length of the coarse rows' rays at ``theta``: a circle or the envelope."""
    if not envelope:
        return np.full(np.shape(theta), min(u * math.sqrt(2.0), 1.0))
    return u * (ENVELOPE[0] + ENVELOPE[1] * np.cos(4 * np.asarray(theta)))


def circles_value(problem, n_radial, n_angles, fine=FINE, envelope=False):
    """The merit with the coarse OTF on circles (or the envelope's curves) and
    trigonometric angular interpolation."""
    ab, field, u, signal, noise = problem.arguments()
    ab = ab.without_tilt()
    t, _ = _radial_rule(n_radial)
    theta = (np.arange(n_angles) + 0.5) * (math.pi / 2) / n_angles
    r = ray_length(u, theta, envelope)[:, None] * t[None, :]
    nx = np.cos(theta)[:, None] * r
    ny = np.sin(theta)[:, None] * r
    h = np.asarray(_otf_overlap(ab, jnp.asarray(nx), jnp.asarray(ny), field, ORDER))
    panels = polar_panels(u, *fine, jnp.float64, n_outer=OUTER_NODES)
    nu_x, nu_y = np.asarray(panels.nu_x), np.asarray(panels.nu_y)  # (2, rows, n_r)
    theta_f = np.arctan2(nu_y[:, :, 0], nu_x[:, :, 0])  # (2, rows)
    m_re, m_im = angular_matrices(theta, theta_f.reshape(-1))
    h_re = (m_re @ h.real).reshape(2, -1, n_radial)
    h_im = (m_im @ h.imag).reshape(2, -1, n_radial)
    rad = np.asarray(panels.radius)  # (rows, n_r), both triangles alike
    h_fine = np.empty(nu_x.shape, complex)
    for row in range(rad.shape[0]):
        for tri in range(2):
            t_fine = rad[row] / ray_length(u, theta_f[tri, row], envelope)
            assert t_fine.max() <= 1 + 1e-12, "the coarse rows must cover the band"
            lr = radial_matrix(n_radial, np.minimum(t_fine, 1.0))
            h_fine[tri, row] = lr @ h_re[tri, row] + 1j * (lr @ h_im[tri, row])
    s_e = jj.error_spectral_density(jnp.asarray(h_fine), signal(panels.nu_x, panels.nu_y),
                                    noise(panels.nu_x, panels.nu_y))
    total = (jnp.sum(panels.weights * s_e)
             + jnp.sum(panels.outer_weights * signal(panels.outer_nu_x, panels.outer_nu_y)))
    return float(total) / (2.0 * math.pi)


def triangles_value(problem, n_radial, n_angles, fine=FINE):
    return float(jj.jmse(*problem.arguments(), nodes=(n_radial, n_angles), se_nodes=fine,
                         overlap_nodes=ORDER))


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--radial", type=int, nargs="+", default=[16, 20, 24, 28, 32, 40])
    parser.add_argument("--cases", nargs="+", default=list(CASES))
    parser.add_argument("--name", default="angular_fourier",
                        help="results/<name>.{json,md} (default: %(default)s)")
    parser.add_argument("--summarise", action="store_true",
                        help="rewrite results/<name>.md from its JSON, computing nothing")
    args = parser.parse_args()
    if args.summarise:
        stored = json.loads((_common.RESULTS / f"{args.name}.json").read_text())
        write_results(args.name, stored["rows"], stored["seconds"], stored["machine"])
        return
    rows = []
    start = time.perf_counter()
    for name in args.cases:
        problem = PROBLEMS_BY_NAME[name]
        if problem.u > 1 / math.sqrt(2):
            continue
        ref = problem.reference
        floor = triangles_value(problem, 80, 40)  # about the fine rule's own error
        print(f"{name}: triangles at (80, 40) {abs(floor - ref) / ref:.1e} off", flush=True)
        for n_r in args.radial:
            for a in (4, 5, 6, 8, 10, 12, 16, 20):
                err = abs(triangles_value(problem, n_r, a) - ref) / ref
                rows.append(dict(case=name, layout="triangles", radial=n_r, angular=2 * a,
                                 nodes=2 * n_r * a, error=err))
            for layout in ("circles", "envelope"):
                for n in (8, 10, 12, 14, 16, 20, 24, 32):
                    value = circles_value(problem, n_r, n, envelope=layout == "envelope")
                    rows.append(dict(case=name, layout=layout, radial=n_r, angular=n,
                                     nodes=n_r * n, error=abs(value - ref) / ref))
            for layout in ("triangles", "circles", "envelope"):
                line = " ".join(f"{x['angular']}:{x['error']:.1e}" for x in rows
                                if x["case"] == name and x["radial"] == n_r
                                and x["layout"] == layout)
                print(f"  R={n_r} {layout:9s} (angles per quadrant:error) {line}", flush=True)
        # Each grid is its own program: without this the compiled programs of a whole run
        # outgrow 24 GB ("LLVM compilation error: Cannot allocate memory").
        jax.clear_caches()
        write_results(args.name, rows, time.perf_counter() - start)
    seconds = time.perf_counter() - start
    print(f"{seconds:.0f} s")
    write_results(args.name, rows, seconds)


#: Error levels of the summary table.
LEVELS = (1e-4, 1e-5, 1e-6, 1e-7)
LAYOUTS = ("triangles", "circles", "envelope")


def fewest_nodes(rows, case, layout, level):
    """The cheapest tried grid of ``layout`` within ``level`` at ``case``: (nodes, R, angles)."""
    hits = [(x["nodes"], x["radial"], x["angular"]) for x in rows
            if x["case"] == case and x["layout"] == layout and x["error"] <= level]
    return min(hits) if hits else None


def strength(case):
    """``aberration_strength`` of a bank case (the shortcut serves strengths up to 5)."""
    ab, field, u, *_ = PROBLEMS_BY_NAME[case].arguments()
    return float(jj.aberration_strength(ab, field, u))


def fixed_grid_table(rows, cases):
    """Per layout and level: the cheapest one grid whose worst error over ``cases`` is
    within the level (a fixed grid must hold for every design it serves)."""
    worst, count = {}, {}
    for x in rows:
        if x["case"] in cases:
            key = (x["layout"], x["radial"], x["angular"], x["nodes"])
            worst[key] = max(worst.get(key, 0.0), x["error"])
            count[key] = count.get(key, 0) + 1
    seen = [k for k in worst if count[k] == len(cases)]  # grids tried on every case
    lines = []
    for level in LEVELS:
        cells = []
        for layout in LAYOUTS:
            hits = sorted((k[3], k[1], k[2], worst[k]) for k in seen
                          if k[0] == layout and worst[k] <= level)
            cells.append(f"{hits[0][0]} ({hits[0][1]} x {hits[0][2]}), worst "
                         f"{hits[0][3]:.1e}" if hits else "-")
        lines.append(f"| {level:.0e} | " + " | ".join(cells) + " |")
    return lines


def write_results(name, rows, seconds, meta=None):
    meta = meta or _common.machine_info()
    (_common.RESULTS / f"{name}.json").write_text(
        json.dumps(dict(machine=meta, order=ORDER, fine=FINE, seconds=seconds, rows=rows),
                   indent=1))
    cases = list(dict.fromkeys(x["case"] for x in rows))
    lines = [
        "# Coarse OTF layouts: two Gauss triangles against trigonometric rows",
        "",
        f"`python benchmarks/angular_fourier.py`, commit {meta.get('commit')}, "
        f"{seconds:.0f} s. Overlap order {ORDER}, fine S_e rule {FINE} for every layout; "
        "relative error against each bank case's converged reference. Each cell: the "
        "fewest coarse OTF nodes of a tried grid within the level, as nodes (radial x "
        "angles per quadrant); `-`: no tried grid reached it.",
        "",
        "| case | level | " + " | ".join(LAYOUTS) + " | triangles / best other |",
        "|---|---|" + "---|" * (len(LAYOUTS) + 1),
    ]
    for case in cases:
        for level in LEVELS:
            best = [fewest_nodes(rows, case, lay, level) for lay in LAYOUTS]
            cells = [f"{b[0]} ({b[1]} x {b[2]})" if b else "-" for b in best]
            others = [b[0] for b in best[1:] if b]
            ratio = (f"{best[0][0] / min(others):.2f}" if best[0] and others else "-")
            lines.append(f"| {case} | {level:.0e} | " + " | ".join(cells) + f" | {ratio} |")
    weak = [c for c in cases if strength(c) <= 5.0]
    lines += [
        "",
        "One fixed grid for several designs: per layout, the cheapest tried grid whose "
        f"worst error over the cases of strength <= 5 ({', '.join(weak)}; the designs the "
        "default's shortcut serves) is within the level, as nodes (radial x angles per "
        "quadrant) and that worst error.",
        "",
        "| level | " + " | ".join(LAYOUTS) + " |",
        "|---|" + "---|" * len(LAYOUTS),
        *fixed_grid_table(rows, weak),
    ]
    (_common.RESULTS / f"{name}.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
