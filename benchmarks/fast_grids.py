"""Would the default's cheap grids serve the ``fast`` preset? Errors by strength, and times.

At the paper's Fig. 1 point the default (1.6 ms a value in the run at 9ce5ba5) is faster
than ``fast`` (2.4 ms) and far more accurate: the default keeps its shortcut's first grid
there (``_FIRST_GRID``, 384 OTF nodes with an (18, 14) overlap rule, about a quarter of
``fast``'s overlap work), checked by a float32 grid and an interpolation-error estimate.
``fast`` has no check; it takes one fixed grid whatever the design. So the question is
whether, without a check, the first grid (or tier 0's grid, ``_TIER0_GRID``) is as accurate
as ``fast``'s own grid on designs of low strength, where ``fast`` could then take it by
strength alone.

The same study showed that ``fast``'s fine ``S_e`` rule was short of radial nodes at high
SNR: its grid until 2026-12-03 (fine nodes (400, 120)) is kept here beside the present one
((800, 48): fewer fine nodes, more of them along the rays,
in the same time).

On the 832 stored calibration designs (``results/calibrate_tiers.json`` and
``calibrate_tiers_kink.json``, with their converged references) this script evaluates the
three fixed grids, jitted, and reports the worst and median relative error by
``aberration_strength`` and ``u``; then it times the three grids at the Fig. 1 point
(value and ``value_and_grad``, alternated rounds, medians).

    .venv/bin/python benchmarks/fast_grids.py          # ~1 min on 2 cores

Writes ``results/fast_grids.json`` and ``results/fast_grids.md``.
"""

from __future__ import annotations

import json
import statistics

import _common as common  # turns on float64
import jax
import numpy as np
from accuracy_speed import _alternate  # the headlines' alternation

import jmse_jax as jj
from jmse_jax._merit import _FIRST_GRID, _TIER0_GRID, PRESETS

SOURCES = ("calibrate_tiers", "calibrate_tiers_kink")
_FAST = PRESETS["fast"]
GRIDS = {
    "fast": dict(nodes=_FAST["nodes"], se_nodes=_FAST["se_nodes"],
                 overlap_nodes=_FAST["overlap_nodes"], overlap_floor=_FAST["overlap_floor"]),
    # ``fast``'s grid until 2026-12-03: the same OTF grid with fine S_e nodes (400, 120).
    "fast until 2026-12-03": dict(nodes=(24, 16), se_nodes=(400, 120), overlap_nodes=(28, 16),
                                  overlap_floor=24),
    "first grid": dict(_FIRST_GRID),
    "tier 0": dict(_TIER0_GRID),
}
STRENGTH_BINS = ((0, 1), (1, 3), (3, 5), (5, 8), (8, 15), (15, 25))
U_BINS = ((0.0, 2 ** -0.5), (2 ** -0.5, 2.0))


def _merit(options):
    def merit(aberrations, field, u, noise):
        return jj.jmse(aberrations, field, u, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(noise),
                       **options)
    return merit


def errors_on_stored_designs(designs):
    out = {}
    for name, options in GRIDS.items():
        fn = jax.jit(_merit(options))
        errs = []
        for d in designs:
            value = fn(jj.Seidel(**d["coefficients"]), d["field"], d["u"], d["noise"])
            errs.append(common.relative_error(float(value), d["reference"]))
        out[name] = errs
    return out


def fig1_times(rounds: int = 9, calls: int = 5):
    args = (jj.Seidel(**common.FIG1), common.FIG1_FIELD, common.FIG1_U, 1e-3)
    compiled = {}
    for name, options in {**GRIDS, "default (as called)": {}}.items():
        fn = _merit(options)
        compiled[name] = (jax.jit(fn).lower(*args).compile(),
                          jax.jit(jax.value_and_grad(fn)).lower(*args).compile())
        for f in compiled[name]:
            jax.block_until_ready(f(*args))
    times = _alternate(compiled, args, rounds, dict.fromkeys(compiled, calls))
    return {name: dict(value_s=statistics.median(v), value_and_grad_s=statistics.median(g))
            for name, (v, g) in times.items()}


def main():
    machine = common.machine_info()
    designs = []
    for source in SOURCES:
        designs += json.loads((common.RESULTS / f"{source}.json").read_text())["designs"]
    errors = errors_on_stored_designs(designs)
    times = fig1_times()
    strength = np.array([d["strength"] for d in designs])
    u = np.array([d["u"] for d in designs])
    lines = ["# The default's cheap grids as `fast`'s, without a check", "",
             common.machine_line(machine, common.load_average()), "",
             f"{len(designs)} stored calibration designs ({', '.join(SOURCES)}); relative "
             "error against their converged references, worst / median per bin. Grids:",
             ""]
    lines += [f"- {name}: {options}" for name, options in GRIDS.items()]
    lines += ["", "| strength | u | designs | " + " | ".join(GRIDS) + " |",
              "|---|---|---|" + "---|" * len(GRIDS)]
    bins = []
    for lo, hi in STRENGTH_BINS:
        for ulo, uhi in U_BINS:
            mask = (strength > lo) & (strength <= hi) & (u > ulo) & (u <= uhi)
            if not mask.any():
                continue
            cells = {name: (float(np.max(np.asarray(e)[mask])),
                            float(np.median(np.asarray(e)[mask]))) for name, e in errors.items()}
            bins.append(dict(strength=(lo, hi), u=(ulo, uhi), designs=int(mask.sum()),
                             errors=cells))
            lines.append(f"| {lo}-{hi} | {ulo:.2f}-{uhi:.2f} | {int(mask.sum())} | " + " | ".join(
                f"{w:.1e} / {m:.0e}" for w, m in cells.values()) + " |")
    lines += ["", "Fig. 1 point, jitted, warm, medians of 9 alternated rounds of 5 calls:", "",
              "| grid | value | value_and_grad |", "|---|---|---|"]
    lines += [f"| {name} | {common.fmt_seconds(t['value_s'])} | "
              f"{common.fmt_seconds(t['value_and_grad_s'])} |" for name, t in times.items()]
    report = dict(machine=machine, grids=GRIDS, bins=bins, fig1_times=times,
                  designs=[dict(strength=float(s), u=float(x)) for s, x in zip(strength, u,
                                                                               strict=True)],
                  errors=errors)
    common.write_report("fast_grids", report, lines)


if __name__ == "__main__":
    main()
