"""The one benchmark command: accuracy/speed of every method, then the paper's figures.

Run from the repository root, in one process (float64)::

    .venv/bin/python benchmarks/run_all.py            # full (~20 min on a quiet 2-core CPU)
    .venv/bin/python benchmarks/run_all.py --quick    # small subset (about 5 min)

Outputs go to ``benchmarks/results/`` (see ``benchmarks/README.md``); ``--quick`` writes the
same files with a ``_quick`` suffix, so a development run never overwrites the full results.
"""

from __future__ import annotations

import argparse
import sys
import time

import _common as common
import accuracy_speed
import paper_figures


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small subset (~5 min, 2 cores)")
    parser.add_argument("--skip-figures", action="store_true", help="accuracy/speed only")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    print(f"load before: {common.load_average()['uptime']}", flush=True)
    report = accuracy_speed.run(quick=args.quick)
    if not args.skip_figures:
        paper_figures.run(quick=args.quick)
    h = report["headlines"]
    print("=" * 72)
    if "equal_accuracy" in h:
        ea, et = h["equal_accuracy"], h.get("equal_time", {})
        bound = not ea["reached"] and ea.get("lower_bound")
        print(f"(1) equal-accuracy speed-up: {'at least ' if bound else ''}{ea['speedup']:.3g}x"
              f" vs {ea['baseline']}"
              f"{'' if ea['reached'] else ' (no tested B reaches the default accuracy)'}"
              + (f"; {ea['stand_in_speedup']:.3g}x at {ea['stand_in']}"
                 if ea.get("stand_in") else "")
              + "  [target >= 100]")
        if et:
            gain = "none of ours is as fast" if et["gain"] is None else f"{et['gain']:.3g}x"
            detail = ("" if et["default_within_baseline_time"] else
                      f" (default slower than B=64; best of ours within its time: "
                      f"{et.get('best_within_time')}; default alone {et['gain_default']:.3g}x)")
            print(f"(2) equal-time accuracy gain: {gain}{detail}  [target >= 1000]")
        print(f"(3) value_and_grad / value (default): "
              f"{h['default_value_and_grad_over_value']:.2f}  [target <= 2.5]")
    print(f"load after: {common.load_average()['uptime']}")
    print(f"run_all: {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
