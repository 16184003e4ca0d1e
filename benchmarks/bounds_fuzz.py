"""Random extreme designs: finite values and gradients, and the JMSE between its two bounds.

Every JMSE lies between two bounds that hold for any wavefront. The modulus of an aberrated
OTF never exceeds the diffraction-limited one (Cauchy-Schwarz on the overlap integral),
and ``S_e = S_x S_n / (|H|^2 S_x + S_n)`` falls as ``|H|`` grows, so

    jmse(no aberration)  <=  jmse(design)  <=  (1 / 2 pi) iint_band S_x

(the right-hand side is the error with no transfer at all). For ``MarkovSignal(v, mu)`` the
upper bound has a closed form over the square band ``|nu_x|, |nu_y| < u`` (the solid angle of
a rectangle): ``(1 / 2 pi) (2 v / pi) arctan(u^2 / (c sqrt(c^2 + 2 u^2)))`` with
``c = 1 / (2 pi mu)``. The lower bound is the package's own value for the unaberrated lens,
which ``tests/test_merit.py`` checks against a SciPy oracle.

The designs are drawn to be hard: all six Seidel coefficients (distortion included) at
scales from 0 to 20 waves, with random exact zeros (symmetric designs, which take the
one-ray plans), or with ``--family zernike`` the 36 Noll terms 2-37 (tilt to radial order
8) at scales from 0 to 3 waves RMS each, most of them zero and in some designs every term
beyond Seidel's degree zero (so both kinds of Zernike plan are drawn); fields at 0, 1 and
next to them; ``u`` from 1e-3 to 1.5 with the values
where the rules change (``1/sqrt(2)``, 1); noise variances 1e-8 to 1 (peak SNR up to
~1e10, beyond ``CHECKED_SNR``); signal variances 1e-2 to 1e2 and correlation lengths 0.1 to
100. For each, ``jax.value_and_grad`` of the JMSE with respect to every argument (the six
coefficients, field, u, noise variance, signal variance and correlation length) is
evaluated under ``jit``, and the script counts results that are not finite, values outside
the bounds beyond a tolerance (the preset's documented worst error within the checked
range, looser beyond it), and values that are not positive. The checked range is where a
concrete ``jmse`` call with the preset gives no ``UserWarning``: strength, slope,
cancellation and peak ``S_x / S_n`` within the bounds the preset was checked at
(``CHECKED_STRENGTH`` or ``CHECKED_STRENGTH_ONE_RAY``, ``CHECKED_SLOPE``,
``CHECKED_CANCELLATION`` or, for ``fast``, ``BALANCED_CANCELLATION``, ``CHECKED_SNR`` or
``CHECKED_SNR_PEAKS``); the script asks the library which of them a design passes, without
evaluating it.

Usage (from the repository root; about 10 min on 2 cores with the defaults)::

    .venv/bin/python benchmarks/bounds_fuzz.py [--designs 150] [--seed 11]
        [--presets fast,default,high] [--dtypes float64,float32] [--family seidel]

Writes ``benchmarks/results/bounds_fuzz.json`` and ``.md`` (``--tag`` adds a suffix; the
Zernike family writes ``bounds_fuzz_zernike``). ``--family zernike --designs 60`` takes
about 25 min on 2 cores (such designs take the steep tier and the balanced plans).
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import _common as common
import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import jmse_jax as jj  # noqa: E402
from jmse_jax import _merit  # noqa: E402  (which checked bound a design passes)

sys.path.insert(0, str(common.TESTS))
import oracles  # noqa: E402  (the closed-form upper bound, shared with the tests)

NAMES = ("w020", "w040", "w131", "w222", "w220", "w311")
SCALES = (0.0, 1e-3, 0.1, 1.0, 3.0, 8.0, 20.0)
#: The Zernike family: one static set of Noll terms (one program per preset and dtype),
#: tilt to radial order 8; coefficients in waves RMS.
NOLL = tuple(range(2, 38))
ZERNIKE_SCALES = (0.0, 1e-3, 0.1, 0.3, 1.0, 3.0)
#: Each Zernike term is zero with this probability, and every term beyond Seidel's degree
#: (radial order 5 and more) in this share of the designs.
ZERNIKE_ZERO, SEIDEL_DEGREE_ONLY = 0.8, 0.25
#: Relative tolerance on the bounds within the checked range (strength <= CHECKED_STRENGTH,
#: peak SNR <= CHECKED_SNR): above each preset's worst error on the bank and the tiers'
#: calibrations (README). Beyond it the grids are not checked and only 10 % is asked.
TOLERANCE = {"fast": 5e-2, "default": 1e-4, "high": 1e-5}
UNCHECKED_TOLERANCE = 0.1
#: float32 adds its own rounding: about 1e-5 relative on the presets (README).
FLOAT32_EXTRA = 1e-4
#: The ``high`` preset costs ~40 ms a design; it gets this share of the designs.
HIGH_SHARE = 3


def draw(rng, family: str = "seidel") -> dict:
    """One hard design (see the module docstring)."""
    if family == "zernike":
        scale = ZERNIKE_SCALES[rng.integers(len(ZERNIKE_SCALES))]
        c = rng.normal(size=len(NOLL)) * scale
        c = np.where(rng.random(len(NOLL)) < ZERNIKE_ZERO, 0.0, c)
        if rng.random() < SEIDEL_DEGREE_ONLY:
            c = np.where([jj.noll_to_nm(j)[0] >= 5 for j in NOLL], 0.0, c)
    else:
        scale = SCALES[rng.integers(len(SCALES))]
        c = rng.normal(size=len(NAMES)) * scale
        c = np.where(rng.random(len(NAMES)) < 0.4, 0.0, c)
    field = float(rng.choice([0.0, 1.0, 1e-9, 1.0 - 1e-9, rng.random(), rng.random()]))
    u = float(rng.choice([1e-3, 0.05, 1.0 / math.sqrt(2.0), 0.7071, 0.7072, 1.0, 1.5,
                          rng.uniform(0.05, 1.5), rng.uniform(0.05, 1.5)]))
    return dict(coefficients=c.tolist(), field=field, u=u,
                noise=float(10 ** rng.uniform(-8, 0)),
                signal_variance=float(10 ** rng.uniform(-2, 2)),
                correlation_length=float(10 ** rng.uniform(-1, 2)))


def aberrations(c, family: str):
    """The design's ``Seidel`` or ``Zernike`` from its coefficient vector."""
    if family == "zernike":
        return jj.Zernike(c, noll=NOLL)
    return jj.Seidel(**{name: c[i] for i, name in enumerate(NAMES)})


