"""Would a second grid behind the shortcut's first grid pay? (A study; nothing in the
package uses it.)

On the designs tier 1's shortcut serves (those of ``recheck_shortcut.py``) whose first grid
the rule refuses, each candidate second grid is judged two ways: kept when the float32
check agrees with it to ``rtol`` and its own error estimate is within ``first_tol`` (the
first grid's rule), or kept when the first grid's value (already computed) agrees with it
and its estimate is within ``first_tol``. Reports how many refused designs each keeps and
the worst error among them, and each grid's warm time at the Fig. 1 point (one process;
run under ``taskset -c 1`` for one-core figures).

Usage (from the repository root; ~6 min on 2 cores)::

    .venv/bin/python benchmarks/shortcut_second_grid.py

Writes ``results/shortcut_second_grid.json`` and ``.md``.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import numpy as np  # noqa: E402
import recheck_shortcut as rs  # noqa: E402
from problems import PROBLEMS  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._merit import _accepts, _first_kept  # noqa: E402

CANDIDATES = {
    "(32, 12) / (600, 64) / (28, 24) floor 10": dict(
        nodes=(32, 12), se_nodes=(600, 64), overlap_nodes=(28, 24), overlap_floor=10),
    "tier 0's own grid": dict(jj.DEFAULT_TIERS[0][2]),
    "(24, 8) / (300, 40) / (28, 24) floor 12": dict(
        nodes=(24, 8), se_nodes=(300, 40), overlap_nodes=(28, 24), overlap_floor=12),
    "(32, 10) / (500, 48) / (24, 20) floor 10": dict(
        nodes=(32, 10), se_nodes=(500, 48), overlap_nodes=(24, 20), overlap_floor=10),
    "(28, 10) / (400, 48) / (24, 18) floor 10": dict(
        nodes=(28, 10), se_nodes=(400, 48), overlap_nodes=(24, 18), overlap_floor=10),
}


def _fig1_times(grid):
    """Warm (value, value_and_grad) times of ``grid`` at the Fig. 1 point, in ms."""
    args = next(p for p in PROBLEMS if p.name == "fig1").arguments()

    def merit(ab, *rest):
        return jj.jmse(ab, *rest, **grid)

    return tuple(1e3 * common.time_compiled(fn, args, budget_s=1.0, max_repeats=60)["warm_s"]
                 for fn in (merit, jax.value_and_grad(merit)))


def main() -> None:
    tier = 1
    shortcut = jj.DEFAULT_TIERS[tier][3]
    names, args, refs = rs._served(tier)
    check = rs._values(shortcut.check, args, float32=True)
    first = rs._values(shortcut.first, args)
    first_estimate = rs._estimates(shortcut.first, args)

    def agrees(value, other):
        return np.asarray(_accepts(value, other, shortcut.rtol))

    def kept(value, estimate, other):
        return np.asarray(_first_kept(value, estimate, other, shortcut.rtol,
                                      shortcut.first_tol))

    refused = ~kept(first, first_estimate, check)
    index = np.where(refused)[0]
    subset = [args[i] for i in index]
    grids = {"first grid (present)": dict(shortcut.first), **CANDIDATES,
             "tier 1's own grid": dict(jj.DEFAULT_TIERS[tier][2])}
    report = dict(machine=common.machine_info(), designs=len(args), refused=len(index),
                  refused_by_estimate=int(np.sum(first_estimate[index] > shortcut.first_tol)),
                  refused_by_check=int(np.sum(~agrees(first, check)[index])), rows=[])
    lines = ["# A second grid behind the shortcut's first grid (tier 1)", "",
             "`python benchmarks/shortcut_second_grid.py`", "",
             f"Commit {report['machine'].get('commit')}. Of the {len(args)} designs tier 1's "
             f"shortcut serves, the first grid is refused for {len(index)} (its estimate "
             f"above tolerance for {report['refused_by_estimate']}, the check disagreeing "
             f"for {report['refused_by_check']}). On those, each candidate second grid is "
             "kept when (a) the float32 check agrees and its estimate is within tolerance, "
             "or (b) the first grid's value agrees and its estimate is within tolerance; "
             "cells: designs kept (worst error among them). Times: warm, Fig. 1 point.", "",
             "| second grid | (a) check + estimate | (b) first grid + estimate | "
             "worst error on the refused | Fig. 1 value | Fig. 1 value_and_grad |",
             "|---|---|---|---|---|---|"]
    for name, grid in grids.items():
        value_ms, vag_ms = _fig1_times(grid)
        row = dict(name=name, grid=grid, value_ms=value_ms, value_and_grad_ms=vag_ms)
        if name in CANDIDATES:
            values = rs._values(grid, subset)
            estimate = rs._estimates(grid, subset)
            errors = np.abs(values / refs[index] - 1.0)
            by_check = kept(values, estimate, check[index])
            by_first = kept(values, estimate, first[index])
            row.update(kept_by_check=int(by_check.sum()),
                       worst_by_check=float(np.max(errors[by_check], initial=0.0)),
                       kept_by_first=int(by_first.sum()),
                       worst_by_first=float(np.max(errors[by_first], initial=0.0)),
                       worst=float(errors.max()))
            cells = (f"{row['kept_by_check']} ({row['worst_by_check']:.1e}) | "
                     f"{row['kept_by_first']} ({row['worst_by_first']:.1e}) | "
                     f"{row['worst']:.1e}")
        else:
            cells = "– | – | –"
        lines.append(f"| {name} | {cells} | {value_ms:.2f} ms | {vag_ms:.2f} ms |")
        print(lines[-1], flush=True)
        report["rows"].append(row)
    common.write_report("shortcut_second_grid", report, lines)


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                            epilog="No options: runs the study and writes its results "
                            "(results/<name>.json and .md).").parse_args()
    main()
