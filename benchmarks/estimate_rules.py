"""Cheaper forms of the shortcut's interpolation-error estimate.

The shortcut's first grid is kept only where its own interpolation-error estimate is at
most ``first_tol`` (``_merit._interpolation_estimate``): the larger change of the fine S_e
total when the coarse OTF's interpolants lose their top Legendre coefficient, radially or
angularly. As the library computes it, that is two more passes over the first grid's fine
S_e rule, (300, 40), about a tenth of the default's time at the Fig. 1 point. This study
measures two cheaper forms, alone and together:

- ``exact`` on a coarser rule: the two lowered totals and the plain total, all three on the
  estimate's own coarser fine rule (the value keeps its rule);
- ``linear``: lowering an interpolant is a coarse-sized linear map ``Lambda`` on the coarse
  OTF ``h``, so to first order the change is ``Re <G, (Lambda - 1) h>``, with ``G`` the
  fine stage's coarse gradient (``_merit._fine_total`` with ``adjoint``): one adjoint pass
  instead of two plain ones.

Each form is judged as ``recheck_shortcut.py`` judges a first grid, on the designs the
default's two shortcuts serve: kept where the float32 check agrees to ``rtol`` and the
estimate is at most ``first_tol``. Reported: designs kept, those lost and gained against the
present estimate, the worst error kept, the range of the estimate over the present one where
the present one exceeds 1e-7 and the check agrees, and the first grid's time at the Fig. 1
point with the estimate, against its value alone, in alternated rounds.

Usage (from the repository root; about 1-2 min; pinned to one core for steadier times)::

    taskset -c 1 .venv/bin/python benchmarks/estimate_rules.py

Writes ``results/estimate_rules.json`` and ``.md``.
"""

from __future__ import annotations

import functools
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
import radial_shares  # noqa: E402
import recheck_shortcut  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit, _quadrature  # noqa: E402
from jmse_jax._merit import _compiled_estimated, _first_kept, _merit_value, _Static  # noqa: E402
from jmse_jax._numerics import EXACT  # noqa: E402

#: ``(form, the estimate's fine rule)``; ``None``: the value's own rule. The first row is
#: the library's estimate.
CANDIDATES = (
    ("exact", None),
    ("exact", (200, 24)),
    ("exact", (150, 20)),
    ("exact", (100, 16)),
    ("linear", None),
    ("linear", (150, 20)),
    ("linear", (100, 16)),
)
#: Where the present estimate exceeds this, the others' ratios to it are reported.
RATIO_FLOOR = 1e-7


def _estimate(form, rule, h, u, signal, noise, total, options, dtype, ridges):
    """``_merit._interpolation_estimate`` in the form ``form`` on the fine rule ``rule``."""
    nodes = options["nodes"]
    own = options["se_nodes"]
    rule = own if rule is None else rule
    h, u, signal, noise, total = jax.lax.stop_gradient((h, u, signal, noise, total))
    fine = functools.partial(_merit._fine_total, h, u, signal, noise, nodes, rule, dtype)
    if form == "linear":
        _, adjoint = fine(True, (0, 0), ridges)
        radial = jnp.asarray(_quadrature._radial_lowering(nodes[0], 1).T, dtype)
        split = _quadrature.angular_split(u, nodes[1], dtype)
        angular = jnp.asarray(_quadrature._angular_lowering(nodes[1], 1), dtype)[split[0]]
        lowered = (jnp.matmul(h, radial, precision=EXACT),  # h: (triangles, angular, radial)
                   jnp.einsum("fc,tcr->tfr", angular, h, precision=EXACT))
        change = [jnp.abs(jnp.sum(jnp.real(jnp.conj(adjoint) * (low - h)))) for low in lowered]
    else:
        base = total if tuple(rule) == tuple(own) else fine(False, (0, 0), ridges)
        change = [jnp.abs(fine(False, drop, ridges) - base) for drop in _merit._ESTIMATE_DROP]
    return jnp.maximum(*change) / jnp.abs(total)


def _estimate_form(form, rule):
    """A context in which the library's estimate is ``_estimate(form, rule, ...)``."""
    return radial_shares._patched(_merit, "_interpolation_estimate",
                                  functools.partial(_estimate, form, rule))


def _fig1_program(grid, estimated):
    """AOT-compiled first grid at the Fig. 1 point: with its estimate, as the shortcut runs
    it, or (``estimated`` false) its value alone."""
    operands = radial_shares._fig1_operands()
    static, f64 = _Static({**jj.jmse_options(), **grid}), jnp.dtype(jnp.float64)
    if estimated:
        fn = jax.jit(lambda ops: _compiled_estimated(static, f64, ops))
    else:
        fn = jax.jit(lambda ops: _merit_value(static.value, f64, *ops))
    return fn.lower(operands).compile(), (operands,)


