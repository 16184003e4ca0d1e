"""How far the weak tiers' first grid can be off when the shortcut keeps it, near its
acceptance threshold (``TierShortcut.first_tol``).

The default's two weak tiers keep their shortcut's first grid when the float32 check grid
agrees with it to ``rtol`` = 1e-5 and the first grid's own interpolation-error estimate is
at most ``first_tol``. The estimate is an estimate, not a bound: session 79's continuity
audit found a design (``Seidel(w020=-0.4, w131=0.5, w222=1.5611)``, field 1, u = 0.6) whose
estimate sits at 1e-5 and whose first grid is 1.15e-5 off, so the merit jumps by 1.15e-5
where the estimate crosses the threshold. This script samples random designs of the weak
tiers (Seidel coefficients uniform in [-a, a], ``a`` 0.5-2 waves, field 0-1, u 0.1-0.7,
white noise log-uniform 1e-5 to 1e-2, Markov correlation 2-10), keeps those whose first
grid the rule keeps with an estimate above ``--above`` and measures their error against a
converged polar grid, to give the ratio of the error to the estimate. Then it searches for
the worst kept first grid (``--climb`` steps of a random hill climb on the kept grid's
error from each of the audit's design and the sample's three worst, moving coefficients by
0.1 waves, field by 0.1, u by 0.03 up to 1/sqrt(2), correlation length and noise by factors
of e^0.3 and e^0.5, keeping the peak SNR below the 2e6 the presets were checked at).

Usage (from the repository root; about 10 min on 2 cores)::

    .venv/bin/python benchmarks/shortcut_margin.py [--designs 1000] [--above 2e-6] \
        [--climb 40]

Writes ``results/shortcut_margin.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._merit import (  # noqa: E402
    _compiled_check,
    _compiled_estimated,
    _first_kept,
    _prepare,
    _Static,
    _strength,
    _tier_index,
    _tier_plans,
)

REFERENCE = common.CONVERGED_POLAR
#: The continuity audit's design, at the threshold (session 79).
TERMS = ("w020", "w040", "w131", "w222", "w220")
AUDIT = dict(w020=-0.4, w131=0.5, w222=1.56114355602806 * (1 - 1e-9))


def _first_grid_state(args):
    """``(tier, kept, first value, estimate, |first - check| / |first|)`` of the weak tiers'
    shortcut at this design (tier None when no weak tier or no shortcut serves it)."""
    static, inputs = _prepare(args, jj.jmse_options())
    options, tiers = static.value[0], static.value[1]
    strength = _strength(*inputs[:3])
    tier = int(_tier_index(strength, inputs[2], tiers))
    if tier > 1 or float(inputs[2]) > tiers[tier][3].u_max:
        return None
    _, check_grid, rtol, _, first_grid, first_tol = _tier_plans(options, tiers)[tier][1]
    dtype = jnp.dtype(jnp.float64)
    check = float(_compiled_check(_Static(check_grid), dtype, inputs))
    first, estimate = _compiled_estimated(_Static(first_grid), dtype, inputs)
    first, estimate = float(first), float(estimate)
    kept = bool(_first_kept(first, estimate, check, rtol, first_tol))  # the library's rule
    return tier, kept, first, estimate, abs(first - check) / abs(first)


def _measure(name, design, state):
    """A row for a kept first grid: its error against ``REFERENCE`` and its estimate."""
    ab, field, u, signal, noise = design
    tier, _, first, estimate, agree = state
    reference = float(jj.jmse(*design, **REFERENCE))
    error = abs(first / reference - 1.0)
    return dict(design=name, coefficients={k: float(getattr(ab, k)) for k in TERMS},
                field=field, u=u, correlation_length=float(signal.correlation_length),
                noise=float(noise.variance), tier=tier, estimate=estimate, agreement=agree,
                error=error, ratio=error / estimate)


def _design(row):
    return (jj.Seidel(**row["coefficients"]), row["field"], row["u"],
            jj.MarkovSignal(1.0, row["correlation_length"]), jj.WhiteNoise(row["noise"]))


#: The largest peak SNR (max S_x / S_n) the climb visits: the presets were checked to 2e6,
#: and ``jmse`` warns past it.
CLIMB_SNR = 1.9e6


def climb(start, steps, rng, label):
    """Random hill climb on the kept first grid's error from the row ``start``; the rows
    it improved through (the last is the worst found)."""
    best, path = start, []
    for step in range(steps):
        c = {k: v + rng.normal(0.0, 0.1) for k, v in best["coefficients"].items()}
        rho = float(np.clip(best["correlation_length"] * np.exp(rng.normal(0.0, 0.3)), 1, 20))
        peak = 2.0 * np.pi * rho ** 2  # max S_x of MarkovSignal(1, rho)
        row = dict(coefficients=c, field=float(np.clip(best["field"] + rng.normal(0, 0.1), 0, 1)),
                   u=float(np.clip(best["u"] + rng.normal(0.0, 0.03), 0.05, 0.7071)),
                   correlation_length=rho,
                   noise=float(np.clip(best["noise"] * np.exp(rng.normal(0.0, 0.5)),
                                       peak / CLIMB_SNR, 1e-2)))
        design = _design(row)
        state = _first_grid_state(design)
        if state is None or not state[1]:
            continue
        row = _measure(f"{label}+{step}", design, state)
        if row["error"] > best["error"]:
            best = row
            path.append(row)
            print(f"  climb {label} step {step}: error {row['error']:.2e} estimate "
                  f"{row['estimate']:.2e} check agreement {row['agreement']:.1e}", flush=True)
    return path


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=600)
    parser.add_argument("--above", type=float, default=4e-6,
                        help="measure kept designs whose estimate is above this")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--climb", type=int, default=40, help="hill-climb steps per start")
    parser.add_argument("--name", default="shortcut_margin", help="results file name")
    args_ = parser.parse_args(argv)
    rng = np.random.default_rng(args_.seed)
    start = time.perf_counter()
    audit = (jj.Seidel(**AUDIT), 1.0, 0.6, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3))
    state = _first_grid_state(audit)
    audit_row = dict(_measure("audit", audit, state), kept=bool(state[1]))
    print(f"audit: kept {audit_row['kept']} estimate {audit_row['estimate']:.2e} error "
          f"{audit_row['error']:.2e} check agreement {audit_row['agreement']:.1e}", flush=True)
    rows, served, kept_count = [], 0, 0
    for i in range(args_.designs):
        scale = float(rng.choice([0.5, 1.0, 2.0]))
        ab = jj.Seidel(**{k: float(rng.uniform(-scale, scale)) for k in TERMS})
        design = (ab, float(rng.uniform(0, 1)), float(rng.uniform(0.1, 0.7)),
                  jj.MarkovSignal(1.0, float(rng.uniform(2, 10))),
                  jj.WhiteNoise(float(10 ** rng.uniform(-5, -2))))
        state = _first_grid_state(design)
        if state is None:
            continue
        served += 1
        tier, kept, first, estimate, agree = state
        kept_count += kept
        if not kept or estimate <= args_.above:
            continue
        rows.append(_measure(i, design, state))
        print(f"{i}: tier {tier} estimate {estimate:.2e} error {rows[-1]['error']:.2e} "
              f"ratio {rows[-1]['ratio']:.2f} [{time.perf_counter() - start:.0f} s]", flush=True)
    sampled = rows
    climbs = []
    if args_.climb:
        # A refused start counts as error 0: the climb looks for kept designs near it.
        starts = [audit_row if audit_row["kept"] else dict(audit_row, error=0.0)] + sorted(
            sampled, key=lambda r: -r["error"])[:3]
        for row in starts:
            path = climb(row, args_.climb, rng, str(row["design"]))
            climbs.append(dict(start=row, path=path, worst=path[-1] if path else row))
    ratios = np.array([r["ratio"] for r in sampled])
    check = jj.DEFAULT_TIERS[1][3].check
    lines = ["# The weak tiers' first grid near its acceptance threshold", "",
             f"`python benchmarks/shortcut_margin.py --designs {args_.designs} --above "
             f"{args_.above:g} --seed {args_.seed} --climb {args_.climb}`; check grid "
             f"{check}.", "",
             common.machine_line(common.machine_info(), common.load_average()), "",
             f"{served} of {args_.designs} random designs are served by a weak tier's shortcut; "
             f"the rule keeps the first grid for {kept_count}; {len(sampled)} of those have "
             f"an estimate above {args_.above:g} and are measured against the grid "
             f"{REFERENCE}.", ""]
    if len(ratios):
        lines += [f"Error / estimate over them: median {np.median(ratios):.2f}, "
                  f"90th percentile {np.quantile(ratios, 0.9):.2f}, largest {ratios.max():.2f}; "
                  f"worst error {max(r['error'] for r in sampled):.2e}.", ""]
    lines += [f"The audit's design (`Seidel({AUDIT})`, field 1, u = 0.6, MarkovSignal(1, 5), "
              f"WhiteNoise(1e-3)): first grid {'kept' if audit_row['kept'] else 'refused'}, "
              f"{audit_row['error']:.2e} off, estimate {audit_row['estimate']:.2e}, check "
              f"agreement {audit_row['agreement']:.1e}.", ""]
    if climbs:
        lines += [f"Hill climb on the kept first grid's error, {args_.climb} steps from each "
                  f"start (peak SNR at most {CLIMB_SNR:g}):", "",
                  "| start | its error | worst found | its estimate | its check agreement | "
                  "design |", "|---|---|---|---|---|---|"]
        for c in climbs:
            w = c["worst"]
            lines.append(f"| {c['start']['design']} | {c['start']['error']:.2e} | "
                         f"{w['error']:.2e} | {w['estimate']:.2e} | {w['agreement']:.1e} | "
                         f"{ {k: round(v, 4) for k, v in w['coefficients'].items()} }, field "
                         f"{w['field']:.3f}, u {w['u']:.4f}, correlation length "
                         f"{w['correlation_length']:.3f}, noise {w['noise']:.3g} |")
        lines.append("")
    lines += ["| design | tier | estimate | check agreement | error | error / estimate |",
              "|---|---|---|---|---|---|"]
    for r in sorted(rows, key=lambda r: -r["estimate"]):  # the sample's measured designs
        lines.append(f"| {r['design']} | {r['tier']} | {r['estimate']:.2e} | "
                     f"{r['agreement']:.1e} | {r['error']:.2e} | {r['ratio']:.2f} |")
    print("\n".join(lines))
    report = dict(machine=common.machine_info(), reference=REFERENCE, audit=audit_row,
                  served=served, kept=kept_count, rows=rows, climbs=climbs)
    common.write_report(args_.name, report, lines)


if __name__ == "__main__":
    main()
