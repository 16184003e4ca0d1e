"""How the shortcut's first grid shares its radial OTF nodes between the three panels.

The polar rule splits each ray into radial panels ``t`` in (0, 0.15), (0.15, 0.4) and
(0.4, 1) (``_quadrature._RADIAL_EDGES``) and gives them 30 %, 30 % and 40 % of the radial
nodes (``_RADIAL_SHARES``): the first grid's 24 radial nodes are 7, 7 and 10. The inner
panels are narrow, and their nodes are cheaper (the overlap order grows with the panel's
outer radius, ``_merit._panel_overlap_orders``), so this study asks whether another split,
or fewer nodes in all, keeps the shortcut's decisions and accuracy for less time.

Each candidate replaces the radial counts of the first grid's coarse OTF rule only (the
fine rule, the check grid and the tiers' own grids keep theirs), and is judged as
``recheck_shortcut.py`` judges a first grid: on the designs the default's two shortcuts
serve (the stored calibration designs with references and the bank's converged cases), the
first grid is kept where the float32 check grid agrees with it to ``rtol`` and its own
interpolation-error estimate is at most ``first_tol``; otherwise the tier's own grid runs.
Reported per candidate: designs kept, the worst error among them, the worst error returned,
and the first grid's time at the Fig. 1 point (its coarse OTF alone, and its value with the
estimate, as the shortcut runs it), each against the present split in alternated rounds.

Usage (from the repository root; about 5 min; pinned to one core for steadier times)::

    taskset -c 1 .venv/bin/python benchmarks/radial_shares.py

Writes ``results/radial_shares.json`` and ``.md``.
"""

from __future__ import annotations

import contextlib
import statistics
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
import recheck_shortcut  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit, _otf, _quadrature  # noqa: E402
from jmse_jax._merit import _compiled_estimated, _first_kept, _Static  # noqa: E402

#: Radial counts per panel (inner, middle, outer) of the first grid's coarse rule; the
#: first is the present split of 24 nodes.
CANDIDATES = (
    (7, 7, 10),
    (5, 7, 12), (6, 6, 12), (5, 6, 13), (4, 8, 12),
    (6, 6, 10), (5, 7, 10), (5, 6, 11), (4, 7, 11),
    (6, 6, 8), (5, 5, 10), (4, 6, 10), (5, 6, 9),
    (5, 5, 8), (4, 5, 9),
)
#: Alternated timing rounds and calls per round.
ROUNDS, CALLS = 30, 5


def _clear_host_caches():
    for module in (_quadrature, _otf, _merit):
        for value in vars(module).values():
            if hasattr(value, "cache_clear"):  # functools.cache
                value.cache_clear()
    jax.clear_caches()


@contextlib.contextmanager
def _patched(module, name, value):
    """Within the block, ``module.name`` is ``value``. Host and jit caches are cleared on
    entry and exit: both key on the grid's counts, not on the patched code."""
    present = getattr(module, name)
    _clear_host_caches()
    setattr(module, name, value)
    try:
        yield
    finally:
        setattr(module, name, present)
        _clear_host_caches()


@contextlib.contextmanager
def _radial_counts(counts):
    """Within the block, a polar rule of ``sum(counts)`` radial nodes has ``counts`` per
    panel; every other rule keeps ``_quadrature._radial_counts``."""
    present = _quadrature._radial_counts
    n = sum(counts)

    def patched(total):
        return tuple(counts) if total == n else present(total)

    if tuple(counts) == present(n):
        yield
        return
    with _patched(_quadrature, "_radial_counts", patched):
        yield


def _fig1_operands():
    """The Fig. 1 point as the shortcut's grids take it: ``(aberrations without tilt, field,
    u, signal, noise)``, float64."""
    return (jj.Seidel(**common.FIG1).without_tilt(), jnp.float64(common.FIG1_FIELD),
            jnp.float64(common.FIG1_U), common.fig1_signal(), common.fig1_noise())


def _fig1_programs(grid):
    """AOT-compiled ``(coarse OTF, value with estimate)`` of ``grid`` at the Fig. 1 point."""
    operands = _fig1_operands()
    aberrations, field = operands[:2]
    options = {**jj.jmse_options(), **grid}
    coarse = _quadrature.polar_panels(common.FIG1_U, *grid["nodes"], jnp.float64)
    otf_args = (aberrations, coarse.nu_x, coarse.nu_y, field)
    otf = jax.jit(lambda a, x, y, f: _merit._polar_otf(a, x, y, f, options))
    static = _Static(options)
    whole = jax.jit(lambda ops: _compiled_estimated(static, jnp.dtype(jnp.float64), ops))
    return ((otf.lower(*otf_args).compile(), otf_args),
            (whole.lower(operands).compile(), (operands,)))


