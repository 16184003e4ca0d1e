"""Re-check the default's shortcuts (``TierShortcut``) against stored references.

A shortcut tries cheaper grids before its tier's own: its ``first`` grid is kept when a
coarse check grid (computed in float32) agrees with it to ``rtol`` and its own
interpolation-error estimate is at most ``first_tol``; otherwise its ``trial`` grid (if
any) is kept when the check agrees with it; otherwise the tier's own grid runs. This script
evaluates, on the designs each shortcut serves (tier 0: strength <= 1 and u <= 0.5; tier 1:
the rest of strength <= 5, for u <= ``u_max``; the stored calibration designs of
``calibrate_tiers.py`` with references, and the bank's converged cases), every grid of the
rule, and reports how many designs keep each grid, the worst error each kept grid has, the
worst error the tier returns, how many decisions the float32 check changes, and what the
check alone (without the estimate) would have kept of the first grid. Candidate first grids
(``--first``) are tried in place of the present one, with the same check and ``first_tol``
(``--first-tol``).

Usage (from the repository root; ~3 min on 2 cores)::

    .venv/bin/python benchmarks/recheck_shortcut.py \\
        [--first "nodes=18,8 se_nodes=300,40 overlap_nodes=18,14 overlap_floor=10" ...]
        [--first-tol 1e-5] [--check "nodes=16,8 se_nodes=160,24 overlap_nodes=14,12" ...]

Prints its tables and writes ``results/recheck_shortcut.json`` and ``.md``.

``--probes`` asks instead whether the check grid could be replaced by error estimates taken
from the first grid itself (``probes``; writes ``results/recheck_shortcut_probes.*``), with
the overlap rule's error either measured exactly or bounded per node from the Bernstein
ellipse (``overlap_error_bound.py``; about 8 min more).

``--panel-ends`` asks whether a cheap probe of the overlap rule's error can stand in for the
exact one (``panel_ends``; writes ``results/recheck_shortcut_panel_ends.*``, about 3 min):
``|dH|``, the change of the first grid's OTF when each panel's overlap order grows by the
exact probe's factors, taken at a few coarse nodes only and carried to the merit as their
largest ``|dH|`` times the sum of ``w |dS_e/d|H||`` over all coarse nodes. Each rule is
given at two estimate tolerances, with the present rule and the Fig. 1 point's estimate and
probes for comparison, and the probe's OTF is timed at the Fig. 1 point.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import overlap_error_bound  # noqa: E402
import recheck_tiers  # noqa: E402
from problems import PROBLEMS  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402
from jmse_jax._merit import (  # noqa: E402
    _accepts,
    _compiled_estimated,
    _first_kept,
    _panel_overlap_orders,
    _Static,
    _tier_index,
)
from jmse_jax._otf import _otf_overlap  # noqa: E402
from jmse_jax._quadrature import polar_panels  # noqa: E402


def _parse_grid(text: str) -> dict:
    grid = {}
    for item in text.split():
        key, _, value = item.partition("=")
        numbers = tuple(int(v) for v in value.split(","))
        grid[key] = numbers if len(numbers) > 1 else numbers[0]
    return grid


def _served(tier):
    """``(names, arguments, references)`` of the designs tier ``tier``'s shortcut serves."""
    u_max = jj.DEFAULT_TIERS[tier][3].u_max
    names, args, refs = [], [], []

    def serves(strength, u):
        return int(_tier_index(strength, u, jj.DEFAULT_TIERS)) == tier and u <= u_max

    for d in recheck_tiers._designs():
        if serves(d["strength"], d["u"]):
            names.append(f"{d['source']} K={d['strength']:.2f} u={d['u']} noise={d['noise']:.1e}")
            args.append((jj.Seidel(**d["coefficients"]), d["field"], d["u"],
                         jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(d["noise"])))
            refs.append(d["reference"])
    for p in PROBLEMS:
        a = p.arguments()
        if p.converged and serves(float(jj.aberration_strength(a[0], a[1], a[2])), a[2]):
            names.append(f"bank {p.name}")
            args.append(a)
            refs.append(p.reference)
    return names, args, np.asarray(refs)


