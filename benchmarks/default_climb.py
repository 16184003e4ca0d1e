"""Adversarial accuracy of the default preset: a hill climb on its relative error.

The default's tiers were calibrated on random designs (``calibrate_tiers.py``), which say
little about the worst design in a region. This script draws random Seidel designs over the
checked range (where a concrete ``jmse`` call gives no ``UserWarning``: strength, slope,
cancellation and peak SNR within the bounds the preset was checked at), keeps the
``--starts`` worst by the default's error against a converged polar grid, and from each runs
``--steps`` steps of a random hill climb on that error (coefficients moved by 10 % of the
start's scale plus 0.05 waves, field by 0.1, u by 0.05 within 0.05-1.2, correlation length
and noise by factors of e^0.3 and e^0.5; a step that leaves the checked range is dropped).
The worst design of each climb is re-checked against a finer reference, so that a large
error cannot be the reference's.

Usage (from the repository root; about 25 min on 2 cores with the defaults)::

    .venv/bin/python benchmarks/default_climb.py [--designs 150] [--starts 6] [--steps 30]
        [--preset default] [--seed 0] [--start JSON]

``--start`` climbs from one given design instead of a sample's worst (``--designs 0``), as a
JSON object with ``coefficients`` (the five Seidel terms), ``field``, ``u``,
``correlation_length``, ``noise`` and ``scale`` (the step's size is 10 % of it). Session
80's longer climb, at 71e64e4 (before the fix it found)::

    .venv/bin/python benchmarks/default_climb.py --designs 0 --steps 60 --seed 7 --start \
        '{"scale": 2, "coefficients": {"w020": -1.9746, "w040": 0.1858, "w131": 1.6254,
          "w222": 0.8552, "w220": 0.2196}, "field": 0.117, "u": 0.17,
          "correlation_length": 1.895, "noise": 9.38e-5}'

``--family zernike`` climbs on Zernike designs instead (Noll 4 to ``--noll``, default 22;
coefficients normal with deviation ``scale / n`` for radial order ``n``, scale 0.1-2,
stepped by 10 % of that plus 0.05 / n; the field is ignored), and ``--signal powerlaw``
under ``PowerLawSignal(amplitude, exponent, knee)`` instead of ``MarkovSignal(1, mu)``
(exponent 1.5-3, knee 10^-2.5 to 10^-0.5, amplitude 10^-4 to 1; steps of 0.15 in the
exponent and factors of e^0.3 and e^0.5 in the knee and amplitude). Either adds to the
results' name (``default_climb_zernike``, ``default_climb_powerlaw``,
``default_climb_high_zernike``...). Zernike designs are measured against references finer
than their balanced plan (``ZERNIKE_REFERENCE``, ``ZERNIKE_FINER``), and ``--preset high``
against references with more fine S_e nodes than ``"high"``'s grids (since session 83).

``--gradient`` climbs on the error of the gradient instead of the value's (since session 84):
``jax.value_and_grad`` under ``jit`` in the coefficients, the field, ``u`` and the noise
variance, each component taken as a sensitivity ``s_i = sigma_i (dJ/dx_i) / J`` (``sigma_i``
one wave for a coefficient, 1 for the field, the value itself for ``u`` and the noise), and
the design's error ``max_i |s_i - s_i^ref| / max_i |s_i^ref|`` against the same program on the
reference grid. The value's error is kept beside it (``value_error``). Adds ``_gradient`` to
the results' name.

``--noise LO HI`` draws the noise variance as ``10^uniform(LO, HI)`` instead of
``10^uniform(-5, -2)`` (steps then reach down to ``min(1e-6, 10^LO)``) and holds the peak
``S_x / S_n`` to ``CHECKED_SNR_PEAKS`` (2e8) whatever the preset's own bound (the default's
is ``CHECKED_SNR``, 2e6): it measures the preset where ``"high"`` claims to hold and the
default warns (session 85). Adds ``_lownoise`` to the results' name.

``--se-angular`` runs the preset with ``se_angular=jj.se_angular_for(u, signal, noise)``,
the count ``optimise`` gives ``"high"`` past ``CHECKED_SNR`` (session 86), and since
session 88 with ``otf_radial=jj.otf_radial_for(u, signal, noise)`` too, against
references with 4/3 and twice ``SE_ANGULAR_BY_SNR``'s largest count of angular fine nodes
and 8/5 and twice ``OTF_RADIAL_BY_SNR``'s largest count of radial OTF nodes. Adds
``_se_angular`` to the results' name.

Writes ``results/default_climb.json`` and ``.md`` (``--preset high``: ``default_climb_high``;
``--start``: ``default_climb_given``; ``--tag`` is appended to any name).
"""

