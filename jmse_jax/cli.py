"""The ``jmse-jax`` console script.

Float64 is switched on here (the library itself never does so at import).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

FIG1 = dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
FIG1_FIELD = 0.95
FIG1_U = 0.2


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error and exit status 2."""

    def error(self, message):
        self.exit(2, f"jmse-jax: error: {message}\n")


def _timed(fn, *args, repeats=5):
    import jax

    result = jax.block_until_ready(fn(*args))  # compile + first run
    start = time.perf_counter()
    for _ in range(repeats):
        result = jax.block_until_ready(fn(*args))
    return result, (time.perf_counter() - start) / repeats


def _fig1_comparison(out_dir: str | None) -> dict:
    import jax

    import jmse_jax as jj

    ab = jj.Seidel(**FIG1)
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)

    def merit(a):
        return jj.jmse(a, FIG1_FIELD, FIG1_U, signal, noise)

    def baseline(a):
        return jj.baseline_jmse(a, FIG1_FIELD, FIG1_U, signal, noise, B=64)

    rows = {}
    for name, fn in (("baseline B=64", baseline), ("jmse default", merit)):
        (value, _), t_vg = _timed(jax.jit(jax.value_and_grad(fn)), ab)
        _, t_v = _timed(jax.jit(fn), ab)
        rows[name] = dict(jmse=float(value), time_value_s=t_v, time_value_and_grad_s=t_vg)
    reference = 2.6539432e-3  # SPEC §5, converged float64 value
    print("Fig. 1 operating point of Berkner & Shroff (field 0.95, u = 0.2,"
          " MarkovSignal(1, 5), WhiteNoise(1e-3)); float64")
    print(f"{'method':<16}{'JMSE':>14}{'rel. err':>11}{'value':>11}{'value+grad':>13}")
    for name, row in rows.items():
        row["relative_error"] = row["jmse"] / reference - 1.0
        print(f"{name:<16}{row['jmse']:>14.7e}{row['relative_error']:>+11.2e}"
              f"{row['time_value_s'] * 1e3:>9.2f}ms{row['time_value_and_grad_s'] * 1e3:>11.2f}ms")
    base, ours = rows["baseline B=64"]["jmse"], rows["jmse default"]["jmse"]
    print(f"baseline vs default: {base / ours - 1.0:+.2%}")
    result = dict(reference=reference, methods=rows, device=str(jax.devices()[0]))
    if out_dir:
        os.makedirs(out_dir, exist_ok=True)
        with open(os.path.join(out_dir, "fig1_comparison.json"), "w") as f:
            json.dump(result, f, indent=2)
        print(f"wrote {os.path.join(out_dir, 'fig1_comparison.json')}")
    return result


def _cmd_reproduce(args) -> int:
    _fig1_comparison(args.out)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="jmse-jax",
        description="JMSE (Wiener-restoration MSE) merit for computational-imaging design. "
        "Frequencies are in units of the optical cutoff 1/(lambda N); wavefront coefficients "
        "in waves; u = sensor Nyquist / optical cutoff.",
    )
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    rep = sub.add_parser("reproduce", help="reproduce the paper's results into an output folder")
    rep.add_argument("--out", default="jmse_output", help="output folder (default: jmse_output)")
    rep.set_defaults(func=_cmd_reproduce)
    return parser


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    return args.func(args)


if __name__ == "__main__":
    sys.exit(main())