def beyond_checked(d: dict, preset: str, family: str) -> list[str]:
    """The bounds a concrete ``jmse`` call with ``preset`` would warn about for design
    ``d`` (empty: the checked range), from the library's own tests of them."""
    signal = jj.MarkovSignal(d["signal_variance"], d["correlation_length"])
    noise = jj.WhiteNoise(d["noise"])
    ab = aberrations(np.asarray(d["coefficients"]), family)
    static, inputs = _merit._prepare((ab, d["field"], d["u"], signal, noise),
                                     jj.jmse_options(preset))
    _, _, symmetric, strength, cancellation = (
        x.item() for x in _merit._concrete_choice(static, *inputs[:3]))
    flags = _merit._beyond_checked(strength, d["u"], symmetric, cancellation,
                                   balanced=static.value[4] is not None)
    reasons = [name for name, flag in zip(("strength", "slope", "cancellation"), flags[:3],
                                          strict=True) if bool(flag)]
    peaks = bool(symmetric) or _merit._snr_peaks(static.value[0]["peaks"], static.value[1])
    snr = float(_merit._peak_snr(inputs[2], signal, noise))
    if snr > (jj.CHECKED_SNR_PEAKS if peaks else jj.CHECKED_SNR):
        reasons.append("snr")
    return reasons


def _programs(preset: str, dtype, family: str):
    size = len(NOLL) if family == "zernike" else len(NAMES)

    def merit(c, field, u, noise, variance, length):
        return jj.jmse(aberrations(c, family), field, u, jj.MarkovSignal(variance, length),
                       jj.WhiteNoise(noise), preset=preset)

    value_and_grad = jax.jit(jax.value_and_grad(merit, argnums=tuple(range(6))))
    unaberrated = jax.jit(lambda *a: merit(jnp.zeros(size, dtype), *a))
    return value_and_grad, unaberrated


def run_one(preset: str, dtype, designs: list[dict], family: str = "seidel") -> dict:
    value_and_grad, unaberrated = _programs(preset, dtype, family)
    rows, start = [], time.perf_counter()
    for d in designs:
        scalars = [jnp.asarray(d[k], dtype) for k in
                   ("field", "u", "noise", "signal_variance", "correlation_length")]
        value, grads = value_and_grad(jnp.asarray(d["coefficients"], dtype), *scalars)
        lower = float(unaberrated(*scalars))
        upper = oracles.markov_no_transfer_jmse(d["u"], d["signal_variance"],
                                                d["correlation_length"])
        ab = aberrations(np.asarray(d["coefficients"]), family)
        strength = float(jj.aberration_strength(ab, d["field"], d["u"]))
        peak_snr = jj.MarkovSignal(d["signal_variance"], d["correlation_length"]).radial(
            0.0) / d["noise"]
        beyond = beyond_checked(d, preset, family)
        checked = not beyond
        tol = TOLERANCE[preset] if checked else UNCHECKED_TOLERANCE
        if dtype == jnp.float32:
            tol += FLOAT32_EXTRA
        v = float(value)
        finite = bool(np.isfinite(v) and all(np.all(np.isfinite(np.asarray(g))) for g in grads))
        rows.append(dict(design=d, value=v, lower=lower, upper=upper, strength=strength,
                         peak_snr=float(peak_snr), checked=checked, beyond=beyond,
                         tolerance=tol,
                         finite=finite, positive=v > 0,
                         below_lower=(lower - v) / lower, above_upper=(v - upper) / upper))
    seconds = time.perf_counter() - start
    bad = [r for r in rows if not r["finite"] or not r["positive"]
           or r["below_lower"] > r["tolerance"] or r["above_upper"] > r["tolerance"]]
    return dict(preset=preset, dtype=jnp.dtype(dtype).name, family=family, designs=len(rows),
                checked=sum(r["checked"] for r in rows),
                not_finite=sum(not r["finite"] for r in rows),
                not_positive=sum(not r["positive"] for r in rows),
                worst_below_lower=max(r["below_lower"] for r in rows),
                worst_above_upper=max(r["above_upper"] for r in rows),
                checked_below_lower=max((r["below_lower"] for r in rows if r["checked"]),
                                        default=None),
                checked_above_upper=max((r["above_upper"] for r in rows if r["checked"]),
                                        default=None),
                max_strength=max(r["strength"] for r in rows),
                max_peak_snr=max(r["peak_snr"] for r in rows),
                failures=bad, seconds=seconds, rows=rows)


