"""Accuracy of the presets at low noise (high SNR), beyond the bank's noise of 1e-4.

At a high peak ``S_x / S_n`` the error spectral density ``S_e = S_x S_n / (|H|^2 S_x + S_n)``
has peaks of height ``S_x`` and width ``~ sqrt(S_n / S_x) / |grad H|`` wherever the OTF
vanishes, and the JMSE of a design with OTF zeros in the band falls only as ``sqrt(S_n)``:
the peaks carry it. A rotationally symmetric design on the axis has a real OTF, whose
zeros are whole rings; an off-axis design's complex OTF vanishes only at isolated points.

References. On the axis, where ``S_e`` depends on ``r = |nu|`` alone, the JMSE is the 1-D
integral ``(1 / 2 pi) int S_e(r) L(r) dr`` with ``L(r)`` the length of the circle of radius
``r`` inside the band's square; it is computed with ``scipy.integrate.quad`` (relative
tolerance 1e-11, breakpoints at the OTF's zeros found on a 400 001-point ray) and the OTF
from ``jmse_jax.otf`` with a (96, 96) overlap rule. Off the axis the reference is the polar
grid ``REFERENCE`` (22 400 fine radial nodes), checked against ``CHECK`` (half as many).

Compared (``COMPARED``): ``jmse`` with the ``fast`` and ``default`` presets, the default with
``peaks=True`` (the closed-form peaks of the polar grids, ``jmse_jax._ridges``), ``high``
(which has them) and ``high`` without them, the explicit polar grid ``FINE`` with them, and on
the axis the default without the one-ray plan's closed-form peaks
(``jmse_jax._radial._zero_peaks``; the package before them). Findings feed ``CHECKED_SNR``
and ``CHECKED_SNR_PEAKS`` (docs/accuracy.md, "Accuracy at low noise"). The near-axis designs
(6 waves of defocus with 0.5 wave of coma or astigmatism at field 0.1, and a weaker mix at
field 0.3) are the polar grid's hard case: their OTF nearly vanishes on rings. The references
``REFERENCE`` and ``CHECK`` have the closed-form peaks too (and are compared with ``REFERENCE``
without).

Gradients. The bank's gradient tests compare ``jax.grad`` with finite differences of the
same grid, so they cannot see a grid that resolves neither. Here the presets' gradients in
the Seidel coefficients and the field are compared with the gradient of the converged
polar grid ``REFERENCE`` (itself checked against ``CHECK``'s), for the off-axis cases at
noise 1e-4, 1e-5 and 1e-6: the error is the largest component's difference over the
largest component of the reference gradient.

Usage (from the repository root; about 14 min on 2 cores with the gradients)::

    .venv/bin/python benchmarks/low_noise.py [--values-only | --gradients-only]

Writes ``results/low_noise.json`` and ``.md`` (with ``--gradients-only``,
``results/low_noise_gradients.json`` and ``.md``).
"""

from __future__ import annotations

import argparse
import functools
import math
import sys
import warnings
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

import _common as common  # noqa: E402 - turns on float64
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy import integrate  # noqa: E402

import jmse_jax as jj  # noqa: E402
import jmse_jax._radial as radial  # noqa: E402

