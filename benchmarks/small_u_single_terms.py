"""The default at small ``u`` on designs of one strong Seidel term: a known accuracy gap.

``aberration_strength`` is ``max |grad W|`` (the slope, waves per pupil radius) times
``min(sqrt(2) u, 1)``. At small ``u`` a design of moderate strength therefore has a large
slope: 14.5 at ``u = 0.1`` is 44 waves of coma. The tiers were calibrated on random designs
with every coefficient within +-8 waves (slopes up to about 35-42), and
``single_term_tiers.py`` checked single terms at ``u >= 0.3`` only. Session 55 found the
default far off below that, with no warning, inside ``CHECKED_STRENGTH``: the overlap
rule's orders across and along the chords bind (the phase difference across the overlap
lens grows with the slope, not with the strength), and the one-ray plans miss too.

Since then designs steeper than ``STEEP_SLOPE`` (35 waves per pupil radius) take the last
tier, whose overlap rule was raised for them, and ``jmse`` warns past ``CHECKED_SLOPE`` (65).
This script records, for each design, the default's error against a converged polar
reference with its tier and candidate measures of need: strength, slope, and the spread
(max - min, waves) of the phase difference ``W(p + s e) - W(p - s e)`` over the overlap lens
(``E``), along one chord (``E_along``) and across the chords (``E_across``), up to
``s = min(sqrt(2) u, 1)``. A second table takes designs of slope 45-67 (single terms and
random mixtures), the range the last tier now serves below ``CHECKED_SLOPE``.

Usage (from the repository root; about 10 min on 2 cores)::

    .venv/bin/python benchmarks/small_u_single_terms.py

Writes ``results/small_u_single_terms.json`` and ``.md``.
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._merit import _concrete_choice, _prepare, jmse_options  # noqa: E402

#: Every count well past the default's; with (192, 192) overlap nodes instead it moved by
#: at most 1.0e-4 (74 waves of coma at u = 0.1) and otherwise by <= 3e-8 on six of these
#: designs (session 55).
REFERENCE = dict(nodes=(160, 96), se_nodes=(8000, 1920), overlap_nodes=(96, 96),
                 overlap_floor=96)
TERMS = ("w131", "w222", "w040", "w020")
US = (0.1, 0.2, 0.3)
STRENGTHS = (9.0, 14.5, 19.0, 24.5)
FIELD = 1.0
SIGNAL, NOISE = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)


def spreads(aberrations, field, s_max, n_s=12, n_dir=12, n_grid=21):
    """``(E, E_along, E_across)`` in waves: the spread of the phase difference over the
    lens, along its chords (largest over chords) and across them (on the mid-chord line)."""
    g = np.linspace(-1.0, 1.0, n_grid)
    best = np.zeros(3)
    for s in np.arange(1, n_s + 1) / n_s * min(s_max, 0.999):
        for angle in np.arange(n_dir) * math.pi / n_dir:
            ex, ey = math.cos(angle), math.sin(angle)
            along_e, across_e = np.meshgrid(g * (1 - s), g * math.sqrt(1 - s * s),
                                            indexing="ij")  # rows: position along e
            px, py = along_e * ex - across_e * ey, along_e * ey + across_e * ex
            inside = (((px + s * ex) ** 2 + (py + s * ey) ** 2 <= 1)
                      & ((px - s * ex) ** 2 + (py - s * ey) ** 2 <= 1))
            diff = np.asarray(aberrations(jnp.asarray(px + s * ex), jnp.asarray(py + s * ey),
                                          field)
                              - aberrations(jnp.asarray(px - s * ex), jnp.asarray(py - s * ey),
                                            field))
            high = np.where(inside, diff, -np.inf)
            low = np.where(inside, diff, np.inf)
            whole = high.max() - low.min()
            per_chord = high.max(axis=1) - low.min(axis=1)
            along = np.max(per_chord[np.isfinite(per_chord)], initial=0.0)
            mid = diff[:, n_grid // 2][inside[:, n_grid // 2]]
            across = float(mid.max() - mid.min()) if mid.size else 0.0
            best = np.maximum(best, [whole, along, across])
    return tuple(float(b) for b in best)


def _steep_designs() -> list[dict]:
    """Designs of slope 45-67 at u 0.1-0.3 (between ``STEEP_SLOPE`` and ``CHECKED_SLOPE``):
    coma and astigmatism alone at field 1 and three random mixtures of five terms (seed 11)
    at fields 0.3-1, scaled to the slope; strength above 25 left out."""
    rng = np.random.default_rng(11)
    designs = []
    for kind in ("w131", "w222", "mix", "mix", "mix"):
        for u in (0.1, 0.15, 0.2, 0.3):
            for slope in (45.0, 55.0, 67.0):
                if kind == "mix":
                    c = {n: float(rng.uniform(-1, 1))
                         for n in ("w020", "w040", "w131", "w222", "w220")}
                    field = float(rng.uniform(0.3, 1))
                else:
                    c, field = {kind: 1.0}, 1.0
                band = min(math.sqrt(2.0) * u, 1.0)
                unit = float(jj.aberration_strength(jj.Seidel(**c), field, u)) / band
                coefficients = {k: v * slope / unit for k, v in c.items()}
                if slope * band <= 25.0:
                    designs.append(dict(kind=kind, u=u, slope=slope, field=field,
                                        coefficients=coefficients))
    return designs


def main() -> None:
    machine = common.machine_info()
    reference = jax.jit(lambda ab, f, u: jj.jmse(ab, f, u, SIGNAL, NOISE, **REFERENCE))
    default = jax.jit(lambda ab, f, u: jj.jmse(ab, f, u, SIGNAL, NOISE))
    rows = []
    for term in TERMS:
        for u in US:
            unit = float(jj.aberration_strength(jj.Seidel(**{term: 1.0}), FIELD, u))
            for strength in STRENGTHS:
                ab = jj.Seidel(**{term: strength / unit})
                static, _ = _prepare((ab, FIELD, u, SIGNAL, NOISE), jmse_options("default"))
                tier, _, symmetric, *_ = _concrete_choice(static, ab, FIELD, u)
                ref = float(reference(ab, FIELD, u))
                error = float(default(ab, FIELD, u)) / ref - 1.0
                e, e_along, e_across = spreads(ab.without_tilt(), FIELD,
                                               min(math.sqrt(2.0) * u, 1.0))
                rows.append(dict(term=term, u=u, strength=strength,
                                 coefficient=strength / unit,
                                 slope=strength / min(math.sqrt(2.0) * u, 1.0),
                                 tier=int(tier), one_ray=bool(symmetric), reference=ref,
                                 error=error, spread=e, spread_along=e_along,
                                 spread_across=e_across))
                print(f"{term} u={u} strength {strength}: {error:+.1e}", flush=True)
    steep = _steep_designs()
    for d in steep:
        ab = jj.Seidel(**d["coefficients"])
        d["error"] = float(default(ab, d["field"], d["u"])) / float(
            reference(ab, d["field"], d["u"])) - 1.0
        print(f"{d['kind']} u={d['u']} slope {d['slope']}: {d['error']:+.1e}", flush=True)
    worst = max(abs(r["error"]) for r in rows)
    lines = ["# The default at small u on designs of one strong Seidel term", "",
             common.machine_line(machine, common.load_average()), "",
             f"Relative error of `jmse` (default preset, as a user calls it) at field {FIELD} "
             f"against a polar reference ({REFERENCE}); MarkovSignal(1, 5), WhiteNoise(1e-3). "
             "Slope: `max |grad W|` [waves per pupil radius]; E, E along, E across: spread of "
             "the phase difference over the overlap lens, along one chord, across the chords "
             "[waves] (see the script). Tier: the default's, `ray` for the one-ray plans.", "",
             "| term | u | strength | coefficient [waves] | slope | tier | E | E along | "
             "E across | error |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        tier = "ray" if r["one_ray"] else str(r["tier"])
        lines.append(f"| {r['term']} | {r['u']} | {r['strength']} | {r['coefficient']:.1f} | "
                     f"{r['slope']:.0f} | {tier} | {r['spread']:.1f} | "
                     f"{r['spread_along']:.1f} | {r['spread_across']:.1f} | "
                     f"{r['error']:+.1e} |")
    inside = [r for r in rows if r["slope"] <= jj.CHECKED_SLOPE]
    lines += ["", f"Worst: {worst:.1e}; {sum(abs(r['error']) > 1e-4 for r in rows)} of "
              f"{len(rows)} designs are more than 1e-4 off; with a slope up to "
              f"`CHECKED_SLOPE` = {jj.CHECKED_SLOPE:g}: worst "
              f"{max(abs(r['error']) for r in inside):.1e} ({len(inside)} designs).", "",
              "Designs of slope 45-67 (past `STEEP_SLOPE`, around `CHECKED_SLOPE`) at u 0.1-0.3: "
              "coma and astigmatism alone at field 1, three random mixtures of five terms "
              "(seed 11), against the same reference:", "",
              "| kind | u | slope | field | strength | error |", "|---|---|---|---|---|---|"]
    for d in steep:
        lines.append(f"| {d['kind']} | {d['u']} | {d['slope']:.0f} | {d['field']:.2f} | "
                     f"{d['slope'] * min(math.sqrt(2.0) * d['u'], 1.0):.1f} | "
                     f"{d['error']:+.1e} |")
    lines.append(f"\nWorst: {max(abs(d['error']) for d in steep):.1e} ({len(steep)} designs).")
    common.write_report("small_u_single_terms",
                        dict(machine=machine, reference=REFERENCE, field=FIELD, designs=rows,
                             steep=steep),
                        lines)


if __name__ == "__main__":
    main()
