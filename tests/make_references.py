"""Compute the converged reference JMSE of every case in ``tests/problems.py``.

Run from the repository root (float64, a few seconds per case)::

    .venv/bin/python tests/make_references.py            # print the block
    .venv/bin/python tests/make_references.py --write    # also rewrite it in problems.py

Each case is evaluated with ``preset="high"`` and with ``problems.STRICT_OPTIONS``; both values
are recorded, the strict one is the reference and ``abs(high - strict) / strict`` is the
convergence estimate. ``--check OPTIONS`` (a Python dict literal) additionally evaluates a
third setting for diagnosis, e.g. ``--check "dict(overlap_nodes=(160, 160))"``.
"""

from __future__ import annotations

import argparse
import ast
import datetime
import pathlib
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))

import problems  # noqa: E402

import jmse_jax as jj  # noqa: E402

BEGIN, END = "# REFERENCES-BEGIN", "# REFERENCES-END"


def _compiled(**options):
    return jax.jit(lambda ab, field, u, signal, noise: jj.jmse(ab, field, u, signal, noise,
                                                                **options))


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--write", action="store_true", help="rewrite the block in problems.py")
    parser.add_argument("--check", default=None, help="a third option dict to evaluate")
    parser.add_argument("--only", nargs="*", default=None, help="case names to compute")
    args = parser.parse_args(argv)

    settings = {"high": _compiled(preset="high"), "strict": _compiled(**problems.STRICT_OPTIONS)}
    if args.check:
        settings["check"] = _compiled(**eval(args.check, {"dict": dict}))  # noqa: S307
    rows = {}
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

    lines = [
        BEGIN,
        f"# Computed by tests/make_references.py on {datetime.date.today().isoformat()} "
        f"(jax {jax.__version__}, float64, CPU).",
        "# name: (preset='high', STRICT_OPTIONS); comment: abs(high - strict) / strict",
        "REFERENCES: dict[str, tuple[float, float]] = {",
    ]
    for name, (high, strict, rel) in rows.items():
        flag = "" if rel <= problems.CONVERGED_RTOL else "  NOT CONVERGED"
        lines.append(f"    {name!r}: ({high!r}, {strict!r}),  # {rel:.1e}{flag}")
    lines += ["}", END]
    block = "\n".join(lines)
    print(block)
    if args.write:
        if args.only:
            raise SystemExit("--write needs the whole bank (drop --only)")
        path = pathlib.Path(problems.__file__)
        text = path.read_text()
        head, rest = text.split(BEGIN, 1)
        _, tail = rest.split(END, 1)
        path.write_text(head + block + tail)
        ast.parse(path.read_text())
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
