"""Random hard designs: the gradient under ``jit`` against central differences of the value.

The tests check ``jax.grad`` of the JMSE against finite differences on the problem bank and
at chosen singular points. This script does it on random designs drawn as in
``bounds_fuzz.py`` (hard ones: up to 20 waves of each Seidel term, or up to 3 waves RMS on
each of the Noll terms 2-37, many of them zero; u from 1e-3 to 1.5; peak SNR up to 1e10), in
every input: the coefficients, the field, ``u``, the noise variance and the signal's
variance and correlation length. The oracle is a central difference of the same program's
value with Richardson steps (``(4 D(h/2) - D(h)) / 3``), the step halved until three
extrapolations in a row agree (at high SNR the value varies on a scale finer than the
first step: the narrow peaks of ``S_e`` at the OTF's zeros move with every input; results
up to commit ce0d6e7 stopped at two, which a plateau once fooled). A difference whose
two points take different plans (tier, shortcut path, one-ray plan or polar grid;
``_merit._route``, at the first and at the smallest step) measures the jump between two
grids and is left out, as are steps that
would leave the domain (field outside [0, 1], ``u`` past 1.5) or cross a value of ``u``
where the rule changes its form (1/sqrt(2), 1). A one-ray design whose symmetry a
coordinate breaks (coma off the axis at zero, say) is differenced on the polar grid that
both points take: that is the zero-aberration point of a term that breaks the symmetry.

The values differenced are those of the program that gives the gradient
(``jax.value_and_grad`` under ``jit``) for designs that take a one-ray plan: one that is
rotationally symmetric only by its values takes the polar grid under differentiation and
the one-ray plan without it where ``first_order_symmetric`` fails (a Zernike set with a term
``cos 4k theta``, as Noll 2-37), and the gradient is the derivative of the former. Other
designs are differenced with the jitted value alone (the same grid). A Seidel design
symmetric by its values keeps the one ray under differentiation (since session 71): its
derivative in a coefficient that breaks the symmetry is checked against the band's
symmetry (``_symmetry_oracle``), and the gap to the polar grid's differences is reported
apart.

Error measure: each component as a sensitivity ``s_i = sigma_i dJ/dx_i / J`` (``sigma_i`` one
wave for a coefficient, 1 for the field, the value itself for ``u`` and the spectra's
parameters), and per design the largest ``|s_i - s_i^FD|`` over the largest ``|s_i^FD|``.

Usage (from the repository root)::

    .venv/bin/python benchmarks/gradient_fuzz.py [--designs 40] [--seed 5]
        [--presets fast,default] [--family seidel|zernike]

Writes ``benchmarks/results/gradient_fuzz[_zernike].{json,md}``; exits with 1 if a design's
gradient is off by more than ``TOLERANCE`` or not finite.
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import _common as common
import bounds_fuzz
import jax
import jax.numpy as jnp
import numpy as np

import jmse_jax as jj
from jmse_jax import _merit

#: The largest sensitivity error accepted (an exact derivative of the discretised value
#: agrees with a Richardson central difference to about 1e-9 here).
TOLERANCE = 1e-6
#: Relative step of the differences (absolute for the coefficients, in waves, times
#: max(1, |c|), and for the field).
STEP = 1e-4
FIELD_STEP = 1e-5
#: u values where the polar rule changes form; a difference must not straddle them.
U_BREAKS = (1.0 / math.sqrt(2.0), 1.0)
#: Zernike designs: the zero coefficients differenced (besides every nonzero one).
ZERO_TERMS = 3
#: The differences are halved (at most ``LEVELS - 1`` times) until three Richardson
#: extrapolations in a row agree to this, relative to the sensitivity (or absolute below
#: 1). Two in a row were fooled once: at peak S_x / S_n 3e11 four extrapolations at the
#: first steps agreed to 6e-8 on a value 2.3e-5 off the limit the fine steps reach.
CONVERGED = 1e-8
LEVELS = 14
SCALAR_NAMES = ("field", "u", "noise", "signal_variance", "correlation_length")


def _program(preset: str, family: str):
    def merit(c, field, u, noise, variance, length):
        return jj.jmse(bounds_fuzz.aberrations(c, family), field, u,
                       jj.MarkovSignal(variance, length), jj.WhiteNoise(noise), preset=preset)

    return jax.jit(jax.value_and_grad(merit, argnums=tuple(range(6)))), jax.jit(merit)


def route_of(x: np.ndarray, n_c: int, preset: str, family: str) -> tuple:
    """``(tier, balanced, steep, one_ray, path)`` that a concrete ``jmse`` call takes."""
    c, (field, u, noise, variance, length) = x[:n_c], x[n_c:]
    r = _merit._route(bounds_fuzz.aberrations(c, family), float(field), float(u),
                      jj.MarkovSignal(float(variance), float(length)),
                      jj.WhiteNoise(float(noise)), preset=preset)
    return (r["tier"], r["balanced"], r["steep"], r["one_ray"], r["path"])


def _unit(i: int, n: int) -> np.ndarray:
    e = np.zeros(n)
    e[i] = 1.0
    return e


def _central(value_at, x: np.ndarray, i: int, h: float) -> float:
    e = _unit(i, len(x)) * h
    return (value_at(x + e) - value_at(x - e)) / (2 * h)


def step_of(i: int, x: np.ndarray, n_c: int) -> float | None:
    """The step of coordinate ``i`` at ``x``, or None where no central difference fits."""
    if i < n_c:
        return STEP * max(1.0, abs(float(x[i])))
    name = SCALAR_NAMES[i - n_c]
    value = float(x[i])
    if name == "field":
        h = FIELD_STEP
        return h if 0.0 <= value - h and value + h <= 1.0 else None
    h = STEP * value
    if name == "u":
        if value + h > _merit.U_MAX or any(abs(value - b) <= h for b in U_BREAKS):
            return None
    return h


def sigma_of(i: int, x: np.ndarray, n_c: int) -> float:
    """The scale of coordinate ``i`` in the sensitivity (see the module docstring)."""
    if i < n_c or SCALAR_NAMES[i - n_c] == "field":
        return 1.0
    return float(x[i])


def _symmetry_oracle(i, x, n_c, fd):
    """The derivative of a Seidel design symmetric by its values (off the axis, coma and
    astigmatism zero) in coefficient ``i``, a change that breaks the symmetry, from the
    band's turns and mirrors, which leave the merit unchanged: zero for coma and distortion
    (a half turn flips them), and for astigmatism, ``w222 h^2 y^2``, the change of its
    radial part ``w222 h^2 rho^2 / 2``: ``h^2 / 2`` of the defocus's derivative (differenced
    on the one ray; None when it was not)."""
    name = bounds_fuzz.NAMES[i]
    if name in ("w131", "w311"):
        return 0.0
    if name == "w222" and 0 in fd:
        return 0.5 * x[n_c + SCALAR_NAMES.index("field")] ** 2 * fd[0]
    return None


def _zero_terms(x, n_c, rng) -> list[int]:
    """The zero coefficients of a Zernike design ``x`` that are differenced: up to
    ``ZERO_TERMS`` of them, drawn from ``rng``."""
    zeros = [i for i in range(n_c) if x[i] == 0.0]
    return sorted(int(i) for i in rng.choice(zeros, size=min(ZERO_TERMS, len(zeros)),
                                             replace=False))


def run_one(preset: str, designs: list[dict], family: str, rng, skip: int = 0) -> dict:
    """``skip``: leave out the first designs, drawing their zero terms (``rng``) all the
    same, so that the others are differenced as in a run of all of them."""
    program, value_program = _program(preset, family)
    n_c = len(designs[0]["coefficients"])
    rows, start = [], time.perf_counter()

    def evaluate(x):
        value, grads = program(jnp.asarray(x[:n_c]), *(jnp.asarray(v) for v in x[n_c:]))
        gradient = np.concatenate([np.asarray(grads[0]).ravel(),
                                   [float(g) for g in grads[1:]]])
        return float(value), gradient

    def value_alone(x):  # as the gradient's program gives it, for a design off the one ray
        return float(value_program(jnp.asarray(x[:n_c]), *(jnp.asarray(v) for v in x[n_c:])))

    for k, d in enumerate(designs):
        x = np.array(list(d["coefficients"]) + [d[name] for name in SCALAR_NAMES])
        if k < skip:
            if family == "zernike":
                _zero_terms(x, n_c, rng)  # drawn all the same: the later draws stay
            continue
        value, gradient = evaluate(x)
        finite = bool(np.isfinite(value) and np.all(np.isfinite(gradient)))
        centre = route_of(x, n_c, preset, family)
        # Without differentiation a design symmetric by its values takes the one-ray plan;
        # the program that gives the gradient then takes the polar grid (see above).
        values = (lambda x: evaluate(x)[0]) if centre[3] else value_alone
        coordinates = list(range(n_c, len(x)))
        if family == "zernike":
            nonzero = [i for i in range(n_c) if x[i] != 0.0]
            coordinates = nonzero + _zero_terms(x, n_c, rng) + coordinates
        else:
            coordinates = list(range(n_c)) + coordinates
        fd, skipped, steps, broken, polar = {}, {}, {}, [], {}
        for i in coordinates:
            h = step_of(i, x, n_c)
            if h is None:
                skipped[i] = "domain"
                continue
            routes = {route_of(xs, n_c, preset, family)
                      for xs in (x + _unit(i, len(x)) * h, x - _unit(i, len(x)) * h)}
            if len(routes) > 1:
                skipped[i] = "plan changes"
                continue
            # Central differences at h, h/2, h/4, ... with a Richardson step between
            # neighbours, until three extrapolations in a row agree (at high SNR the value
            # varies on a scale finer than the first step: the peaks of S_e at the OTF's
            # zeros).
            sigma = sigma_of(i, x, n_c)
            plain = [_central(values, x, i, h)]
            extrapolated = []
            for level in range(1, LEVELS):
                plain.append(_central(values, x, i, h / 2 ** level))
                extrapolated.append((4 * plain[-1] - plain[-2]) / 3)
                if len(extrapolated) > 2 and all(
                        sigma * abs(extrapolated[-k] - extrapolated[-k - 1]) <= CONVERGED * max(
                            sigma * abs(extrapolated[-1]), abs(value)) for k in (1, 2)):
                    break
            else:
                skipped[i] = "differences not converged"
                continue
            # The converged extrapolations come from the smallest steps: their points must
            # take the plan of the first step's too (a shortcut's path can change in
            # between, and the differences then settle on another grid's derivative).
            small = h / 2 ** level
            if {route_of(x + _unit(i, len(x)) * small, n_c, preset, family),
                    route_of(x - _unit(i, len(x)) * small, n_c, preset, family)} != routes:
                skipped[i] = "plan changes"
                continue
            fd[i] = extrapolated[-1]
            steps[i] = small
            if routes != {centre}:  # a one-ray design, the symmetry broken on both sides
                broken.append(i)
                if family == "seidel":
                    # The gradient is the one ray's (``Seidel.first_order_symmetric``); the
                    # differences are the polar grid's, another method, so the oracle is the
                    # band's symmetry instead (see above) and the gap is reported apart.
                    polar[i] = fd.pop(i)
                    oracle = _symmetry_oracle(i, x, n_c, fd)
                    if oracle is None:
                        skipped[i] = "no oracle"
                        broken.pop()
                        continue
                    fd[i] = oracle
        names = [f"c{j}" for j in range(n_c)] + list(SCALAR_NAMES)
        sens = {i: sigma_of(i, x, n_c) * gradient[i] / value for i in fd}
        sens_fd = {i: sigma_of(i, x, n_c) * fd[i] / value for i in fd}
        scale = max((abs(v) for v in sens_fd.values()), default=0.0)
        errors = {i: abs(sens[i] - sens_fd[i]) for i in fd}
        worst_i = max(errors, key=errors.get) if errors else None
        error = errors[worst_i] / scale if errors and scale > 0 else 0.0
        polar_gap = max((abs(sens[i] - sigma_of(i, x, n_c) * polar[i] / value) / scale
                         for i in polar), default=None) if scale > 0 else None
        rows.append(dict(
            index=k + 1, design=d, value=value, finite=finite, route=list(centre),
            checked=not bounds_fuzz.beyond_checked(d, preset, family),
            differenced=[names[i] for i in fd], skipped={names[i]: why for i, why in
                                                          skipped.items()},
            error=error, worst_component=None if worst_i is None else names[worst_i],
            sensitivity={names[i]: sens[i] for i in fd},
            sensitivity_fd={names[i]: sens_fd[i] for i in fd},
            smallest_step={names[i]: steps[i] for i in fd},
            symmetry_broken=[names[i] for i in broken],
            polar_fd={names[i]: polar[i] for i in polar}, polar_gap=polar_gap))
        print(f"  {preset} {k + 1}/{len(designs)}: route {centre}, {len(fd)} components "
              f"({len(skipped)} skipped), error {error:.1e}"
              + (f" ({names[worst_i]})" if worst_i is not None else ""), flush=True)
    seconds = time.perf_counter() - start
    failures = [r for r in rows if not r["finite"] or r["error"] > TOLERANCE]
    return dict(preset=preset, family=family, designs=len(rows),
                checked=sum(r["checked"] for r in rows),
                components=sum(len(r["differenced"]) for r in rows),
                symmetry_broken=sum(len(r["symmetry_broken"]) for r in rows),
                skipped_plan=sum(list(r["skipped"].values()).count("plan changes")
                                 for r in rows),
                skipped_domain=sum(list(r["skipped"].values()).count("domain") for r in rows),
                skipped_unconverged=sum(list(r["skipped"].values()).count(
                    "differences not converged") for r in rows),
                skipped_no_oracle=sum(list(r["skipped"].values()).count("no oracle")
                                      for r in rows),
                polar_gap=max((r["polar_gap"] for r in rows if r["polar_gap"] is not None),
                              default=None),
                worst=max(r["error"] for r in rows),
                worst_checked=max((r["error"] for r in rows if r["checked"]), default=None),
                median=float(np.median([r["error"] for r in rows])),
                not_finite=sum(not r["finite"] for r in rows),
                failures=failures, seconds=seconds, rows=rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=40)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--presets", default="fast,default")
    parser.add_argument("--family", choices=("seidel", "zernike"), default="seidel")
    parser.add_argument("--tag", default="")
    parser.add_argument("--skip", type=int, default=0,
                        help="leave out the first designs of the seed's sequence")
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    designs = [bounds_fuzz.draw(rng, args.family) for _ in range(args.skip + args.designs)]
    runs = []
    for preset in args.presets.split(","):
        result = run_one(preset, designs, args.family, np.random.default_rng(args.seed + 1),
                         skip=args.skip)
        runs.append(result)
        print(f"{preset}: {result['designs']} designs, {result['components']} components "
              f"differenced, worst {result['worst']:.1e} (median {result['median']:.1e}), "
              f"not finite {result['not_finite']}, failures {len(result['failures'])} "
              f"({result['seconds']:.0f} s)", flush=True)
    machine = common.machine_info()
    report = dict(description=__doc__.split("\n\n")[0], machine=machine, seed=args.seed,
                  skip=args.skip,
                  family=args.family, tolerance=TOLERANCE, step=STEP, field_step=FIELD_STEP,
                  runs=runs)
    lines = [
        "# Random hard designs: the gradient against central differences", "",
        f"{machine.get('cpu_model')}, {machine.get('cpu_count')} CPUs, jax "
        f"{machine.get('jax_version')}, float64, commit `{machine.get('commit')}`, "
        f"{machine.get('date')}; `python benchmarks/gradient_fuzz.py --designs {args.designs} "
        f"--seed {args.seed} --family {args.family}"
        + (f" --presets {args.presets}" if args.presets != "fast,default" else "")
        + (f" --skip {args.skip}" if args.skip else "")
        + "`. Designs drawn as in `bounds_fuzz.py`. "
        "`jax.value_and_grad` under `jit` in every input against a central difference of the "
        "same program's value with Richardson steps, halved until three extrapolations in a row "
        "agree to "
        f"{CONVERGED:g} relative to the sensitivity, or absolute below 1 (first relative step "
        f"{STEP:g}, field {FIELD_STEP:g}), where the plan stays the same at the differenced "
        "points. Error: the largest difference of sensitivities `sigma_i dJ/dx_i / J` over "
        f"the largest sensitivity, per design. Tolerance {TOLERANCE:g}.", "",
        "| preset | designs (checked range) | components differenced | left out: plan "
        "changes / domain / differences not converged | worst error: all (checked) | median "
        "| not finite | failures | time |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in runs:
        worst_checked = "–" if r["worst_checked"] is None else f"{r['worst_checked']:.1e}"
        lines.append(
            f"| {r['preset']} | {r['designs']} ({r['checked']}) | {r['components']} | "
            f"{r['skipped_plan']} / {r['skipped_domain']} / {r['skipped_unconverged']} | "
            f"{r['worst']:.1e} "
            f"({worst_checked}) | {r['median']:.1e} | {r['not_finite']} | "
            f"{len(r['failures'])} | {r['seconds']:.0f} s |")
    for r in runs:
        if r["skipped_no_oracle"]:
            lines.append(f"\n{r['preset']}: {r['skipped_no_oracle']} symmetry-breaking "
                         "components left out: the defocus's derivative, their oracle, was "
                         "not differenced.")
        if r["polar_gap"] is not None:
            lines.append(
                f"\n{r['preset']}: {r['symmetry_broken']} components break a one-ray design's "
                "symmetry; against the band's symmetry (zero for coma, h^2 / 2 of the "
                "defocus's for astigmatism); the one ray's gradient and the polar grid's "
                f"differences there differ by at most {r['polar_gap']:.1e} (another method).")
    lines += ["", "Largest errors:", ""]
    for r in runs:
        for row in sorted(r["rows"], key=lambda row: -row["error"])[:3]:
            lines.append(f"- {r['preset']}, design {row['index']}: {row['error']:.1e} in "
                         f"{row['worst_component']}, "
                         f"route {tuple(row['route'])}, {row['design']}")
    failures = [(r["preset"], f) for r in runs for f in r["failures"]]
    if failures:
        lines += ["", "Failures:", ""]
        lines += [f"- {p}: error {f['error']:.2e} in {f['worst_component']} (finite "
                  f"{f['finite']}): {f['design']}" for p, f in failures]
    name = "gradient_fuzz" + ("_zernike" if args.family == "zernike" else "")
    common.write_report(name + (f"_{args.tag}" if args.tag else ""), report, lines)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
