"""Calibrate the grids of the adaptive default (``DEFAULT_TIERS``) on random Seidel designs.

For each seed, ``--designs`` random designs are drawn: every coefficient of w020, w040,
w131, w222, w220 uniform in ``[-a, a]`` with ``a`` one of 1, 2, 4, 8 waves, field uniform in
[0, 1], ``u`` one of 0.1, 0.2, 0.3, 0.5, 0.7, 1.0, white noise log-uniform in [1e-4, 1e-2],
``MarkovSignal(1, 5)``. Designs with ``aberration_strength`` above 25 are skipped (no
tier is meant for them). Each design gets a reference on the grid ``REFERENCE`` and, where
it is hard (strength above 5, ``u`` above 0.5 or noise below 3e-4), a check on the finer
``CHECK`` grid; then the relative error of every candidate grid whose strength range covers
it. The summary table gives the worst error per candidate by ranges of ``u`` and strength,
and a second section checks the middle tier's shortcut (``TierShortcut``) where its rule is a
trial grid among the candidates: on every design the default sends to that tier, how often
the trial grid is kept, and the error of what is returned. (The present rule's first grid
is kept on its own error estimate too, which ``recheck_shortcut.py`` evaluates.)

    python benchmarks/calibrate_tiers.py                 # seeds 7, 11, 12 x 150 designs (~10 min)
    python benchmarks/calibrate_tiers.py --seeds 1 --designs 20   # a quick look
    python benchmarks/calibrate_tiers.py --u 0.75 0.85 0.95 --current --name calibrate_tiers_kink

``--u`` replaces the values ``u`` is drawn from (the last line samples only the range
``1/sqrt(2) < u < 1``, where the angular rule is split at ``arccos u``), ``--current`` limits
the candidates to the default's present tiers and its shortcut's check grid, and ``--name``
names the result files. ``--summarise`` rewrites ``results/<name>.md`` from the JSON of an
earlier run (after a change of the tier rules: the tiers' grids are the same).

Writes ``results/<name>.json`` (every design, reference and error) and ``results/<name>.md``
(the summary); ``<name>`` is ``calibrate_tiers`` unless given.
"""

from __future__ import annotations

import argparse
import json
import time

import _common as common
import jax
import numpy as np

import jmse_jax as jj

REFERENCE = dict(nodes=(96, 48), se_nodes=(4800, 960), overlap_nodes=(64, 64))
CHECK = dict(nodes=(112, 56), se_nodes=(6400, 1280), overlap_nodes=(96, 96))

#: Candidate grids: the tiers before (``old_*``) and after this calibration, others tried,
#: and the default's present tier grids (``tier N``, read from ``DEFAULT_TIERS``; ``a2``,
#: ``m2`` and ``t3`` are tiers 1-3 as calibrated, with equal overlap orders).
CANDIDATES = {
    "old_t0 = tier 0": dict(nodes=(24, 12), se_nodes=(800, 96), overlap_nodes=(20, 20)),
    "old_t1": dict(nodes=(48, 24), se_nodes=(1200, 192), overlap_nodes=(32, 32)),
    "old_t1, se 2400": dict(nodes=(48, 24), se_nodes=(2400, 192), overlap_nodes=(32, 32)),
    "f2": dict(nodes=(48, 24), se_nodes=(2400, 192), overlap_nodes=(28, 28)),
    "j": dict(nodes=(48, 24), se_nodes=(1800, 192), overlap_nodes=(28, 28)),
    "a2": dict(nodes=(40, 20), se_nodes=(2400, 160), overlap_nodes=(28, 28)),
    "c2": dict(nodes=(36, 18), se_nodes=(2400, 160), overlap_nodes=(26, 26)),
    "k": dict(nodes=(32, 16), se_nodes=(2400, 128), overlap_nodes=(26, 26)),
    "l": dict(nodes=(36, 18), se_nodes=(1800, 128), overlap_nodes=(24, 24)),
    "old_t2": dict(nodes=(80, 32), se_nodes=(1600, 384), overlap_nodes=(56, 56)),
    "t2se": dict(nodes=(80, 32), se_nodes=(2400, 384), overlap_nodes=(56, 56)),
    "t3": dict(nodes=(80, 32), se_nodes=(2400, 256), overlap_nodes=(56, 56)),
    "h2": dict(nodes=(64, 28), se_nodes=(2400, 256), overlap_nodes=(48, 48)),
    "m": dict(nodes=(56, 28), se_nodes=(2400, 256), overlap_nodes=(40, 40)),
    "m2": dict(nodes=(56, 28), se_nodes=(2400, 128), overlap_nodes=(40, 40)),
    **{f"tier {i}": dict(grid) for i, (*_, grid, _) in enumerate(jj.DEFAULT_TIERS) if i > 0},
    "shortcut check": dict(jj.DEFAULT_TIERS[1][3].check),
}
_STRONG = ("old_t2", "t2se", "t3", "h2", "m", "m2", "tier 2", "tier 3")
#: The candidates that are the default's present grids (``--current``), and the default
#: itself as a user gets it (its tier chosen by the design, its shortcut applied).
CURRENT = ("old_t0 = tier 0", "tier 1", "tier 2", "tier 3", "shortcut check", "default")
#: Values ``u`` is drawn from (``--u`` replaces them).
U_VALUES = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0)