def _shortcut_designs():
    """``(shortcut, names, arguments, references, tiers)`` of the designs the default's two
    shortcuts serve (tiers 0 and 1, which share their first and check grids), tier 0's
    first."""
    shortcut = jj.DEFAULT_TIERS[1][3]
    assert jj.DEFAULT_TIERS[0][3].first == shortcut.first and \
        jj.DEFAULT_TIERS[0][3].check == shortcut.check, \
        "the two shortcuts no longer share their first and check grids"
    names, args, refs, tiers = [], [], [], []
    for tier in (0, 1):
        tier_names, tier_args, tier_refs = _served(tier)
        names += tier_names
        args += tier_args
        refs.append(tier_refs)
        tiers += [tier] * len(tier_args)
    return shortcut, names, args, np.concatenate(refs), np.asarray(tiers)


def _values(grid, args, float32=False):
    def cast(tree):
        return jax.tree_util.tree_map(lambda x: jnp.asarray(x, jnp.float32), tree)

    fn = jax.jit(lambda *a: jj.jmse(*(cast(a) if float32 else a), **grid))
    return np.asarray([float(fn(*a)) for a in args])


def _values_and_estimates(grid, args):
    """``(values, error estimates)`` of the grid ``grid`` on ``args`` in one pass
    (``_estimated_merit_value``), float64."""
    options = _Static({**jj.jmse_options(), **grid})
    out = []
    for a in args:
        ab, field, u, signal, noise = a
        operands = (ab, jnp.float64(field), jnp.float64(u), signal, noise)
        value, estimate = _compiled_estimated(options, jnp.dtype(jnp.float64), operands)
        out.append((float(value), float(estimate)))
    return np.asarray(out).reshape(-1, 2).T


def _estimates(grid, args):
    """The first grid's error estimates (``_estimated_merit_value``), float64."""
    return _values_and_estimates(grid, args)[1]


def _worst(errors, mask):
    return float(np.max(errors[mask], initial=0.0))


def _tier_report(tier, first_grid, first_tol, lines, check_grid=None):
    """The rule of tier ``tier``'s shortcut, with ``first_grid`` (and ``check_grid`` in place
    of its check, if given), on the designs it serves."""
    _, _, own_grid, shortcut = jj.DEFAULT_TIERS[tier]
    check_grid = shortcut.check if check_grid is None else check_grid
    names, args, refs = _served(tier)

    def error(values):
        return np.abs(values / refs - 1.0)

    def agrees(value, check):
        return np.asarray(_accepts(value, check, shortcut.rtol))

    def keeps_first(check):
        return np.asarray(_first_kept(first, estimate, check, shortcut.rtol, first_tol))

    check64 = _values(check_grid, args)
    check32 = _values(check_grid, args, float32=True)
    first = _values(first_grid, args)
    estimate = _estimates(first_grid, args)
    own = _values(own_grid, args)
    keep_first = keeps_first(check32)
    changed = int(np.sum(keep_first != keeps_first(check64)))
    returned = np.where(keep_first, first, own)
    keep_trial = np.zeros(len(args), bool)
    if shortcut.trial is not None:
        trial = _values(shortcut.trial, args)
        keep_trial = ~keep_first & agrees(trial, check32)
        changed += int(np.sum(keep_trial != (~keep_first & agrees(trial, check64))))
        returned = np.where(keep_trial, trial, returned)
    check_alone = agrees(first, check32)
    estimate_alone = estimate <= first_tol
    row = dict(tier=tier, designs=len(names), first=first_grid, first_tol=first_tol,
               check=check_grid,
               kept_first=int(keep_first.sum()), kept_trial=int(keep_trial.sum()),
               own=int(len(names) - keep_first.sum() - keep_trial.sum()),
               worst_returned=float(error(returned).max()),
               at=names[int(np.argmax(error(returned)))],
               worst_kept_first=_worst(error(first), keep_first),
               worst_kept_trial=(_worst(error(trial), keep_trial)
                                 if shortcut.trial is not None else None),
               decisions_changed_by_float32=changed,
               check_alone_kept_first=int(check_alone.sum()),
               check_alone_worst_kept_first=_worst(error(first), check_alone),
               estimate_alone_kept_first=int(estimate_alone.sum()),
               estimate_alone_worst_kept_first=_worst(error(first), estimate_alone),
               worst_first_error=float(error(first).max()),
               worst_first_estimate_ratio=float(np.max(error(first) / np.maximum(
                   estimate, 1e-300))))
    trial_text = ("–" if row["worst_kept_trial"] is None
                  else f"{row['kept_trial']} ({row['worst_kept_trial']:.1e})")
    check_text = "" if check_grid == shortcut.check else f"; check {check_grid}"
    lines.append(f"| {tier} | {first_grid}{check_text} | {len(names)} | {row['kept_first']} "
                 f"({row['worst_kept_first']:.1e}) | {trial_text} | {row['own']} | "
                 f"{row['worst_returned']:.2e} | {changed} | {row['check_alone_kept_first']} "
                 f"({row['check_alone_worst_kept_first']:.1e}) | "
                 f"{row['estimate_alone_kept_first']} "
                 f"({row['estimate_alone_worst_kept_first']:.1e}) |")
    print(lines[-1], flush=True)
    return row