def main():
    machine = common.machine_info()
    shortcut, _, args, refs, _ = recheck_shortcut._shortcut_designs()
    first = shortcut.first
    check32 = recheck_shortcut._values(shortcut.check, args, float32=True)
    print(f"{len(args)} designs", flush=True)

    rows, programs, present = [], [_fig1_program(first, False)], None
    for form, rule in CANDIDATES:
        t0 = time.perf_counter()
        with _estimate_form(form, rule):
            values, estimates = recheck_shortcut._values_and_estimates(first, args)
            programs.append(_fig1_program(first, True))
        error = np.abs(values / refs - 1.0)
        kept = np.asarray(_first_kept(values, estimates, check32, shortcut.rtol,
                                      shortcut.first_tol))
        if present is None:
            present = dict(values=values, estimates=estimates, kept=kept)
        assert np.array_equal(values, present["values"]), "the estimate changed the value"
        compared = (np.abs(values / check32 - 1.0) <= shortcut.rtol) & (
            present["estimates"] > RATIO_FLOOR)
        ratio = estimates[compared] / present["estimates"][compared]
        rows.append(dict(form=form, rule=list(rule or first["se_nodes"]), kept=int(kept.sum()),
                         lost=int(np.sum(present["kept"] & ~kept)),
                         gained=int(np.sum(kept & ~present["kept"])),
                         worst_kept=float(np.max(error[kept], initial=0.0)),
                         ratio_min=float(ratio.min()), ratio_max=float(ratio.max()),
                         compared=int(compared.sum()), seconds=time.perf_counter() - t0))
        print(rows[-1], flush=True)

    timed = radial_shares._alternated(programs)
    (plain_med, plain_min), timed = timed[0], timed[1:]
    for row, (med, fastest) in zip(rows, timed, strict=True):
        row.update(first_median_s=med, first_min_s=fastest,
                   estimate_median_s=med - plain_med, estimate_min_s=fastest - plain_min)

    base = rows[0]
    lines = [
        "# Cheaper forms of the shortcut's interpolation-error estimate",
        "",
        common.machine_line(machine, common.load_average()),
        "",
        f"Designs: {len(args)} served by the default's shortcuts (tiers 0 and 1; stored "
        f"calibration designs with references and the bank's converged cases). First grid "
        f"{first}. Kept: the float32 check agrees to {shortcut.rtol:.0e} and the estimate is "
        f"at most {shortcut.first_tol:.0e}. 'exact': the largest change of the fine S_e total "
        f"when the interpolants lose their top Legendre coefficient (radially, angularly), "
        f"on the estimate's fine rule (a plain total on that rule too, if it is not the "
        f"value's); 'linear': the first-order change from the fine stage's coarse gradient "
        f"(one adjoint pass). Ratio: this estimate over the present one on the "
        f"{base['compared']} designs where the check agrees and the present one exceeds "
        f"{RATIO_FLOOR:.0e}. Times at the Fig. 1 point, one process, "
        f"{radial_shares.ROUNDS} alternated rounds of {radial_shares.CALLS} calls (median / "
        f"fastest); the first grid's value alone took {plain_med * 1e6:.0f} / "
        f"{plain_min * 1e6:.0f} µs, and 'estimate' is the difference.",
        "",
        "| form | estimate's fine rule | kept | lost | gained | worst kept | ratio to present "
        "| first grid with estimate (µs) | estimate (µs) | first grid / present |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['form']} | {tuple(row['rule'])} | {row['kept']} | {row['lost']} | "
            f"{row['gained']} | {row['worst_kept']:.1e} | {row['ratio_min']:.2f}-"
            f"{row['ratio_max']:.2f} | {row['first_median_s'] * 1e6:.0f} / "
            f"{row['first_min_s'] * 1e6:.0f} | {row['estimate_median_s'] * 1e6:.0f} / "
            f"{row['estimate_min_s'] * 1e6:.0f} | "
            f"{row['first_median_s'] / base['first_median_s']:.3f} |")
    report = dict(machine=machine, designs=len(args), first_grid=first,
                  check_grid=shortcut.check, rtol=shortcut.rtol,
                  first_tol=shortcut.first_tol, rounds=radial_shares.ROUNDS,
                  calls=radial_shares.CALLS, first_value_median_s=plain_med,
                  first_value_min_s=plain_min, rows=rows)
    common.write_report("estimate_rules", report, lines)


if __name__ == "__main__":
    main()