STRENGTH_BINS = ((0, 1), (1, 3), (3, 5), (5, 7), (7, 10), (10, 15), (15, 25))
U_BINS = ((0.0, 0.5), (0.5, 1.0))
#: Bins for draws inside the split range of the angular rule (``--u`` above 1/sqrt(2)).
KINK_U_BINS = ((0.7071, 0.8), (0.8, 0.9), (0.9, 1.0))


def _applies(name: str, strength: float, u: float) -> bool:
    """Which candidates are evaluated on a design (the tier ranges they could serve)."""
    if name == "default":
        return True
    if name.startswith("old_t0"):  # also the middle tier's shortcut trial
        return strength <= 5
    if name == "shortcut check":
        return strength <= 5
    if name in _STRONG:
        return strength > 4
    return strength <= 8


def calibrate(seed: int, designs: int, jitted: dict, u_values=U_VALUES,
              candidates=CANDIDATES) -> list[dict]:
    rng = np.random.default_rng(seed)

    def merit(options):
        key = repr(options)
        if key not in jitted:
            jitted[key] = jax.jit(lambda ab, f, u, s, n, o=options: jj.jmse(ab, f, u, s, n, **o))
        return jitted[key]

    rows, start = [], time.perf_counter()
    for i in range(designs):
        scale = rng.choice([1.0, 2.0, 4.0, 8.0])
        coefficients = {k: float(rng.uniform(-scale, scale))
                        for k in ("w020", "w040", "w131", "w222", "w220")}
        field = float(rng.uniform(0, 1))
        u = float(rng.choice(list(u_values)))
        noise_variance = float(10 ** rng.uniform(-4, -2))
        ab = jj.Seidel(**coefficients)
        strength = float(jj.aberration_strength(ab, field, u))
        if strength > 25:
            continue
        args = (ab, field, u, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(noise_variance))
        reference = float(merit(REFERENCE)(*args))
        row = dict(seed=seed, coefficients=coefficients, field=field, u=u,
                   noise=noise_variance, strength=strength, reference=reference, errors={},
                   values={})
        if strength > 5 or u > 0.5 or noise_variance < 3e-4:
            check = float(merit(CHECK)(*args))
            row["check_error"] = abs(check - reference) / reference
        for name, options in candidates.items():
            if _applies(name, strength, u):
                value = float(merit(options)(*args))
                row["values"][name] = value
                row["errors"][name] = abs(value - reference) / reference
        rows.append(row)
        print(f"seed {seed} design {i:3d} strength {strength:5.2f} u {u} "
              f"[{time.perf_counter() - start:.0f} s]", flush=True)
    return rows


def summary(rows: list[dict], candidates=CANDIDATES) -> str:
    checks = [r["check_error"] for r in rows if "check_error" in r]
    lines = [
        "# Calibration of the adaptive default's tiers",
        "",
        f"{len(rows)} random Seidel designs (`benchmarks/calibrate_tiers.py`; seeds "
        f"{sorted({r['seed'] for r in rows})}). Reference grid {REFERENCE}; on the "
        f"{len(checks)} hard designs it agrees with {CHECK} to "
        f"{max(checks):.1e} at worst (median {np.median(checks):.1e}).",
        "",
        "Worst relative error of each candidate grid (nodes, se_nodes, overlap_nodes) by "
        "range of `u` and of `aberration_strength` K (n = designs in the range; a blank cell: "
        "the candidate was not evaluated there):",
        "",
    ]
    names = list(candidates)
    u_bins = KINK_U_BINS if min(r["u"] for r in rows) > KINK_U_BINS[0][0] else U_BINS
    lines.append("| u | K | n | " + " | ".join(names) + " |")
    lines.append("|---" * (len(names) + 3) + "|")
    for u_lo, u_hi in u_bins:
        for k_lo, k_hi in STRENGTH_BINS:
            chosen = [r for r in rows if u_lo < r["u"] <= u_hi and k_lo < r["strength"] <= k_hi]
            cells = []
            for name in names:
                errors = [r["errors"][name] for r in chosen if name in r["errors"]]
                cells.append(f"{max(errors):.0e}" if errors else "")
            lines.append(f"| ({u_lo}, {u_hi}] | ({k_lo}, {k_hi}] | {len(chosen)} | "
                         + " | ".join(cells) + " |")
    lines += ["", "Grids:", ""]
    lines += [f"- `{name}`: {options}" for name, options in candidates.items()]
    return "\n".join(lines + shortcut_summary(rows, candidates)) + "\n"


