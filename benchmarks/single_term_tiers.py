"""The default's tiers on designs of one strong Seidel term, against converged references.

The tiers were calibrated on random designs with every coefficient within +-8 waves
(``calibrate_tiers.py``). An audit (session 54) found designs of one strong term, inside the
checked strength but outside that box, far off: pure coma ``w131 = 15`` at field 1 and
``u = 0.3`` (strength 14.8) 4.6e-3 off, 24.7 waves of coma 6e-2; 22 waves of defocus on the
axis at ``u = 1`` (strength 44, one-ray plan) 1.3e-2. Coma's phase difference varies along
the overlap lens's chords (defocus's does not), so the order along them binds; strong
astigmatism needs more fine radial ``S_e`` nodes and more angular OTF nodes; the one-ray
plan takes its coarse count from the top tier's radial count.

This script measures, for the previous grids of tiers 2 and 3 (session 53) and the present
ones (``DEFAULT_TIERS``):

- designs of one term, ``w131`` and ``w222`` at field 1, ``u`` in 0.3-0.9, strength 9-24.5,
  the default as a user calls it, against a polar reference with every count well past the
  tiers' (nodes (160, 96), se_nodes (8000, 1920), overlap (96, 96)); for ``w222`` its change
  from a reference with 4800 fine radial nodes is given too, as its own uncertainty;
- defocus on the axis at ``u = 1``, strength 24-44 (the one-ray plan), against the same plan
  with three times the radial OTF and ``S_e`` counts;
- the stored calibration designs of tiers 2 and 3 (``calibrate_tiers{,_kink}.json``) on each
  tier's grid alone;
- each tier's grid alone timed on one calibration design (value, median of alternated
  rounds).

Usage (from the repository root; ~10 min on 2 cores)::

    .venv/bin/python benchmarks/single_term_tiers.py

Writes ``results/single_term_tiers.json`` and ``.md``.
"""

from __future__ import annotations

import contextlib
import statistics
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import numpy as np  # noqa: E402
import recheck_tiers  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._merit import _tier_index  # noqa: E402

#: Tiers 2 and 3 as calibrated up to session 53 (the steep tier, tier 4 since session 56,
#: did not exist: its designs took tier 3).
PREVIOUS = {2: dict(nodes=(56, 28), se_nodes=(2400, 128), overlap_nodes=(40, 24)),
            3: dict(nodes=(80, 32), se_nodes=(2400, 256), overlap_nodes=(56, 24))}
PREVIOUS[4] = PREVIOUS[3]
#: The strong tiers: 2, 3 and the steep tier.
STRONG = tuple(range(2, len(jj.DEFAULT_TIERS)))
REFERENCE = dict(nodes=(160, 96), se_nodes=(8000, 1920), overlap_nodes=(96, 96))
REFERENCE_4800 = dict(REFERENCE, se_nodes=(4800, 1920))
TERMS = ("w131", "w222")
US = (0.3, 0.5, 0.7, 0.9)
STRENGTHS = (9.0, 14.5, 19.0, 24.5)
AXIS_STRENGTHS = (24.0, 32.0, 40.0, 44.0)
SIGNAL, NOISE = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)


@contextlib.contextmanager
def _default_tiers(grids: dict):
    """Within the block, the default preset's tiers have ``grids`` (tier index -> grid)."""
    presets = jj.PRESETS["default"]
    present = presets["tiers"]
    tiers = list(present)
    for index, grid in grids.items():
        tiers[index] = (*tiers[index][:2], grid, tiers[index][3])
    presets["tiers"] = tuple(tiers)
    try:
        yield
    finally:
        presets["tiers"] = present


def _scaled(factor: int) -> dict:
    """The strong tiers with ``factor`` times their radial OTF and S_e counts (the one-ray
    plans take their counts along the ray from these)."""
    out = {}
    for index in STRONG:
        grid = jj.DEFAULT_TIERS[index][2]
        out[index] = dict(grid, nodes=(factor * grid["nodes"][0], grid["nodes"][1]),
                          se_nodes=(factor * grid["se_nodes"][0], grid["se_nodes"][1]))
    return out


def _merit(options: dict):
    return jax.jit(lambda ab, field, u: jj.jmse(ab, field, u, SIGNAL, NOISE, **options))


def _single_term_designs() -> list[dict]:
    designs = []
    for term in TERMS:
        for u in US:
            unit = float(jj.aberration_strength(jj.Seidel(**{term: 1.0}), 1.0, u))
            for strength in STRENGTHS:
                designs.append(dict(term=term, u=u, strength=strength,
                                    coefficient=strength / unit, field=1.0))
    return designs


def _axis_designs() -> list[dict]:
    unit = float(jj.aberration_strength(jj.Seidel(w020=1.0), 0.0, 1.0))
    return [dict(term="w020", u=1.0, strength=s, coefficient=s / unit, field=0.0)
            for s in AXIS_STRENGTHS]


def _values(merit, designs) -> list[float]:
    return [float(merit(jj.Seidel(**{d["term"]: d["coefficient"]}), d["field"], d["u"]))
            for d in designs]


