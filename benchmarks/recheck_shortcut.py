"""Re-check the middle tier's shortcut (``TierShortcut``) against stored references.

The shortcut keeps its trial grid's value when a coarse check grid agrees with it to
``rtol``. This script evaluates, on the designs it serves (strength 1-5, ``u <= u_max``:
the stored calibration designs of ``calibrate_tiers.py`` with references, and the bank's
converged cases), the trial, the check in float64 and in float32 (as the default computes
it), and the tier's own grid, and reports how many trials each check keeps, how many
decisions the float32 check changes, and the worst error the tier returns. Candidate
cheaper first trials (``--trial``) are tried as a first stage in front of the present one,
with the same check: a kept candidate must stay accurate, i.e. not agree with the check
while both are off.

Usage (from the repository root; ~3 min on 2 cores)::

    .venv/bin/python benchmarks/recheck_shortcut.py \\
        [--trial "nodes=18,10 se_nodes=800,64 overlap_nodes=18,18 overlap_floor=12" ...]

Prints its tables and writes ``results/recheck_shortcut.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import recheck_tiers  # noqa: E402
from problems import PROBLEMS  # noqa: E402

import jmse_jax as jj  # noqa: E402


def _parse_grid(text: str) -> dict:
    grid = {}
    for item in text.split():
        key, _, value = item.partition("=")
        numbers = tuple(int(v) for v in value.split(","))
        grid[key] = numbers if len(numbers) > 1 else numbers[0]
    return grid


def _served(shortcut, bound):
    """``(names, arguments, references)`` of the designs the shortcut serves."""
    names, args, refs = [], [], []
    for d in recheck_tiers._designs():
        if 1.0 < d["strength"] <= bound and d["u"] <= shortcut.u_max:
            names.append(f"{d['source']} K={d['strength']:.2f} u={d['u']} noise={d['noise']:.1e}")
            args.append((jj.Seidel(**d["coefficients"]), d["field"], d["u"],
                         jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(d["noise"])))
            refs.append(d["reference"])
    for p in PROBLEMS:
        a = p.arguments()
        if p.converged and a[2] <= shortcut.u_max and 1.0 < float(
                jj.aberration_strength(a[0], a[1], a[2])) <= bound:
            names.append(f"bank {p.name}")
            args.append(a)
            refs.append(p.reference)
    return names, args, np.asarray(refs)


def _values(grid, args, float32=False):
    def cast(tree):
        return jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32), tree)

    fn = jax.jit(lambda *a: jj.jmse(*(cast(a) if float32 else a), **grid))
    return np.asarray([float(fn(*a)) for a in args])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trial", nargs="*", default=[],
                        help="candidate first trials, each 'key=a,b key=a,b ...'")
    args_ = parser.parse_args()
    bound, _, own_grid, shortcut = jj.DEFAULT_TIERS[1]
    names, args, refs = _served(shortcut, bound)
    trial = _values(shortcut.trial, args)
    check64 = _values(shortcut.check, args)
    check32 = _values(shortcut.check, args, float32=True)
    own = _values(own_grid, args)

    def kept(value, check):
        return np.abs(value - check) <= shortcut.rtol * np.abs(value)

    kept64, kept32 = kept(trial, check64), kept(trial, check32)
    returned = np.where(kept32, trial, own)
    errors = np.abs(returned / refs - 1.0)
    spread = np.abs(check32 / check64 - 1.0)
    report = dict(machine=common.machine_info(), designs=len(names), rtol=shortcut.rtol,
                  kept_float64_check=int(kept64.sum()), kept_float32_check=int(kept32.sum()),
                  decisions_changed=int(np.sum(kept64 != kept32)),
                  check_float32_vs_float64=dict(median=float(np.median(spread)),
                                                largest=float(spread.max())),
                  worst_error=float(errors.max()),
                  worst_kept_trial=float(np.max(np.abs(trial[kept32] / refs[kept32] - 1.0),
                                                initial=0.0)),
                  candidates=[])
    lines = ["# The middle tier's shortcut re-checked", "",
             f"{len(names)} designs (strength 1-{bound:g}, u <= {shortcut.u_max:.3f}; stored "
             f"calibration designs and converged bank cases); commit "
             f"{report['machine'].get('commit')}.", "",
             f"- trials kept: {kept64.sum()} with the check in float64, {kept32.sum()} in "
             f"float32; decisions changed: {report['decisions_changed']}",
             f"- float32 check against float64: median {np.median(spread):.1e}, largest "
             f"{spread.max():.1e} (relative)",
             f"- worst error returned by the tier: {errors.max():.2e}; worst kept trial: "
             f"{report['worst_kept_trial']:.2e}", ""]
    if args_.trial:
        lines += ["Candidate first trials in front of the present one (same check, float32):",
                  "", "| candidate | kept | worst error | worst among kept | largest error / "
                  "difference among kept | at |", "|---|---|---|---|---|---|"]
    for text in args_.trial:
        grid = _parse_grid(text)
        first = _values(grid, args)
        kept_first = kept(first, check32)
        final = np.where(kept_first, first, returned)
        final_errors = np.abs(final / refs - 1.0)
        first_errors = np.abs(first / refs - 1.0)
        difference = np.abs(first - check32) / np.abs(first)
        ratio = first_errors[kept_first] / np.maximum(difference[kept_first], 1e-16)
        worst = int(np.argmax(final_errors))
        row = dict(grid=grid, kept=int(kept_first.sum()), worst=float(final_errors.max()),
                   worst_kept=float(np.max(first_errors[kept_first], initial=0.0)),
                   largest_ratio=float(np.max(ratio, initial=0.0)), at=names[worst])
        report["candidates"].append(row)
        lines.append(f"| {text} | {row['kept']}/{len(names)} | {row['worst']:.2e} | "
                     f"{row['worst_kept']:.2e} | {row['largest_ratio']:.1f} | {row['at']} |")
    report["machine"]["load_at_end"] = common.load_average()
    print("\n".join(lines))
    common.write_json(common.RESULTS / "recheck_shortcut.json", report)
    (common.RESULTS / "recheck_shortcut.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
