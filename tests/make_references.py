"""Compute the converged reference JMSE of every case in ``tests/problems.py``.

Run from the repository root (float64, a few seconds per case)::

    .venv/bin/python tests/make_references.py            # print the blocks
    .venv/bin/python tests/make_references.py --write    # also rewrite them in problems.py

Each case is evaluated on the polar grid of ``preset="high"`` and with
``problems.STRICT_OPTIONS``; both values are recorded, the strict one is the reference and
``abs(high - strict) / strict`` is the convergence estimate. Rotationally symmetric cases (a
wavefront that depends on ``rho`` only, isotropic spectra) are also integrated along one ray
(``jmse_jax._radial``) with ``problems.RAY_STRICT_OPTIONS`` and ``RAY_FINE_OPTIONS``: the
``RAY_REFERENCES`` block, whose fine value is those cases' reference. ``--check OPTIONS``
(a Python dict literal) additionally evaluates a third setting for diagnosis, e.g.
``--check "dict(overlap_nodes=(160, 160))"``.
"""

from __future__ import annotations

import argparse
import ast
import datetime
import math
import pathlib
import sys
import time

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import problems  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._radial import radial_band_integral  # noqa: E402

BEGIN, END = "# REFERENCES-BEGIN", "# REFERENCES-END"
RAY_BEGIN, RAY_END = "# RAY-REFERENCES-BEGIN", "# RAY-REFERENCES-END"


def _compiled(**options):
    return jax.jit(lambda ab, field, u, signal, noise: jj.jmse(ab, field, u, signal, noise,
                                                                **options))


def _ray(options):
    """The one-ray band integral at ``options``' counts, as a JMSE (``_radial``)."""
    def value(ab, field, u, signal, noise):
        total = radial_band_integral(ab, field, u, signal, noise, options, jnp.float64)
        return total / (2.0 * math.pi)

    return jax.jit(value)


def _block(begin, end, name, legend, rows) -> str:
    """The text of one reference block: ``rows`` maps a case to ``(a, b, rel)``."""
    lines = [
        begin,
        f"# Computed by tests/make_references.py on {datetime.date.today().isoformat()} "
        f"(jax {jax.__version__}, float64, CPU).",
        f"# name: {legend}",
        f"{name}: dict[str, tuple[float, float]] = {{",
    ]
    for case, (first, second, rel) in rows.items():
        flag = "" if rel <= problems.CONVERGED_RTOL else "  NOT CONVERGED"
        lines.append(f"    {case!r}: ({first!r}, {second!r}),  # {rel:.1e}{flag}")
    lines += ["}", end]
    return "\n".join(lines)


def _replace_block(text, begin, end, block):
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    return head + block + tail


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="rewrite the block in problems.py")
    parser.add_argument("--check", default=None, help="a third option dict to evaluate")
    parser.add_argument("--only", nargs="*", default=None, help="case names to compute")
    args = parser.parse_args(argv)

    # The high preset's grid as an override: the polar grid even for symmetric designs.
    high_grid = {k: jj.PRESETS["high"][k] for k in ("nodes", "se_nodes", "overlap_nodes")}
    settings = {"high": _compiled(**high_grid), "strict": _compiled(**problems.STRICT_OPTIONS)}
    rays = {"strict": _ray(problems.RAY_STRICT_OPTIONS), "fine": _ray(problems.RAY_FINE_OPTIONS)}
    if args.check:
        settings["check"] = _compiled(**eval(args.check, {"dict": dict}))  # noqa: S307
    rows, ray_rows = {}, {}
    for problem in problems.PROBLEMS:
        if args.only and problem.name not in args.only:
            continue
        values = {}
        start = time.perf_counter()
        for key, fn in settings.items():
            values[key] = float(fn(*problem.arguments()))
        rel = abs(values["high"] - values["strict"]) / values["strict"]
        extra = ""
        if "check" in values:
            extra = f"  check {values['check']:.16e} rel(strict) " + \
                f"{abs(values['check'] - values['strict']) / values['check']:.1e}"
        print(f"{problem.name:36s} high {values['high']:.16e} strict {values['strict']:.16e} "
              f"rel {rel:.1e} ({time.perf_counter() - start:.1f} s){extra}", flush=True)
        rows[problem.name] = (values["high"], values["strict"], rel)
        if problems.runs_one_ray(problem.arguments()):
            ray = {key: float(fn(*problem.arguments())) for key, fn in rays.items()}
            ray_rel = abs(ray["strict"] - ray["fine"]) / ray["fine"]
            ray_rows[problem.name] = (ray["strict"], ray["fine"], ray_rel)
            print(f"{'':36s} ray strict {ray['strict']:.16e} fine {ray['fine']:.16e} "
                  f"rel {ray_rel:.1e}; polar strict off by "
                  f"{abs(values['strict'] - ray['fine']) / ray['fine']:.1e}", flush=True)

    block = _block(BEGIN, END, "REFERENCES",
                   "(the high preset's polar grid, STRICT_OPTIONS); "
                   "comment: abs(high - strict) / strict", rows)
    print(block)
    ray_block = _block(RAY_BEGIN, RAY_END, "RAY_REFERENCES",
                       "(RAY_STRICT_OPTIONS, RAY_FINE_OPTIONS); comment: abs(strict - fine) / fine",
                       ray_rows)
    print(ray_block)
    if args.write:
        if args.only:
            raise SystemExit("--write needs the whole bank (drop --only)")
        path = pathlib.Path(problems.__file__)
        text = _replace_block(path.read_text(), BEGIN, END, block)
        path.write_text(_replace_block(text, RAY_BEGIN, RAY_END, ray_block))
        ast.parse(path.read_text())
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