#: The probes' grids: the first grid with a higher overlap order, and with a finer fine rule.
PROBE_OVERLAP = (24, 20)
PROBE_FINE = (420, 56)


def _panels(grid, n_radial):
    """``(start, stop, order, probe order)`` of each radial panel of ``grid``: its slice of
    the radial nodes, its overlap order (``_panel_overlap_orders``) and that order grown by
    the exact probe's factors ``PROBE_OVERLAP / overlap_nodes`` per axis."""
    scale = [p / n for p, n in zip(PROBE_OVERLAP, grid["overlap_nodes"], strict=True)]
    panels, start = [], 0
    for count, _, order in _panel_overlap_orders(grid, n_radial):
        probe = tuple(math.ceil(o * f) for o, f in zip(order, scale, strict=True))
        panels.append((start, start + count, order, probe))
        start += count
    return panels


def _weighted_sensitivity(weights, h, signal, noise, x, y):
    """``w |dS_e / d|H||`` at nodes ``(x, y)`` with coarse weights ``w`` and OTF ``h``."""
    s_x = np.asarray(signal(x, y))
    s_n = np.broadcast_to(np.asarray(noise(x, y)), s_x.shape)
    a = np.abs(h)
    return weights * 2.0 * a * s_x**2 * s_n / (s_x * a**2 + s_n) ** 2


def _overlap_bound(grid, arguments, value, sampling=None):
    """Relative bound of the first grid's overlap-rule error in the merit: the Bernstein-
    ellipse bound of ``|dH|`` at each coarse node (``overlap_error_bound.node_bounds``, at
    the node's panel order; ``sampling``: its keyword arguments) times ``|dS_e / d|H||``
    there, summed with the coarse rule's weights, over the merit ``value``."""
    aberrations, field, u, signal, noise = arguments
    coarse = polar_panels(u, *grid["nodes"], jnp.float64)
    nu_x, nu_y = np.asarray(coarse.nu_x), np.asarray(coarse.nu_y)
    weights = np.asarray(coarse.weights)
    total = 0.0
    for start, stop, order, _ in _panels(grid, nu_x.shape[-1]):
        x, y = nu_x[..., start:stop].ravel(), nu_y[..., start:stop].ravel()
        along, across = overlap_error_bound.node_bounds(aberrations, float(field), x, y,
                                                        *order, **(sampling or {}))
        h = np.asarray(_otf_overlap(aberrations, x, y, field, order))
        terms = _weighted_sensitivity(weights[..., start:stop].ravel(), h, signal, noise, x, y)
        total += float(np.sum(terms * (along + across)))
    return total / (2.0 * math.pi) / abs(value)


