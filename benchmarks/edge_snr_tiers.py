"""The default's tiers under flat signal spectra at high SNR at the band's edge.

Near the OTF's cutoff ``H`` falls as ``(1 - r)^{3/2}``; where the signal is still strong
there (a flat spectrum: a power law with a wide knee, a short correlation length), ``S_e``
turns from ``S_n / |H|^2`` to ``S_x`` within a distance of the cutoff that falls with
``S_x / S_n``: on bands that reach the cutoff the radial interpolation of the OTF has to
follow it, and where only rays near the diagonal reach it the fine angular rule. The tiers
were calibrated with ``MarkovSignal`` spectra of correlation length 2-10
(``calibrate_tiers_kink.md``), whose ``S_x / S_n`` at the band's edge stays low; session
81's adversarial climb under power-law spectra (``default_climb.py --signal powerlaw``)
found tier 1 2.6e-4 off at u = 0.9 with ``S_x / S_n`` of 3.8e5 at the cutoff, and led to
``EDGE_TIER_SNR``. This script draws random Seidel designs of strength up to ``--strength``
with u uniform in ``--u`` under flat spectra (half ``PowerLawSignal(1, 1.5-3, 0.1-1)``,
half ``MarkovSignal(1, 0.5-3)``), the noise set for an ``S_x / S_n`` at the band's edge
(``_merit._edge_snr``: at ``min(sqrt(2) u, 1)``) log-uniform in 1e2-1e6 and a peak within
``CHECKED_SNR``, and reports, per edge-SNR bin and band reach, the worst error against the
converged polar grid of the grid of each tier whose bounds admit the design (tiers 0-3 and
the steep tier), of the default as routed and of ``"high"``.

Usage (from the repository root; about 10 min on 2 cores)::

    .venv/bin/python benchmarks/edge_snr_tiers.py [--designs 150] [--seed 0] [--u 0.6 1.2]
        [--strength 5] [--name edge_snr_tiers]

Writes ``results/<name>.json`` and ``.md``.
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
from jmse_jax._merit import _edge_snr  # noqa: E402

TERMS = ("w020", "w040", "w131", "w222", "w220")
BINS = (1e2, 1e3, 3e3, 1e4, 3e4, 1e5, 3e5, 1e6)
TIERS = ("0", "1", "2", "3", "4")
COLUMNS = TIERS + ("default", "high")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=150)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--u", type=float, nargs=2, default=(0.6, 1.2), metavar=("LOW", "HIGH"),
                        help="range of u (uniform)")
    parser.add_argument("--name", default="edge_snr_tiers")
    parser.add_argument("--strength", type=float, default=5.0,
                        help="largest aberration_strength drawn (tier 1 to 5, tier 2 to 15)")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    grids = {t: jj.DEFAULT_TIERS[int(t)][2] for t in TIERS}
    rows, start = [], time.perf_counter()
    for i in range(args.designs):
        scale = float(rng.choice([0.25, 0.5, 1.0, 2.0] + ([4.0] if args.strength > 5 else [])))
        coefficients = {k: float(rng.uniform(-scale, scale)) for k in TERMS}
        field, u = float(rng.uniform(0, 1)), float(rng.uniform(*args.u))
        if i % 2:
            signal = jj.PowerLawSignal(1.0, float(rng.uniform(1.5, 3.0)),
                                       float(10 ** rng.uniform(-1, 0)))
        else:
            signal = jj.MarkovSignal(1.0, float(rng.uniform(0.5, 3.0)))
        target = float(10 ** rng.uniform(2, 6))
        noise = jj.WhiteNoise(float(_edge_snr(u, signal, jj.WhiteNoise(1.0))) / target)
        peak = float(signal.radial(0.0)) / float(noise.variance)
        design = (jj.Seidel(**coefficients), field, u, signal, noise)
        strength = float(jj.aberration_strength(*design[:3]))
        if strength > args.strength or peak > jj.CHECKED_SNR:
            continue
        tiers = [t for t in TIERS if u <= jj.DEFAULT_TIERS[int(t)][1]
                 and strength <= jj.DEFAULT_TIERS[int(t)][0]]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reference = float(jj.jmse(*design, **common.CONVERGED_POLAR))
            errors = {t: abs(float(jj.jmse(*design, **grids[t])) / reference - 1.0)
                      for t in tiers}
            for preset in ("default", "high"):
                errors[preset] = abs(float(jj.jmse(*design, preset=preset)) / reference - 1)
        rows.append(dict(coefficients=coefficients, field=field, u=u, signal=repr(signal),
                         noise=float(noise.variance), edge_snr=target, peak_snr=peak,
                         strength=strength, reference=reference, errors=errors))
        print(f"{i}: strength {strength:.2f} u {u:.2f} edge snr {target:.1e} peak "
              f"{peak:.1e} " + " ".join(f"tier {t} {e:.1e}" for t, e in errors.items())
              + f" [{time.perf_counter() - start:.0f} s]", flush=True)
    lines = ["# The tiers under flat spectra at high SNR at the band's edge", "",
             f"`python benchmarks/edge_snr_tiers.py --designs {args.designs} --seed "
             f"{args.seed} --u {args.u[0]} {args.u[1]} --strength {args.strength:g} --name "
             f"{args.name}`", "",
             common.machine_line(common.machine_info(), common.load_average()), "",
             f"{len(rows)} random designs of strength up to {args.strength:g}, u {args.u[0]}"
             f"-{args.u[1]}, under flat spectra; reference {common.CONVERGED_POLAR}. Each "
             "cell: designs in the bin, worst error (the grid of each tier whose bounds admit "
             "the design, alone; the default and `high` as a user calls them), by the band's "
             "reach: u <= 0.5 (corner within 0.707 of the cutoff), 0.5 < u <= 1/sqrt(2), and "
             "u > 1/sqrt(2) (rays reach the cutoff; tier 2 admits none).", "",
             "| S_x / S_n at the band's edge | u | tier 0 (24 radial OTF nodes, 96 angular "
             "fine) | tier 1 (40, 160) | tier 2 (64, 128) | tier 3 (96, 256) | steep tier (96, "
             "512) | the default as routed | `high` (80, 960) |",
             "|---|---|---|---|---|---|---|---|---|"]
    groups = (("<= 0.5", 0.0, 0.5), ("0.5 - 0.707", 0.5, jj.DEFAULT_TIERS[2][1]),
              ("> 0.707", jj.DEFAULT_TIERS[2][1], math.inf))
    for label, u_low, u_high in groups:
        for low, high in zip(BINS[:-1], BINS[1:], strict=True):
            cells = []
            for t in COLUMNS:
                e = [r["errors"][t] for r in rows if t in r["errors"]
                     and low <= r["edge_snr"] < high and u_low < r["u"] <= u_high]
                cells.append(f"{len(e)}, {max(e):.1e}" if e else "–")
            if any(c != "–" for c in cells):
                lines.append(f"| {low:.0e} - {high:.0e} | {label} | {' | '.join(cells)} |")
    print("\n".join(lines))
    common.write_report(args.name, dict(machine=common.machine_info(), rows=rows),
                        lines)


if __name__ == "__main__":
    main()
