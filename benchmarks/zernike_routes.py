"""Routes for Zernike designs of higher degree than Seidel's, and the grids they need.

In session 66 a design with terms of radial order 5 or more (``beyond_seidel_degree``) of
``aberration_strength`` at least ``CANCELLING_STRENGTH`` was sent to the default's balanced
grid, whatever its cancellation: the tiers by strength, calibrated on Seidel designs, were
up to 2.0e-3 off on random Zernike designs of Noll 4-22 and 4-37 (``zernike_designs.py``),
and the balanced grid held those, at 5-10x their tier's time. This script measures, on
random such designs, each candidate route's grid against a converged polar grid:

- ``tier``: the grid of the design's tier by strength (and ``STEEP_SLOPE``);
- ``next``: the grid of the next tier up (tier 3 stays, the steep tier stays);
- ``steep``: the steep tier's grid (tier 3's with the overlap rule (64, 64), floor 64);
- ``balanced``: ``BALANCED_GRID`` (the route of session 66);
- with ``--add degree``, afterwards, on the stored designs: ``BALANCED_GRID`` with the
  overlap rule ``DEGREE_OVERLAP``, the balanced plan of a program for such designs since
  session 67 (the balanced grid's own rule was found 3.1e-3 off at slope 46).

The report's ``now`` is the route taken now: the steep tier's grid for a design that does
not cancel and is no steeper than ``DEGREE_STEEP_SLOPE`` (``STEEP_SLOPE`` until session 79),
else the balanced plan (``NOW``).

Designs: the 40 stored ones of ``zernike_designs.py`` (with their references) and new ones,
drawn in three families: coefficients of Noll 4-22 or 4-37 normal with deviation ``1/n``
(as ``zernike_designs.py``), the same with deviation 1 (high orders dominate the slope),
and one random polynomial of radial order 5-8 with a random defocus (as Noll 4-45, most
coefficients zero, so that one program serves them all). Strength 2.5-25, u
0.1-1, noise 1e-2 to 1e-4.

Usage (from the repository root; about 12 s a new design on 2 cores, 3 s a stored design
for ``--add``)::

    .venv/bin/python benchmarks/zernike_routes.py [--designs 60] [--seed 2] [--stored N]
        [--families 1/n flat single] [--u 0.1 0.2 ...] [--name zernike_routes]
        [--add degree] [--report]

Writes ``results/<name>.json`` and ``.md`` (``--report``: rebuilds the markdown from the
JSON). Session 67 ran it twice: as above (``zernike_routes``) and with ``--stored 0
--designs 45 --seed 3 --families single --u 0.3 0.5 0.7 0.85 1.0 --name
zernike_routes_single`` (the hardest family where the steep tier's grid serves); then
``--add degree`` on each.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402
from jmse_jax._aberrations import noll_to_nm  # noqa: E402

SIGNAL = jj.MarkovSignal(1.0, 5.0)
FIELD = 0.5  # a Zernike design ignores the field
REFERENCE = dict(nodes=(224, 112), se_nodes=(9600, 768), overlap_nodes=(192, 192),
                 overlap_floor=192, peaks=True)
ROUTES = ("tier", "next", "steep", "balanced")
#: The candidate below that is the balanced plan of a program for such designs: since session
#: 82 ``BALANCED_GRID`` with ``DEGREE_NODES`` and ``DEGREE_OVERLAP`` (session 83's
#: ``DEGREE_SE_NODES`` is not in it; under ``MarkovSignal`` the fine nodes hardly bind).
#: Before, ``degree_128x96_floor96`` (session 67's ``DEGREE_OVERLAP``).
NOW = "degree_s82"
#: Candidate grids evaluated afterwards on the stored designs (``--add``).
EXTRA = dict(
    degree=dict(jj.BALANCED_GRID, overlap_nodes=(128, 128), overlap_floor=128),
    # Cheaper rules tried for DEGREE_OVERLAP, on the designs that take the balanced plan.
    degree_128x96=dict(jj.BALANCED_GRID, overlap_nodes=(128, 96), overlap_floor=128),
    degree_128x96_floor96=dict(jj.BALANCED_GRID, overlap_nodes=(128, 96), overlap_floor=96),
    # Session 82: the plan after the adversarial climbs (DEGREE_NODES, DEGREE_OVERLAP).
    degree_s82=dict(jj.BALANCED_GRID, nodes=(160, 96), overlap_nodes=(128, 128),
                    overlap_floor=96),
)


def _grid(index):
    """The explicit grid options of the default's tier ``index`` (the preset's floor and
    peaks filled in)."""
    grid = dict(overlap_floor=_merit.OVERLAP_FLOOR, peaks=False)
    grid.update(jj.DEFAULT_TIERS[index][2])
    return grid


def _route_grids(tier):
    n = len(jj.DEFAULT_TIERS)
    steep = n - 1
    following = steep if tier == steep else min(tier + 1, steep - 1)
    return dict(tier=_grid(tier), next=_grid(following), steep=_grid(steep),
                balanced=dict(jj.BALANCED_GRID))


def _draw(rng, family):
    if family == "single":
        order = int(rng.integers(5, 9))
        candidates = [j for j in range(11, 46) if noll_to_nm(j)[0] == order]
        j = int(rng.choice(candidates))
        noll = tuple(range(4, 46))  # one Noll set (one compile) for every such design
        c = np.zeros(len(noll))
        c[0], c[j - 4] = rng.normal(), rng.choice([-1.0, 1.0])
        return noll, c
    top = int(rng.choice([22, 37]))
    noll = tuple(range(4, top + 1))
    orders = np.array([noll_to_nm(j)[0] for j in noll], float)
    deviation = 1.0 / orders if family == "1/n" else np.ones_like(orders)
    return noll, rng.normal(size=len(noll)) * deviation


def _evaluate(compiled, grids, ab, u, noise):
    """Value and warm time of each route's grid (jitted per grid and Noll set)."""
    out = {}
    for name, grid in grids.items():
        key = (tuple(sorted((k, str(v)) for k, v in grid.items())), ab.noll)
        if key not in compiled:
            compiled[key] = jax.jit(lambda ab, u, noise, grid=grid: jj.jmse(
                ab, FIELD, u, SIGNAL, jj.WhiteNoise(noise), **grid))
        fn = compiled[key]
        float(fn(ab, u, noise))
        start = time.perf_counter()
        value = float(fn(ab, u, noise))
        out[name] = (value, time.perf_counter() - start)
    return out


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=60, help="new designs")
    parser.add_argument("--seed", type=int, default=2)
    parser.add_argument("--stored", type=int, default=None, help="use only the first N stored")
    parser.add_argument("--families", nargs="+", default=["1/n", "flat", "single"],
                        choices=("1/n", "flat", "single"), help="families of the new designs")
    parser.add_argument("--u", type=float, nargs="+",
                        default=[0.1, 0.2, 0.3, 0.5, 0.7, 0.85, 1.0], help="u to draw from")
    parser.add_argument("--name", default="zernike_routes")
    parser.add_argument("--add", nargs="+", choices=tuple(EXTRA), default=None,
                        help="evaluate these grids on the stored designs and add them")
    parser.add_argument("--report", action="store_true",
                        help="only rebuild the markdown report from the stored JSON")
    args = parser.parse_args(argv)
    if args.report:
        _rewrite(args.name)
        return
    if args.add:
        _add(args.name, args.add)
        return
    machine = common.machine_info()
    reference = jax.jit(lambda ab, u, noise: jj.jmse(
        ab, FIELD, u, SIGNAL, jj.WhiteNoise(noise), **REFERENCE))
    designs = []
    stored = json.loads((HERE / "results" / "zernike_designs.json").read_text())["designs"]
    stored = stored[:args.stored]
    for r in stored:
        designs.append(dict(family="stored", noll=tuple(range(4, r["noll"] + 1)),
                            coefficients=r["coefficients"], u=r["u"], noise=r["noise"],
                            reference=r["reference"]))
    rng = np.random.default_rng(args.seed)
    for i in range(args.designs):
        family = args.families[i % len(args.families)]
        noll, c = _draw(rng, family)
        u = float(rng.choice(args.u))
        noise = float(rng.choice([1e-2, 1e-3, 1e-4]))
        target = float(rng.uniform(2.5, 25.0))
        c = c * target / float(jj.aberration_strength(jj.Zernike(c, noll=noll), FIELD, u))
        designs.append(dict(family=family, noll=noll, coefficients=c.tolist(), u=u,
                            noise=noise, reference=None))
    compiled = {}
    rows = []
    start = time.perf_counter()
    for d in designs:
        ab = jj.Zernike(np.asarray(d["coefficients"]), noll=d["noll"])
        u, noise = d["u"], d["noise"]
        strength = float(jj.aberration_strength(ab, FIELD, u))
        cancellation = float(_merit._cancellation_jit(ab, FIELD, u))
        tier = int(_merit._tier_index(strength, u, jj.DEFAULT_TIERS))
        ref = d["reference"]
        if ref is None:
            ref = float(reference(ab, u, noise))
        values = _evaluate(compiled, _route_grids(tier), ab, u, noise)
        row = dict(family=d["family"], noll=list(d["noll"]), coefficients=d["coefficients"],
                   u=u, noise=noise, strength=strength,
                   slope=strength / min(math.sqrt(2.0) * u, 1.0), cancellation=cancellation,
                   cancels=cancellation >= _merit.BALANCED_CANCELLATION, tier=tier,
                   reference=ref,
                   errors={k: v / ref - 1.0 for k, (v, _) in values.items()},
                   seconds={k: s for k, (_, s) in values.items()})
        rows.append(row)
        print(f"{d['family']:6s} top={max(d['noll']):2d} u={u} noise={noise:.0e} "
              f"strength={strength:5.1f} slope={row['slope']:5.1f} "
              f"canc={cancellation:.2f} t{tier} "
              + " ".join(f"{k}={e:+.1e}" for k, e in row["errors"].items()), flush=True)
    seconds = time.perf_counter() - start
    report = dict(machine=machine, reference=REFERENCE, seed=args.seed, new=args.designs,
                  stored=len(stored), families=args.families, u=args.u, seconds=seconds,
                  designs=rows)
    common.write_report(args.name, report, _lines(report, common.load_average()))


