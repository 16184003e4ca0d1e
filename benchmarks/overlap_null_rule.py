"""Could an embedded error estimate of the overlap rule replace the shortcut's check? (A
study; nothing in the package uses it.)

The shortcut's float32 check grid (0.24 ms of the default's 0.9 ms value at the Fig. 1
point, one core) is there because the first grid's interpolation-error estimate does not
see the errors of its overlap rule. A null rule sees them from the samples the rule already
has: with Gauss-Legendre nodes ``x_i`` and weights ``w_i`` (``n`` of them), the weights
``w_i P_{n-k}(x_i)`` integrate every polynomial of degree below ``n - k`` to zero and
measure the integrand's Legendre coefficient of degree ``n - k`` (a few multiply-adds per
node, no trigonometry). This script perturbs the first grid's overlap rule to
``w_i (1 + P_{n-k}(x_i))``, across the chords (``phi``) or along them (``t``), for
``k = 1, 2``, and takes the relative change of the merit as the estimate (as
``_interpolation_estimate`` does for the interpolants). On the designs the default's
shortcuts serve (``recheck_shortcut.py``) it reports how many designs a rule "interpolation
estimate <= first_tol and null-rule estimate <= tau" keeps, and the worst error among them,
for a range of ``tau``, next to the present rule (check and interpolation estimate).
It also reports what the interpolation estimate alone keeps below each aberration
strength, i.e. whether the check could be skipped for weak designs.

Usage (from the repository root; ~30 s on 2 cores)::

    .venv/bin/python benchmarks/overlap_null_rule.py

Writes ``results/overlap_null_rule.json`` and ``.md``.
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import recheck_shortcut as rs  # noqa: E402
from numpy.polynomial import legendre  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _otf  # noqa: E402
from jmse_jax._merit import _first_kept, _merit_value, aberration_strength  # noqa: E402

#: Perturbations: (axis, k) for the null rule of degree n - k on that axis.
PERTURBATIONS = (("phi", 1), ("phi", 2), ("t", 1), ("t", 2))
TAUS = (1e-7, 1e-6, 1e-5, 1e-4, 1e-3)
STRENGTHS = (1.5, 2.0, 3.0, 4.0, 5.0)

_RULE = _otf._overlap_rule.__wrapped__  # the cached host rule, uncached
_PERTURB: dict = {"by": None}


def _legendre(k, x):
    return legendre.legval(x, np.eye(k + 1)[k])


def _perturbed_rule(n_phi, n_t, chord_points):
    """``_otf._overlap_rule`` with the perturbation ``_PERTURB["by"]`` (or none)."""
    frac, w_frac, t_colloc, interp, moment = _RULE(n_phi, n_t, chord_points)
    by = _PERTURB["by"]
    if by is not None:
        axis, k = by
        if axis == "phi":
            w_frac = w_frac * (1.0 + _legendre(n_phi - k, 2.0 * frac - 1.0))
        else:
            t, w_t = legendre.leggauss(n_t)
            moment = interp * (w_t * (1.0 + _legendre(n_t - k, t)))[:, None]
    return frac, w_frac, t_colloc, interp, moment


def _values(grid, args, by):
    """The merit on ``grid`` (float64) with the overlap rule perturbed ``by``."""
    options = {**jj.jmse_options(), **grid}
    _PERTURB["by"] = by
    try:
        fn = jax.jit(lambda ab, *rest: _merit_value(options, jnp.dtype(jnp.float64),
                                                    ab.without_tilt(), *rest))
        return np.asarray([float(fn(*a)) for a in args])
    finally:
        _PERTURB["by"] = None


def _tier(tier, lines):
    shortcut = jj.DEFAULT_TIERS[tier][3]
    first_grid = shortcut.first
    names, args, refs = rs._served(tier)
    first = _values(first_grid, args, None)
    error = np.abs(first / refs - 1.0)
    estimate = rs._estimates(first_grid, args)
    check = rs._values(shortcut.check, args, float32=True)
    present = np.asarray(_first_kept(first, estimate, check, shortcut.rtol,
                                     shortcut.first_tol))
    small = estimate <= shortcut.first_tol
    null = {by: np.abs(_values(first_grid, args, by) / first - 1.0) for by in PERTURBATIONS}
    both = np.maximum.reduce([null[("phi", 1)], null[("t", 1)]])
    strength = np.asarray([float(aberration_strength(a[0], a[1], a[2])) for a in args])

    def cell(mask):
        return f"{int(mask.sum())} ({float(np.max(error[mask], initial=0.0)):.1e})"

    row = dict(tier=tier, designs=len(names), present=cell(present),
               null_median={f"{a} n-{k}": float(np.median(v)) for (a, k), v in null.items()},
               null_rule={f"{t:.0e}": cell(small & (both <= t)) for t in TAUS},
               estimate_alone_by_strength={f"{k}": cell(small & (strength <= k))
                                           for k in STRENGTHS},
               present_by_strength={f"{k}": cell(present & (strength <= k))
                                    for k in STRENGTHS})
    lines.append(f"| {tier} | {len(names)} | {row['present']} | "
                 + " | ".join(row["null_rule"].values()) + " |")
    return row


def main() -> None:
    _otf._overlap_rule = _perturbed_rule
    report = dict(machine=common.machine_info(), rows=[])
    lines = ["# An embedded (null-rule) estimate of the overlap rule's error", "",
             "`python benchmarks/overlap_null_rule.py`", "",
             f"Commit {report['machine'].get('commit')}. Designs: those the default's "
             "shortcuts serve (`recheck_shortcut.py`). Each cell: designs kept (worst error "
             "among them). `present`: the check and the interpolation estimate; `tau`: the "
             "interpolation estimate and the larger null-rule estimate of degree n - 1 "
             "(across and along the chords) at most tau, without the check.", "",
             "| tier | designs | present | " + " | ".join(f"tau {t:.0e}" for t in TAUS) + " |",
             "|---|---|---|" + "---|" * len(TAUS)]
    for tier in (0, 1):
        report["rows"].append(_tier(tier, lines))
    lines += ["", "Median null-rule estimates (relative change of the merit):", "",
              "| tier | " + " | ".join(f"{a} n-{k}" for a, k in PERTURBATIONS) + " |",
              "|---|" + "---|" * len(PERTURBATIONS)]
    for row in report["rows"]:
        lines.append(f"| {row['tier']} | "
                     + " | ".join(f"{v:.1e}" for v in row["null_median"].values()) + " |")
    lines += ["", "The interpolation estimate alone (no check) on designs of strength <= K, "
              "against the present rule on the same designs:", "",
              "| tier | " + " | ".join(f"K <= {k}" for k in STRENGTHS) + " |",
              "|---|" + "---|" * len(STRENGTHS)]
    for row in report["rows"]:
        lines.append(f"| {row['tier']} | " + " | ".join(
            f"{a} vs {b}" for a, b in zip(row["estimate_alone_by_strength"].values(),
                                          row["present_by_strength"].values(), strict=True))
            + " |")
    common.write_report("overlap_null_rule", report, lines)


if __name__ == "__main__":
    import argparse

    argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                            epilog="No options: runs the study and writes its results "
                            "(results/<name>.json and .md).").parse_args()
    main()
