"""The experiments of Berkner & Shroff reproduced: their Fig. 1 and both panels of Fig. 4.

Run from the repository root (normally through ``benchmarks/run_all.py``)::

    .venv/bin/python benchmarks/paper_figures.py            # full (a few minutes)
    .venv/bin/python benchmarks/paper_figures.py --quick    # coarse, < 1 min

Writes to ``benchmarks/results/`` (``_quick`` suffix for ``--quick``):

``paper_fig4_right.png``
    JMSE versus the number of frequency nodes ``p`` per axis per quadrant (``p**2`` OTF
    nodes per quadrant) for the rectangle, trapezoid, Gauss x Gauss and Gauss-radial x
    trapezoid-angular rules (the paper's four) and our polar panel rule, at ``u = 0.2``, for
    defocus -6.0 and -2.75 at the Fig. 1 aberrations; the converged value as a line; below,
    the relative error. The OTF is evaluated directly at each rule's nodes (overlap engine,
    the high preset's ``overlap_nodes``), so only the frequency rule is compared.
``paper_fig4_left.png``
    OPD error ``d_Omega[K, L]``: mean over a Latin-hypercube sample of the aberration
    hypercube (each of w020, w040, w131, w222, w220 in +-6 waves, field 0.95) of the RMS
    difference, in waves over the unit disc, between the OPD on the cells of a 64 x 64
    reference grid and the OPD rebuilt from the samples on the polar L x K grid, for
    L = 2 ... 10 rings and K = 4 ... 40 arms; rebuilt (a) by piecewise-cubic interpolation
    (scipy's Clough-Tocher interpolant on the Delaunay triangulation of the polar samples,
    i.e. ``griddata(method="cubic")``; nearest sample outside their convex hull), standing in
    for the paper's bicubic interpolation, and (b) by our exact quadrature projection onto
    the Zernike polynomials the grid resolves (``zernike_fit``). The lambda/10 contour is
    drawn.
``paper_fig1.png``
    The OPD map and ``log10 S_e`` over the sensor band of the Fig. 1 point.
``paper_figures.json``, ``paper_figures.md``
    The numbers behind the figures, and the findings: where each rule's error first stays
    below 1e-3 and 1e-6, and which (L, K) each OPD reconstruction needs for lambda/10.
"""

from __future__ import annotations

import argparse
import sys
import time

import _common as common

import jmse_jax as jj
from jmse_jax import _reproduce as reproduce
from jmse_jax._reproduce import (
    PAPER_RULES,
    RULE_LABELS,
    jmse_versus_nodes,
)

# --------------------------------------------------------------------------------------
# Fig. 4 right: JMSE versus the number of frequency nodes
# --------------------------------------------------------------------------------------


def converged_value(case, aberrations, signal, noise, quick=False):
    """The bank's reference when it is converged, else our own: ``preset="high"`` refined
    (1.5x the OTF nodes, 2x the S_e nodes), its convergence estimated against ``"high"``."""
    if case is not None and case.reference is not None and case.converged:
        return case.reference, case.convergence, f"tests/problems.py ({case.name})"
    high = jj.jmse_options("high")
    refined = dict(nodes=tuple(int(1.5 * n) for n in high["nodes"]),
                   se_nodes=tuple(2 * n for n in high["se_nodes"]),
                   overlap_nodes=tuple(int(1.5 * n) for n in high["overlap_nodes"]))
    args = (aberrations, common.FIG1_FIELD, common.FIG1_U, signal, noise)
    value_high = float(jj.jmse(*args, preset="high"))
    if quick:
        return value_high, None, "computed here: preset high (quick run)"
    value = float(jj.jmse(*args, preset="high", **refined))
    note = f"computed here: preset high refined to {refined}"
    if case is not None and case.reference is not None:
        note += (f"; the bank's reference {case.reference:.10e} has convergence estimate "
                 f"{case.convergence:.1e} and differs by "
                 f"{abs(case.reference - value) / value:.1e}")
    return value, abs(value_high - value) / abs(value), note