def _time_grid(grid: dict, design: dict, rounds: int = 9) -> float:
    merit = jax.jit(lambda ab, f, u, n: jj.jmse(ab, f, u, SIGNAL, jj.WhiteNoise(n), **grid))
    args = (jj.Seidel(**design["coefficients"]), design["field"], design["u"], design["noise"])
    jax.block_until_ready(merit(*args))
    times = []
    for _ in range(rounds):
        start = time.perf_counter()
        jax.block_until_ready(merit(*args))
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    machine = common.machine_info()
    singles, axis = _single_term_designs(), _axis_designs()
    print(f"references for {len(singles)} designs of one term ...", flush=True)
    for d, ref, ref_4800 in zip(singles, _values(_merit(REFERENCE), singles),
                                _values(_merit(REFERENCE_4800), singles), strict=True):
        d.update(reference=ref, reference_4800=ref_4800)
    with _default_tiers(_scaled(3)):
        for d, ref in zip(axis, _values(_merit({}), axis), strict=True):
            d["reference"] = ref
    for label, grids in (("previous", PREVIOUS), ("present", {})):
        with _default_tiers(grids):
            default = _merit({})
            for d, value in zip(singles + axis, _values(default, singles + axis), strict=True):
                d[label] = value / d["reference"] - 1.0
        print(f"{label}: done", flush=True)

    calibration = recheck_tiers._designs()
    tiers = jj.DEFAULT_TIERS
    by_tier = []
    for index in STRONG:
        served = [d for d in calibration
                  if int(_tier_index(d["strength"], d["u"], tiers)) == index]
        row = dict(tier=index, designs=len(served))
        for label, grid in (("previous", PREVIOUS[index]), ("present", tiers[index][2])):
            errors = recheck_tiers._errors(grid, served)
            row[label] = dict(grid=grid, worst=float(errors.max()),
                              p90=float(np.percentile(errors, 90)),
                              median=float(np.median(errors)))
        times = {"previous": [], "present": []}
        for _ in range(3):  # alternated, so that the host's drift slows both alike
            for label, grid in (("previous", PREVIOUS[index]), ("present", tiers[index][2])):
                times[label].append(_time_grid(grid, served[0]))
        for label in times:
            row[label]["value_s"] = statistics.median(times[label])
        by_tier.append(row)
        print(f"tier {index}: done", flush=True)

    lines = ["# The default's tiers on designs of one strong Seidel term", "",
             common.machine_line(machine, common.load_average()), "",
             "Relative error of `jmse` (default preset) against a polar reference "
             f"(nodes {REFERENCE['nodes']}, se_nodes {REFERENCE['se_nodes']}, overlap "
             f"{REFERENCE['overlap_nodes']}); the reference's own change from 4800 fine "
             "radial nodes in the last column. Previous: tiers 2 and 3 of session 53 "
             f"({PREVIOUS[2]}, {PREVIOUS[3]}; the latter stands in for the steep tier 4 "
             "too, which did not exist); present: `DEFAULT_TIERS`.", "",
             "| term | u | strength | coefficient [waves] | previous | present | "
             "reference 4800 vs 8000 |", "|---|---|---|---|---|---|---|"]
    for d in singles:
        lines.append(f"| {d['term']} | {d['u']} | {d['strength']} | {d['coefficient']:.2f} | "
                     f"{d['previous']:+.1e} | {d['present']:+.1e} | "
                     f"{d['reference_4800'] / d['reference'] - 1:+.1e} |")
    for label in ("previous", "present"):
        worst = max(abs(d[label]) for d in singles)
        lines.append(f"\nWorst {label}: {worst:.1e}.")
    lines += ["", "Defocus on the axis (one-ray plan), u = 1, against the plan with three times "
              "the radial counts:", "", "| w020 [waves] | strength | previous | present |",
              "|---|---|---|---|"]
    for d in axis:
        lines.append(f"| {d['coefficient']:.1f} | {d['strength']} | {d['previous']:+.1e} | "
                     f"{d['present']:+.1e} |")
    lines += ["", "Stored calibration designs on each tier's grid alone (relative error), and "
              "the grid's value time on the tier's first design (median of 3 alternated "
              "rounds of 9 calls):", "",
              "| tier | designs | grid | worst | p90 | median | value |",
              "|---|---|---|---|---|---|---|"]
    for row in by_tier:
        for label in ("previous", "present"):
            r = row[label]
            lines.append(f"| {row['tier']} {label} | {row['designs']} | {r['grid']} | "
                         f"{r['worst']:.1e} | {r['p90']:.1e} | {r['median']:.1e} | "
                         f"{common.fmt_seconds(r['value_s'])} |")
    report = dict(machine=machine, reference=REFERENCE, previous=PREVIOUS,
                  present={i: jj.DEFAULT_TIERS[i][2] for i in STRONG},
                  single_term=singles, axis=axis, calibration=by_tier)
    common.write_report("single_term_tiers", report, lines)


if __name__ == "__main__":
    main()
