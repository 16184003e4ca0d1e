"""Grids for designs whose terms cancel: the default's balanced tier (``BALANCED_GRID``).

``balanced_polar.py`` found the default's tiers by strength up to 8e-2 off on defocus
balanced against spherical aberration a hair off the axis, and astigmatism at the medial
focus 8.7e-3 off; such designs are told apart by ``_merit._cancellation``
(``BALANCED_CANCELLATION``) and now take the balanced tier. This script measures fixed polar
grids (explicit ``jmse`` options, named in ``GRIDS``; ``default`` is the package's default as
a user calls it) on three sets:

- ``stored``: every stored design of ``results/balanced_polar.json`` and of the tier
  calibrations (``calibrate_tiers.json``, ``calibrate_tiers_kink.json``) whose cancellation
  is at least ``--min-cancellation`` and strength at least ``CANCELLING_STRENGTH``, against
  their stored converged references;
- ``medial``: astigmatism at the medial focus (``w020 = -w222 h^2 / 2``) and three-term
  mixtures (``MIXED``), against a converged polar grid (``MEDIAL_REFERENCE``);
- ``extra``: the balanced family at ``EXTRA_RATIOS`` (up to cancellation 7), against the
  symmetric design's converged one-ray value.

Usage (from the repository root; about 15 min for two grids and every set on 2 cores)::

    .venv/bin/python benchmarks/balanced_tier.py --grids default L [--sets stored medial extra]

Writes ``results/balanced_tier.json`` and ``.md`` (``--name`` to change).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax.numpy as jnp  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402

SIGNAL = jj.MarkovSignal(1.0, 5.0)
#: The candidate grids measured in session 64 (benchmarks/README.md, optimisation log):
#: name -> (nodes, se_nodes, overlap_nodes, overlap_floor, peaks); ``L11`` is the adopted
#: ``BALANCED_GRID``.
_CANDIDATES = {
    "A": ((96, 48), (4800, 256), (64, 64), 64, True),
    "B": ((128, 64), (9600, 256), (96, 96), 96, True),
    "C": ((128, 64), (9600, 256), (128, 128), 128, True),
    "D": ((128, 64), (9600, 384), (128, 128), 128, True),
    "E": ((96, 64), (6400, 256), (96, 96), 96, True),
    "F": ((128, 64), (6400, 256), (96, 96), 96, True),
    "G": ((96, 48), (4800, 256), (96, 96), 96, True),
    "H": ((192, 64), (9600, 256), (96, 96), 96, True),
    "I": ((128, 64), (14400, 256), (96, 96), 96, True),
    "J": ((192, 48), (9600, 256), (64, 64), 64, True),
    "K": ((192, 64), (9600, 256), (80, 80), 80, True),
    "L": ((160, 64), (9600, 256), (96, 96), 96, True),
    "L2": ((160, 64), (4800, 256), (96, 96), 96, True),
    "L3": ((160, 48), (6400, 256), (96, 96), 96, True),
    "L4": ((160, 48), (4800, 256), (96, 96), 96, True),
    "L4np": ((160, 48), (4800, 256), (96, 96), 96, False),
    "L5": ((160, 48), (4800, 256), (96, 96), 48, True),
    "L6": ((160, 48), (4800, 256), (96, 64), 64, True),
    "L8": ((160, 32), (4800, 256), (96, 96), 96, True),
    "L9": ((160, 48), (4800, 256), (96, 96), 24, True),
    "L10": ((160, 48), (4800, 256), (96, 80), 32, True),
    "L11": ((160, 48), (4800, 256), (96, 96), 64, True),
    # Session 65: candidates for the ``"high"`` preset's balanced grid.
    "HA": ((160, 48), (4800, 960), (96, 96), 64, True),  # adopted: HIGH_BALANCED_GRID
    "HB": ((192, 64), (9600, 960), (128, 128), 128, True),
    "HC": ((256, 64), (9600, 512), (128, 128), 128, True),
    "HD": ((192, 64), (9600, 512), (128, 128), 96, True),
}
#: ``tiers``: the default without its balanced tier (its tiers by strength alone).
GRIDS = {"default": {}, "high": {"preset": "high"}, "tiers": {}} | {
    name: dict(nodes=n, se_nodes=se, overlap_nodes=o, overlap_floor=f, peaks=p)
    for name, (n, se, o, f, p) in _CANDIDATES.items()}
#: A converged polar grid for the medial-focus designs.
MEDIAL_REFERENCE = dict(nodes=(192, 96), se_nodes=(9600, 512), overlap_nodes=(192, 192),
                        overlap_floor=192, peaks=True)
MEDIAL = [(a, h, u, noise) for a in (4.0, 8.0, 12.0) for h in (0.5, 1.0)
          for u in (0.3, 0.5, 0.8) for noise in (1e-3, 1e-4)]
#: Three terms that cancel: astigmatism at the medial focus with defocus balanced against
#: spherical aberration (``w222 = a``, ``w020 = -a/2 + c``, ``w040 = -2c/3`` at field 1;
#: cancellation 2.5-4.4), and the r = -2/3 balance with coma at field 0.7 (about 6.5).
MIXED = ([(jj.Seidel(w222=a, w020=-a / 2 + c, w040=-2 * c / 3), 1.0, u, noise)
          for a in (5.0, 10.0) for c in (5.0, 10.0) for u in (0.3, 0.6, 1.0)
          for noise in (1e-3, 1e-4)]
         + [(jj.Seidel(w020=c, w040=-2 * c / 3, w131=k), 0.7, u, 1e-4)
            for c in (5.0, 10.0, 15.0) for k in (0.5, 2.0) for u in (0.3, 0.6)])


def _cancellation(ab, field, u):
    return float(_merit._cancellation_jit(ab.without_tilt(), jnp.asarray(field),
                                          jnp.asarray(u)))


def stored_designs(min_cancellation):
    """``(source, ab, field, u, noise, reference, strength, cancellation)`` of the stored
    designs that cancel."""
    out = []
    data = json.loads((common.RESULTS / "balanced_polar.json").read_text())
    for r in data["designs"]:
        ab = jj.Seidel(w020=r["w020"], w040=r["w040"], w222=data["astigmatism"])
        out.append(("balanced", ab, data["field"], r["u"], r["noise"], r["reference"]))
    for name in ("calibrate_tiers", "calibrate_tiers_kink"):
        data = json.loads((common.RESULTS / f"{name}.json").read_text())
        for r in data["designs"]:
            ab = jj.Seidel(**r["coefficients"])
            out.append((name, ab, r["field"], r["u"], r["noise"], r["reference"]))
    kept = []
    for source, ab, field, u, noise, ref in out:
        strength = float(jj.aberration_strength(ab, field, u))
        slope = strength / min(math.sqrt(2.0) * u, 1.0)
        if strength > jj.CHECKED_STRENGTH or slope > jj.CHECKED_SLOPE:
            continue
        c = _cancellation(ab, field, u)
        if c >= min_cancellation and strength >= jj.CANCELLING_STRENGTH:
            kept.append((source, ab, field, u, noise, ref, strength, c))
    return kept


def medial_designs():
    """Astigmatism at the medial focus and ``MIXED``, against ``MEDIAL_REFERENCE``."""
    out = []
    cases = [(jj.Seidel(w222=a, w020=-a * h * h / 2), h, u, noise) for a, h, u, noise in MEDIAL]
    for ab, h, u, noise in cases + MIXED:
        strength = float(jj.aberration_strength(ab, h, u))
        slope = strength / min(math.sqrt(2.0) * u, 1.0)
        if strength > jj.CHECKED_STRENGTH or slope > jj.CHECKED_SLOPE:
            continue
        ref = float(jj.jmse(ab, h, u, SIGNAL, jj.WhiteNoise(noise), **MEDIAL_REFERENCE))
        source = "medial" if float(ab.w040) == 0.0 else "mixed"
        out.append((source, ab, h, u, noise, ref, strength, _cancellation(ab, h, u)))
    return out


#: More of the balanced family than ``balanced_polar.py`` stored: r = -2/3 gives the most
#: cancellation defocus and spherical aberration can reach (7.0).
EXTRA_RATIOS = (-0.6, -2.0 / 3.0)
EXTRA_STRENGTHS = (3.0, 5.0, 10.0, 15.0, 20.0, 25.0)


def extra_designs():
    """The balanced family at ``EXTRA_RATIOS``, 1e-7 waves of astigmatism at field 1, against
    the symmetric design's converged one-ray value (as ``balanced_polar.py``)."""
    import balanced_one_ray
    import jax
    from balanced_one_ray import REFERENCE

    from jmse_jax._radial import radial_band_integral

    reference = jax.jit(lambda ab, u, noise: radial_band_integral(
        ab, 0.0, u, SIGNAL, jj.WhiteNoise(noise), REFERENCE, jnp.float64) / (2 * math.pi))
    out = []
    for _, u, _, _, symmetric in balanced_one_ray.designs(EXTRA_RATIOS, (0.2, 0.4, 0.7, 1.0),
                                                          EXTRA_STRENGTHS):
        ab = jj.Seidel(w020=symmetric.w020, w040=symmetric.w040, w222=1e-7)
        strength = float(jj.aberration_strength(ab, 1.0, u))
        if strength > jj.CHECKED_STRENGTH:
            continue
        for noise in (1e-3, 1e-4):
            out.append(("balanced_extra", ab, 1.0, u, noise, float(reference(symmetric, u, noise)),
                        strength, _cancellation(ab, 1.0, u)))
    return out


