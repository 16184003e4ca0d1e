"""The default's gradient against the converged gradient, with and without the closed-form peaks.

``gradient_fuzz.py`` checks that each program's gradient is the derivative of its own value
(central differences of the same program). This script asks how far that gradient is from
the derivative of the converged JMSE: for random designs drawn as in ``default_climb.py``
(Seidel or Zernike terms, Markov or power-law spectra, within the checked range), the
sensitivities ``s_i = sigma_i (dJ/dx_i) / J`` in the coefficients, the field, ``u`` and the
noise variance (``default_climb._sensitivities``) of

- the default preset,
- the default with ``peaks=True`` (the tiers' own grids integrate the narrow peaks of
  ``S_e`` in closed form, ``jmse_jax._ridges``; the shortcuts' first and check grids do not),

against those of the converged polar reference (``default_climb.REFERENCE``, with the
peaks), per design ``max_i |s_i - s_i^ref| / max_i |s_i^ref|``, with the value's error
beside it and the warm ``value_and_grad`` time of both (one call after a warm-up; a rough
figure on a shared host).

Session 84 found by ``default_climb.py --gradient --signal powerlaw`` a tier-3 design whose
value is 1.3e-6 off and whose gradient is 3.1e-2 off (its derivative in ``u``): narrow peaks
of ``S_e`` at the OTF's near-zeros move across the fine nodes as a parameter moves, and the
fine rule's error, small in the value, oscillates with the node spacing, which its
derivative amplifies.

Usage (from the repository root)::

    .venv/bin/python benchmarks/gradient_accuracy.py [--designs 60] [--seed 0]
        [--signal markov|powerlaw] [--family seidel|zernike]

Writes ``results/gradient_accuracy_<family>_<signal>.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import collections
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import default_climb as climb  # noqa: E402
import numpy as np  # noqa: E402

VARIANTS = {"default": dict(preset="default"), "default, peaks": dict(preset="default",
                                                                         peaks=True)}


def _timed(row, options):
    """Sensitivities and the warm time of one ``value_and_grad`` call [s]."""
    climb._sensitivities(row, options)  # compiles, warms
    start = time.perf_counter()
    value, s = climb._sensitivities(row, options)
    return value, s, time.perf_counter() - start


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=60)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--signal", default="powerlaw", choices=("markov", "powerlaw"))
    parser.add_argument("--family", default="seidel", choices=("seidel", "zernike"))
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    reference = climb.ZERNIKE_REFERENCE if args.family == "zernike" else climb.REFERENCE
    rows, start = [], time.perf_counter()
    for i in range(args.designs):
        row = climb._evaluate(climb._random_row(rng, args.family, args.signal), "default",
                              reference)
        if row is None:
            continue
        _, s_ref = climb._sensitivities(row, reference)
        row = dict(row, design=i, variants={})
        for name, options in VARIANTS.items():
            value, s, seconds = _timed(row, options)
            row["variants"][name] = dict(
                value_error=abs(value / row["reference"] - 1.0),
                gradient_error=climb.gradient_error(s, s_ref), seconds=seconds)
        rows.append(row)
        v = row["variants"]
        print(f"design {i}: tier {row['tier']} {row['path']}, gradient "
              f"{v['default']['gradient_error']:.1e} / with peaks "
              f"{v['default, peaks']['gradient_error']:.1e}, value "
              f"{v['default']['value_error']:.1e}, vag {1e3 * v['default']['seconds']:.1f} / "
              f"{1e3 * v['default, peaks']['seconds']:.1f} ms "
              f"[{time.perf_counter() - start:.0f} s]", flush=True)
    groups = collections.defaultdict(list)
    for row in rows:
        key = ("one ray" if row["one_ray"] else "balanced" if row["balanced"]
               else f"tier {row['tier']}, {row['path']}")
        groups[key].append(row)
    flags = f"--designs {args.designs} --seed {args.seed} --signal {args.signal} " \
            f"--family {args.family}"
    lines = ["# The default's gradient against the converged gradient", "",
             f"`python benchmarks/gradient_accuracy.py {flags}`", "",
             common.machine_line(common.machine_info(), common.load_average()), "",
             f"{len(rows)} of {args.designs} random designs in the checked range. Gradient "
             "error: the largest difference of the sensitivities over the largest reference "
             f"sensitivity; reference {reference}. Times: one warm `value_and_grad` call "
             "(median of the group).", "",
             "| route | designs | value: worst error | gradient: worst (median) | with peaks: "
             "worst (median) | vag time | with peaks |", "|---|---|---|---|---|---|---|"]

    def stats(group, name, key):
        return np.array([r["variants"][name][key] for r in group])

    for key in sorted(groups):
        group = groups[key]
        g, gp = stats(group, "default", "gradient_error"), stats(group, "default, peaks",
                                                                 "gradient_error")
        lines.append(
            f"| {key} | {len(group)} | {stats(group, 'default', 'value_error').max():.1e} | "
            f"{g.max():.1e} ({np.median(g):.1e}) | {gp.max():.1e} ({np.median(gp):.1e}) | "
            f"{1e3 * np.median(stats(group, 'default', 'seconds')):.1f} ms | "
            f"{1e3 * np.median(stats(group, 'default, peaks', 'seconds')):.1f} ms |")
    worst = sorted(rows, key=lambda r: -r["variants"]["default"]["gradient_error"])[:5]
    lines += ["", "Worst five by the default's gradient:", "",
              "| design | tier, path | gradient | with peaks | value | design |",
              "|---|---|---|---|---|---|"]
    for r in worst:
        v = r["variants"]
        lines.append(f"| {r['design']} | {r['tier']}, {r['path']} | "
                     f"{v['default']['gradient_error']:.1e} | "
                     f"{v['default, peaks']['gradient_error']:.1e} | "
                     f"{v['default']['value_error']:.1e} | {climb._describe(r)} |")
    print("\n".join(lines))
    common.write_report(f"gradient_accuracy_{args.family}_{args.signal}",
                        dict(machine=common.machine_info(), reference=reference, rows=rows),
                        lines)


if __name__ == "__main__":
    main()