NOISES = (1e-4, 3e-5, 1e-5, 1e-6, 1e-7, 1e-8)
GRADIENT_NOISES = (1e-4, 1e-5, 1e-6)
FIG1 = dict(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
#: (name, Seidel coefficients, field, u)
CASES = (
    ("defocus 1, axis", dict(w020=1.0), 0.0, 0.2),
    ("defocus 6, axis", dict(w020=6.0), 0.0, 0.2),
    ("defocus -2 + spherical 1.2, axis, u 0.5", dict(w020=-2.0, w040=1.2), 0.0, 0.5),
    ("Fig. 1 (field 0.95)", FIG1, 0.95, 0.2),
    ("defocus 6 + coma 0.5, field 0.1", dict(w020=6.0, w131=0.5), 0.1, 0.2),
    ("defocus 6 + astigmatism 0.5, field 0.1", dict(w020=6.0, w222=0.5), 0.1, 0.2),
    ("defocus 3 + coma 0.3 + astigmatism 0.3, field 0.3",
     dict(w020=3.0, w131=0.3, w222=0.3), 0.3, 0.2),
)
FINE = dict(quadrature="polar", nodes=(80, 40), se_nodes=(8000, 960), overlap_nodes=(48, 48),
            peaks=True)
REFERENCE = dict(quadrature="polar", nodes=(80, 40), se_nodes=(22400, 960),
                 overlap_nodes=(48, 48), peaks=True)
CHECK = dict(quadrature="polar", nodes=(80, 40), se_nodes=(11200, 960),
             overlap_nodes=(48, 48), peaks=True)
#: The compared settings of ``jmse`` (column name, keywords).
COMPARED = (("fast", dict(preset="fast")), ("default", dict(preset="default")),
            ("default, peaks", dict(preset="default", peaks=True)),
            ("high", dict(preset="high")), ("high, no peaks", dict(preset="high", peaks=False)),
            ("se_nodes (8000, 960)", FINE))


def uncorrected(fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` with the closed-form peaks of the one-ray plan
    (``_radial._zero_peaks``) turned off (the polar grids' are the option ``peaks``)."""
    radial._SUBTRACT = False
    jax.clear_caches()
    try:
        return fn(*args, **kwargs)
    finally:
        radial._SUBTRACT = True
        jax.clear_caches()


def radial_reference(coefficients, u, signal, noise_variance, nodes=(96, 96)):
    """The on-axis JMSE as a 1-D adaptive integral (module docstring): ``(value, quad's
    error estimate, number of breakpoints)``."""
    ab = jj.Seidel(**coefficients)
    ray = jax.jit(lambda r: jj.otf(ab, r, jnp.zeros_like(r), 0.0, nodes=nodes))
    r_max = math.sqrt(2.0) * u
    grid = np.linspace(1e-9, min(r_max, 1.0 - 1e-6), 400_001)
    mod2 = np.abs(np.asarray(ray(jnp.asarray(grid)))) ** 2
    minima = np.where((mod2[1:-1] < mod2[:-2]) & (mod2[1:-1] <= mod2[2:]))[0] + 1
    points = sorted({float(grid[i]) for i in minima} | ({u} if u < r_max else set()))

    def integrand(r):
        h = complex(ray(jnp.float64(r))) if r < 1.0 else 0.0
        s_x = float(signal.radial(jnp.float64(r)))
        s_e = s_x * noise_variance / (abs(h) ** 2 * s_x + noise_variance)
        length = 2 * math.pi * r - (8 * r * math.acos(u / r) if r > u else 0.0)
        return s_e * length / (2 * math.pi)

    value, error = integrate.quad(integrand, 0.0, r_max, points=points, limit=5000,
                                  epsabs=0.0, epsrel=1e-11)
    return value, error, len(points)


_GRADIENT_KEYS = ("w020", "w040", "w131", "w222", "w220")


@functools.cache
def _gradient_fn(options):
    """``jax.jit(jax.grad(jmse))`` in the coefficients and the field, for hashable
    ``options`` (a tuple of items); one compilation per option set."""
    def merit(values, field, u, signal, noise):
        return jj.jmse(jj.Seidel(**dict(zip(_GRADIENT_KEYS, values, strict=True))), field, u,
                       signal, noise, **dict(options))

    return jax.jit(jax.grad(merit, argnums=(0, 1)))


def gradient(options, coefficients, field, u, signal, noise):
    """``jax.grad`` of ``jmse`` in the named Seidel coefficients and the field, as one
    vector (the coefficients in ``_GRADIENT_KEYS`` order, the field last)."""
    values = jnp.asarray([coefficients.get(k, 0.0) for k in _GRADIENT_KEYS])
    g_ab, g_field = _gradient_fn(tuple(options.items()))(values, jnp.float64(field),
                                                          jnp.float64(u), signal, noise)
    return np.append(np.asarray(g_ab), float(g_field))


def gradient_rows(signal, peak):
    """The gradient study (module docstring): ``(rows, markdown lines)``, the lines
    without a heading."""
    lines = ["Largest difference of the gradient in (w020, w040, w131, w222, w220, field) over "
             "the largest component of the reference gradient (`REFERENCE`'s, by `jax.grad`; "
             "its own difference from `CHECK`'s in the reference column, and from its own "
             "grid's without the closed-form peaks of `jmse_jax._ridges`, `peaks=False`).", "",
             "| case | noise | peak S_x/S_n | reference (vs CHECK; vs no peaks) | "
             + " | ".join(name for name, _ in COMPARED) + " |",
             "|---|---|---|---|" + "---|" * len(COMPARED)]
    rows = []
    for name, coefficients, field, u in CASES:
        if field == 0.0:
            continue
        for noise_variance in GRADIENT_NOISES:
            noise = jj.WhiteNoise(noise_variance)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the SNR warning, which this study measures
                reference = gradient(REFERENCE, coefficients, field, u, signal, noise)
                grads = {key: gradient(options, coefficients, field, u, signal, noise)
                         for key, options in COMPARED}
                grads["check"] = gradient(CHECK, coefficients, field, u, signal, noise)
                grads["plain reference"] = gradient({**REFERENCE, "peaks": False},
                                                    coefficients, field, u, signal, noise)
            scale = float(np.max(np.abs(reference)))
            errors = {k: float(np.max(np.abs(g - reference))) / scale for k, g in grads.items()}
            rows.append(dict(case=name, coefficients=coefficients, field=field, u=u,
                             noise=noise_variance, peak_snr=peak / noise_variance,
                             reference=reference.tolist(),
                             gradients={k: g.tolist() for k, g in grads.items()},
                             errors=errors))
            lines.append(f"| {name} | {noise_variance:.0e} | {peak / noise_variance:.1e} | "
                         f"{errors['check']:.0e}; {errors['plain reference']:.0e} | "
                         + " | ".join(f"{errors[key]:.1e}" for key, _ in COMPARED) + " |")
            print(lines[-1], flush=True)
    return rows, lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    only = parser.add_mutually_exclusive_group()
    only.add_argument("--values-only", action="store_true", help="skip the gradient study")
    only.add_argument("--gradients-only", action="store_true",
                      help="only the gradient study (results/low_noise_gradients.*)")
    arguments = parser.parse_args()
    signal = jj.MarkovSignal(1.0, 5.0)
    peak = float(signal.radial(jnp.float64(0.0)))
    report = dict(description=__doc__.split("\n\n")[0], machine=common.machine_info(),
                  checked_snr=jj.CHECKED_SNR, signal="MarkovSignal(1, 5)", rows=[])
    if arguments.gradients_only:
        report["gradient_rows"], lines = gradient_rows(signal, peak)
        header = ["# Gradients at low noise", "",
                  f"Signal `MarkovSignal(1, 5)`, white noise, u = 0.2; commit "
                  f"{report['machine'].get('commit')}.", ""]
        common.write_report("low_noise_gradients", report, header + lines)
        return
    lines = ["# Accuracy at low noise", "",
             f"Relative error against a converged reference; signal `MarkovSignal(1, 5)` "
             f"(S_x(0) = {peak:.1f}), white noise, u = 0.2 unless named; commit "
             f"{report['machine'].get('commit')}. `CHECKED_SNR` = {jj.CHECKED_SNR:.0e}: a "
             f"concrete call that takes a polar grid warns above it. `peaks`: the closed-form "
             f"peaks of the polar grids (`jmse_jax._ridges`). The last column is the default "
             f"without the closed-form peaks of its one-ray plan (on the axis): the package "
             f"before them. Off the axis the reference is the polar grid `REFERENCE` with "
             f"`peaks=True`, compared with `CHECK` and with `REFERENCE` without them.", "",
             "| case | noise | peak S_x/S_n | reference | "
             + " | ".join(name for name, _ in COMPARED) + " | default, no one-ray peaks |",
             "|---|---|---|---|" + "---|" * (len(COMPARED) + 1)]
    for name, coefficients, field, u in CASES:
        ab = jj.Seidel(**coefficients)
        for noise_variance in NOISES:
            args = (ab, field, u, signal, jj.WhiteNoise(noise_variance))
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # the SNR warning, which this study measures
                values = {key: float(jj.jmse(*args, **options)) for key, options in COMPARED}
                if field == 0.0:
                    values["uncorrected"] = uncorrected(lambda a=args: float(jj.jmse(*a)))
                if field == 0.0:
                    reference, quad_error, _ = radial_reference(coefficients, u, signal,
                                                                noise_variance)
                    how = f"1-D quad (error estimate {quad_error / reference:.0e})"
                else:
                    reference = float(jj.jmse(*args, **REFERENCE))
                    check = float(jj.jmse(*args, **CHECK))
                    plain = float(jj.jmse(*args, **{**REFERENCE, "peaks": False}))
                    how = (f"polar, 22400 fine radial (vs 11200: "
                           f"{common.relative_error(check, reference):.0e}; vs no peaks: "
                           f"{common.relative_error(plain, reference):.0e})")
            errors = {k: common.relative_error(v, reference) for k, v in values.items()}
            snr = peak / noise_variance
            report["rows"].append(dict(case=name, coefficients=coefficients, field=field, u=u,
                                       noise=noise_variance, peak_snr=snr, reference=reference,
                                       reference_kind=how, values=values, errors=errors))
            before = f"{errors['uncorrected']:.1e}" if "uncorrected" in errors else "–"
            lines.append(f"| {name} | {noise_variance:.0e} | {snr:.1e} | {reference:.6e}, "
                         f"{how} | " + " | ".join(f"{errors[key]:.1e}" for key, _ in COMPARED)
                         + f" | {before} |")
            print(lines[-1], flush=True)
    if not arguments.values_only:
        report["gradient_rows"], more = gradient_rows(signal, peak)
        lines += ["", "## Gradients against the converged grid's", "", *more]
    common.write_report("low_noise", report, lines)


if __name__ == "__main__":
    main()
