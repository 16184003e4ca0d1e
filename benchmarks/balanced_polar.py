"""The default's polar tiers on defocus balanced against spherical aberration: a known gap.

``balanced_one_ray.py`` found the one-ray plans far off on ``W = c (rho^2 + r rho^4)`` with
``r`` between -1.5 and -0.3 (fixed there). A design a hair off rotational symmetry takes
the polar tiers instead, whose grids were calibrated on random designs with every
coefficient within +-8 waves, which seldom balance one term against another. This script
measures them on such designs made non-symmetric by 1e-7 waves of astigmatism at field 1
(a change of the JMSE of about 1e-8, as the pure spherical rows show), against the
symmetric design's converged one-ray value (``balanced_one_ray.REFERENCE``), for the
default and the ``"high"`` preset, as a user calls them.

Usage (from the repository root; about 10 min on 2 cores)::

    .venv/bin/python benchmarks/balanced_polar.py

Writes ``results/balanced_polar.json`` and ``.md``.
"""

from __future__ import annotations

import math
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import balanced_one_ray  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from balanced_one_ray import REFERENCE  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402
from jmse_jax._radial import radial_band_integral  # noqa: E402

RATIOS = ("spherical", -0.3, -0.5, -0.7, -0.8, -1.0, -1.5)
US = (0.2, 0.4, 0.7, 1.0)
STRENGTHS = (2.0, 3.0, 4.0, 5.0, 10.0, 15.0, 20.0, 25.0)
NOISES = (1e-3, 1e-4)
SIGNAL = jj.MarkovSignal(1.0, 5.0)
FIELD = 1.0
ASTIGMATISM = 1e-7


def main() -> None:
    machine = common.machine_info()
    reference = jax.jit(lambda ab, u, noise: radial_band_integral(
        ab, 0.0, u, SIGNAL, jj.WhiteNoise(noise), REFERENCE, jnp.float64) / (2 * math.pi))
    tiers = jj.DEFAULT_TIERS
    rows = []
    start = time.perf_counter()
    for ratio, u, _, slope, symmetric in balanced_one_ray.designs(RATIOS, US, STRENGTHS):
        ab = jj.Seidel(w020=symmetric.w020, w040=symmetric.w040, w222=ASTIGMATISM)
        actual = float(jj.aberration_strength(ab, FIELD, u))
        tier = int(_merit._tier_index(jnp.asarray(actual), jnp.asarray(u), tiers))
        for noise in NOISES:
            ref = float(reference(symmetric, u, noise))
            row = dict(ratio=ratio, u=u, strength=actual, slope=slope,
                       w020=float(ab.w020), w040=float(ab.w040), noise=noise, tier=tier,
                       reference=ref)
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                for preset in ("default", "high"):
                    value = float(jj.jmse(ab, FIELD, u, SIGNAL, jj.WhiteNoise(noise),
                                          preset=preset))
                    row[preset] = value / ref - 1.0
            messages = [str(w.message) for w in caught]
            row["cancelling"] = any("cancel" in m for m in messages)
            row["warned"] = any("cancel" not in m for m in messages)
            rows.append(row)
        print(f"{ratio} u={u} strength {actual:.3g}: {len(rows)} designs, "
              f"{time.perf_counter() - start:.0f} s", flush=True)
    quiet = [r for r in rows if not r["warned"]]
    lines = ["# The default's polar tiers on defocus balanced against spherical aberration", "",
             common.machine_line(machine, common.load_average()), "",
             f"Relative error of `jmse` (as a user calls it) on `W = c (rho^2 + r rho^4)` plus "
             f"{ASTIGMATISM:g} waves of astigmatism at field {FIELD} (so not symmetric: the "
             "polar tiers), against the symmetric design's converged one-ray value "
             f"({REFERENCE}); MarkovSignal(1, 5). Warned: the call gave a strength or slope "
             "warning (beyond `CHECKED_STRENGTH`); cancel: the cancellation warning.", "",
             "| r | u | strength | slope | w020 | w040 | noise | tier | default | high | warned |",
             "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['ratio']} | {r['u']} | {r['strength']:.1f} | {r['slope']:.0f} | "
                     f"{r['w020']:.1f} | {r['w040']:.1f} | {r['noise']:g} | {r['tier']} | "
                     f"{r['default']:+.1e} | {r['high']:+.1e} | "
                     f"{'strength' if r['warned'] else ''}{' cancel' if r['cancelling'] else ''} |")
    for preset in ("default", "high"):
        bad = [r for r in quiet if abs(r[preset]) > 1e-4]
        lines.append(f"\n{preset}: {len(bad)} of {len(quiet)} designs without a strength or "
                     f"slope warning more than 1e-4 off, worst "
                     f"{max(abs(r[preset]) for r in quiet):.1e}.")
    flagged = [r for r in quiet if r["cancelling"]]
    bad = [r for r in quiet if abs(r["default"]) > 1e-4]
    lines.append(f"\nThe cancellation warning (`CHECKED_CANCELLATION` = "
                 f"{jj.CHECKED_CANCELLATION:g} from a strength of {jj.CANCELLING_STRENGTH:g}) "
                 f"is given to {len(flagged)} of those designs, {sum(r['cancelling'] for r in bad)}"
                 f" of the {len(bad)} that are more than 1e-4 off.")
    common.write_report("balanced_polar",
                        dict(machine=machine, reference=REFERENCE, field=FIELD,
                             astigmatism=ASTIGMATISM, designs=rows), lines)


if __name__ == "__main__":
    main()