def shortcut_summary(rows: list[dict], candidates=CANDIDATES) -> list[str]:
    """How the middle tier's shortcut fares on the designs the default sends to that tier.

    The shortcut is tried only for ``u <= u_max``; designs above the bound are reported
    separately as if it were tried there (the evidence for the bound)."""
    from jmse_jax._merit import _accepts, _tier_index

    shortcut = jj.DEFAULT_TIERS[1][3]
    trial_name = next((k for k in candidates if candidates[k] == shortcut.trial), None)
    if shortcut.trial is None or trial_name is None:
        # The present rule keeps a ``first`` grid on its own error estimate as well as the
        # check, which this script does not compute: recheck_shortcut.py evaluates it.
        return ["", "## The middle tier's shortcut", "",
                f"The shortcut's rule (first grid {shortcut.first}, trial {shortcut.trial}) "
                "is not among these candidates; `benchmarks/recheck_shortcut.py` evaluates "
                "it on these designs (`results/recheck_shortcut.md`)."]
    # A report stored before the present tier-1 grid names its own tier-1 grid "... tier 1".
    grid_name = next((k for k in candidates if candidates[k] == jj.DEFAULT_TIERS[1][2]),
                     None) or next(k for k in candidates if k.endswith("tier 1"))
    middle = [r for r in rows if int(_tier_index(r["strength"], r["u"], jj.DEFAULT_TIERS)) == 1]
    lines = [
        "",
        "## The middle tier's shortcut",
        "",
        f"Rule: for u <= {shortcut.u_max:.4g}, keep the trial grid `{trial_name}` "
        f"({shortcut.trial}) when it agrees with the check grid ({shortcut.check}) to rtol "
        f"{shortcut.rtol:g}; otherwise (and above that u) use the tier's own grid "
        f"`{grid_name}`. Of the {len(middle)} designs the default sends to the middle tier:",
        "",
    ]
    eligible = [r for r in middle if r["u"] <= shortcut.u_max]
    above = [r for r in middle if r["u"] > shortcut.u_max]
    for group, label in ((eligible, f"u <= {shortcut.u_max:.4g} (the shortcut is tried)"),
                         (above, f"u > {shortcut.u_max:.4g} (not tried; shown as if it were)")):
        if not group:
            lines.append(f"- {label}: no designs.")
            continue
        kept, returned, ratios = [], [], []
        for r in group:
            trial, check = r["values"][trial_name], r["values"]["shortcut check"]
            difference = abs(trial - check) / abs(trial)
            accepted = bool(_accepts(trial, check, shortcut.rtol))
            if shortcut.rtol / 10 < difference:  # near the threshold, where the ratio matters
                ratios.append(r["errors"][trial_name] / difference)
            if accepted:
                kept.append(r["errors"][trial_name])
            returned.append(r["errors"][trial_name] if accepted else r["errors"][grid_name])
        worst_kept = f", worst error of a kept trial {max(kept):.1e}" if kept else ""
        ratio = (f"; largest ratio of the trial's error to its difference from the check, "
                 f"over the {len(ratios)} designs whose difference exceeds rtol / 10: "
                 f"{max(ratios):.2f} (below 1, the difference bounds the error)"
                 if ratios else "")
        lines.append(
            f"- {label}, {len(group)} designs: trial kept on {len(kept)} "
            f"({100 * len(kept) / len(group):.0f} %){worst_kept}; worst error of the value "
            f"the rule would return {max(returned):.1e} (median {np.median(returned):.1e})"
            f"{ratio}.")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[7, 11, 12])
    parser.add_argument("--designs", type=int, default=150, help="designs drawn per seed")
    parser.add_argument("--u", type=float, nargs="+", default=list(U_VALUES),
                        help="values u is drawn from")
    parser.add_argument("--current", action="store_true",
                        help="only the default's present tiers and shortcut check")
    parser.add_argument("--name", default="calibrate_tiers", help="name of the result files")
    parser.add_argument("--summarise", action="store_true",
                        help="rewrite results/<name>.md from results/<name>.json (no new run)")
    args = parser.parse_args(argv)
    if args.summarise:
        report = json.loads((common.RESULTS / f"{args.name}.json").read_text())
        candidates = {name: {key: tuple(value) if isinstance(value, list) else value
                             for key, value in grid.items()}
                      for name, grid in report["candidates"].items()}
        text = summary(report["designs"], candidates)
        (common.RESULTS / f"{args.name}.md").write_text(text)
        print(text)
        return 0
    for u in args.u:
        if not 0 < u <= 1:
            parser.error(f"--u values must lie in (0, 1], got {u}")
    candidates = ({k: CANDIDATES.get(k, {}) for k in CURRENT} if args.current else CANDIDATES)
    jitted: dict = {}
    rows = [row for seed in args.seeds
            for row in calibrate(seed, args.designs, jitted, args.u, candidates)]
    report = dict(description=__doc__.splitlines()[0], machine=common.machine_info(),
                  reference=REFERENCE, check=CHECK, candidates=candidates, u_values=args.u,
                  designs=rows)
    common.write_json(common.RESULTS / f"{args.name}.json", report)
    text = summary(rows, candidates)
    (common.RESULTS / f"{args.name}.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