def _fmt(x) -> str:
    return "–" if x is None else f"{x:.1e}"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=150)
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--presets", default="fast,default,high")
    parser.add_argument("--dtypes", default="float64,float32")
    parser.add_argument("--family", choices=("seidel", "zernike"), default="seidel")
    parser.add_argument("--tag", default="")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    designs = [draw(rng, args.family) for _ in range(args.designs)]
    runs = []
    for preset in args.presets.split(","):
        for name in args.dtypes.split(","):
            subset = designs[::HIGH_SHARE] if preset == "high" else designs
            result = run_one(preset, jnp.dtype(name).type, subset, args.family)
            runs.append(result)
            print(f"{preset:8s} {name}: {result['designs']} designs "
                  f"({result['checked']} in the checked range), not finite "
                  f"{result['not_finite']}, outside the bounds {len(result['failures'])}; "
                  f"worst below the lower bound {result['worst_below_lower']:.1e}, above the "
                  f"upper {result['worst_above_upper']:.1e} ({result['seconds']:.0f} s)",
                  flush=True)

    machine = common.machine_info()
    report = dict(description=__doc__.split("\n\n")[0], machine=machine, seed=args.seed,
                  family=args.family, noll=NOLL if args.family == "zernike" else None,
                  tolerance=TOLERANCE, unchecked_tolerance=UNCHECKED_TOLERANCE,
                  float32_extra=FLOAT32_EXTRA, runs=runs)
    lines = [
        "# Random extreme designs: finite results and the JMSE between its bounds", "",
        f"{machine.get('cpu_model')}, {machine.get('cpu_count')} CPUs, jax "
        f"{machine.get('jax_version')}, commit `{machine.get('commit')}`, {machine.get('date')}; "
        f"`python benchmarks/bounds_fuzz.py --designs {args.designs} --seed {args.seed} "
        f"--family {args.family}` (`high` on every {HIGH_SHARE}rd design). "
        + ("Zernike designs, Noll terms 2-37 (one program per preset and dtype); "
           if args.family == "zernike" else "Seidel designs; ")
        + "`jax.value_and_grad` under `jit` in every input (the coefficients, field, u, the "
        "noise variance and the signal's two parameters). Bounds: the unaberrated lens's "
        "JMSE below, `(1/2 pi) iint_band S_x` (closed form) above; `below` / `above` are the "
        "largest relative amounts by which a value passed them (negative: inside), over all "
        "designs and over those in the checked range (where a concrete `jmse` call with the "
        "preset gives no warning: strength, slope, cancellation and peak SNR within the "
        "bounds the preset was checked at). Tolerance "
        f"{TOLERANCE} in the checked range, {UNCHECKED_TOLERANCE} beyond it, "
        f"+{FLOAT32_EXTRA} in float32.", "",
        "| preset | dtype | designs (checked range) | beyond: strength / slope / "
        "cancellation / SNR | max strength | max peak SNR "
        "| not finite | not positive | below lower: all (checked) "
        "| above upper: all (checked) | failures | time |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        lines.append(
            f"| {r['preset']} | {r['dtype']} | {r['designs']} ({r['checked']}) | "
            + " / ".join(str(sum(why in row["beyond"] for row in r["rows"]))
                         for why in ("strength", "slope", "cancellation", "snr"))
            + f" | {r['max_strength']:.0f} | {r['max_peak_snr']:.1e} | {r['not_finite']} | "
            f"{r['not_positive']} | {r['worst_below_lower']:.1e} "
            f"({_fmt(r['checked_below_lower'])}) | {r['worst_above_upper']:.1e} "
            f"({_fmt(r['checked_above_upper'])}) | {len(r['failures'])} | "
            f"{r['seconds']:.0f} s |")
    failures = [(r["preset"], r["dtype"], f) for r in runs for f in r["failures"]]
    if failures:
        lines += ["", "Failures:", ""]
        lines += [f"- {p} {t}: {f['design']} -> {f['value']:.6e} (bounds {f['lower']:.6e}, "
                  f"{f['upper']:.6e}; finite {f['finite']})" for p, t, f in failures]
    name = "bounds_fuzz" + ("_zernike" if args.family == "zernike" else "")
    common.write_report(name + (f"_{args.tag}" if args.tag else ""), report, lines)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