def probes(lines, sampling=None) -> list[dict]:
    """A rule without the check grid, with its probes at full cost.

    The first grid's error has three sources: the interpolation of the OTF from the coarse
    nodes (which the estimate measures), the overlap rule at each node and the fine S_e
    rule. Here the last two are measured exactly, as the relative change of the first
    grid's value when its overlap order is raised to ``PROBE_OVERLAP`` and when its fine
    rule is refined to ``PROBE_FINE``, and the first grid is kept when the estimate and both
    probes are under tolerances. Probes this exact cost more than the check grid; the study
    asks whether the check carries information beyond them, i.e. whether a cheap probe of
    the two errors could stand in for it.
    """
    rows = []
    lines += ["| tier | designs | rule | first kept | worst kept |", "|---|---|---|---|---|"]
    for tier, (_, _, _, shortcut) in enumerate(jj.DEFAULT_TIERS):
        if shortcut is None or shortcut.first is None:
            continue
        names, args, refs = _served(tier)
        first_grid = shortcut.first
        first = _values(first_grid, args)
        error = np.abs(first / refs - 1.0)
        estimate = _estimates(first_grid, args)
        check = _values(shortcut.check, args, float32=True)
        overlap = np.abs(_values({**first_grid, "overlap_nodes": PROBE_OVERLAP}, args)
                         / first - 1.0)
        fine = np.abs(_values({**first_grid, "se_nodes": PROBE_FINE}, args) / first - 1.0)
        bound = np.asarray([_overlap_bound(first_grid, a, v, sampling)
                            for a, v in zip(args, first, strict=True)])
        present = np.asarray(_first_kept(first, estimate, check, shortcut.rtol,
                                         shortcut.first_tol))
        rules = [("present: estimate <= 1e-5 and the check agrees to 1e-5", present)]
        for tol_e in (1e-5, 5e-6, 3e-6):
            for tol_p in (1e-5, 1e-6):
                rules.append((f"estimate <= {tol_e:.0e}, both probes <= {tol_p:.0e}",
                              (estimate <= tol_e) & (overlap <= tol_p) & (fine <= tol_p)))
            rules.append((f"estimate <= {tol_e:.0e}, overlap probe <= 1e-6 (no fine probe)",
                          (estimate <= tol_e) & (overlap <= 1e-6)))
            for tol_b in (3e-4, 1e-4, 3e-5, 1e-5):
                rules.append((f"estimate <= {tol_e:.0e}, fine probe <= 1e-6, overlap bound "
                              f"<= {tol_b:.0e}",
                              (estimate <= tol_e) & (fine <= 1e-6) & (bound <= tol_b)))
        for text, kept in rules:
            worst = _worst(error, kept)
            lines.append(f"| {tier} | {len(names)} | {text} | {int(kept.sum())} | "
                         f"{worst:.1e} |")
            print(lines[-1], flush=True)
            rows.append(dict(tier=tier, designs=len(names), rule=text,
                             kept=int(kept.sum()), worst_kept=worst))
        resolved = overlap > 1e-12  # below it the probe is rounding
        tight = bound[resolved] / overlap[resolved]
        rows.append(dict(tier=tier, probe_resolved=int(resolved.sum()),
                         bound_over_overlap_probe_min=float(tight.min()),
                         bound_over_overlap_probe_median=float(np.median(tight))))
        lines.append(f"| {tier} | {len(names)} | overlap bound / overlap probe, where the probe "
                     f"exceeds 1e-12 ({int(resolved.sum())} designs): smallest "
                     f"{tight.min():.2g}, median {np.median(tight):.2g} | | |")
        ratio = error / np.maximum(estimate + overlap + fine, 1e-300)
        rows.append(dict(tier=tier, error_over_sum_of_estimates_max=float(ratio.max()),
                         error_over_sum_of_estimates_median=float(np.median(ratio))))
        lines.append(f"| {tier} | {len(names)} | error / (estimate + probes): largest "
                     f"{ratio.max():.2f}, median {np.median(ratio):.2f} | | |")
    return rows