@contextlib.contextmanager
def _tiers_by_strength_alone():
    """The default without its balanced tier, for the duration of the block."""
    saved = _merit.PRESETS["default"]["balanced"]
    _merit.PRESETS["default"]["balanced"] = None
    try:
        yield
    finally:
        _merit.PRESETS["default"]["balanced"] = saved


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--grids", nargs="+", default=["default", "B"], choices=tuple(GRIDS))
    parser.add_argument("--min-cancellation", type=float, default=jj.BALANCED_CANCELLATION)
    parser.add_argument("--sets", nargs="+", default=["stored", "medial", "extra"],
                        choices=("stored", "medial", "extra"),
                        help="stored: the stored designs that cancel; medial: astigmatism at "
                             "the medial focus and MIXED (references computed); extra: the "
                             "balanced family at EXTRA_RATIOS (references computed)")
    parser.add_argument("--only-failing", action="store_true",
                        help="only the designs the default's tiers by strength have more "
                             "than 1e-4 off")
    parser.add_argument("--name", default="balanced_tier")
    args = parser.parse_args()
    machine = common.machine_info()
    warnings.simplefilter("ignore")
    start = time.perf_counter()
    designs = stored_designs(args.min_cancellation) if "stored" in args.sets else []
    if "medial" in args.sets:
        designs += medial_designs()
    if "extra" in args.sets:
        designs += extra_designs()
    print(f"{len(designs)} designs, {time.perf_counter() - start:.0f} s", flush=True)
    rows = [dict(source=s, w020=float(ab.w020), w040=float(ab.w040),
                 w131=float(ab.w131), w222=float(ab.w222), w220=float(ab.w220),
                 w311=float(ab.w311), field=f, u=u, noise=n,
                 reference=ref, strength=st, cancellation=c, errors={}, times={})
            for s, ab, f, u, n, ref, st, c in designs]
    objects = [d[1] for d in designs]
    if args.only_failing:  # the default's tiers by strength alone (no balanced tier)
        keep = []
        with _tiers_by_strength_alone():
            for row, ab in zip(rows, objects, strict=True):
                v = float(jj.jmse(ab, row["field"], row["u"], SIGNAL,
                                  jj.WhiteNoise(row["noise"])))
                if abs(v / row["reference"] - 1) > 1e-4:
                    keep.append((row, ab))
        rows, objects = [k[0] for k in keep], [k[1] for k in keep]
        print(f"{len(rows)} designs the default has off", flush=True)
    for name in args.grids:
        grid = GRIDS[name]
        t0 = time.perf_counter()
        with _tiers_by_strength_alone() if name == "tiers" else contextlib.nullcontext():
            for row, ab in zip(rows, objects, strict=True):
                t = time.perf_counter()
                v = float(jj.jmse(ab, row["field"], row["u"], SIGNAL,
                                  jj.WhiteNoise(row["noise"]), **grid))
                row["times"][name] = time.perf_counter() - t
                row["errors"][name] = v / row["reference"] - 1.0
        errs = [abs(r["errors"][name]) for r in rows]
        bad = sum(e > 1e-4 for e in errs)
        times = sorted(r["times"][name] for r in rows)
        print(f"{name}: {bad} of {len(rows)} more than 1e-4 off ({sum(e > 1e-5 for e in errs)}"
              f" more than 1e-5, {sum(e > 1e-6 for e in errs)} 1e-6), worst {max(errs):.1e}, "
              f"median time {times[len(times) // 2]:.2f} s, total "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
        for r in sorted(rows, key=lambda r: -abs(r["errors"][name]))[:6]:
            print(f"   {r['source']} u={r['u']} h={r['field']:.2f} noise={r['noise']:.1e} "
                  f"strength {r['strength']:.1f} canc {r['cancellation']:.2f} w020 "
                  f"{r['w020']:.2f} w040 {r['w040']:.2f} w222 {r['w222']:.2g}: "
                  f"{r['errors'][name]:+.1e}", flush=True)
    lines = ["# Candidate grids for designs whose terms cancel", "",
             common.machine_line(machine, common.load_average()), "",
             f"Stored designs with cancellation >= {args.min_cancellation:g} and strength >= "
             f"{jj.CANCELLING_STRENGTH:g} (within the checked strength and slope): the stored "
             "designs of balanced_polar and of the tier calibrations, and astigmatism at the "
             "medial focus against " + str(MEDIAL_REFERENCE) + ".", "",
             "| grid | options | designs | > 1e-4 | > 1e-5 | > 1e-6 | worst | median s |",
             "|---|---|---|---|---|---|---|---|"]
    for name in args.grids:
        errs = [abs(r["errors"][name]) for r in rows]
        times = sorted(r["times"][name] for r in rows)
        label = GRIDS[name] or ("the default's tiers by strength alone" if name == "tiers"
                                else "jmse default")
        lines.append(f"| {name} | {label} | {len(rows)} | "
                     f"{sum(e > 1e-4 for e in errs)} | {sum(e > 1e-5 for e in errs)} | "
                     f"{sum(e > 1e-6 for e in errs)} | {max(errs):.1e} | "
                     f"{times[len(times) // 2]:.2f} |")
    common.write_report(args.name, dict(machine=machine, grids={k: GRIDS[k] for k in args.grids},
                                        designs=rows), lines)


if __name__ == "__main__":
    main()
