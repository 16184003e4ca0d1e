"""The ``"high"`` preset on designs on the axis (its one-ray plan, ``HIGH_RAY_GRID``).

Designs, with their stored converged references: the designs of ``balanced_one_ray.py``
(``results/balanced_one_ray.json``: defocus, spherical aberration and defocus balanced
against it, strength 1-45, u 0.05-1.2) at noise 1e-3 to 1e-6 (a peak ``S_x / S_n`` up to
1.6e8, within ``CHECKED_SNR_PEAKS``), and the designs on the axis of
``small_u_single_terms.py`` within ``CHECKED_SLOPE``. Each is evaluated with ``"high"`` as a
user calls it and with the one ray of ``"high"``'s own grid (its counts before session 65);
the default's stored error is listed beside them.

Usage (from the repository root; about 1 min on 2 cores)::

    .venv/bin/python benchmarks/high_one_ray.py

Writes ``results/high_one_ray.json`` and ``.md``.
"""

from __future__ import annotations

import json
import math
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402
from jmse_jax._radial import radial_band_integral  # noqa: E402

SIGNAL = jj.MarkovSignal(1.0, 5.0)
#: ``"high"``'s own grid along one ray (its one-ray plan before ``HIGH_RAY_GRID``).
OWN = {**{k: v for k, v in jj.jmse_options("high").items() if k not in _merit._PRESET_ONLY},
       "_radial": True}


def designs():
    """``(source, aberrations, u, noise, reference, default error, strength, slope)``."""
    out = []
    data = json.loads((common.RESULTS / "balanced_one_ray.json").read_text())
    for r in data["designs"]:
        if r["noise"] >= 1e-6:
            out.append((r["ratio"], jj.Seidel(w020=r["w020"], w040=r["w040"]), r["u"],
                        r["noise"], r["reference"], r["after"], r["strength"], r["slope"]))
    data = json.loads((common.RESULTS / "small_u_single_terms.json").read_text())
    for r in data["designs"]:
        if r["one_ray"] and r["slope"] <= jj.CHECKED_SLOPE:
            out.append((f"small u {r['term']}", jj.Seidel(**{r["term"]: r["coefficient"]}),
                        r["u"], 1e-3, r["reference"], r["error"], r["strength"], r["slope"]))
    return out


def main() -> None:
    machine = common.machine_info()
    warnings.simplefilter("ignore")
    own = jax.jit(lambda ab, u, noise: radial_band_integral(
        ab, 0.0, u, SIGNAL, jj.WhiteNoise(noise), OWN, jnp.float64) / (2 * math.pi))
    rows = []
    start = time.perf_counter()
    for source, ab, u, noise, ref, default, strength, slope in designs():
        high = float(jj.jmse(ab, 0.0, u, SIGNAL, jj.WhiteNoise(noise), preset="high"))
        rows.append(dict(source=source, w020=float(ab.w020), w040=float(ab.w040), u=u,
                         noise=noise, strength=strength, slope=slope, reference=ref,
                         high=high / ref - 1.0, own=float(own(ab, u, noise)) / ref - 1.0,
                         default=default))
    print(f"{len(rows)} designs, {time.perf_counter() - start:.0f} s", flush=True)
    lines = ["# The high preset on designs on the axis (one ray)", "",
             common.machine_line(machine, common.load_average()), "",
             "Designs of `balanced_one_ray.py` at noise 1e-3 to 1e-6 and the designs on the axis "
             "of `small_u_single_terms.py` within `CHECKED_SLOPE`, against their stored "
             "converged references; MarkovSignal(1, 5). `high`: the preset as a user calls "
             "it (`HIGH_RAY_GRID`); `own`: the one ray of `high`'s own grid (before session "
             "65); `default`: the default's stored error.", "",
             "| method | designs | > 1e-4 | > 1e-5 | > 1e-6 | worst |", "|---|---|---|---|---|---|"]
    for name in ("high", "own", "default"):
        errs = [abs(r[name]) for r in rows]
        line = (f"| {name} | {len(rows)} | {sum(e > 1e-4 for e in errs)} | "
                f"{sum(e > 1e-5 for e in errs)} | {sum(e > 1e-6 for e in errs)} | "
                f"{max(errs):.1e} |")
        lines.append(line)
        print(line, flush=True)
    lines += ["", "Worst ten for `own`:", "", "| design | u | strength | slope | noise | high | "
              "own | default |", "|---|---|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: -abs(r["own"]))[:10]:
        lines.append(f"| {r['source']} w020 {r['w020']:.2f} w040 {r['w040']:.2f} | {r['u']} | "
                     f"{r['strength']:.0f} | {r['slope']:.0f} | {r['noise']:.0e} | "
                     f"{r['high']:+.1e} | {r['own']:+.1e} | {r['default']:+.1e} |")
    common.write_report("high_one_ray", dict(machine=machine, designs=rows), lines)


if __name__ == "__main__":
    main()
