"""What holds ``"high"``'s gradient on session 87's small-``u`` low-noise design.

Session 88's ``otf_radial.py --recheck`` left one of session 87's worst low-noise designs
of ``"high"`` where it was: seed 3's climb 2 (u 0.13, strength 2.2, peak ``S_x / S_n``
1.2e8), 3.9e-5 off in the gradient with both low-noise counts, its value within 1e-8.
This script varies each count of the grid it takes (``HIGH``, ``"high"``'s own grid with
``se_angular_for``'s and ``otf_radial_for``'s counts) and of the reference
(``otf_radial.REFERENCE``), with and without the closed-form peaks
(``jmse_jax._ridges``), and gives each gradient's error (``default_climb.gradient_error``)
and value's against the finest grid without the peaks (``FINEST``), which needs no model
of them.

Usage (from the repository root; about 12 min on 2 cores)::

    .venv/bin/python benchmarks/small_u_peaks.py

Writes ``results/small_u_peaks.json`` and ``.md``.
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import default_climb as dc  # noqa: E402
import jax  # noqa: E402
import otf_radial as orad  # noqa: E402

import jmse_jax as jj  # noqa: E402

CLIMBS = HERE / "results" / orad.CLIMBS[0]  # seed 3's
REFERENCE = dict(orad.REFERENCE, nodes=(256, 64))
#: The finest grid, without the peaks: the fine rule alone resolves them there.
FINEST = dict(REFERENCE, se_nodes=(32000, 7680), peaks=False)


def _row():
    climb = json.loads(CLIMBS.read_text())["climbs"][1]
    worst = climb.get("worst", climb)
    return {k: worst[k] for k in ("scale", "coefficients", "field", "u", "amplitude",
                                  "exponent", "knee", "noise")}


def runs(row):
    """``(name, options)`` of each grid: ``"high"``'s with the counts and more radial fine
    S_e nodes, the reference with more, each with the peaks and some without."""
    import se_angular as sa

    _, grid = sa._grid_taken(row)
    design = dc._design(row)
    high = dict(grid, nodes=(max(grid["nodes"][0], jj.otf_radial_for(*design[2:])),
                             grid["nodes"][1]),
                se_nodes=(grid["se_nodes"][0],
                          max(grid["se_nodes"][1], jj.se_angular_for(*design[2:]))))
    out = []
    for radial in (high["se_nodes"][0], 4000, 5600, 11200):
        options = dict(high, se_nodes=(radial, high["se_nodes"][1]))
        out.append((f"high, {radial} radial fine nodes", options))
    out.append((f"high, {high['se_nodes'][0]} radial fine nodes, no peaks",
                dict(high, peaks=False)))
    for radial in (8000, 16000, 24000, 32000):
        out.append((f"reference, {radial} radial fine nodes",
                    dict(REFERENCE, se_nodes=(radial, REFERENCE["se_nodes"][1]))))
    out.append(("reference, 16000 radial fine nodes, no peaks",
                dict(REFERENCE, se_nodes=(16000, 7680), peaks=False)))
    return out


def main():
    machine = common.machine_info()
    row = _row()
    warnings.simplefilter("ignore")  # beyond CHECKED_SNR, as the climbs allowed
    value_ref, s_ref = dc._sensitivities(row, FINEST)
    dc._gradient_program.cache_clear()
    jax.clear_caches()
    rows = []
    for name, options in runs(row):
        start = time.perf_counter()
        value, s = dc._sensitivities(row, options)
        dc._gradient_program.cache_clear()
        jax.clear_caches()
        worst = int(abs(s - s_ref).argmax())
        rows.append(dict(name=name, options=options, value=value, s=s.tolist(),
                         gradient_error=dc.gradient_error(s, s_ref),
                         worst=(list(dc.TERMS) + ["field", "u", "noise"])[worst],
                         value_error=abs(value / value_ref - 1.0),
                         seconds=time.perf_counter() - start))
        print(rows[-1], flush=True)
    lines = ["# `high` on session 87's small-`u` design: what holds its gradient", "",
             "`python benchmarks/small_u_peaks.py`", "",
             common.machine_line(machine, common.load_average()), "",
             f"Seed 3's climb 2 (`{CLIMBS.name}`): u {row['u']:.3f}, noise "
             f"{row['noise']:.3g}. Errors against {FINEST} (the fine rule alone, no model "
             "of the peaks); the gradient's is `default_climb.gradient_error` of the "
             "sensitivities, with the entry where it is largest.", "",
             "| grid | gradient's error | largest in | value's error |", "|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['name']} | {r['gradient_error']:.2e} | {r['worst']} | "
                     f"{r['value_error']:.1e} |")
    common.write_report("small_u_peaks", dict(machine=machine, row=row, finest=FINEST,
                                              value_ref=value_ref, s_ref=s_ref.tolist(),
                                              rows=rows), lines)


if __name__ == "__main__":
    main()