def _route_now(row):
    """The grid the default gives such a design now: the balanced plan (``NOW``, or the
    latest earlier plan measured) if it cancels or is steeper than ``DEGREE_STEEP_SLOPE``,
    else the steep tier's."""
    if row["cancels"] or row["slope"] > _merit.DEGREE_STEEP_SLOPE:
        return next((k for k in (NOW, "degree_128x96_floor96", "degree") if k in row["errors"]),
                    "balanced")
    return "steep"


#: The columns that describe a design in the reports' tables (``design_cells``).
DESIGN_HEADER = "Noll | u | noise | strength | slope | cancellation"


def design_cells(row):
    """A design's cells under ``DESIGN_HEADER`` (also ``zernike_high_routes.py``)."""
    return (f"4-{max(row['noll'])} | {row['u']} | {row['noise']:.0e} | "
            f"{row['strength']:.1f} | {row['slope']:.1f} | {row['cancellation']:.2f}")


def _lines(report, load):
    rows = report["designs"]
    for r in rows:
        r["now"] = r["errors"][_route_now(r)]
    names = (*ROUTES, *report.get("added", {}))
    routes = (*names, "now")
    seconds = report.get("seconds")
    lines = ["# Routes and grids for Zernike designs beyond Seidel's degree", "",
             common.machine_line(report["machine"], load), "",
             f"{len(rows)} designs ({report.get('stored', 40)} stored from "
             f"`zernike_designs.json`, {report.get('new', len(rows) - 40)} new of the families "
             f"{report.get('families', ['1/n', 'flat', 'single'])} at u in "
             f"{report.get('u', [0.1, 0.2, 0.3, 0.5, 0.7, 0.85, 1.0])}, seed "
             f"{report.get('seed', 2)}); reference {report['reference']}. Each route's grid is "
             "called directly (no shortcut, no one-ray plan); `degree...`: `BALANCED_GRID` with "
             "the overlap rule (across, along) and floor named (`degree`: (128, 128) floor "
             f"128); `{NOW}` is the balanced plan of a program for such designs "
             "(`DEGREE_NODES`, `DEGREE_OVERLAP`); `now`: the route this package takes (the "
             "balanced plan for a design that cancels or is steeper than "
             f"`DEGREE_STEEP_SLOPE` = {_merit.DEGREE_STEEP_SLOPE:g}, else "
             "the steep tier's grid)."
             + (f" {seconds:.0f} s in all." if seconds else ""), ""]
    header = ("| designs | count | " + " | ".join(f"{k} > 1e-4 | {k} > 1e-5 | {k} worst"
                                                  for k in routes) + " |")
    lines += [header, "|---|---|" + "---|" * (3 * len(routes))]
    quiet = [r for r in rows if not r["cancels"]]
    steep, checked = _merit.STEEP_SLOPE, _merit.CHECKED_SLOPE
    groups = [("all", rows), (f"all, slope <= {checked:g} (checked)",
                              [r for r in rows if r["slope"] <= checked]),
              (f"cancelling, slope <= {checked:g}",
               [r for r in rows if r["cancels"] and r["slope"] <= checked]),
              ("not cancelling", quiet),
              (f"not cancelling, slope <= {steep:g}", [r for r in quiet if r["slope"] <= steep]),
              (f"not cancelling, slope {steep:g}-{checked:g}",
               [r for r in quiet if steep < r["slope"] <= checked]),
              (f"not cancelling, slope > {checked:g} (warned)",
               [r for r in quiet if r["slope"] > checked])]
    groups += [(f"not cancelling, tier {t}", [r for r in quiet if r["tier"] == t])
               for t in range(1, len(jj.DEFAULT_TIERS))]
    for label, group in groups:
        if not group:
            continue
        cells = []
        for k in routes:
            errors = [abs(r["errors"][k] if k in r["errors"] else r[k]) for r in group
                      if k in r["errors"] or k == "now"]
            cells += ([str(sum(e > 1e-4 for e in errors)), str(sum(e > 1e-5 for e in errors)),
                       f"{max(errors):.1e}"] if errors else ["-", "-", "-"])
        lines.append(f"| {label} | {len(group)} | " + " | ".join(cells) + " |")
    lines += ["", "Median warm time of one value (jitted, 2 cores, one call each) by tier, "
              "not cancelling:", "",
              "| tier | designs | " + " | ".join(names) + " |",
              "|---|---|" + "---|" * len(names)]
    for t in range(1, len(jj.DEFAULT_TIERS)):
        group = [r for r in quiet if r["tier"] == t]
        if group:
            lines.append(f"| {t} | {len(group)} | " + " | ".join(
                common.fmt_seconds(float(np.median([r["seconds"][k] for r in group])))
                if all(k in r["seconds"] for r in group) else "-" for k in names) + " |")
    lines += ["", "Every design:", "",
              f"| family | {DESIGN_HEADER} | tier | " + " | ".join(routes) + " |",
              "|" + "---|" * (8 + len(routes))]
    for r in rows:
        lines.append(
            f"| {r['family']} | {design_cells(r)} | {r['tier']} | "
            + " | ".join(f"{r['errors'][k]:+.1e}" if k in r["errors"] else "-" for k in names)
            + f" | {r['now']:+.1e} |")
    for line in lines[6:8 + len(groups)]:
        print(line)
    return lines