def _overlap_changes(grid, arguments):
    """Per coarse node of ``grid``: ``w |dS_e/d|H||`` and ``|dH|``, the change of the OTF
    from each panel's order to its probe order (``_panels``; ``(2, n_angular, n_radial)``
    each), and the index of each panel's last node."""
    aberrations, field, u, signal, noise = arguments
    coarse = polar_panels(u, *grid["nodes"], jnp.float64)
    nu_x, nu_y = np.asarray(coarse.nu_x), np.asarray(coarse.nu_y)
    weights = np.asarray(coarse.weights)
    terms, changes, ends = [], [], []
    for start, stop, order, probe in _panels(grid, nu_x.shape[-1]):
        x, y = nu_x[..., start:stop], nu_y[..., start:stop]
        h = np.asarray(_otf_overlap(aberrations, x, y, field, order))
        changes.append(np.abs(np.asarray(_otf_overlap(aberrations, x, y, field, probe)) - h))
        terms.append(_weighted_sensitivity(weights[..., start:stop], h, signal, noise, x, y))
        ends.append(stop - 1)
    return np.concatenate(terms, axis=-1), np.concatenate(changes, axis=-1), ends


#: Interpolation-error estimate tolerances of ``panel_ends``' rules (the present rule's is
#: 1e-5; the exact probes study found 5e-6 needed without the check).
ESTIMATE_TOLS = (5e-6, 1e-5)
#: The cheap probes of ``panel_ends``: which coarse nodes' ``|dH|`` they take.
SUBSETS = {
    "every node, sum of w |dS_e/d|H|| |dH|": None,
    "each panel's last node per row, largest |dH| x sum w |dS_e/d|H||": "panel ends",
    "the last node per row, largest |dH| x sum w |dS_e/d|H||": "last",
}


def _probe_time(grid):
    """Warm time of the panel-end probe's OTF (the nodes of ``SUBSETS['panel ends']`` at the
    probe orders) at the Fig. 1 point, against the first grid's whole coarse OTF."""
    aberrations = jj.Seidel(**common.FIG1)
    coarse = polar_panels(common.FIG1_U, *grid["nodes"], jnp.float64)
    panels = _panels(grid, coarse.nu_x.shape[-1])
    field = common.FIG1_FIELD

    def probe(a, x, y):
        return [_otf_overlap(a, x[..., stop - 1], y[..., stop - 1], field, probe_order)
                for _, stop, _, probe_order in panels]

    def first(a, x, y):
        return _merit._polar_otf(a, x, y, field, {**jj.jmse_options(), **grid})

    args = (aberrations, coarse.nu_x, coarse.nu_y)
    return {name: common.time_compiled(fn, args, max_repeats=31)["warm_s"]
            for name, fn in (("probe", probe), ("first", first))}


