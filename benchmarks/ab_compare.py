"""Time two (or more) versions of the package side by side, in one process.

On a shared host, timings of the same code move by 10-30 % between processes and minutes;
an A/B comparison made of separate runs mixes that drift into the difference. This script
loads each version's ``jmse_jax`` under its own module name into one process, compiles the
same calls for each, and then alternates between them in rounds, keeping each call's
fastest time. Each version is a checkout, e.g. a ``git worktree`` of the older commit::

    git worktree add /tmp/old <commit>
    taskset -c 1 python benchmarks/ab_compare.py /tmp/old . --problem fig1 \\
        --presets fast,default --modes value,vag

``taskset -c 1`` (one core) gives steadier figures than two cores shared with the host.
Problems are the test bank's (``tests/problems.py``), or a design of one's own with
``--design`` (Seidel coefficients, field, u and noise over the bank problem's)::

    taskset -c 1 python benchmarks/ab_compare.py /tmp/old . --presets default \
        --design '{"w020": -6, "field": 0, "u": 0.5, "noise": 1e-2}'

With ``--traced`` the field, ``u`` and the spectra are arguments of the jitted calls, as in
an optimiser's loop and in ``accuracy_speed.py``, rather than constants closed over (which
XLA folds); only the coefficients are differentiated either way. ``jmse``'s run-time checks
are on in each version that has them unless ``JMSE_JAX_RUN_TIME_CHECKS=0`` is set.

Values are printed to 16 digits next to the times, so a change that should only round can be
checked at the same time.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import os
import pathlib
import shutil
import sys
import tempfile
import time

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

ROOT = pathlib.Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from problems import PROBLEMS_BY_NAME  # noqa: E402


def _parse_args(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkouts", nargs="+", help="directories that hold a jmse_jax package")
    parser.add_argument("--problem", default="fig1", help="bank problem (tests/problems.py)")
    parser.add_argument("--presets", default="fast,default", help="comma separated")
    parser.add_argument("--modes", default="value,vag", help="value, vag and/or jvp")
    parser.add_argument("--rounds", type=int, default=7, help="alternation rounds")
    parser.add_argument("--calls", type=int, default=5, help="calls per version per round")
    parser.add_argument("--options", default="{}",
                        help='jmse keyword overrides as JSON, e.g. \'{"nodes": [24, 12]}\'')
    parser.add_argument("--dtype", default="float64", choices=("float64", "float32"),
                        help="dtype of the problem's numbers, hence of the computation")
    parser.add_argument("--traced", action="store_true",
                        help="pass field, u and the spectra as arguments of the jitted calls "
                             "instead of closing over them")
    parser.add_argument("--design", default=None,
                        help="JSON: Seidel coefficients (w020, w040, w131, w222, w220, w311, "
                             "w111) and field, u, noise, replacing the problem's")
    return parser.parse_args(argv)


def _problem(name, design):
    """The bank problem ``name``, with the entries of the JSON object ``design`` (Seidel
    coefficients, ``field``, ``u``, ``noise``) in place of its own."""
    problem = PROBLEMS_BY_NAME[name]
    if design is None:
        return problem
    given = json.loads(design)
    scalars = {"field": "field", "u": "u", "noise": "noise_variance"}
    seidel = {f.name for f in dataclasses.fields(problem.aberrations())}
    unknown = set(given) - set(scalars) - seidel
    if unknown:
        raise SystemExit(f"--design: unknown entries {sorted(unknown)}")
    coefficients = {k: v for k, v in given.items() if k not in scalars}
    return dataclasses.replace(
        problem, name=f"{name} with {design}", coefficients=coefficients or problem.coefficients,
        **{scalars[k]: float(v) for k, v in given.items() if k in scalars})


def _load(checkouts):
    """Each checkout's package as its own module (``jmse_ab0``, ``jmse_ab1``, ...)."""
    tmp = tempfile.mkdtemp(prefix="jmse_ab_")
    sys.path.insert(0, tmp)
    modules = []
    for i, checkout in enumerate(checkouts):
        source = pathlib.Path(checkout) / "jmse_jax"
        if not (source / "__init__.py").is_file():
            raise SystemExit(f"{checkout!r} holds no jmse_jax package")
        shutil.copytree(source, os.path.join(tmp, f"jmse_ab{i}"))
        modules.append(importlib.import_module(f"jmse_ab{i}"))
    return modules


def _cast(x, dtype):
    return jnp.asarray(x, dtype) if isinstance(x, (float, int, np.ndarray, jax.Array)) else x


def _rebuild(obj, module, dtype="float64"):
    """``obj`` (an aberration or spectrum of the installed package) as ``module``'s class,
    its numbers in ``dtype``."""
    if not hasattr(obj, "__dataclass_fields__"):
        return _cast(obj, dtype)
    cls = getattr(module, type(obj).__name__)
    return cls(**{name: _cast(getattr(obj, name), dtype) for name in obj.__dataclass_fields__})


def main(argv=None):
    args = _parse_args(argv)
    problem = _problem(args.problem, args.design)
    modules = _load(args.checkouts)
    presets, modes = args.presets.split(","), args.modes.split(",")
    options = {k: tuple(v) if isinstance(v, list) else v
               for k, v in json.loads(args.options).items()}
    calls = {}
    for i, module in enumerate(modules):
        operands = [_rebuild(x, module, args.dtype) for x in problem.arguments()]
        # The arguments of each jitted call: the coefficients, and with --traced the rest.
        call_args = (operands[0], tuple(operands[1:])) if args.traced else (operands[0],)
        for preset in presets:
            for mode in modes:
                def merit(w, rest=tuple(operands[1:]), preset=preset, module=module):
                    return module.jmse(w, *rest, preset=preset, **options)

                if mode == "value":
                    fn = jax.jit(merit)
                elif mode == "vag":
                    fn = jax.jit(jax.value_and_grad(merit))
                elif mode == "jvp":  # forward mode, all coefficients' tangents 1
                    fn = jax.jit(lambda w, *rest, merit=merit: jax.jvp(
                        lambda w: merit(w, *rest), (w,),
                        (jax.tree_util.tree_map(jnp.ones_like, w),)))
                else:
                    raise SystemExit(f"unknown mode {mode!r}: value, vag or jvp")
                out = jax.block_until_ready(fn(*call_args))
                value = float(out if mode == "value" else out[0])
                calls[i, preset, mode] = (fn, call_args, value)
    best = dict.fromkeys(calls, float("inf"))
    for _ in range(args.rounds):
        for key, (fn, call_args, _) in calls.items():
            for _ in range(args.calls):
                start = time.perf_counter()
                jax.block_until_ready(fn(*call_args))
                best[key] = min(best[key], time.perf_counter() - start)
    print(f"{problem.name} ({args.dtype}{', all traced' if args.traced else ''}): fastest of "
          f"{args.rounds} x {args.calls} calls per version")
    for preset in presets:
        for mode in modes:
            cells = []
            for i, checkout in enumerate(args.checkouts):
                key = (i, preset, mode)
                cells.append(f"{checkout}: {best[key] * 1e3:.2f} ms ({calls[key][2]:.15e})")
            row = " | ".join(cells)
            print(f"  {preset:8s} {mode:5s} {row}")


if __name__ == "__main__":
    main()
