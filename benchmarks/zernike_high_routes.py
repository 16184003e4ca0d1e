"""The ``"high"`` preset's grids on Zernike designs beyond Seidel's degree.

Session 67 routed such designs (terms of radial order 5 or more, ``beyond_seidel_degree``)
in the default by ``benchmarks/zernike_routes.py``; ``"high"`` kept sending every one of them
from ``CANCELLING_STRENGTH`` to its balanced grid (now with ``DEGREE_OVERLAP``), measured on
one design only. This script evaluates ``"high"``'s three grids on the designs of
``zernike_routes.py`` (``results/zernike_routes.json`` and ``zernike_routes_single.json``,
175 designs with their converged references):

- ``own``: the preset's fixed grid, which a Seidel design of slope up to ``STEEP_SLOPE``
  takes;
- ``steep``: ``HIGH_STEEP_GRID``, which a Seidel design past ``STEEP_SLOPE`` takes;
- ``balanced``: ``HIGH_BALANCED_GRID`` with ``DEGREE_OVERLAP``, the grid every such design
  took in session 67 from ``CANCELLING_STRENGTH``;
- ``steep_degree``: ``HIGH_STEEP_GRID`` with the overlap rule ``DEGREE_OVERLAP``;
- ``balanced_64``: ``balanced`` with (160, 64) OTF nodes, which became ``HIGH_DEGREE_NODES``
  (``"high"``'s balanced plan for such designs since session 68);
- ``fast`` (only when named in ``--grids``): the ``"fast"`` preset's one grid, which it
  gives every design.

Each grid is called directly, jitted per grid and Noll set, against the stored reference
(the polar grid (224, 112) / (9600, 768) / (192, 192) floor 192 with peaks; on the 40
designs that ``zernike_designs.py`` stored, a coarser reference differs from it by up to
1.1e-6, so differences below about 1e-6 are not resolved).

Usage (from the repository root; about 10 s a design on 2 cores)::

    .venv/bin/python benchmarks/zernike_high_routes.py [--sets zernike_routes ...]
        [--grids own steep balanced steep_degree] [--limit N] [--name zernike_high_routes]
        [--add]

Writes ``results/<name>.json`` and ``.md`` (``--add``: evaluates ``--grids`` on the designs
of that report and adds them to it). Session 68 ran it as above, then with ``--add --grids
balanced_64``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import numpy as np  # noqa: E402
import zernike_routes as routes  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402

_OWN = {k: jj.PRESETS["high"][k] for k in (*_merit._GRID_OPTIONS, "peaks")}
#: ``"fast"``'s one grid (``--grids fast``), which it gives every design.
_FAST = {k: jj.PRESETS["fast"][k] for k in _OWN}
GRIDS = dict(
    own=_OWN,
    steep={**_OWN, **jj.HIGH_STEEP_GRID},
    balanced={**_OWN, **jj.HIGH_BALANCED_GRID, **jj.DEGREE_OVERLAP},
    steep_degree={**_OWN, **jj.HIGH_STEEP_GRID, **jj.DEGREE_OVERLAP},
    balanced_64={**_OWN, **jj.HIGH_BALANCED_GRID, **jj.DEGREE_OVERLAP, "nodes": (160, 64)},
    fast=_FAST,
)
#: The grids evaluated unless ``--grids`` names others.
HIGH_GRIDS = ("own", "steep", "balanced", "steep_degree")


def _lines(report, load):
    rows = report["designs"]
    names = report["grids"]
    lines = ["# Preset grids on Zernike designs beyond Seidel's degree", "",
             common.machine_line(report["machine"], load), "",
             f"{len(rows)} designs of {', '.join(f'`{s}.json`' for s in report['sets'])} "
             "with their stored references. Grids (called directly, jitted per grid and Noll "
             "set): " + "; ".join(f"`{k}` {v}" for k, v in report["grid_options"].items())
             + f". {report['seconds']:.0f} s in all. Errors below about 1e-6 are not "
             "resolved by the references.", ""]
    header = "| designs | count | " + " | ".join(
        f"{k} > 1e-5 | {k} > 1e-6 | {k} worst" for k in names) + " |"
    lines += [header, "|---|---|" + "---|" * (3 * len(names))]
    steep, checked = _merit.STEEP_SLOPE, _merit.CHECKED_SLOPE
    quiet = [r for r in rows if not r["cancels"]]
    groups = [
        ("all", rows),
        (f"all, slope <= {checked:g} (checked)", [r for r in rows if r["slope"] <= checked]),
        (f"cancelling, slope <= {checked:g}",
         [r for r in rows if r["cancels"] and r["slope"] <= checked]),
        (f"not cancelling, slope <= {steep:g}", [r for r in quiet if r["slope"] <= steep]),
        (f"not cancelling, slope {steep:g}-{checked:g}",
         [r for r in quiet if steep < r["slope"] <= checked]),
        (f"slope > {checked:g} (warned)", [r for r in rows if r["slope"] > checked]),
    ]
    for label, group in groups:
        if not group:
            continue
        cells = []
        for k in names:
            errors = [abs(r["high"][k]) for r in group]
            cells += [str(sum(e > 1e-5 for e in errors)), str(sum(e > 1e-6 for e in errors)),
                      f"{max(errors):.1e}"]
        lines.append(f"| {label} | {len(group)} | " + " | ".join(cells) + " |")
    lines += ["", "Median warm time of one value (jitted, one call each):", "",
              "| designs | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for label, group in groups[3:5]:
        if group:
            lines.append(f"| {label} | " + " | ".join(common.fmt_seconds(float(np.median(
                [r["high_seconds"][k] for r in group]))) for k in names) + " |")
    lines += ["", "Every design:", "",
              f"| set | family | {routes.DESIGN_HEADER} | " + " | ".join(names) + " |",
              "|" + "---|" * (8 + len(names))]
    for r in rows:
        lines.append(f"| {r['set']} | {r['family']} | {routes.design_cells(r)} | "
                     + " | ".join(f"{r['high'][k]:+.1e}" for k in names) + " |")
    for line in lines[6:8 + len(groups)]:
        print(line)
    return lines


def _add(name, grids):
    """Evaluate ``grids`` on the designs of ``results/<name>.json`` and rewrite its report."""
    path = HERE / "results" / f"{name}.json"
    report = json.loads(path.read_text())
    compiled = {}
    start = time.perf_counter()
    for r in report["designs"]:
        ab = jj.Zernike(np.asarray(r["coefficients"]), noll=tuple(r["noll"]))
        values = routes._evaluate(compiled, grids, ab, r["u"], r["noise"])
        for k, (v, seconds) in values.items():
            r["high"][k] = v / r["reference"] - 1.0
            r["high_seconds"][k] = seconds
        print(f"u={r['u']} slope={r['slope']:5.1f} canc={r['cancellation']:.2f} "
              + " ".join(f"{k}={r['high'][k]:+.1e}" for k in r["high"]), flush=True)
    report["grids"] = [*report["grids"], *(k for k in grids if k not in report["grids"])]
    report["grid_options"].update({k: {o: v for o, v in g.items()
                                       if o not in ("quadrature", "otf_method")}
                                   for k, g in grids.items()})
    report["seconds"] += time.perf_counter() - start
    common.write_report(name, report, _lines(report, common.load_average()))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sets", nargs="+", default=["zernike_routes", "zernike_routes_single"])
    parser.add_argument("--grids", nargs="+", choices=tuple(GRIDS), default=list(HIGH_GRIDS))
    parser.add_argument("--limit", type=int, default=None, help="first N designs of each set")
    parser.add_argument("--name", default="zernike_high_routes")
    parser.add_argument("--add", action="store_true",
                        help="evaluate --grids on the designs of results/<name>.json and add "
                             "them to its report")
    args = parser.parse_args(argv)
    if args.add:
        _add(args.name, {k: GRIDS[k] for k in args.grids})
        return
    machine = common.machine_info()
    grids = {k: GRIDS[k] for k in args.grids}
    compiled, rows = {}, []
    start = time.perf_counter()
    for name in args.sets:
        designs = json.loads((HERE / "results" / f"{name}.json").read_text())["designs"]
        for r in designs[:args.limit]:
            ab = jj.Zernike(np.asarray(r["coefficients"]), noll=tuple(r["noll"]))
            values = routes._evaluate(compiled, grids, ab, r["u"], r["noise"])
            row = {k: r[k] for k in ("family", "noll", "coefficients", "u", "noise",
                                     "strength", "slope", "cancellation", "cancels",
                                     "reference")}
            row.update(set=name, high={k: v / r["reference"] - 1.0 for k, (v, _) in
                                       values.items()},
                       high_seconds={k: s for k, (_, s) in values.items()})
            rows.append(row)
            print(f"{name[15:] or 'routes':6s} {r['family']:6s} u={r['u']} "
                  f"slope={r['slope']:5.1f} canc={r['cancellation']:.2f} "
                  + " ".join(f"{k}={e:+.1e}" for k, e in row["high"].items()), flush=True)
    report = dict(machine=machine, sets=args.sets, grids=args.grids,
                  grid_options={k: {o: v for o, v in g.items() if o not in ("quadrature",
                                                                              "otf_method")}
                                for k, g in grids.items()},
                  seconds=time.perf_counter() - start, designs=rows)
    common.write_report(args.name, report, _lines(report, common.load_average()))


if __name__ == "__main__":
    main()
