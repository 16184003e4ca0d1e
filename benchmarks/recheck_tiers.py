"""Re-check the default's tier grids against the references stored by ``calibrate_tiers.py``.

The calibration's cost is its references (one converged grid per design, ~14 min for 426
designs). Once stored (``results/calibrate_tiers.json`` and ``calibrate_tiers_kink.json``),
another candidate grid for a tier is checked in seconds: this script evaluates, for every
tier of ``DEFAULT_TIERS``, the present grid and variants of its fine angular S_e count and
of its overlap order along the chords on the stored designs that the tier serves, and
reports the worst, 90th-percentile and median relative error and the largest change in any
design's error against the present grid.

Usage (from the repository root; ~4 min on 2 cores)::

    .venv/bin/python benchmarks/recheck_tiers.py [--angular 1:96,64 2:256 3:384,192]
                                                 [--along 1:28,20 2:40 3:56]
                                                 [--floor 0:24,10 1:24,10 2:12 3:12]

``--angular TIER:A,B,...`` lists the fine angular counts tried for a tier, ``--along
TIER:A,B,...`` the overlap rule's orders along the chords (the second entry of
``overlap_nodes``) and ``--floor TIER:A,B,...`` its order on the inner radial panels
(``overlap_floor``). The defaults are the values of the 2026-11-24 checks, which lowered the
angular count of tier 2 from 256 to 128 and of tier 3 from 384 to 256, and the order along
the chords of tiers 1, 2 and 3 from 28, 40 and 56 to 24, 24 and 32. Tier 0's grid is also
tier 1's trial: a change to its angular count is checked on tier 1's designs through the
default as a whole as well (``jmse`` with the changed tiers in ``PRESETS``).

The stored designs are not the whole story: tier 0 at 48 angular nodes passed here (largest
change 1.5e-10) but moved the bank case ``fig1_defocus_m6_u_0.1_noise_1e-4`` from 6.9e-6 to
1.8e-4 (its trial and the shortcut's check agreed while both were off), so it was not
adopted. Check the bank too (``accuracy_speed.py`` or the tests) before changing a tier.
Writes ``results/recheck_tiers.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._merit import _tier_index  # noqa: E402

SOURCES = ("calibrate_tiers", "calibrate_tiers_kink")
#: Fine angular counts tried by default, per tier index.
DEFAULT_ANGULAR = {0: (48,), 1: (96,), 2: (256, 96), 3: (384, 192)}
#: Orders along the chords tried by default, per tier index: the former ones (and 20 for tier 1).
DEFAULT_ALONG = {1: (28, 20), 2: (40,), 3: (56,)}
#: Overlap floors tried by default, per tier index: the presets' and 10 for the tiers that use
#: 12 since 2026-11-25, and 12 for those that keep the presets'.
DEFAULT_FLOOR = {0: (24, 10), 1: (24, 10), 2: (12,), 3: (12,)}


def _designs() -> list[dict]:
    designs = []
    for name in SOURCES:
        for design in json.loads((common.RESULTS / f"{name}.json").read_text())["designs"]:
            if design.get("reference") is not None:
                designs.append(dict(design, source=name))
    return designs


def _errors(grid: dict, designs: list[dict]) -> np.ndarray:
    merit = jax.jit(lambda ab, f, u, s, n: jj.jmse(ab, f, u, s, n, **grid))
    errors = []
    for d in designs:
        value = float(merit(jj.Seidel(**d["coefficients"]), d["field"], d["u"],
                            jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(d["noise"])))
        errors.append(abs(value / d["reference"] - 1.0))
    return np.asarray(errors)


def _tiers_with_tier0(grid: dict) -> tuple:
    """``DEFAULT_TIERS`` with tier 0's grid, and tier 1's trial, replaced by ``grid``."""
    tiers = list(jj.DEFAULT_TIERS)
    tiers[0] = (*tiers[0][:2], grid, tiers[0][3])
    bound, u_bound, own, shortcut = tiers[1]
    tiers[1] = (bound, u_bound, own, shortcut._replace(trial=grid))
    return tuple(tiers)


def _recheck_trial(designs, grid, counts, lines) -> list[dict]:
    """The default as a user gets it (shortcut included) on the designs of strength <= 5,
    with tier 0's fine angular count at the present value and at each of ``counts``."""
    served = [d for d in designs if d["strength"] <= jj.DEFAULT_TIERS[1][0]]
    lines += ["", f"The default as a whole on the {len(served)} designs of strength <= "
              f"{jj.DEFAULT_TIERS[1][0]:g} (tier 0's grid is tier 1's trial):", "",
              "| tier 0 angular | worst | p90 | median | largest change vs present |",
              "|---|---|---|---|---|"]
    presets = jj.PRESETS["default"]
    original = presets["tiers"]
    rows, present = [], None
    try:
        for count in (grid["se_nodes"][1], *counts):
            presets["tiers"] = _tiers_with_tier0(dict(grid, se_nodes=(grid["se_nodes"][0],
                                                                     count)))
            errors = _errors({}, served)
            present = errors if present is None else present
            change = errors - present
            rows.append(dict(angular=count, worst=float(errors.max()),
                             p90=float(np.percentile(errors, 90)),
                             median=float(np.median(errors)),
                             largest_change=float(change.max())))
            lines.append(f"| {count} | {errors.max():.2e} | {np.percentile(errors, 90):.2e} | "
                         f"{np.median(errors):.2e} | "
                         f"{'–' if len(rows) == 1 else f'{change.max():+.1e}'} |")
            print(lines[-1], flush=True)
    finally:
        presets["tiers"] = original
    return rows


