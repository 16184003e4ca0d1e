"""Designs whose terms cancel, given as Zernike coefficients instead of Seidel ones.

The default (and ``"high"``) send a design off the axis whose terms cancel much of each
other's wavefront slope to a balanced grid (``_merit._cancellation`` >= 2.5 from a strength
of 2.5). The measure was calibrated on Seidel coefficients. A Zernike polynomial is itself a
balanced combination (``Z11`` = sqrt 5 (6 rho^4 - 6 rho^2 + 1) holds defocus against
spherical aberration), so the same wavefront given by its Zernike coefficients, taken one
polynomial at a time, looked as if it cancelled much less, and took the tiers by strength.

Designs: the 488 stored designs of ``balanced_tier.py`` (``results/balanced_tier.json``:
defocus against spherical aberration a hair off the axis, astigmatism at the medial focus,
three-term mixtures, the calibration designs that cancel), each rewritten exactly as
Zernike coefficients at its field point (Noll 4, 6, 8 and 11; Seidel's coma and
astigmatism lie along ``y``, Zernike's cosine terms), against its stored converged
reference. Each is evaluated with the default as a user calls it; the table gives its
route, error and warning, and the default's stored error on the Seidel form beside it.

Usage (from the repository root; about 3 min on 2 cores)::

    .venv/bin/python benchmarks/zernike_cancellation.py [--name NAME]

Writes ``results/<NAME>.json`` and ``.md`` (default name ``zernike_cancellation``). To
measure another version of the package, put its checkout first on ``PYTHONPATH`` (the
script calls ``_merit._prepare``, ``_merit._concrete_merit`` and ``_merit._cancellation_jit``
besides the public API).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402

SIGNAL = jj.MarkovSignal(1.0, 5.0)


def as_zernike(r):
    """The stored Seidel design ``r`` at its field point as Zernike coefficients (Noll 4, 6,
    8, 11), the same wavefront less piston and tilt."""
    h = r["field"]
    astigmatism = r["w222"] * h * h / 2.0  # w222 h^2 y^2 = A rho^2 + A rho^2 cos 2 theta
    c2 = r["w020"] + r["w220"] * h * h + astigmatism
    a11 = r["w040"] / (6.0 * math.sqrt(5.0))
    a4 = (c2 + r["w040"]) / (2.0 * math.sqrt(3.0))
    a6 = astigmatism / math.sqrt(6.0)
    a8 = r["w131"] * h / (3.0 * math.sqrt(8.0))  # Seidel coma less its tilt
    return jj.Zernike([a4, a6, a8, a11], noll=(4, 6, 8, 11))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--name", default="zernike_cancellation")
    args = parser.parse_args(argv)
    machine = common.machine_info()
    stored = json.loads((common.RESULTS / "balanced_tier.json").read_text())["designs"]
    rows = []
    start = time.perf_counter()
    for r in stored:
        ab = as_zernike(r)
        noise = jj.WhiteNoise(r["noise"])
        # As ``jmse`` calls it (with its warnings), keeping the index of the plan it took.
        static, inputs = _merit._prepare((ab, r["field"], r["u"], SIGNAL, noise),
                                         jj.jmse_options())
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            value, index, _, _ = _merit._concrete_merit(static, inputs, warn=True)
        rows.append(dict(
            source=r["source"], u=r["u"], noise=r["noise"], strength=r["strength"],
            seidel_cancellation=r["cancellation"],
            cancellation=float(_merit._cancellation_jit(ab, r["field"], r["u"])),
            balanced=int(index) == len(jj.DEFAULT_TIERS), tier=int(index),
            error=float(value) / r["reference"] - 1.0,
            warned=any(issubclass(w.category, UserWarning) for w in caught),
            seidel_error=r["errors"]["default"]))
    seconds = time.perf_counter() - start
    print(f"{len(rows)} designs, {seconds:.0f} s", flush=True)
    silent = [x for x in rows if not x["warned"]]
    lines = ["# Designs that cancel, given as Zernike coefficients", "",
             common.machine_line(machine, common.load_average()), "",
             f"The {len(rows)} designs of `balanced_tier.py`, each rewritten as Zernike "
             "coefficients (Noll 4, 6, 8, 11) at its field point, against its stored converged "
             "reference; the default as a user calls it; MarkovSignal(1, 5). `cancellation`: "
             "the Zernike form's, as the library measures it; `Seidel form`: the default's "
             f"stored error on the Seidel coefficients. {seconds:.0f} s in all.", "",
             "| designs | to the balanced grid | warned | > 1e-4 (silent) | > 1e-5 | worst | "
             "worst silent | Seidel form: > 1e-4, worst |", "|---|---|---|---|---|---|---|---|"]
    errors = [abs(x["error"]) for x in rows]
    seidel = [abs(x["seidel_error"]) for x in rows]
    lines.append(
        f"| {len(rows)} | {sum(x['balanced'] for x in rows)} | {sum(x['warned'] for x in rows)} "
        f"| {sum(e > 1e-4 for e in errors)} ({sum(abs(x['error']) > 1e-4 for x in silent)}) "
        f"| {sum(e > 1e-5 for e in errors)} | {max(errors):.1e} "
        f"| {max((abs(x['error']) for x in silent), default=0.0):.1e} "
        f"| {sum(e > 1e-4 for e in seidel)}, {max(seidel):.1e} |")
    print(lines[-1], flush=True)
    lines += ["", "By source:", "", "| source | designs | balanced | > 1e-4 | worst | "
              "cancellation (Zernike form) | cancellation (Seidel form) |",
              "|---|---|---|---|---|---|---|"]
    for source in dict.fromkeys(x["source"] for x in rows):
        group = [x for x in rows if x["source"] == source]
        zc = [x["cancellation"] for x in group]
        sc = [x["seidel_cancellation"] for x in group]
        lines.append(f"| {source} | {len(group)} | {sum(x['balanced'] for x in group)} | "
                     f"{sum(abs(x['error']) > 1e-4 for x in group)} | "
                     f"{max(abs(x['error']) for x in group):.1e} | "
                     f"{min(zc):.2f}-{max(zc):.2f} | {min(sc):.2f}-{max(sc):.2f} |")
    lines += ["", "Worst ten:", "", "| source | u | strength | noise | cancellation | "
              "Seidel form's | balanced | tier | warned | error | Seidel form's error |",
              "|---|---|---|---|---|---|---|---|---|---|---|"]
    for x in sorted(rows, key=lambda x: -abs(x["error"]))[:10]:
        lines.append(f"| {x['source']} | {x['u']} | {x['strength']:.1f} | {x['noise']:.0e} | "
                     f"{x['cancellation']:.2f} | {x['seidel_cancellation']:.2f} | "
                     f"{x['balanced']} | {x['tier']} | {x['warned']} | {x['error']:+.1e} | "
                     f"{x['seidel_error']:+.1e} |")
    common.write_report(args.name, dict(machine=machine, designs=rows), lines)


if __name__ == "__main__":
    main()