def panel_ends(lines) -> list[dict]:
    """The first grid kept by its estimate, the fine probe and a cheap overlap probe."""
    rows = []
    lines += ["| tier | designs | overlap measure | measure / exact probe (min, median) | "
              "estimate at most | kept at tolerance 1e-6 / 1e-5 / 1e-4 / none (worst kept) |",
              "|---|---|---|---|---|---|"]
    for tier, (_, _, _, shortcut) in enumerate(jj.DEFAULT_TIERS):
        if shortcut is None or shortcut.first is None:
            continue
        names, args, refs = _served(tier)
        first_grid = shortcut.first
        options = {**jj.jmse_options(), **first_grid}
        first = _values(first_grid, args)
        error = np.abs(first / refs - 1.0)
        estimate = _estimates(first_grid, args)
        overlap = np.abs(_values({**first_grid, "overlap_nodes": PROBE_OVERLAP}, args)
                         / first - 1.0)
        fine = np.abs(_values({**first_grid, "se_nodes": PROBE_FINE}, args) / first - 1.0)
        measures = {"exact probe": overlap, **{k: [] for k in SUBSETS}}
        for a, v in zip(args, first, strict=True):
            terms, changes, ends = _overlap_changes(options, a)
            total = np.sum(terms) / (2.0 * math.pi) / abs(v)
            for text, subset in SUBSETS.items():
                if subset is None:
                    measures[text].append(np.sum(terms * changes) / (2.0 * math.pi) / abs(v))
                else:
                    nodes = ends if subset == "panel ends" else ends[-1:]
                    measures[text].append(np.max(changes[..., nodes]) * total)
        resolved = overlap > 1e-12
        for text, measure in measures.items():
            measure = np.asarray(measure)
            ratio = measure[resolved] / overlap[resolved]
            for tol_e in ESTIMATE_TOLS:
                cells = []
                for tol in (1e-6, 1e-5, 1e-4, math.inf):
                    kept = (estimate <= tol_e) & (fine <= 1e-6) & (measure <= tol)
                    cells.append(f"{int(kept.sum())} ({_worst(error, kept):.1e})")
                    rows.append(dict(tier=tier, designs=len(names), measure=text,
                                     estimate_tol=tol_e, tol=tol, kept=int(kept.sum()),
                                     worst_kept=_worst(error, kept)))
                lines.append(f"| {tier} | {len(names)} | {text} | {ratio.min():.3g}, "
                             f"{np.median(ratio):.3g} | {tol_e:.0e} | {' / '.join(cells)} |")
                print(lines[-1], flush=True)
        present = _first_kept(first, estimate, _values(shortcut.check, args, float32=True),
                              shortcut.rtol, shortcut.first_tol)
        lines.append(f"| {tier} | {len(names)} | present rule (check grid, estimate <= "
                     f"{shortcut.first_tol:.0e}) | | | {int(np.sum(present))} "
                     f"({_worst(error, np.asarray(present)):.1e}) |")
        print(lines[-1], flush=True)
    fig1 = (jj.Seidel(**common.FIG1), common.FIG1_FIELD, common.FIG1_U, common.fig1_signal(),
            common.fig1_noise())
    grid = jj.DEFAULT_TIERS[1][3].first
    value = _values(grid, [fig1])[0]
    terms, changes, ends = _overlap_changes({**jj.jmse_options(), **grid}, fig1)
    fig1_row = dict(
        estimate=float(_estimates(grid, [fig1])[0]),
        fine=float(abs(_values({**grid, "se_nodes": PROBE_FINE}, [fig1])[0] / value - 1.0)),
        overlap=float(abs(_values({**grid, "overlap_nodes": PROBE_OVERLAP}, [fig1])[0] / value
                          - 1.0)),
        panel_ends=float(np.max(changes[..., ends]) * np.sum(terms) / (2.0 * math.pi)
                         / abs(value)))
    rows.append(dict(fig1=fig1_row))
    lines += ["", "The paper's Fig. 1 point (tier 1): estimate {estimate:.1e}, fine probe "
              "{fine:.1e}, exact overlap probe {overlap:.1e}, panel-end probe "
              "{panel_ends:.1e}.".format(**fig1_row)]
    print(lines[-1], flush=True)
    times = _probe_time(jj.DEFAULT_TIERS[0][3].first)
    rows.append(dict(times=times))
    lines += ["", f"At the Fig. 1 point (one process; run under `taskset -c 1` for one core) "
              f"the panel-end probe's OTF takes {times['probe'] * 1e6:.0f} us, the first "
              f"grid's whole coarse OTF {times['first'] * 1e6:.0f} us."]
    print(lines[-1], flush=True)
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--first", nargs="*", default=[],
                        help="candidate first grids, each 'key=a,b key=a,b ...'")
    parser.add_argument("--first-tol", type=float, default=None,
                        help="error-estimate tolerance of the candidates (default: present)")
    parser.add_argument("--check", nargs="*", default=[],
                        help="candidate check grids (with the present first grid)")
    parser.add_argument("--probes", action="store_true",
                        help="the first grid kept by its estimate and two exact probes of "
                             "its overlap and fine-rule errors, without the check grid")
    parser.add_argument("--cheap-bound", action="store_true",
                        help="with --probes: the bound's sparse sampling "
                             "(overlap_error_bound.CHEAP; writes ..._probes_cheap)")
    parser.add_argument("--panel-ends", action="store_true",
                        help="the first grid kept by its estimate, the fine probe and cheap "
                             "probes of its overlap error at a few coarse nodes")
    args_ = parser.parse_args()
    report = dict(machine=common.machine_info(), rows=[])
    if args_.panel_ends:
        lines = ["# A cheap probe of the first grid's overlap error", "",
                 "`python benchmarks/recheck_shortcut.py --panel-ends`", "",
                 f"Commit {report['machine'].get('commit')}. Designs as for `--probes`. The "
                 "first grid is kept when its interpolation-error estimate is <= 5e-6 or "
                 "1e-5, the fine probe (its value's change with fine rule "
                 f"{PROBE_FINE}) <= 1e-6 and the overlap measure <= the tolerance. "
                 "Measures: the exact probe (its value's "
                 f"change with overlap order {PROBE_OVERLAP}), and the first-order change "
                 "`sum w |dS_e/d|H|| |dH|` over the coarse nodes, or its bound from a few "
                 "nodes, with `|dH|` the OTF's change when each panel's overlap order grows "
                 "by the same factors.", ""]
        report["rows"] = panel_ends(lines)
        common.write_report("recheck_shortcut_panel_ends", report, lines)
        return
    if args_.probes:
        lines = ["# The shortcuts' check grid against exact probes of the first grid's "
                 "errors", "", "`python benchmarks/recheck_shortcut.py --probes"
                 + (" --cheap-bound" if args_.cheap_bound else "") + "`", "",
                 f"Commit {report['machine'].get('commit')}. Designs: the stored calibration "
                 "designs and converged bank cases each shortcut serves (one first grid, "
                 f"{jj.DEFAULT_TIERS[0][3].first}). Probes: the relative change of the first "
                 f"grid's value with overlap order {PROBE_OVERLAP} and with fine rule "
                 f"{PROBE_FINE}.", ""]
        report["rows"] = probes(lines, overlap_error_bound.CHEAP if args_.cheap_bound
                                else None)
        common.write_report("recheck_shortcut_probes" + ("_cheap" if args_.cheap_bound
                                                         else ""), report, lines)
        return
    command = " ".join(["python benchmarks/recheck_shortcut.py",
                        *(f'"{a}"' if " " in a else a for a in sys.argv[1:])])
    lines = ["# The default's shortcuts re-checked", "", f"`{command}`", "",
             f"Commit {report['machine'].get('commit')}. Designs: the stored calibration "
             "designs and converged bank cases each shortcut serves. Each cell: designs that "
             "keep the grid (the worst error among them); `check alone` and `estimate "
             "alone`: what the check without the error estimate, and the estimate without "
             "the check, would keep of the first grid.", "",
             "| tier | first grid | designs | first kept | trial kept | own grid | worst "
             "returned | decisions float32 changed | check alone | estimate alone |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for tier, (_, _, _, shortcut) in enumerate(jj.DEFAULT_TIERS):
        if shortcut is None or shortcut.first is None:
            continue
        candidates = [shortcut.first] + [_parse_grid(t) for t in args_.first]
        tol = shortcut.first_tol if args_.first_tol is None else args_.first_tol
        for i, grid in enumerate(candidates):
            report["rows"].append(_tier_report(tier, grid, shortcut.first_tol if i == 0
                                               else tol, lines))
        for text in args_.check:
            report["rows"].append(_tier_report(tier, shortcut.first, shortcut.first_tol,
                                               lines, check_grid=_parse_grid(text)))
    common.write_report("recheck_shortcut", report, lines)


if __name__ == "__main__":
    main()