def _parse_counts(items, default) -> dict[int, tuple[int, ...]]:
    if not items:
        return dict(default)
    out = {}
    for item in items:
        tier, _, counts = item.partition(":")
        out[int(tier)] = tuple(int(c) for c in counts.split(","))
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--angular", nargs="*", help="TIER:A,B,... fine angular counts to try")
    parser.add_argument("--along", nargs="*",
                        help="TIER:A,B,... overlap orders along the chords to try")
    parser.add_argument("--floor", nargs="*",
                        help="TIER:A,B,... overlap floors (overlap_floor) to try")
    args = parser.parse_args()
    angular = _parse_counts(args.angular, DEFAULT_ANGULAR)
    along = _parse_counts(args.along, DEFAULT_ALONG)
    floors = _parse_counts(args.floor, DEFAULT_FLOOR)
    designs = _designs()
    report = dict(description=__doc__.split("\n\n")[0], machine=common.machine_info(),
                  sources=list(SOURCES), tiers=[])
    lines = ["# Tier grids re-checked against the stored calibration references", "",
             f"{len(designs)} designs with references from "
             f"{', '.join(f'`results/{s}.json`' for s in SOURCES)}; commit "
             f"{report['machine'].get('commit')}.", "",
             "| tier | designs | grid | worst | p90 | median | largest change vs present |",
             "|---|---|---|---|---|---|---|"]
    trial_lines: list[str] = []
    for index, (*_bounds, grid, _shortcut) in enumerate(jj.DEFAULT_TIERS):
        served = [d for d in designs
                  if int(_tier_index(d["strength"], d["u"], jj.DEFAULT_TIERS)) == index]
        if not served:
            continue
        present = _errors(grid, served)
        variants = [(grid, present)]
        for count in angular.get(index, ()):
            if count != grid["se_nodes"][1]:
                variant = dict(grid, se_nodes=(grid["se_nodes"][0], count))
                variants.append((variant, _errors(variant, served)))
        for order in along.get(index, ()):
            if order != grid["overlap_nodes"][1]:
                variant = dict(grid, overlap_nodes=(grid["overlap_nodes"][0], order))
                variants.append((variant, _errors(variant, served)))
        for floor in floors.get(index, ()):
            if floor != grid.get("overlap_floor", jj.OVERLAP_FLOOR):
                variant = dict(grid, overlap_floor=floor)
                variants.append((variant, _errors(variant, served)))
        entry = dict(tier=index, designs=len(served), grid=grid, variants=[])
        for variant, errors in variants:
            is_present = variant is grid
            change = errors - present
            worst_change = int(np.argmax(change))
            row = dict(angular=variant["se_nodes"][1], along=variant["overlap_nodes"][1],
                       floor=variant.get("overlap_floor", jj.OVERLAP_FLOOR),
                       worst=float(errors.max()),
                       p90=float(np.percentile(errors, 90)), median=float(np.median(errors)),
                       largest_change=float(change[worst_change]),
                       at=dict(u=served[worst_change]["u"],
                               noise=served[worst_change]["noise"],
                               strength=served[worst_change]["strength"]))
            entry["variants"].append(row)
            label = (f"nodes {tuple(variant['nodes'])}, se {tuple(variant['se_nodes'])}, "
                     f"overlap {tuple(variant['overlap_nodes'])}, floor {row['floor']}"
                     + (" (present)" if is_present else ""))
            change_text = ("–" if is_present else
                           f"{row['largest_change']:+.1e} (u {row['at']['u']}, "
                           f"K {row['at']['strength']:.1f})")
            lines.append(f"| {index} | {len(served)} | {label} | {row['worst']:.2e} | "
                         f"{row['p90']:.2e} | {row['median']:.2e} | {change_text} |")
            print(lines[-1], flush=True)
        report["tiers"].append(entry)
        if index == 0:  # tier 0's grid is also tier 1's trial: the default as a whole
            report["trial"] = _recheck_trial(designs, grid, angular.get(0, ()), trial_lines)
    lines += trial_lines
    common.write_report("recheck_tiers", report, lines)


if __name__ == "__main__":
    main()