from __future__ import annotations

import argparse
import functools
import json
import sys
import time
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import jmse_jax as jj  # noqa: E402
from jmse_jax._aberrations import noll_to_nm  # noqa: E402
from jmse_jax._merit import _peak_snr, _route  # noqa: E402

TERMS = ("w020", "w040", "w131", "w222", "w220")
REFERENCE = common.CONVERGED_POLAR
#: A step finer in every count, for the worst designs.
FINER = dict(nodes=(200, 80), se_nodes=(8000, 1200), overlap_nodes=(160, 160),
             overlap_floor=160, peaks=True)
#: For Zernike designs: their balanced plan has 96 angular OTF nodes and the overlap rule
#: (128, 128) since session 82 (``DEGREE_NODES``, ``DEGREE_OVERLAP``), more than
#: ``REFERENCE``'s 64 and as many as its rule; finer in both. (Session 82's seed-1 search ran
#: against (160, 80) and (200, 96), when the plan had 64.)
#: Since session 83 the plan has 960 angular fine S_e nodes (``DEGREE_SE_NODES``), as many
#: as ``REFERENCE``: the references have more.
ZERNIKE_REFERENCE = dict(REFERENCE, nodes=(160, 128), se_nodes=(6400, 1280),
                         overlap_nodes=(160, 160), overlap_floor=160)
ZERNIKE_FINER = dict(FINER, nodes=(200, 160), se_nodes=(8000, 1600), overlap_nodes=(192, 192),
                     overlap_floor=192)


def _aberrations(row):
    if "noll" in row:
        return jj.Zernike(row["coefficients"], noll=tuple(row["noll"]))
    return jj.Seidel(**row["coefficients"])


def _signal(row):
    if "exponent" in row:
        return jj.PowerLawSignal(row["amplitude"], row["exponent"], row["knee"])
    return jj.MarkovSignal(1.0, row["correlation_length"])


def _design(row):
    return (_aberrations(row), row["field"], row["u"], _signal(row),
            jj.WhiteNoise(row["noise"]))


@functools.cache
def _gradient_program(options, noll, powerlaw):
    """Jitted ``value_and_grad`` of the JMSE in (coefficients, field, u, noise) with the
    jmse options ``options`` (a sorted tuple of items); ``noll`` is None for Seidel designs."""

    def merit(c, field, u, noise, spectrum):
        ab = (jj.Seidel(**dict(zip(TERMS, c, strict=True))) if noll is None
              else jj.Zernike(c, noll=noll))
        signal = (jj.PowerLawSignal(spectrum[0], spectrum[1], spectrum[2]) if powerlaw
                  else jj.MarkovSignal(1.0, spectrum[0]))
        return jj.jmse(ab, field, u, signal, jj.WhiteNoise(noise), **dict(options))

    return jax.jit(jax.value_and_grad(merit, argnums=(0, 1, 2, 3)))


def _sensitivities(row, options):
    """The value and the sensitivities ``sigma_i (dJ/dx_i) / J`` (module docstring) of the
    design ``row`` under the jmse options ``options``."""
    noll = tuple(row["noll"]) if "noll" in row else None
    c = (np.asarray(row["coefficients"], float) if noll is not None
         else np.array([row["coefficients"][k] for k in TERMS]))
    powerlaw = "exponent" in row
    spectrum = (np.array([row["amplitude"], row["exponent"], row["knee"]]) if powerlaw
                else np.array([row["correlation_length"]]))
    program = _gradient_program(tuple(sorted(options.items())), noll, powerlaw)
    value, (g_c, g_field, g_u, g_noise) = program(
        jnp.asarray(c), jnp.asarray(row["field"]), jnp.asarray(row["u"]),
        jnp.asarray(row["noise"]), jnp.asarray(spectrum))
    value = float(value)
    s = np.concatenate([np.asarray(g_c), [float(g_field), row["u"] * float(g_u),
                                          row["noise"] * float(g_noise)]]) / value
    return value, s


def gradient_error(s, s_ref):
    """``max_i |s_i - s_ref_i| / max_i |s_ref_i|`` (the climb's measure with ``--gradient``)."""
    return float(np.max(np.abs(s - s_ref)) / np.max(np.abs(s_ref)))