def _add(name, grids):
    """Evaluate the ``EXTRA`` grids on the designs of ``results/<name>.json``, against
    their stored references, and rewrite the report."""
    path = HERE / "results" / f"{name}.json"
    report = json.loads(path.read_text())
    compiled = {}
    for r in report["designs"]:
        if grids != ["degree"] and _route_now(r) == "steep":
            continue  # the candidate rules of the balanced plan: only its designs
        ab = jj.Zernike(np.asarray(r["coefficients"]), noll=tuple(r["noll"]))
        values = _evaluate(compiled, {k: EXTRA[k] for k in grids}, ab, r["u"], r["noise"])
        for k, (v, seconds) in values.items():
            r["errors"][k] = v / r["reference"] - 1.0
            r["seconds"][k] = seconds
        print(f"u={r['u']} slope={r['slope']:5.1f} canc={r['cancellation']:.2f} "
              + " ".join(f"{k}={r['errors'][k]:+.1e}" for k in ("degree", *grids)),
              flush=True)
    report.setdefault("added", {}).update({k: EXTRA[k] for k in grids})
    common.write_json(path, report)
    _rewrite(name)


def _rewrite(name):
    """Rebuild the markdown report from the stored JSON (``--report``)."""
    path = HERE / "results" / f"{name}.json"
    report = json.loads(path.read_text())
    (HERE / "results" / f"{name}.md").write_text("\n".join(_lines(report, report["machine"].get(
        "load_at_end", common.load_average()))) + "\n")

if __name__ == "__main__":
    main()