def fig4_right(quick, cases_by_name):
    ps = (4, 8, 16, 32) if quick else (4, 5, 6, 7, 8, 10, 12, 14, 16, 20, 24, 28, 32, 40, 48,
                                       56, 64)
    rules = PAPER_RULES + ("polar",)
    overlap = jj.jmse_options("high")["overlap_nodes"]
    signal, noise = common.fig1_signal(), common.fig1_noise()
    out = dict(u=common.FIG1_U, field=common.FIG1_FIELD, ps=list(ps), overlap_nodes=overlap,
               signal=repr(signal), noise=repr(noise), rules=list(rules), defocus={})
    for defocus, name in ((-6.0, "fig1_defocus_m6"), (-2.75, "fig1")):
        aberrations = jj.Seidel(**{**common.FIG1, "w020": defocus})
        case = cases_by_name.get(name)
        reference, convergence, source = converged_value(case, aberrations, signal, noise,
                                                         quick)
        start = time.perf_counter()
        values, n_nodes = jmse_versus_nodes(aberrations, common.FIG1_FIELD, common.FIG1_U,
                                            signal, noise, rules, ps, overlap)
        seconds = time.perf_counter() - start
        # Consistency: the same sums through the public jmse at one p per rule.
        p_check = 16
        check = {}
        for rule in () if quick else rules:
            options = (dict(quadrature="polar", nodes=(p_check, p_check // 2),
                            se_nodes=(p_check, p_check // 2))
                       if rule == "polar" else dict(quadrature=rule, nodes=p_check))
            direct = float(jj.jmse(aberrations, common.FIG1_FIELD, common.FIG1_U, signal, noise,
                                   overlap_nodes=overlap, **options))
            check[rule] = abs(direct - values[rule][p_check]) / abs(direct)
        presets = {}
        for preset in (("default",) if quick else ("fast", "default", "high")):
            options = jj.jmse_options(preset)
            value = float(jj.jmse(aberrations, common.FIG1_FIELD, common.FIG1_U, signal, noise,
                                  preset=preset))
            otf_nodes = (2 * options["nodes"][0] * options["nodes"][1]
                         if options["quadrature"] == "polar" else None)
            presets[preset] = dict(jmse=value, otf_nodes_per_quadrant=otf_nodes,
                                   relative_error=abs(value - reference) / abs(reference),
                                   options=options)
        rows = reproduce.rule_rows(values, reference, ps)
        out["defocus"][str(defocus)] = dict(
            case=name, reference=reference, reference_convergence=convergence,
            reference_source=source,
            otf_evaluations=n_nodes, seconds=seconds, presets=presets,
            consistency_with_jmse_at_p16=check, rules=rows)
        print(f"fig4 right, defocus {defocus}: reference {reference:.10e} "
              f"({n_nodes} OTF nodes, {seconds:.1f} s)", flush=True)
        for rule in rules:
            below = rows[rule]["first_stays_below"]
            print(f"   {rule:12s} stays below 1e-3 from p={below['0.001']}, "
                  f"1e-6 from p={below['1e-06']}", flush=True)
    return out


def plot_fig4_right(data, path):
    """The package's Fig. 4 (right) plot, with the presets marked as stars."""
    reproduce.plot_fig4_right(data, path, dpi=130)


# --------------------------------------------------------------------------------------
# Fig. 4 left: OPD error d_Omega[K, L]
# --------------------------------------------------------------------------------------


def opd_error(quick, seed=20240607):
    """Fig. 4 (left) through the package (quick: fewer designs and grids)."""
    if quick:
        return reproduce.opd_error(8, (2, 3, 4, 6, 8), (4, 6, 8, 10, 16, 24, 40), seed,
                                   common.FIG1_FIELD)
    return reproduce.opd_error(seed=seed, field=common.FIG1_FIELD)


def plot_fig4_left(data, path):
    reproduce.plot_fig4_left(data, path, dpi=130)


# --------------------------------------------------------------------------------------
# Fig. 1: OPD and log S_e of the Fig. 1 point
# --------------------------------------------------------------------------------------


def fig1(quick, path, wide=0.6):
    """Fig. 1 of the paper (OPD and log10 S_e maps): the package's own plot, at benchmark size."""
    n_pupil, n_freq = (64, 61) if quick else (256, 201)
    start = time.perf_counter()
    data = reproduce.fig1_maps(path, n_pupil=n_pupil, n_freq=n_freq, wide=wide)
    data["seconds"] = time.perf_counter() - start
    data["s_e_min"] = 10.0 ** data["log10_s_e_band_min"]
    data["s_e_max"] = 10.0 ** data["log10_s_e_band_max"]
    return data


# --------------------------------------------------------------------------------------


def _e(x):
    return "?" if x is None else f"{x:.1e}"


def _p(x):
    return "not within the tested p" if x is None else f"p = {x} ({x * x} nodes/quadrant)"


def markdown(report) -> str:
    m = report["machine"]
    lines = ["# Berkner & Shroff experiments reproduced" +
             (" (quick)" if report["quick"] else ""), "",
             f"{m['cpu_model']}, {m['cpu_count']} CPUs, jax {m['jax_version']}, {m['dtype']}, "
             f"commit `{(m['commit'] or '?')[:10]}`, {m['date']}.", "",
             "## Fig. 4 right: JMSE versus frequency nodes (u = 0.2)", "",
             "OTF evaluated directly at each rule's nodes (overlap engine, overlap_nodes "
             f"{tuple(report['fig4_right']['overlap_nodes'])}); relative error against the "
             "bank's reference. *First stays below* = the smallest tested p from which every "
             "larger tested p stays below the threshold.", "",
             "| defocus | rule | stays < 1e-3 from | stays < 1e-6 from | error at p=16 | "
             "error at p=64 |", "|---|---|---|---|---|---|"]
    f4 = report["fig4_right"]
    for defocus, block in f4["defocus"].items():
        for rule in f4["rules"]:
            row = block["rules"][rule]
            err = row["relative_error"]
            lines.append(f"| {defocus} | {RULE_LABELS[rule]} | "
                         f"{_p(row['first_stays_below']['0.001'])} | "
                         f"{_p(row['first_stays_below']['1e-06'])} | "
                         f"{err.get('16', float('nan')):.1e} | "
                         f"{err.get('64', float('nan')):.1e} |")
        for preset, entry in block["presets"].items():
            lines.append(f"| {defocus} | preset {preset} ({entry['otf_nodes_per_quadrant']} OTF "
                         f"nodes/quadrant, interpolated to finer S_e nodes) | | | "
                         f"{entry['relative_error']:.1e} | |")
    lines += ["", "Reference values: " + ", ".join(
        f"defocus {d}: {b['reference']:.10e} (convergence estimate "
        f"{_e(b['reference_convergence'])}; {b['reference_source']})"
        for d, b in f4["defocus"].items()), ""]
    f4l = report["fig4_left"]
    lines += ["## Fig. 4 left: OPD error d_Ω[K, L] (waves RMS, λ/10 = 0.1)", "",
              f"{f4l['n_designs']} Latin-hypercube designs, each Seidel coefficient in ±6 waves, "
              f"field {f4l['field']}; reference: OPD at the 64 × 64 cell centres inside the disc.",
              "", "| reconstruction | fewest samples with d ≤ λ/10 | d at the paper's L=6, K=40 |"
              " smallest K (for all larger K) per L |", "|---|---|---|---|"]
    for key, label in (("cubic", "piecewise cubic (Clough–Tocher, as bicubic)"),
                       ("zernike", "Zernike projection (ours)")):
        fnd = f4l[key]
        fewest = fnd["fewest_samples"]
        lines.append(f"| {label} | "
                     + (f"L={fewest['rings']}, K={fewest['arms']} ({fewest['samples']})"
                        if fewest else "none") + " | "
                     + ("–" if fnd["d_at_paper_choice_L6_K40"] is None
                        else f"{fnd['d_at_paper_choice_L6_K40']:.2e}")
                     + " | " + ", ".join(f"L={r}: {a}" for r, a in
                                        fnd["min_arms_per_rings"].items()) + " |")
    f1 = report["fig1"]
    lines += ["", "## Fig. 1", "",
              f"OPD from {f1['opd_min']:.2f} to {f1['opd_max']:.2f} waves (RMS "
              f"{f1['opd_rms']:.2f}); S_e from {f1['s_e_min']:.2e} to {f1['s_e_max']:.2e}; "
              f"JMSE (default preset) {f1['jmse_default']:.9e}.", ""]
    return "\n".join(lines) + "\n"


def run(quick: bool = False) -> dict:
    start = time.perf_counter()
    machine = common.machine_info()
    cases = common.load_bank(reference_fallback="high" if quick else "strict")
    cases_by_name = {c.name: c for c in cases}
    suffix = "_quick" if quick else ""
    out = common.RESULTS
    right = fig4_right(quick, cases_by_name)
    plot_fig4_right(right, out / f"paper_fig4_right{suffix}.png")
    left = opd_error(quick)
    plot_fig4_left(left, out / f"paper_fig4_left{suffix}.png")
    figure1 = fig1(quick, out / f"paper_fig1{suffix}.png")
    report = dict(description="Berkner & Shroff Fig. 1 and Fig. 4 reproduced", quick=quick,
                  machine=machine, fig4_right=right, fig4_left=left, fig1=figure1,
                  load_at_end=common.load_average(), seconds=time.perf_counter() - start)
    common.write_json(out / f"paper_figures{suffix}.json", report)
    (out / f"paper_figures{suffix}.md").write_text(markdown(report))
    print(markdown(report))
    print(f"paper_figures: {report['seconds']:.0f} s, wrote {out}/paper_*{suffix}.png, "
          f"paper_figures{suffix}.json/.md")
    return report


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="coarse grids (< 1 min)")
    args = parser.parse_args(argv)
    run(quick=args.quick)
    return 0


if __name__ == "__main__":
    sys.exit(main())
