"""The default's one-ray plans on defocus balanced against spherical aberration.

A rotationally symmetric design (any design on the axis) is integrated along one ray
(``jmse_jax._radial``). The default has two such plans, one for its weak tiers and one for
its strong ones; until 2026-12-01 each took the grid of the last tier of its group as it
stands. That held on single terms (``small_u_single_terms.py``), but not on the designs an
optical designer makes on purpose: defocus set against spherical aberration,
``W = c (rho^2 + r rho^4)`` with ``r`` between -1.5 and -0.3. Such a design holds far more
spherical aberration than its slope ``max |grad W|`` (which sets its tier) suggests, so the
phase difference varies along the overlap chords more than on a single term and the OTF
ripples more finely along the ray. This script measures the plans as they were
(``before``: ``_merit._RAY_GRIDS`` emptied) and as they are (``after``) against a one-ray
reference with every count far past theirs, on designs of each ratio ``r`` (and pure defocus
and pure spherical aberration) scaled to strengths 1-45 (the one-ray plans' checked bound)
and slopes up to ``CHECKED_SLOPE``, at u 0.05-1.2 and noise 1e-3, 1e-4, 1e-6 and 1e-8 (peak
``S_x / S_n`` 1.6e5-1.6e10).

Usage (from the repository root; about 8 min on 2 cores)::

    .venv/bin/python benchmarks/balanced_one_ray.py

Writes ``results/balanced_one_ray.json`` and ``.md``.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402
from jmse_jax._radial import radial_band_integral  # noqa: E402

#: Every count far past the plans' (coarse nodes along the ray 576 / 384, overlap rule
#: (192, 288), 19200 fine nodes): on three of the hardest designs it agreed with
#: nodes (192, 48) and overlap (128, 128) to 1e-8 (session 63).
REFERENCE = dict(nodes=(384, 96), se_nodes=(9600, 256), overlap_nodes=(192, 288))
RATIOS = ("defocus", "spherical", -0.3, -0.5, -0.6, -0.7, -0.8, -1.0, -1.5, 0.5)
US = (0.05, 0.1, 0.2, 0.3, 0.5, 0.7, 1.0, 1.2)
STRENGTHS = (1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 30.0, 45.0)
NOISES = (1e-3, 1e-4, 1e-6, 1e-8)
SIGNAL = jj.MarkovSignal(1.0, 5.0)


def _unit(ratio) -> jj.Seidel:
    if ratio == "defocus":
        return jj.Seidel(w020=1.0)
    if ratio == "spherical":
        return jj.Seidel(w040=1.0)
    return jj.Seidel(w020=1.0, w040=float(ratio))


def designs(ratios, us, strengths):
    """``(ratio, u, strength, slope, design)`` for each ratio (or pure term), u and strength
    whose slope is at most ``CHECKED_SLOPE``: ``W = c (rho^2 + r rho^4)`` scaled to it."""
    for ratio in ratios:
        unit = _unit(ratio)
        unit_slope = float(jj.aberration_strength(unit, 0.0, 1.0))
        for u in us:
            for strength in strengths:
                slope = strength / min(math.sqrt(2.0) * u, 1.0)
                if slope <= jj.CHECKED_SLOPE:
                    c = slope / unit_slope
                    yield ratio, u, strength, slope, jj.Seidel(w020=c * unit.w020,
                                                              w040=c * unit.w040)


def _plans():
    """The default's one-ray plans as they are and with ``_RAY_GRIDS`` emptied, and the
    index of the first tier of the strong group."""
    options = _merit.jmse_options("default")
    tiers = options.pop("tiers")
    plans = _merit._tier_plans(options, tiers)
    after, split = _merit._radial_plans(plans)
    saved = _merit._RAY_GRIDS
    _merit._RAY_GRIDS = ({}, {})
    try:
        before, _ = _merit._radial_plans(plans)
    finally:
        _merit._RAY_GRIDS = saved
    return [p for p, _ in before], [p for p, _ in after], split, tiers


def main() -> None:
    machine = common.machine_info()
    before, after, split, tiers = _plans()

    def program(options):
        return jax.jit(lambda ab, u, noise: radial_band_integral(
            ab, 0.0, u, SIGNAL, jj.WhiteNoise(noise), options, jnp.float64) / (2 * math.pi))

    reference = program(REFERENCE)
    runs = {"before": [program(p) for p in before], "after": [program(p) for p in after]}
    rows = []
    start = time.perf_counter()
    for ratio, u, strength, slope, ab in designs(RATIOS, US, STRENGTHS):
        tier = int(_merit._tier_index(jnp.asarray(strength), jnp.asarray(u), tiers))
        group = int(tier >= split)
        for noise in NOISES:
            ref = float(reference(ab, u, noise))
            row = dict(ratio=ratio, u=u, strength=strength, slope=slope, w020=float(ab.w020),
                       w040=float(ab.w040), noise=noise, tier=tier, group=group, reference=ref)
            for name, programs in runs.items():
                row[name] = float(programs[group](ab, u, noise)) / ref - 1.0
            rows.append(row)
        print(f"{ratio} u={u} strength {strength:g}: {len(rows)} designs, "
              f"{time.perf_counter() - start:.0f} s", flush=True)
    # The default as a user calls it takes the same plan (a spot check on a few designs).
    spot = [r for r in rows if r["noise"] == 1e-4][::25]
    for r in spot:
        value = float(jj.jmse(jj.Seidel(w020=r["w020"], w040=r["w040"]), 0.0, r["u"], SIGNAL,
                              jj.WhiteNoise(r["noise"])))
        r["jmse_minus_after"] = value / r["reference"] - 1.0 - r["after"]

    def summary(group, name):
        sub = [r for r in rows if r["group"] == group]
        worst = max(sub, key=lambda r: abs(r[name]))
        return (len(sub), sum(abs(r[name]) > 1e-4 for r in sub), abs(worst[name]), worst)

    grid_text = [f"`{ {k: p[k] for k in ('nodes', 'se_nodes', 'overlap_nodes')} }`"
                 for p in before + after]
    lines = ["# The default's one-ray plans on defocus balanced against spherical aberration",
             "", common.machine_line(machine, common.load_average()), "",
             "Relative error of the default's one-ray plans against a one-ray reference "
             f"({REFERENCE}) on `W = c (rho^2 + r rho^4)` (and pure defocus, pure spherical "
             f"aberration) scaled to strengths {STRENGTHS} with slope up to CHECKED_SLOPE = "
             f"{jj.CHECKED_SLOPE:g}, u in {US}, noise in {NOISES}, MarkovSignal(1, 5). "
             "Weak: the group of tiers 0-1 (strength <= 5, slope <= 35), strong: the rest.", "",
             f"Grids: weak before {grid_text[0]}, strong before {grid_text[1]}; weak after "
             f"{grid_text[2]}, strong after {grid_text[3]} (counts along the ray follow from "
             "`nodes[0]` and `se_nodes[0]`: `jmse_jax._radial.radial_counts`).", "",
             "| group | designs | before: > 1e-4 | before: worst | after: > 1e-4 | "
             "after: worst | worst design (after) |", "|---|---|---|---|---|---|---|"]
    for group, label in ((0, "weak"), (1, "strong")):
        n, bad_b, worst_b, _ = summary(group, "before")
        _, bad_a, worst_a, w = summary(group, "after")
        lines.append(f"| {label} | {n} | {bad_b} | {worst_b:.1e} | {bad_a} | {worst_a:.1e} | "
                     f"r = {w['ratio']}, u = {w['u']}, strength {w['strength']:g}, "
                     f"noise {w['noise']:g} |")
    lines += ["", "Designs more than 1e-4 off before (after in the last column):", "",
              "| r | u | strength | slope | w020 | w040 | noise | tier | before | after |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if abs(r["before"]) > 1e-4:
            lines.append(f"| {r['ratio']} | {r['u']} | {r['strength']:g} | {r['slope']:.0f} | "
                         f"{r['w020']:.1f} | {r['w040']:.1f} | {r['noise']:g} | {r['tier']} | "
                         f"{r['before']:+.1e} | {r['after']:+.1e} |")
    spread = max(abs(r["jmse_minus_after"]) for r in spot)
    lines += ["", f"`jj.jmse` (default) against the `after` plan on {len(spot)} of the designs: "
              f"largest difference {spread:.1e} (the same plan)."]
    common.write_report("balanced_one_ray",
                        dict(machine=machine, reference=REFERENCE, before=before, after=after,
                             designs=rows), lines)


if __name__ == "__main__":
    main()
