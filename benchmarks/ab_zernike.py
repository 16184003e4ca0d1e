"""Time two (or more) versions of the package side by side on Zernike designs, in one process.

``ab_compare.py`` for Zernike designs (the test bank holds Seidel designs only): each
version's ``jmse_jax`` is loaded under its own module name, the default's (or ``--preset``'s)
jitted value and ``value_and_grad`` (with respect to the coefficients) are compiled once per
version with ``field``, ``u`` and the noise as traced arguments, so that one program serves
every design of the same Noll indices whichever plan it takes, and the calls then alternate
between the versions in rounds, keeping each call's fastest time. Designs are JSON objects
with ``coefficients``, ``field``, ``u`` and ``noise`` (``MarkovSignal(1, 5)``), sharing
``--noll``::

    git worktree add /tmp/old <commit>
    taskset -c 1 python benchmarks/ab_zernike.py /tmp/old . --noll 4 22 \\
        --design '{"coefficients": [...], "field": 0.5, "u": 0.3, "noise": 1e-4}' ...

Prints, per design, its route (in the last version) and each version's times and values.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(Path(__file__).resolve().parent))
from ab_compare import _load  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._merit import _route  # noqa: E402


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkouts", nargs="+", help="directories that hold a jmse_jax package")
    parser.add_argument("--noll", type=int, nargs=2, default=(4, 22), metavar=("FIRST", "LAST"))
    parser.add_argument("--design", type=json.loads, action="append", required=True)
    parser.add_argument("--preset", default="default")
    parser.add_argument("--modes", default="value,vag", help="value and/or vag")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--calls", type=int, default=3)
    args = parser.parse_args(argv)
    noll = tuple(range(args.noll[0], args.noll[1] + 1))
    modules = _load(args.checkouts)
    modes = args.modes.split(",")
    calls = {}
    for i, module in enumerate(modules):
        def merit(c, field, u, noise, module=module):
            return module.jmse(module.Zernike(c, noll=noll), field, u,
                               module.MarkovSignal(1.0, 5.0), module.WhiteNoise(noise),
                               preset=args.preset)

        fns = {"value": jax.jit(merit), "vag": jax.jit(jax.value_and_grad(merit))}
        for d, design in enumerate(args.design):
            operands = (jnp.asarray(design["coefficients"], float),
                        *(jnp.asarray(design[k], float) for k in ("field", "u", "noise")))
            for mode in modes:
                start = time.perf_counter()
                out = jax.block_until_ready(fns[mode](*operands))
                if d == 0:
                    print(f"version {i} {mode}: first call (compile) "
                          f"{time.perf_counter() - start:.1f} s", flush=True)
                value = float(out if mode == "value" else out[0])
                calls[i, d, mode] = (fns[mode], operands, value)
    best = dict.fromkeys(calls, float("inf"))
    for _ in range(args.rounds):
        for key, (fn, operands, _) in calls.items():
            for _ in range(args.calls):
                start = time.perf_counter()
                jax.block_until_ready(fn(*operands))
                best[key] = min(best[key], time.perf_counter() - start)
    print(f"Zernike Noll {noll[0]}-{noll[-1]}, preset {args.preset!r}: fastest of "
          f"{args.rounds} x {args.calls} calls per version")
    for d, design in enumerate(args.design):
        route = _route(jj.Zernike(design["coefficients"], noll=noll), design["field"],
                       design["u"], jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(design["noise"]),
                       preset=args.preset)
        print(f"design {d} (u = {design['u']}, tier {route['tier']}, balanced "
              f"{route['balanced']}, path {route['path']})")
        for mode in modes:
            cells = [f"{c}: {best[i, d, mode] * 1e3:.1f} ms ({calls[i, d, mode][2]:.15e})"
                     for i, c in enumerate(args.checkouts)]
            print(f"  {mode:5s} " + " | ".join(cells))


if __name__ == "__main__":
    main()
