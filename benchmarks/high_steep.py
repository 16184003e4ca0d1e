"""The ``"high"`` preset on steep designs (many waves at small ``u``): does its fixed overlap
rule hold where the default needed its steep tier (``STEEP_SLOPE``)?

Designs: the stored designs of ``small_u_single_terms.py`` (``results/small_u_single_terms.json``)
that take a polar grid and lie within ``CHECKED_SLOPE``: its single terms, against their
stored polar references, and its 55 steep designs (single terms and mixtures of slope
45-67), whose references are recovered from the stored error of the default's steep tier
(the tier's grid is evaluated again; it is deterministic). Each grid named on the command
line (``GRIDS``: ``high`` is the preset as a user calls it, the others are ``"high"``'s own
grid with another overlap rule) is evaluated on every design.

Usage (from the repository root; about 3 min for three grids on 2 cores)::

    .venv/bin/python benchmarks/high_steep.py --grids high own S64 S80

Writes ``results/high_steep.json`` and ``.md`` (``--name`` to change).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64

import jmse_jax as jj  # noqa: E402

SIGNAL, NOISE = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
#: ``"high"``'s own grid, without its balanced or steep grids.
OWN = {k: jj.PRESETS["high"][k]
       for k in ("nodes", "se_nodes", "overlap_nodes", "overlap_floor", "peaks")}
GRIDS = {
    "high": {"preset": "high"},
    "own": OWN,
    "S64": dict(OWN, overlap_nodes=(64, 64), overlap_floor=64),
    "S80": dict(OWN, overlap_nodes=(80, 80), overlap_floor=80),
    "S96": dict(OWN, overlap_nodes=(96, 96), overlap_floor=96),
    "T1": dict(OWN, nodes=(96, 48), se_nodes=(4800, 960), overlap_nodes=(64, 64),
               overlap_floor=64),
    "T2": dict(OWN, nodes=(128, 48), se_nodes=(6400, 960), overlap_nodes=(64, 64),
               overlap_floor=64),
    "T3": dict(OWN, nodes=(96, 48), se_nodes=(4800, 960), overlap_nodes=(80, 80),
               overlap_floor=80),
    "T5": dict(OWN, nodes=(128, 64), se_nodes=(6400, 960), overlap_nodes=(64, 64),
               overlap_floor=64),
    "T6": dict(OWN, nodes=(128, 64), se_nodes=(6400, 960), overlap_nodes=(80, 80),
               overlap_floor=80),
}


def designs():
    """``(label, aberrations, field, u, slope, reference)`` of the stored designs."""
    data = json.loads((common.RESULTS / "small_u_single_terms.json").read_text())
    out = []
    for r in data["designs"]:
        if r["one_ray"] or r["slope"] > jj.CHECKED_SLOPE:
            continue
        ab = jj.Seidel(**{r["term"]: r["coefficient"]})
        out.append((r["term"], ab, data["field"], r["u"], r["slope"], r["reference"]))
    steep_grid = jj.DEFAULT_TIERS[-1][2]
    for r in data["steep"]:
        ab = jj.Seidel(**r["coefficients"])
        value = float(jj.jmse(ab, r["field"], r["u"], SIGNAL, NOISE, **steep_grid))
        out.append((f"steep {r['kind']}", ab, r["field"], r["u"], r["slope"],
                    value / (1.0 + r["error"])))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--grids", nargs="+", default=["high", "own"], choices=tuple(GRIDS))
    parser.add_argument("--name", default="high_steep")
    args = parser.parse_args()
    machine = common.machine_info()
    warnings.simplefilter("ignore")
    cases = designs()
    rows = [dict(label=label, coefficients={k: float(getattr(ab, k)) for k in
                                            ("w020", "w040", "w131", "w222", "w220")},
                 field=f, u=u, slope=slope, reference=ref, errors={}, times={})
            for label, ab, f, u, slope, ref in cases]
    print(f"{len(rows)} designs", flush=True)
    for name in args.grids:
        for row, (_, ab, f, u, _, ref) in zip(rows, cases, strict=True):
            t = time.perf_counter()
            value = float(jj.jmse(ab, f, u, SIGNAL, NOISE, **GRIDS[name]))
            row["times"][name] = time.perf_counter() - t
            row["errors"][name] = value / ref - 1.0
        errs = [abs(r["errors"][name]) for r in rows]
        print(f"{name}: worst {max(errs):.1e}, {sum(e > 1e-4 for e in errs)} more than 1e-4, "
              f"{sum(e > 1e-5 for e in errs)} more than 1e-5", flush=True)
        for r in sorted(rows, key=lambda r: -abs(r["errors"][name]))[:4]:
            print(f"   {r['label']} u={r['u']} slope {r['slope']:.0f} {r['coefficients']}: "
                  f"{r['errors'][name]:+.1e}", flush=True)
    lines = ["# The high preset on steep designs", "",
             common.machine_line(machine, common.load_average()), "",
             "Designs of `small_u_single_terms.py` within `CHECKED_SLOPE` (single terms against "
             "stored polar references; the steep set against references recovered from the "
             "default's steep tier's stored error); MarkovSignal(1, 5), WhiteNoise(1e-3).", "",
             "| grid | options | designs | > 1e-4 | > 1e-5 | > 1e-6 | worst | median s |",
             "|---|---|---|---|---|---|---|---|"]
    for name in args.grids:
        errs = [abs(r["errors"][name]) for r in rows]
        times = sorted(r["times"][name] for r in rows)
        lines.append(f"| {name} | {GRIDS[name]} | {len(rows)} | {sum(e > 1e-4 for e in errs)} | "
                     f"{sum(e > 1e-5 for e in errs)} | {sum(e > 1e-6 for e in errs)} | "
                     f"{max(errs):.1e} | {times[len(times) // 2]:.2f} |")
    lines += ["", "| design | u | slope | " + " | ".join(args.grids) + " |",
              "|---|---|---|" + "---|" * len(args.grids)]
    for r in rows:
        lines.append(f"| {r['label']} {r['coefficients']} | {r['u']} | {r['slope']:.0f} | "
                     + " | ".join(f"{r['errors'][n]:+.1e}" for n in args.grids) + " |")
    common.write_report(args.name, dict(machine=machine, grids={k: GRIDS[k] for k in args.grids},
                                        designs=rows), lines)


if __name__ == "__main__":
    main()
