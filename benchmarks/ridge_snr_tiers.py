"""The weak tiers' grids near the axis at high SNR: how far the peak SNR can go in each.

Near the axis a design's OTF nearly vanishes on rings inside the band, and there ``S_e``
has narrow ridges whose width falls as ``1/sqrt(S_x / S_n)``. The default's weak tiers have
no closed-form peaks (``peaks=False``) and 800 (tier 0) or 2400 (tier 1) fine radial
nodes; session 80's adversarial climb (``default_climb.py``) found tier 0 1.3e-2 off at a
peak SNR of 1.9e6, inside ``CHECKED_SNR``, on 2.5 waves of defocus near the axis at
u = 0.1 with a short correlation length (1.35: a flat signal spectrum, so the SNR on the
ring is nearly the peak's). This script draws random designs near the axis (field 0-0.15,
defocus, spherical, coma, astigmatism and field curvature within +-0.5 to +-3 waves,
u 0.05-0.5, correlation length 0.5-10, peak SNR log-uniform 1e3 to 2e6), evaluates the
grids of tiers 0 and 1 where their strength bound admits the design (tier 0 also needs
u <= 0.5), and reports each grid's worst error per peak-SNR bin against the converged
polar grid.

Usage (from the repository root; about 10 min on 2 cores)::

    .venv/bin/python benchmarks/ridge_snr_tiers.py [--designs 200] [--seed 0]

Writes ``results/ridge_snr_tiers.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402

TERMS = ("w020", "w040", "w131", "w222", "w220")
BINS = (1e3, 1e4, 3e4, 1e5, 3e5, 1e6, 2e6)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    grids = {0: jj.DEFAULT_TIERS[0][2], 1: jj.DEFAULT_TIERS[1][2]}
    rows, start = [], time.perf_counter()
    for i in range(args.designs):
        scale = float(rng.choice([0.5, 1.0, 2.0, 3.0]))
        coefficients = {k: float(rng.uniform(-scale, scale)) for k in TERMS}
        field, u = float(rng.uniform(0, 0.15)), float(rng.uniform(0.05, 0.5))
        mu = float(10 ** rng.uniform(math.log10(0.5), 1))
        snr = float(10 ** rng.uniform(3, math.log10(2e6)))
        design = (jj.Seidel(**coefficients), field, u, jj.MarkovSignal(1.0, mu),
                  jj.WhiteNoise(2 * math.pi * mu ** 2 / snr))  # peak S_x = 2 pi mu^2
        strength = float(jj.aberration_strength(*design[:3]))
        tiers = [t for t in (0, 1) if strength <= jj.DEFAULT_TIERS[t][0]
                 and u <= jj.DEFAULT_TIERS[t][1]]
        if not tiers:
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reference = float(jj.jmse(*design, **common.CONVERGED_POLAR))
            errors = {t: abs(float(jj.jmse(*design, **grids[t])) / reference - 1.0)
                      for t in tiers}
        rows.append(dict(coefficients=coefficients, field=field, u=u, correlation_length=mu,
                         snr=snr, strength=strength, reference=reference,
                         errors={str(t): e for t, e in errors.items()}))
        print(f"{i}: strength {strength:.2f} u {u:.2f} mu {mu:.2f} snr {snr:.2e} "
              + " ".join(f"tier {t} {e:.1e}" for t, e in errors.items())
              + f" [{time.perf_counter() - start:.0f} s]", flush=True)
    lines = ["# The weak tiers near the axis at high SNR", "",
             f"`python benchmarks/ridge_snr_tiers.py --designs {args.designs} --seed "
             f"{args.seed}`", "", common.machine_line(common.machine_info(),
                                                      common.load_average()), "",
             f"{len(rows)} random designs near the axis that tier 0 or 1 admits by strength; "
             f"reference {common.CONVERGED_POLAR}. Each cell: designs in the bin, worst "
             "error (the grid of the tier alone, without the shortcut).", "",
             "| peak SNR | tier 0 (800 fine radial nodes) | tier 1 (2400) |", "|---|---|---|"]
    for low, high in zip(BINS[:-1], BINS[1:], strict=True):
        cells = []
        for t in ("0", "1"):
            e = [r["errors"][t] for r in rows if t in r["errors"] and low <= r["snr"] < high]
            cells.append(f"{len(e)}, {max(e):.1e}" if e else "–")
        lines.append(f"| {low:.0e} - {high:.0e} | {cells[0]} | {cells[1]} |")
    print("\n".join(lines))
    common.write_report("ridge_snr_tiers", dict(machine=common.machine_info(), rows=rows),
                        lines)


if __name__ == "__main__":
    main()