def _evaluate(row, preset, reference_grid=REFERENCE, gradient=False, snr_bound=None,
              se_angular=False):
    """``row`` with the preset's value, route and error against ``reference_grid``, or None
    when a concrete call warns (the design is outside the checked range). With
    ``gradient``, ``error`` is the gradient's (``gradient_error``) and ``value_error`` the
    value's. With ``snr_bound`` the peak ``S_x / S_n`` is held to it instead of the
    preset's own bound (the peak-SNR warning is then ignored; the others still count).
    With ``se_angular`` the preset runs with ``se_angular=jj.se_angular_for(...)`` and
    (since session 88) ``otf_radial=jj.otf_radial_for(...)`` of the design's spectra
    (``optimise``'s choice for ``"high"``), kept as ``se_angular`` and ``otf_radial``."""
    design = _design(row)
    options = dict(preset=preset)
    if se_angular:
        options["se_angular"] = jj.se_angular_for(*design[2:])
        options["otf_radial"] = jj.otf_radial_for(*design[2:])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        value = float(jj.jmse(*design, **options))
    snr = float(_peak_snr(*design[2:]))
    texts = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
    if snr_bound is not None:
        texts = [t for t in texts if not t.startswith("the peak signal-to-noise ratio")]
        if snr > snr_bound:
            return None
    if texts:
        return None
    route = _route(*design, preset=preset) if preset == "default" else {}
    reference = float(jj.jmse(*design, **reference_grid))
    out = dict(row, value=value, reference=reference, error=abs(value / reference - 1.0),
               peak_snr=snr,
               strength=float(jj.aberration_strength(*design[:3])),
               tier=route.get("tier"), path=route.get("path"),
               balanced=route.get("balanced"), one_ray=route.get("one_ray"),
               se_angular=options.get("se_angular"), otf_radial=options.get("otf_radial"))
    if gradient:
        _, s = _sensitivities(row, options)
        _, s_ref = _sensitivities(row, reference_grid)
        out.update(value_error=out["error"], error=gradient_error(s, s_ref),
                   sensitivities=s.tolist(), reference_sensitivities=s_ref.tolist())
    return out


def _orders(noll):
    return np.array([noll_to_nm(j)[0] for j in noll], float)


def _random_row(rng, family="seidel", signal="markov", noll=22, noise=(-5.0, -2.0)):
    scale = float(rng.choice([0.5, 1.0, 2.0, 4.0, 8.0] if family == "seidel"
                             else [0.1, 0.25, 0.5, 1.0, 2.0]))
    if family == "zernike":
        indices = list(range(4, noll + 1))
        aberrations = dict(noll=indices, coefficients=(
            rng.normal(size=len(indices)) * scale / _orders(indices)).tolist())
    else:
        aberrations = dict(coefficients={k: float(rng.uniform(-scale, scale)) for k in TERMS})
    if signal == "powerlaw":
        spectrum = dict(amplitude=float(10 ** rng.uniform(-4, 0)),
                        exponent=float(rng.uniform(1.5, 3.0)),
                        knee=float(10 ** rng.uniform(-2.5, -0.5)))
    else:
        spectrum = dict(correlation_length=float(rng.uniform(2, 10)))
    return dict(scale=scale, **aberrations,
                field=float(rng.uniform(0, 1)), u=float(rng.choice([0.1, 0.2, 0.3, 0.5, 0.7,
                                                                     0.85, 1.0])),
                **spectrum, noise=float(10 ** rng.uniform(*noise)))


def _step(row, rng, noise_floor=1e-6):
    size = 0.1 * row["scale"] + 0.05
    if "noll" in row:
        step = rng.normal(size=len(row["noll"])) * size / _orders(row["noll"])
        aberrations = dict(noll=row["noll"],
                           coefficients=(np.asarray(row["coefficients"]) + step).tolist())
    else:
        aberrations = dict(coefficients={k: v + float(rng.normal(0, size))
                                         for k, v in row["coefficients"].items()})
    if "exponent" in row:
        spectrum = dict(
            amplitude=float(np.clip(row["amplitude"] * np.exp(rng.normal(0, 0.5)), 1e-6, 10)),
            exponent=float(np.clip(row["exponent"] + rng.normal(0, 0.15), 1.0, 4.0)),
            knee=float(np.clip(row["knee"] * np.exp(rng.normal(0, 0.3)), 1e-3, 1.0)))
    else:
        spectrum = dict(correlation_length=float(np.clip(
            row["correlation_length"] * np.exp(rng.normal(0, 0.3)), 1, 20)))
    return dict(scale=row["scale"], **aberrations,
                field=float(np.clip(row["field"] + rng.normal(0, 0.1), 0, 1)),
                u=float(np.clip(row["u"] + rng.normal(0, 0.05), 0.05, 1.2)),
                **spectrum,
                noise=float(np.clip(row["noise"] * np.exp(rng.normal(0, 0.5)), noise_floor,
                                    1e-2)))