def _alternated(programs):
    """Median and fastest time per call of each ``(compiled, args)``, in alternated rounds."""
    times = [[] for _ in programs]
    for compiled, args in programs:
        jax.block_until_ready(compiled(*args))
    for _ in range(ROUNDS):
        for k, (compiled, args) in enumerate(programs):
            for _ in range(CALLS):
                start = time.perf_counter()
                jax.block_until_ready(compiled(*args))
                times[k].append(time.perf_counter() - start)
    return [(statistics.median(t), min(t)) for t in times]


def main():
    machine = common.machine_info()
    shortcut, names, args, refs, tiers = recheck_shortcut._shortcut_designs()
    first = shortcut.first
    n_angular = first["nodes"][1]
    own = np.concatenate([recheck_shortcut._values(
        jj.DEFAULT_TIERS[tier][2], [a for a, t in zip(args, tiers, strict=True) if t == tier])
        for tier in (0, 1)])
    check32 = recheck_shortcut._values(shortcut.check, args, float32=True)
    own_error = np.abs(own / refs - 1.0)
    print(f"{len(args)} designs; tiers' own grids worst {own_error.max():.1e}", flush=True)

    rows, programs = [], []
    for counts in CANDIDATES:
        grid = {**first, "nodes": (sum(counts), n_angular)}
        t0 = time.perf_counter()
        with _radial_counts(counts):
            values, estimates = recheck_shortcut._values_and_estimates(grid, args)
            programs.append(_fig1_programs(grid))
        error = np.abs(values / refs - 1.0)
        kept = np.asarray(_first_kept(values, estimates, check32, shortcut.rtol,
                                      shortcut.first_tol))
        returned = np.where(kept, error, own_error)
        rows.append(dict(counts=counts, n_radial=sum(counts), coarse_nodes=2 * sum(counts) *
                         n_angular, kept=int(kept.sum()),
                         worst_kept=float(np.max(error[kept], initial=0.0)),
                         worst_returned=float(returned.max()),
                         at=names[int(np.argmax(returned))],
                         worst_first=float(error.max()),
                         median_first=float(np.median(error)),
                         estimate_below_tol=int(np.sum(estimates <= shortcut.first_tol)),
                         seconds=time.perf_counter() - t0))
        print(rows[-1], flush=True)

    flat = [p for pair in programs for p in pair]
    timed = _alternated(flat)
    for k, row in enumerate(rows):
        (otf_med, otf_min), (whole_med, whole_min) = timed[2 * k], timed[2 * k + 1]
        row.update(otf_median_s=otf_med, otf_min_s=otf_min, first_median_s=whole_med,
                   first_min_s=whole_min)

    base = rows[0]
    lines = [
        "# Radial node shares of the shortcut's first grid",
        "",
        common.machine_line(machine, common.load_average()),
        "",
        f"Designs: {len(args)} served by the default's shortcuts (tiers 0 and 1; stored "
        f"calibration designs with references and the bank's converged cases). The first "
        f"grid is {first}; each row changes its coarse radial counts per panel (t in "
        f"(0, 0.15), (0.15, 0.4), (0.4, 1)) and keeps everything else. Kept: the float32 "
        f"check agrees to {shortcut.rtol:.0e} and the estimate is at most "
        f"{shortcut.first_tol:.0e}; otherwise the tier's own grid's value is returned. "
        f"Times at the Fig. 1 point, one process, {ROUNDS} alternated rounds of {CALLS} "
        f"calls (median / fastest); 'first grid' is its value with the estimate, as the "
        f"shortcut runs it.",
        "",
        "| radial counts | coarse nodes | kept | worst kept | worst returned | worst first "
        "grid | median first grid | coarse OTF (µs) | first grid (µs) | first grid / "
        "present |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['counts']} | {row['coarse_nodes']} | {row['kept']} | "
            f"{row['worst_kept']:.1e} | {row['worst_returned']:.1e} | "
            f"{row['worst_first']:.1e} | {row['median_first']:.1e} | "
            f"{row['otf_median_s'] * 1e6:.0f} / {row['otf_min_s'] * 1e6:.0f} | "
            f"{row['first_median_s'] * 1e6:.0f} / {row['first_min_s'] * 1e6:.0f} | "
            f"{row['first_median_s'] / base['first_median_s']:.3f} |")
    report = dict(machine=machine, designs=len(args), first_grid=first,
                  check_grid=shortcut.check, rtol=shortcut.rtol,
                  first_tol=shortcut.first_tol, rounds=ROUNDS, calls=CALLS, rows=rows)
    common.write_report("radial_shares", report, lines)


if __name__ == "__main__":
    main()