def _describe(row):
    """The design of ``row`` in a table cell."""
    if "noll" in row:
        terms = ", ".join(f"Z{j} {c:.3f}" for j, c in zip(row["noll"], row["coefficients"],
                                                                strict=True)
                          if abs(c) >= 0.05)
        text = f"Zernike {terms}"
    else:
        text = f"{ {k: round(v, 4) for k, v in row['coefficients'].items()} }, field " \
               f"{row['field']:.3f}"
    text += f", u {row['u']:.3f}, "
    if "exponent" in row:
        text += (f"power law amplitude {row['amplitude']:.3g}, exponent "
                 f"{row['exponent']:.3f}, knee {row['knee']:.3g}")
    else:
        text += f"correlation length {row['correlation_length']:.3f}"
    text += f", noise {row['noise']:.3g}"
    return text + (f", se_angular {row['se_angular']}" if row.get("se_angular") else "")


def _family_flags(args):
    flags = "" if args.family == "seidel" else f" --family {args.family} --noll {args.noll}"
    flags += "" if args.signal == "markov" else f" --signal {args.signal}"
    flags += "" if args.noise is None else f" --noise {args.noise[0]:g} {args.noise[1]:g}"
    flags += " --se-angular" if args.se_angular else ""
    return flags + (" --gradient" if args.gradient else "")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--designs", type=int, default=150)
    parser.add_argument("--starts", type=int, default=6)
    parser.add_argument("--steps", type=int, default=30)
    parser.add_argument("--preset", default="default")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--start", type=json.loads, default=None,
                        help="climb from this design (JSON), see the module docstring")
    parser.add_argument("--tag", default="", help="suffix of the results' name")
    parser.add_argument("--family", default="seidel", choices=("seidel", "zernike"))
    parser.add_argument("--noll", type=int, default=22,
                        help="highest Noll index of --family zernike (from 4)")
    parser.add_argument("--signal", default="markov", choices=("markov", "powerlaw"))
    parser.add_argument("--gradient", action="store_true",
                        help="climb on the gradient's error (module docstring)")
    parser.add_argument("--noise", type=float, nargs=2, default=None, metavar=("LO", "HI"),
                        help="draw the noise variance as 10^uniform(LO, HI) instead of "
                             "10^uniform(-5, -2) (module docstring)")
    parser.add_argument("--se-angular", action="store_true",
                        help="run the preset with se_angular=se_angular_for(u, signal, noise), "
                             "as optimise does for 'high' (module docstring)")
    args = parser.parse_args(argv)
    noise = (-5.0, -2.0) if args.noise is None else tuple(args.noise)
    noise_floor = min(1e-6, 10 ** noise[0])
    snr_bound = None if args.noise is None else jj.CHECKED_SNR_PEAKS
    rng = np.random.default_rng(args.seed)
    reference_grid, finer_grid = ((ZERNIKE_REFERENCE, ZERNIKE_FINER) if args.family == "zernike"
                                  else (REFERENCE, FINER))
    if args.preset == "high":
        # "high"'s grids have up to (6400, 960) fine S_e nodes, as many as REFERENCE; the
        # references have more (2560 angular since session 85, which tried 1920 in "high").
        reference_grid = dict(reference_grid, se_nodes=(8000, 2560))
        finer_grid = dict(finer_grid, se_nodes=(9600, 3200))
    if args.se_angular:
        # se_angular_for gives up to SE_ANGULAR_BY_SNR's last count: the references have
        # 4/3 and 2 times that (session 86; memory is no bar since the fine stage's blocks
        # are rematerialised in reverse mode).
        most = jj.SE_ANGULAR_BY_SNR[-1][1]
        reference_grid = dict(reference_grid, se_nodes=(8000, most * 4 // 3))
        finer_grid = dict(finer_grid, se_nodes=(9600, 2 * most))
        # otf_radial_for gives up to OTF_RADIAL_BY_SNR's last count (160, the references'
        # own since session 83): they have 8/5 and 2 times that (session 88).
        radial = jj.OTF_RADIAL_BY_SNR[-1][1]
        reference_grid = dict(reference_grid, nodes=(radial * 8 // 5,
                                                     reference_grid["nodes"][1]))
        finer_grid = dict(finer_grid, nodes=(2 * radial, finer_grid["nodes"][1]))
    start = time.perf_counter()
    sample = []
    for i in range(args.designs):
        row = _evaluate(_random_row(rng, args.family, args.signal, args.noll, noise),
                        args.preset, reference_grid, args.gradient, snr_bound,
                        args.se_angular)
        if row is not None:
            sample.append(dict(row, design=i))
    worst = max((r["error"] for r in sample), default=float("nan"))
    print(f"{len(sample)} of {args.designs} random designs in the checked range; worst "
          f"{worst:.2e} [{time.perf_counter() - start:.0f} s]", flush=True)
    starts = sorted(sample, key=lambda r: -r["error"])[:args.starts]
    if args.start is not None:
        starts = [dict(_evaluate(args.start, args.preset, reference_grid, args.gradient,
                                 snr_bound, args.se_angular), design="given")]
    climbs = []
    for row in starts:
        best, improved = row, 0
        for _ in range(args.steps):
            candidate = _evaluate(_step(best, rng, noise_floor), args.preset, reference_grid,
                                  args.gradient, snr_bound, args.se_angular)
            if candidate is not None and candidate["error"] > best["error"]:
                best, improved = candidate, improved + 1
        finer = float(jj.jmse(*_design(best), **finer_grid))
        best = dict(best, finer=finer, reference_change=abs(best["reference"] / finer - 1.0),
                    error_finer=abs(best["value"] / finer - 1.0))
        if args.gradient:
            _, s_finer = _sensitivities(best, finer_grid)
            s_ref = np.asarray(best["reference_sensitivities"])
            best.update(value_error_finer=best["error_finer"],
                        error_finer=gradient_error(np.asarray(best["sensitivities"]), s_finer),
                        reference_change=gradient_error(s_ref, s_finer))
        climbs.append(dict(start=row, worst=best, improved=improved))
        print(f"climb from design {row['design']} ({row['error']:.2e}): {best['error']:.2e} "
              f"after {improved} improvements, tier {best['tier']} path {best['path']}, "
              f"reference moves {best['reference_change']:.1e} on the finer grid "
              f"[{time.perf_counter() - start:.0f} s]", flush=True)
    errors = np.array([r["error"] for r in sample] or [np.nan])
    measure = ("the gradient's error (sensitivities, module docstring; the value's error in "
               "the last column)" if args.gradient else "the value's relative error")
    lines = [f"# Adversarial accuracy of `preset={args.preset!r}`", "",
             f"`python benchmarks/default_climb.py --designs {args.designs} --starts "
             f"{args.starts} --steps {args.steps} --preset {args.preset} --seed {args.seed}"
             f"{_family_flags(args)}`",
             "", common.machine_line(common.machine_info(), common.load_average()), "",
             f"Random sample: {len(sample)} of {args.designs} designs in the checked range; "
             f"error median {np.median(errors):.1e}, worst {errors.max():.2e}. Reference "
             f"{reference_grid}; the climbs' worst designs re-checked on {finer_grid}. "
             f"Error: {measure}.", "",
             "| start | its error | worst found | on the finer reference | reference change | "
             "strength | tier | path | design |" + (" value's error |" if args.gradient else ""),
             "|---|---|---|---|---|---|---|---|---|" + ("---|" if args.gradient else "")]
    for c in climbs:
        w = c["worst"]
        lines.append(
            f"| {c['start']['design']} | {c['start']['error']:.2e} | {w['error']:.2e} | "
            f"{w['error_finer']:.2e} | {w['reference_change']:.1e} | {w['strength']:.2f} | "
            f"{w['tier']} | {w['path']} | {_describe(w)} |"
            + (f" {w['value_error']:.1e} |" if args.gradient else ""))
    print("\n".join(lines))
    name = "default_climb" if args.preset == "default" else f"default_climb_{args.preset}"
    name += "" if args.family == "seidel" else f"_{args.family}"
    name += "" if args.signal == "markov" else f"_{args.signal}"
    name += "" if args.noise is None else "_lownoise"
    name += "_se_angular" if args.se_angular else ""
    name += "_gradient" if args.gradient else ""
    name += ("" if args.start is None else "_given") + args.tag
    common.write_report(name, dict(machine=common.machine_info(), preset=args.preset,
                                   family=args.family, signal=args.signal,
                                   reference=reference_grid, finer=finer_grid, sample=sample,
                                   climbs=climbs), lines)


if __name__ == "__main__":
    main()
