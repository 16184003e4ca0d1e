"""The ``jmse-jax`` console script: ``eval``, ``optimise``, ``sweep``, ``bench``, ``reproduce``.

Units: Seidel coefficients in waves; frequencies in units of the optical cutoff 1/(lambda N);
``u`` = sensor Nyquist / optical cutoff = lambda N / (2 pixel pitch); field as a fraction of
the full field in [0, 1]; lens quantities in mm (curvatures in 1/mm). Float64 is switched on
here (the library itself never does so at import). Bad arguments give a one-line
``jmse-jax: error: ...`` and exit status 2.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import pathlib
import subprocess
import sys
import tempfile
import warnings
from typing import Any

from ._merit import U_MAX
from ._numerics import AccuracyWarning, check_range
from ._reproduce import FIG1, FIG1_FIELD, FIG1_U
from ._sweep import DEFAULT_ACCELERATOR_BATCH, _checked_already

COEFFICIENTS = ("w020", "w040", "w131", "w222", "w220", "w311", "w111")
COEFFICIENT_NAMES = {"w020": "defocus", "w040": "spherical", "w131": "coma",
                     "w222": "astigmatism", "w220": "field curvature", "w311": "distortion",
                     "w111": "tilt"}
PRESET_NAMES = ("fast", "default", "high")
EVAL_KEYS = COEFFICIENTS + ("zernike", "field", "u", "noise", "signal", "preset", "nu")
EVAL_DEFAULTS = dict(field=FIG1_FIELD, u=FIG1_U, noise=1e-3, signal="markov:1,5",
                     preset="default", nu="0.05,0.1,0.2", zernike=None)
ZERNIKE_HELP = ("Zernike coefficients in place of Seidel's: comma-separated NOLL:WAVES pairs, "
                "e.g. 4:0.5,11:-0.2 (Noll index >= 1; each coefficient is its term's RMS over "
                "the pupil in waves; polar angle from +y, so the cosine terms are even in x, "
                "docs/conventions.md; one field point, so --field is not used)")
UNITS = ("Units: Seidel coefficients in waves; spatial frequencies nu in units of the optical "
         "cutoff 1/(lambda N); u = sensor Nyquist / optical cutoff = lambda N / (2 pixel pitch) "
         "in (0, 1.5]; field = fractional field height in [0, 1]; signal and noise spectra in "
         "the same normalised frequency units.")
SIGNAL_HELP = ("signal spectrum S_x: 'markov:VARIANCE,MU' (exponentially correlated, "
               "correlation length MU in units of lambda N), 'powerlaw:A,GAMMA,NU0' "
               "(A / (NU0^2 + |nu|^2)^(GAMMA/2), NU0 in cutoff units) or 'white:LEVEL'")


class _Parser(argparse.ArgumentParser):
    """argparse with a one-line error and exit status 2."""

    def error(self, message):
        self.exit(2, f"jmse-jax: error: {message}\n")


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Adds ``(default: X)`` to an option's help, unless the help already states its default
    or there is none to state (``None``, a flag's ``False``)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "default" in text or action.default in (None, False):
            return text
        return super()._get_help_string(action)


class UsageError(ValueError):
    """A bad value on the command line (reported in one line, exit status 2)."""


# --------------------------------------------------------------------------------------
# Parsing helpers (ValueError with a sentence a user can act on)
# --------------------------------------------------------------------------------------


def _floats(text: str, name: str) -> list[float]:
    try:
        # An empty piece ("1,,5", "1,5,") is an error, not a number to skip.
        values = [float(v) for v in str(text).split(",")]
    except ValueError:
        raise UsageError(f"{name} must be comma-separated numbers, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise UsageError(f"{name} must be finite numbers, got {text!r}")
    return values


def parse_signal(text: str):
    """``markov:VAR,MU`` / ``powerlaw:A,GAMMA,NU0`` / ``white:LEVEL`` -> signal model."""
    import jmse_jax as jj

    kind, _, rest = str(text).partition(":")
    kind = kind.strip().lower()
    forms = {"markov": 2, "powerlaw": 3, "white": 1}
    if kind not in forms or not rest:
        raise UsageError(f"--signal must be markov:VAR,MU, powerlaw:A,GAMMA,NU0 or white:LEVEL, "
                         f"got {text!r}")
    values = _floats(rest, "--signal")
    if len(values) != forms[kind]:
        raise UsageError(f"--signal {kind} takes {forms[kind]} numbers, got {text!r}")
    if any(v <= 0 for v in values[:1]) or (kind == "markov" and values[1] <= 0):
        raise UsageError(f"--signal parameters must be positive, got {text!r}")
    if kind == "markov":
        return jj.MarkovSignal(values[0], values[1])
    if kind == "powerlaw":
        if values[2] <= 0:
            raise UsageError(f"--signal powerlaw knee NU0 must be positive, got {text!r}")
        return jj.PowerLawSignal(values[0], values[1], values[2])
    return jj.WhiteSignal(values[0])


def parse_zernike(value, name: str = "zernike") -> dict[int, float]:
    """``"4:0.5,11:-0.2"`` (the flag) or ``{"4": 0.5, "11": -0.2}`` (the JSON key) ->
    ``{Noll index: coefficient [waves RMS]}`` in rising index."""
    if isinstance(value, str):
        pairs = []
        for piece in value.split(","):
            index, colon, coefficient = piece.partition(":")
            if not colon:
                raise UsageError(f"{name} must be NOLL:WAVES pairs separated by commas "
                                 f"(e.g. 4:0.5,11:-0.2), got {value!r}")
            pairs.append((index.strip(), coefficient.strip()))
    elif isinstance(value, dict):
        pairs = list(value.items())
    else:
        raise UsageError(f"{name} must be an object of Noll index: waves (e.g. "
                         f'{{"4": 0.5, "11": -0.2}}), got {json.dumps(value)}')
    if not pairs:
        raise UsageError(f"{name} must name at least one Zernike term, got none")
    terms: dict[int, float] = {}
    for index, coefficient in pairs:
        digits = str(index).strip()
        j = int(digits) if digits.isdigit() and not isinstance(index, bool) else 0
        if j < 1:
            raise UsageError(f"{name}: a Noll index must be an integer >= 1, got {index!r}")
        if j in terms:
            raise UsageError(f"{name}: Noll index {j} is given twice")
        try:
            if isinstance(coefficient, bool):
                raise TypeError
            terms[j] = float(coefficient)
        except (TypeError, ValueError):
            raise UsageError(f"{name}: the coefficient of Z{j} must be a number [waves], "
                             f"got {coefficient!r}") from None
        if not math.isfinite(terms[j]):
            raise UsageError(f"{name}: the coefficient of Z{j} must be finite, "
                             f"got {coefficient!r}")
    return dict(sorted(terms.items()))


def _positive(name, value) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise UsageError(f"{name} must be a positive number, got {value!r}")
    return value


def _check_out(path, flag: str = "--out-json", folder: bool = False, files=()) -> None:
    """``UsageError`` now, before any computation, when ``path`` cannot be written: a file, or
    with ``folder`` a folder to write ``files`` into. Call it after every other argument is
    checked. The folders missing on the way are made to try them and removed again (the
    writers make them when they write), so a run that fails later leaves none behind."""
    if not path:
        return
    target = os.path.abspath(path)
    if folder:
        if os.path.exists(target) and not os.path.isdir(target):
            raise UsageError(f"{flag}: {path} exists and is not a folder")
        taken = [name for name in files if os.path.isdir(os.path.join(target, name))]
        if taken:
            raise UsageError(f"{flag}: {os.path.join(path, taken[0])} is a folder, "
                             "where a file is to be written")
        directory = target
    else:
        if os.path.isdir(target):
            raise UsageError(f"{flag}: {path} is a folder, not a file")
        directory = os.path.dirname(target)
    missing = []
    probe = directory
    while not os.path.exists(probe) and os.path.dirname(probe) != probe:
        missing.append(probe)
        probe = os.path.dirname(probe)
    try:
        os.makedirs(directory, exist_ok=True)
        with tempfile.TemporaryFile(dir=directory):
            pass
        if os.path.exists(target) and not folder and not os.access(target, os.W_OK):
            raise PermissionError(13, "Permission denied")
    except OSError as e:
        raise UsageError(f"{flag}: cannot write {path} ({e.strerror})") from None
    finally:
        for made in missing:  # innermost first
            try:
                os.rmdir(made)
            except OSError:
                pass


def _finite_or_null(data):
    """``data`` with every non-finite float (``inf``, ``nan``) replaced by ``None``: strict
    JSON has no infinities."""
    if isinstance(data, float):
        return data if math.isfinite(data) else None
    if isinstance(data, dict):
        return {k: _finite_or_null(v) for k, v in data.items()}
    if isinstance(data, (list, tuple)):
        return [_finite_or_null(v) for v in data]
    return data


def _write_json(path, data):
    """Write ``data`` as strict JSON (non-finite numbers become ``null``)."""
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    with open(path, "w") as f:
        json.dump(_finite_or_null(data), f, indent=2, allow_nan=False)
    print(f"wrote {path}")


def warn_like_jmse(aberrations, field, u, signal, noise, preset: str) -> list:
    """The library's warnings for designs that run under ``jit`` (``jmse_jax._sweep.
    warn_like_jmse``: strength, wavefront slope, cancelling terms and peak ``S_x / S_n``
    beyond what ``preset`` was checked at), each on stderr as one line; returns their
    texts. Leaves of shape (n,), one design per row."""
    from ._sweep import warn_like_jmse as library_warnings

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        library_warnings(aberrations, field, u, signal, noise, {"preset": preset})
    return report_warnings(caught)


def report_warnings(caught, printed=()) -> list:
    """Report warnings recorded by ``warnings.catch_warnings(record=True)``: the library's
    own (``jmse_jax.AccuracyWarning``) on stderr as ``jmse-jax: warning: <text>``, one line
    each, each text once and none of those in ``printed``; any other warning (JAX's, NumPy's,
    the optimiser's) is given back to Python's warning machinery as it was raised, so it
    shows in Python's own form, naming its category and source, and obeys the filters in
    force (a ``DeprecationWarning`` from a library stays hidden by default). Each distinct
    warning once. Returns the texts printed."""
    shown = set(printed)
    texts, others = [], set()
    for w in caught:
        if issubclass(w.category, AccuracyWarning):
            text = " ".join(str(w.message).split())
            if text not in shown:
                shown.add(text)
                texts.append(text)
                print(f"jmse-jax: warning: {text}", file=sys.stderr, flush=True)
        elif (key := (w.category, str(w.message), w.filename, w.lineno)) not in others:
            others.add(key)
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno,
                                   source=w.source)
    return texts


# --------------------------------------------------------------------------------------
# eval
# --------------------------------------------------------------------------------------


def eval_inputs(args) -> dict:
    """Merge defaults <- ``--json`` file <- explicit flags; return the validated settings."""
    settings: dict[str, Any] = dict(EVAL_DEFAULTS, **{k: 0.0 for k in COEFFICIENTS})
    if args.preset_point == "fig1":
        settings.update(FIG1)
    if args.json:
        try:
            with open(args.json) as f:
                data = json.load(f)
        except OSError as e:
            raise UsageError(f"cannot read --json {args.json}: {e.strerror}") from None
        except json.JSONDecodeError as e:
            raise UsageError(f"--json {args.json} is not valid JSON ({e.msg}, line {e.lineno})"
                             ) from None
        except UnicodeDecodeError as e:
            raise UsageError(f"--json {args.json} is not UTF-8 text ({e.reason} at byte "
                             f"{e.start})") from None
        if not isinstance(data, dict):
            raise UsageError(f"--json {args.json} must hold an object with keys such as w020")
        unknown = sorted(set(data) - set(EVAL_KEYS))
        if unknown:
            raise UsageError(f"--json {args.json}: unknown keys {unknown}; allowed: "
                             f"{', '.join(EVAL_KEYS)}")
        for key in COEFFICIENTS + ("field", "u", "noise", "nu"):
            value = data.get(key)
            # bool is an int in Python, but true is no number of waves (docs/conventions.md).
            if isinstance(value, bool) or (isinstance(value, list)
                                           and any(isinstance(v, bool) for v in value)):
                raise UsageError(f"--json {args.json}: {key} must be a number, "
                                 f"got {json.dumps(value)}")
        settings.update(data)
    for key in EVAL_KEYS:
        value = getattr(args, key, None)
        if value is not None:
            settings[key] = value
    for key in COEFFICIENTS + ("field", "u", "noise"):
        try:
            settings[key] = float(settings[key])
        except (TypeError, ValueError):
            raise UsageError(f"{key} must be a number, got {settings[key]!r}") from None
        if not math.isfinite(settings[key]):
            raise UsageError(f"{key} must be finite, got {settings[key]!r}")
    if settings["zernike"] is not None:
        settings["zernike"] = parse_zernike(settings["zernike"])
        seidel = {k: settings[k] for k in COEFFICIENTS if settings[k] != 0.0}
        if seidel:
            given = ", ".join(f"{k} = {v:g}" for k, v in seidel.items())
            raise UsageError(f"give Seidel coefficients or --zernike, not both (got {given} "
                             f"with --zernike)")
    if settings["preset"] not in PRESET_NAMES:
        raise UsageError(f"preset must be one of {', '.join(PRESET_NAMES)}, "
                         f"got {settings['preset']!r}")
    _positive("noise", settings["noise"])
    nu = settings["nu"]
    if isinstance(nu, str):
        settings["nu"] = _floats(nu, "nu")
    else:
        try:
            settings["nu"] = [float(v) for v in (nu if isinstance(nu, list) else [nu])]
        except (TypeError, ValueError):
            raise UsageError(f"nu must be a number or a list of numbers (cutoff units), "
                             f"got {nu!r}") from None
        if not all(math.isfinite(v) for v in settings["nu"]):
            raise UsageError(f"nu must be finite, got {nu!r}")
    if not all(0.0 <= v for v in settings["nu"]):
        raise UsageError(f"nu must be >= 0 (cutoff units), got {settings['nu']}")
    return settings


def eval_design(settings: dict) -> tuple:
    """``(aberrations, field, u, signal, noise)`` of ``settings``, checked with the messages
    ``jmse`` gives (under ``jit`` its checks see traced values)."""
    import jmse_jax as jj
    from jmse_jax._merit import _validate

    ab: jj.AbstractAberrations
    if settings["zernike"] is not None:
        terms = settings["zernike"]
        ab = jj.Zernike(list(terms.values()), noll=tuple(terms))
    else:
        ab = jj.Seidel(**{k: settings[k] for k in COEFFICIENTS})
    signal, noise = parse_signal(settings["signal"]), jj.WhiteNoise(settings["noise"])
    _validate(ab, settings["field"], settings["u"], signal, noise)
    return ab, settings["field"], settings["u"], signal, noise


def evaluate(settings: dict) -> dict:
    """JMSE, its gradient w.r.t. the coefficients (Seidel's, or the Zernike terms'), and the
    OTF for ``settings``."""
    import jax
    import numpy as np

    import jmse_jax as jj

    ab, field, u, signal, noise = eval_design(settings)
    preset = settings["preset"]
    # Not jitted: a derivative taken outside jit sees the concrete design, so it compiles only
    # the grid that design takes (at the Fig. 1 point, 7.6 s for the whole command against
    # 41.8 s for the jitted program holding every tier, 2-core AMD EPYC, no compile cache).
    value, grad = jax.value_and_grad(jj.jmse)(ab, field, u, signal, noise, preset=preset)
    nu = np.asarray(settings["nu"], dtype=float)
    zeros = np.zeros_like(nu)
    h_x = np.asarray(jj.otf(ab, nu, zeros, field))
    h_y = np.asarray(jj.otf(ab, zeros, nu, field))
    if isinstance(ab, jj.Zernike):
        inputs = {"zernike": {str(j): c for j, c in settings["zernike"].items()}}
        gradient = {f"Z{j}": float(g) for j, g in zip(ab.noll, grad.coefficients, strict=True)}
    else:
        inputs = {k: settings[k] for k in COEFFICIENTS}
        gradient = {k: float(getattr(grad, k)) for k in COEFFICIENTS}
    return dict(
        inputs=dict(inputs, **{k: settings[k] for k in ("field", "u", "noise", "signal",
                                                         "preset")}),
        jmse=float(value),
        # The design beyond what the preset was checked at (the warning's condition).
        beyond_checked=bool(jj.beyond_checked(ab, field, u, signal, noise, preset=preset)),
        gradient=gradient,
        otf=[dict(nu=float(n), nu_x=dict(re=float(a.real), im=float(a.imag), mtf=float(abs(a))),
                  nu_y=dict(re=float(b.real), im=float(b.imag), mtf=float(abs(b))))
             for n, a, b in zip(nu, h_x, h_y, strict=True)],
    )


def _cmd_eval(args) -> int:
    import jax
    import numpy as np

    settings = eval_inputs(args)
    ab, field, u, signal, noise = eval_design(settings)
    _check_out(args.out_json)
    # jmse's warnings before the computation (seconds of compiling), in sweep's form.
    printed = warn_like_jmse(jax.tree_util.tree_map(lambda x: np.asarray(x)[None], ab),
                             np.reshape(field, 1), np.reshape(u, 1), signal, noise,
                             settings["preset"])
    # The concrete call gives the same warnings again as Python warnings: print only others.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = evaluate(settings)
    report_warnings(caught, printed)
    inp = result["inputs"]
    print(f"JMSE (Wiener-restoration MSE), preset {inp['preset']}: field {inp['field']:g}, "
          f"u = {inp['u']:g} (Nyquist/cutoff), signal {inp['signal']}, "
          f"noise {inp['noise']:g}")
    if "zernike" in inp:
        import jmse_jax as jj

        print(f"{'Zernike term (n, m)':<26}{'value [waves]':>15}{'dJMSE/dc [1/wave]':>20}")
        for j, c in settings["zernike"].items():
            n, m = jj.noll_to_nm(j)
            print(f"{f'Z{j} ({n}, {m})':<26}{c:>15.6g}{result['gradient'][f'Z{j}']:>20.6e}")
    else:
        print(f"{'coefficient':<26}{'value [waves]':>15}{'dJMSE/dw [1/wave]':>20}")
        for k in COEFFICIENTS:
            print(f"{k + ' (' + COEFFICIENT_NAMES[k] + ')':<26}{inp[k]:>15.6g}"
                  f"{result['gradient'][k]:>20.6e}")
    caveat = " (beyond the checked range: see the warning)" if result["beyond_checked"] else ""
    print(f"JMSE = {result['jmse']:.10e}{caveat}")
    print("OTF H (nu in cutoff units 1/(lambda N)):")
    print(f"{'nu':>8}{'H(nu, 0)':>28}{'|H(nu,0)|':>12}{'H(0, nu)':>28}{'|H(0,nu)|':>12}")
    for row in result["otf"]:
        a, b = row["nu_x"], row["nu_y"]
        print(f"{row['nu']:>8.4g}{a['re']:>+14.6e}{a['im']:>+13.6e}i{a['mtf']:>12.6f}"
              f"{b['re']:>+14.6e}{b['im']:>+13.6e}i{b['mtf']:>12.6f}")
    if args.out_json:
        _write_json(args.out_json, result)
    return 0


# --------------------------------------------------------------------------------------
# optimise
# --------------------------------------------------------------------------------------

LENS_VARIABLES = ("curvatures[0]", "stop_position", "image_shift")


def _cmd_optimise(args) -> int:
    import jmse_jax as jj
    from jmse_jax import lens as jl

    lo, hi = jl.PAPER_SINGLET["front_curvature_range"]
    if not lo <= args.front_curvature <= hi:
        raise UsageError(f"--front-curvature must be in [{lo}, {hi}] 1/mm, "
                         f"got {args.front_curvature}")
    lo, hi = jl.PAPER_SINGLET["stop_distance_range"]
    if not lo <= args.stop_distance <= hi:
        raise UsageError(f"--stop-distance must be in [{lo}, {hi}] mm, got {args.stop_distance}")
    if args.max_steps < 1:
        raise UsageError(f"--max-steps must be a positive integer, got {args.max_steps}")
    check_range("--u", args.u, 0.0, U_MAX, low_inclusive=False)
    signal = parse_signal(args.signal)
    noise = jj.WhiteNoise(_positive("--noise", args.noise))
    _check_out(args.out_json)
    start = jl.paper_singlet(args.stop_distance, args.front_curvature,
                             image_shift=args.image_shift)
    print(f"paper singlet (F/{jl.PAPER_SINGLET['f_number']}, f = "
          f"{jl.PAPER_SINGLET['focal_length']} mm, {jl.PAPER_SINGLET['field_angle']} deg): "
          f"start stop {args.stop_distance} mm, front curvature {args.front_curvature} 1/mm, "
          f"image shift {args.image_shift} mm; merit {args.merit}, preset {args.preset}, "
          f"u = {args.u}; optimising {', '.join(args.variables)} ...", flush=True)
    # jmse checks the designs the optimiser tries when its program runs; their warnings
    # (one per kind) are printed as this command's, after the run.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = jj.optimise(start, tuple(args.variables), merit=args.merit, u=args.u,
                             signal=signal, noise=noise, f_number=jl.PAPER_SINGLET["f_number"],
                             max_steps=args.max_steps, jmse_options={"preset": args.preset})
    report_warnings(caught)
    print(result.summary())
    # The JMSE figures above are jmse's on the designs lens_merit gives it for the start and
    # the result (their Seidel waves, the band and spectra referred to the start's lambda N):
    # the warnings jmse gives such designs (e.g. a large --image-shift) are given here too,
    # on the designs result.beyond_checked marks.
    from ._optimise import _lens_designs

    for lens in (start, result.lens):
        for waves, fields, band, scaled_signal, scaled_noise in _lens_designs(
                lens, args.u, signal, noise, result.fields, None, result.reference_scale):
            warn_like_jmse(waves, fields, band, scaled_signal, scaled_noise, args.preset)
    # The lens stores the stop's position on the axis (stop_position = -stop distance); report
    # it as --stop-distance takes it.
    final = dict(stop_distance_mm=-float(result.lens.stop_position),
                 front_curvature_per_mm=float(result.lens.curvatures[0]),
                 image_shift_mm=float(result.lens.image_shift))
    print(f"  as the flags take them: --stop-distance {final['stop_distance_mm']:.8g} mm "
          f"(stop to front vertex; stop_position above is the lens's axial coordinate of the "
          f"stop, its negative), --front-curvature {final['front_curvature_per_mm']:.8g} "
          f"1/mm, --image-shift {final['image_shift_mm']:.8g} mm")
    if args.out_json:
        _write_json(args.out_json, dict(
            start=dict(stop_distance_mm=args.stop_distance,
                       front_curvature_per_mm=args.front_curvature,
                       image_shift_mm=args.image_shift),
            final=final,
            parameters_convention="parameters: the lens's own variables; stop_position is the "
            "axial coordinate of the stop [mm], -stop_distance_mm",
            merit=result.merit, preset=args.preset, u=args.u, signal=args.signal,
            noise=args.noise, parameters=result.parameters, value=result.value,
            jmse=result.jmse, jmse_per_field=list(result.jmse_per_field),
            fields=list(result.fields), rms_wavefront_waves=result.rms_wavefront,
            start_jmse=result.start_jmse, start_rms_wavefront_waves=result.start_rms_wavefront,
            curvatures_per_mm=[float(c) for c in result.lens.curvatures],
            iterations=result.iterations, wall_time_s=result.wall_time, result=result.result,
            solver=result.solver,
            # per field: the result's JMSE beyond the preset's checked range (None: unchecked)
            beyond_checked=_optional_list(result.beyond_checked)))
    return 0


def _optional_list(values):
    """``list(values)``, or None for None."""
    return None if values is None else list(values)


# --------------------------------------------------------------------------------------
# sweep
# --------------------------------------------------------------------------------------

SWEEP_AXES = COEFFICIENTS + ("field", "u")
SWEEP_FILES = ("sweep.npz", "sweep.json", "sweep_summary.json")


def zernike_axis(name: str) -> int | None:
    """The Noll index of an axis named ``Z<j>`` (``j >= 1``), else None."""
    if len(name) > 1 and name[0] == "Z" and name[1:].isdigit() and int(name[1:]) >= 1:
        return int(name[1:])
    return None


def axis_spec(text: str) -> tuple[str, float, float, int]:
    """``NAME=MIN,MAX,N`` -> ``(name, min, max, n)``, checked; no array is made."""
    name, sep, rest = str(text).partition("=")
    name = name.strip()
    if not sep or (name not in SWEEP_AXES and zernike_axis(name) is None):
        raise UsageError(f"--axis must be NAME=MIN,MAX,N with NAME one of "
                         f"{', '.join(SWEEP_AXES)} or Z<j> (a Zernike term, Noll index "
                         f"j >= 1), got {text!r}")
    if zernike_axis(name) is not None:
        name = f"Z{zernike_axis(name)}"  # Z04 is Z4, so that a term is not swept twice
    values = _floats(rest, f"--axis {name}")
    if len(values) != 3 or values[2] != int(values[2]) or values[2] < 1:
        raise UsageError(f"--axis {name} needs MIN,MAX,N with N a positive integer, "
                         f"got {rest!r}")
    return name, values[0], values[1], int(values[2])


def parse_axis(text: str) -> tuple[str, list[float]]:
    """``NAME=MIN,MAX,N`` -> (name, N equally spaced values)."""
    import numpy as np

    name, low, high, n = axis_spec(text)
    return name, np.linspace(low, high, n).tolist()


def _check_sweep_arguments(args) -> dict[str, tuple[float, float, int]]:
    """Every check of ``sweep``'s arguments, before any array or folder is made; returns the
    axes as ``{name: (min, max, n)}``."""
    if args.max_designs < 1:
        raise UsageError(f"--max-designs must be a positive integer, got {args.max_designs}")
    if args.zernike is not None and not args.axis:
        raise UsageError("--zernike needs at least one --axis (e.g. --axis Z4=-0.5,0.5,5 or "
                         "--axis u=0.1,0.5,5): the default axes are Seidel coefficients")
    axes = {}
    for text in args.axis or ["w020=-3,3,5", "w222=-1.5,1.5,3"]:
        name, low, high, n = axis_spec(text)
        if name in axes:
            raise UsageError(f"--axis {name} is given twice; give each axis once")
        # N against --max-designs before anything of size N exists.
        if n > args.max_designs:
            raise UsageError(f"--axis {name} has N = {n}, more than --max-designs "
                             f"{args.max_designs}; lower N or raise --max-designs")
        axes[name] = (low, high, n)
    zernike = [name for name in axes if zernike_axis(name) is not None]
    if zernike or args.zernike is not None:
        base = parse_zernike(args.zernike) if args.zernike is not None else {}
        seidel = [f"--axis {k}" for k in axes if k in COEFFICIENTS]
        seidel += [f"--{k} {getattr(args, k):g}" for k in COEFFICIENTS if getattr(args, k) != 0]
        if seidel:
            raise UsageError(f"give Seidel coefficients or Zernike terms, not both (got "
                             f"{', '.join(seidel)} with {', '.join(zernike) or '--zernike'})")
        if "field" in axes:
            raise UsageError("--axis field sweeps nothing for Zernike terms, which describe "
                             "one field point; leave it out")
        given = sorted(set(base) & {zernike_axis(name) for name in zernike})
        if given:
            raise UsageError(f"Z{given[0]} is both an --axis and a --zernike term; give it once")
    n = math.prod(spec[2] for spec in axes.values())
    if n > args.max_designs:
        raise UsageError(f"the grid has {n} designs, more than --max-designs "
                         f"{args.max_designs}; lower N or raise --max-designs")
    if args.batch_size is not None and args.batch_size < 1:
        raise UsageError(f"--batch-size must be a positive integer, got {args.batch_size}")
    if args.workers is not None and args.workers < 1:
        raise UsageError(f"--workers must be a positive integer, got {args.workers}")
    # The values eval refuses, refused here too (a sweep would mark every design INVALID).
    for k in COEFFICIENTS:
        if not math.isfinite(getattr(args, k)):
            raise UsageError(f"--{k} must be finite, got {getattr(args, k)}")
    check_range("--field", args.field, 0.0, 1.0)
    check_range("--u", args.u, 0.0, U_MAX, low_inclusive=False)
    for name, (low, high, _) in axes.items():
        for end in (low, high):
            if name == "field":
                check_range("--axis field (MIN and MAX)", end, 0.0, 1.0)
            elif name == "u":
                check_range("--axis u (MIN and MAX)", end, 0.0, U_MAX, low_inclusive=False)
    parse_signal(args.signal)
    _positive("--noise", args.noise)
    return axes


def _cmd_sweep(args) -> int:
    import jax
    import numpy as np

    import jmse_jax as jj

    specs = _check_sweep_arguments(args)
    _check_out(args.out, "--out", folder=True, files=SWEEP_FILES)
    axes = {name: np.linspace(low, high, n).tolist() for name, (low, high, n) in specs.items()}
    n = math.prod(len(v) for v in axes.values())
    cube = jj.hypercube(**axes)
    fixed: dict[str, Any] = {k: getattr(args, k) for k in COEFFICIENTS}
    zernike_axes = {j: name for name in axes if (j := zernike_axis(name)) is not None}
    base = parse_zernike(args.zernike) if args.zernike is not None else {}

    def numbers(name, value):  # the whole computation runs in the designs' dtype
        largest, limit = float(np.max(np.abs(value))), float(np.finfo(args.dtype).max)
        if largest > limit:
            raise UsageError(f"--{name} reaches {largest:g}, beyond {args.dtype}'s largest "
                             f"number ({limit:.4g}); use --dtype float64")
        return np.asarray(value, dtype=args.dtype)

    every = np.zeros(n, dtype=args.dtype)
    ab: jj.AbstractAberrations
    batch_ab: jj.AbstractAberrations
    if zernike_axes or base:
        # One row of coefficients per design, in rising Noll index; a batched Zernike is
        # made under vmap (its constructor checks one design's shape).
        noll = tuple(sorted(set(base) | set(zernike_axes)))
        columns = [numbers(f"axis Z{j}", cube[zernike_axes[j]]) if j in zernike_axes
                   else numbers(f"zernike Z{j}", base[j]) for j in noll]
        coefficients = np.stack([every + c for c in columns], axis=1)  # fixed terms: (n,)
        ab = jax.vmap(lambda c: jj.Zernike(c, noll=noll))(coefficients)
        fixed = {"zernike": {str(j): c for j, c in base.items()}}
        batch_ab = ab
    else:
        ab = jj.Seidel(**{k: numbers(k, cube.get(k, fixed[k])) for k in COEFFICIENTS})
        batch_ab = jj.Seidel(**{k: every + getattr(ab, k) for k in COEFFICIENTS})
    field = numbers("field", cube.get("field", args.field))
    u = numbers("u", cube.get("u", args.u))
    signal = parse_signal(args.signal)
    noise = jj.WhiteNoise(_positive("--noise", args.noise))
    # Under vmap jmse gives its warnings only when the program runs, without the designs'
    # values: give them here, before the sweep compiles.
    warn_like_jmse(batch_ab, every + field, every + u, signal, noise, args.preset)
    print(f"sweep of {n} designs over {', '.join(f'{k} ({len(v)})' for k, v in axes.items())}; "
          f"preset {args.preset}, grad {args.grad}, {args.dtype}", flush=True)
    with _checked_already():  # the warnings above are sweep_jmse's own: not twice
        result = jj.sweep_jmse(ab, field, u, signal, noise, grad=args.grad,
                               preset=args.preset, batch_size=args.batch_size,
                               workers=args.workers, progress=not args.quiet,
                               metadata=dict(axes=axes, fixed=dict(fixed, field=args.field,
                                                                   u=args.u),
                                             signal=args.signal, noise=args.noise,
                                             preset=args.preset, dtype=args.dtype,
                                             grad=args.grad, command="jmse-jax sweep"))
    path = result.save(os.path.join(args.out, "sweep.npz"))
    values = np.asarray(result.value)
    ok = result.ok
    print(f"status: {result.status_counts()}")
    beyond = result.beyond_checked
    n_beyond = None if beyond is None else int(beyond.sum())
    if n_beyond:
        print(f"beyond the checked range (warned above): {n_beyond} of {n} designs, marked "
              f"in sweep.npz's beyond_checked")
    if ok.any():
        best = int(np.argmin(np.where(ok, values, np.inf)))
        design = ", ".join(f"{k} = {cube[k][best]:g}" for k in axes)
        caveat = " (beyond the checked range)" if beyond is not None and beyond[best] else ""
        print(f"JMSE min {values[ok].min():.6e}, max {values[ok].max():.6e}; best: {design}"
              f"{caveat}")
    compile_s, run_s = result.metadata.get("compile_s"), result.metadata.get("run_s")
    seconds = None if compile_s is None or run_s is None else compile_s + run_s
    # A design that failed has JMSE +inf: written as null (strict JSON), see its status.
    summary = dict(n_designs=n, axes=axes, preset=args.preset, dtype=args.dtype,
                   status_counts=result.status_counts(), n_beyond_checked=n_beyond,
                   jmse=values.tolist(), npz=str(path),
                   seconds=seconds, compile_s=compile_s, run_s=run_s)
    _write_json(os.path.join(args.out, "sweep_summary.json"), summary)
    print(f"wrote {path} and {path.with_suffix('.json')}")
    return 0


# --------------------------------------------------------------------------------------
# bench
# --------------------------------------------------------------------------------------


def benchmarks_folder() -> pathlib.Path:
    """``benchmarks/`` next to the package (present in a repository checkout)."""
    return pathlib.Path(__file__).resolve().parent.parent / "benchmarks"


def builtin_bench(repeats: int = 5) -> dict:
    """Warm time of ``jmse`` (the ``"fast"`` preset) vs ``baseline_jmse`` B = 64, Fig. 1 point:
    each the fastest of ``repeats`` warm calls, the four programs taken in turn, traced
    without ``jmse``'s run-time checks (``_warm_times``)."""
    import jax

    import jmse_jax as jj
    from jmse_jax._reproduce import _warm_times

    ab = jj.Seidel(**FIG1)
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
    cases = [("baseline B=64", lambda a: jj.baseline_jmse(a, FIG1_FIELD, FIG1_U, signal, noise,
                                                           B=64))]
    cases.append(("jmse fast", lambda a: jj.jmse(a, FIG1_FIELD, FIG1_U, signal, noise,
                                                 preset="fast")))
    print(f"{'method':<16}{'JMSE':>14}{'value':>12}{'value+grad':>13}", flush=True)
    rows = _warm_times(cases, (ab,), rounds=repeats, calls=1)
    for name, row in rows.items():
        print(f"{name:<16}{row['jmse']:>14.7e}{row['time_value_s'] * 1e3:>10.2f}ms"
              f"{row['time_value_and_grad_s'] * 1e3:>11.2f}ms", flush=True)
    return dict(methods=rows, repeats=repeats, device=str(jax.devices()[0]),
                run_time_checks=False)


def _cmd_bench(args) -> int:
    if args.builtin:
        if args.repeats < 1:
            raise UsageError(f"--repeats must be an integer >= 1, got {args.repeats}")
        _check_out(args.out_json)
        result = builtin_bench(args.repeats)
        if args.out_json:
            _write_json(args.out_json, result)
        return 0
    folder = benchmarks_folder()
    script = folder / "run_all.py"
    if not script.is_file():
        raise UsageError(f"no benchmarks/run_all.py next to the package ({folder}): it ships "
                         "with the repository only; use 'jmse-jax bench --builtin'")
    command = [sys.executable, str(script)] + ([] if args.full else ["--quick"])
    print(f"running {' '.join(command)} (outputs in {folder / 'results'})", flush=True)
    return subprocess.call(command, cwd=folder.parent)


# --------------------------------------------------------------------------------------
# reproduce
# --------------------------------------------------------------------------------------


def _cmd_reproduce(args) -> int:
    from ._reproduce import run

    _check_out(args.out, "--out", folder=True)
    run(args.out, quick=args.quick, log=lambda text: print(text, flush=True))
    return 0


# --------------------------------------------------------------------------------------


def _add_coefficients(parser, default=None, what="value"):
    for k in COEFFICIENTS:
        parser.add_argument(f"--{k}", type=float, default=default, metavar="WAVES",
                            help=f"{COEFFICIENT_NAMES[k]} coefficient {what} [waves]"
                            + ("" if default is None else f" (default {default})"))


def _add_spectra(parser, defaults: bool):
    parser.add_argument("--signal", default="markov:1,5" if defaults else None,
                        help=SIGNAL_HELP + " (default markov:1,5)")
    parser.add_argument("--noise", type=float, default=1e-3 if defaults else None,
                        metavar="VARIANCE",
                        help="white noise power spectral density S_n (default 1e-3)")


def _version() -> str:
    """``jmse-jax --version``: the package's version and what it computes with (what a
    report or a citation of a result should name)."""
    import platform

    import jax
    import jaxlib

    from . import __version__

    return (f"jmse-jax {__version__} (jax {jax.__version__}, jaxlib {jaxlib.__version__}, "
            f"Python {platform.python_version()})")


def build_parser() -> argparse.ArgumentParser:
    fmt = _HelpFormatter
    parser = _Parser(
        prog="jmse-jax",
        description="JMSE (Wiener-restoration MSE) merit for computational-imaging design. "
        + UNITS + " Lens quantities in mm.",
    )
    parser.add_argument("--version", action="version", version=_version(),
                        help="print the package's version, and JAX's, and exit")
    parser.add_argument("--no-compile-cache", action="store_true",
                        help="do not keep compiled programs between runs (by default they are "
                        "kept in $XDG_CACHE_HOME/jmse_jax/xla, or ~/.cache/jmse_jax/xla, unless "
                        "JAX_COMPILATION_CACHE_DIR names another place)")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)

    ev = sub.add_parser(
        "eval", help="JMSE, its gradient and the OTF for Seidel or Zernike coefficients [waves]",
        description="Evaluate the JMSE, its gradient with respect to the Seidel coefficients "
        "(or the Zernike terms of --zernike) and the OTF at a few frequencies. Values come "
        "from the defaults, then --json FILE (an object with the same keys: w020 ... w111, "
        "zernike as an object such as {\"4\": 0.5}, field, u, noise, signal, preset, nu), "
        "then the flags. " + UNITS)
    _add_coefficients(ev, what="(default 0, or the Fig. 1 value with --point fig1)")
    ev.add_argument("--point", dest="preset_point", choices=("zero", "fig1"), default="zero",
                    help="starting coefficients: all zero, or the paper's Fig. 1 point")
    ev.add_argument("--zernike", metavar="NOLL:WAVES,...", help=ZERNIKE_HELP)
    ev.add_argument("--field", type=float, help="fractional field height in [0, 1] "
                    f"(default {FIG1_FIELD})")
    ev.add_argument("--u", type=float, help="sensor Nyquist / optical cutoff, in (0, 1.5] "
                    f"(default {FIG1_U})")
    _add_spectra(ev, defaults=False)
    ev.add_argument("--preset", choices=PRESET_NAMES, help="jmse accuracy preset "
                    "(default 'default')")
    ev.add_argument("--nu", help="comma-separated frequencies [cutoff units 1/(lambda N)] at "
                    "which the OTF is printed along nu_x and nu_y (default 0.05,0.1,0.2)")
    ev.add_argument("--json", metavar="FILE", help="JSON file with the inputs (keys as flags)")
    ev.add_argument("--out-json", metavar="FILE", help="write the numbers to FILE")
    ev.set_defaults(func=_cmd_eval)

    op = sub.add_parser(
        "optimise", formatter_class=fmt,
        help="optimise the paper's F/4.6 singlet (mm) for the field-averaged JMSE",
        description="Optimise the paper's F/4.6, f = 9 mm, 10 deg N-BK7 singlet (the setup of "
        "benchmarks/optimise_singlet.py): variables front curvature [1/mm], stop position "
        "[mm] and image shift [mm]; the back curvature is solved for F/4.6. Objective: JMSE "
        "averaged over fields 0, 0.7, 1.0. " + UNITS)
    op.add_argument("--stop-distance", type=float, default=1.0,
                    help="start: stop to front vertex [mm], in [0, 3]")
    op.add_argument("--front-curvature", type=float, default=0.05,
                    help="start: front curvature [1/mm], in [-0.1, 0.1]")
    op.add_argument("--image-shift", type=float, default=0.0,
                    help="start: image plane from paraxial focus [mm], + away from the lens")
    op.add_argument("--variables", nargs="+", default=list(LENS_VARIABLES),
                    help="lens parameters to optimise")
    op.add_argument("--merit", choices=("jmse", "rms"), default="jmse",
                    help="JMSE or RMS wavefront [waves]")
    op.add_argument("--preset", choices=PRESET_NAMES, default="fast", help="jmse preset")
    op.add_argument("--u", type=float, default=0.2,
                    help="sensor Nyquist / optical cutoff, in (0, 1.5]")
    _add_spectra(op, defaults=True)
    op.add_argument("--max-steps", type=int, default=200, help="solver step limit")
    op.add_argument("--out-json", metavar="FILE", help="write the result to FILE")
    op.set_defaults(func=_cmd_optimise)

    sw = sub.add_parser(
        "sweep", formatter_class=fmt,
        help="JMSE over a small aberration hypercube; .npz + JSON into --out",
        description="JMSE over every combination of the given axes (jmse_jax.hypercube + "
        "sweep_jmse). Each --axis NAME=MIN,MAX,N gives N equally spaced values of NAME "
        f"({', '.join(SWEEP_AXES)}, or Z<j> for the Zernike term of Noll index j, in waves "
        "RMS, with the terms of --zernike held fixed); the other coefficients take their flag "
        "values. Default "
        "axes: w020=-3,3,5 and w222=-1.5,1.5,3 (waves). Writes sweep.npz, its JSON header "
        "sweep.json and sweep_summary.json, whose jmse list has null for a design that "
        "failed (its status says why; strict JSON has no Infinity). " + UNITS)
    sw.add_argument("--axis", action="append", metavar="NAME=MIN,MAX,N",
                    help="a grid axis (repeatable); coefficients in waves")
    _add_coefficients(sw, default=0.0, what="held fixed when not an axis")
    sw.add_argument("--zernike", metavar="NOLL:WAVES,...",
                    help="Zernike terms held fixed (Z<j> axes vary the others); "
                    + ZERNIKE_HELP.split(": ", 1)[1])
    sw.add_argument("--field", type=float, default=FIG1_FIELD,
                    help="fractional field height in [0, 1] (when not an axis)")
    sw.add_argument("--u", type=float, default=FIG1_U,
                    help="sensor Nyquist / optical cutoff in (0, 1.5] (when not an axis)")
    _add_spectra(sw, defaults=True)
    sw.add_argument("--preset", choices=PRESET_NAMES, default="fast", help="jmse preset")
    sw.add_argument("--grad", action="store_true", help="also store the gradients")
    sw.add_argument("--dtype", choices=("float64", "float32"), default="float64",
                    help="precision of the whole computation; float32 is about 1.7x faster "
                         "on a CPU and within about 2e-6 of float64 on the presets")
    sw.add_argument("--batch-size", type=int, default=None,
                    help="designs per vmap chunk (default: 1 on CPU, "
                         f"{DEFAULT_ACCELERATOR_BATCH} on GPU/TPU)")
    sw.add_argument("--workers", type=int, default=None,
                    help="host threads issuing calls at once (default: on CPU, cores per "
                         "device)")
    sw.add_argument("--max-designs", type=int, default=10000, help="refuse larger grids")
    sw.add_argument("--quiet", action="store_true", help="no progress bar")
    sw.add_argument("--out", default="jmse_output/sweep", help="output folder")
    sw.set_defaults(func=_cmd_sweep)

    be = sub.add_parser(
        "bench", formatter_class=fmt,
        help="run benchmarks/run_all.py --quick, or a built-in timing (--builtin)",
        description="Without --builtin: run the repository's benchmarks/run_all.py --quick "
        "(--full: everything, ~20 min) if the benchmarks folder is next to the package. With "
        "--builtin: time jmse (fast preset) against baseline_jmse B = 64 at the Fig. 1 point "
        "(field 0.95, u = 0.2 Nyquist/cutoff, waves). Times in ms, float64.")
    be.add_argument("--builtin", action="store_true", help="tiny built-in timing only")
    be.add_argument("--full", action="store_true", help="run_all.py without --quick")
    be.add_argument("--repeats", type=int, default=5,
                    help="timed calls of each program after the compiling one, the programs "
                         "taken in turn; the fastest is reported (--builtin)")
    be.add_argument("--out-json", metavar="FILE", help="write the timings (--builtin)")
    be.set_defaults(func=_cmd_bench)

    rep = sub.add_parser(
        "reproduce", formatter_class=fmt,
        help="reproduce the paper's Fig. 1 and Fig. 4 into an output folder",
        description="Berkner & Shroff's Fig. 1 point (baseline B = 64 vs jmse), the Fig. 1 "
        "maps (OPD [waves] and log10 S_e over the band, frequencies in cutoff units "
        "1/(lambda N), u = 0.2 Nyquist/cutoff) and Fig. 4 right (JMSE versus p for the "
        "quadrature rules at defocus -6 and -2.75 waves) and Fig. 4 left (RMS error [waves] "
        "of the wavefront rebuilt from L rings x K arms of polar samples, needs scipy), as "
        "PNG + JSON + markdown. "
        "1-3 minutes on a 2-core CPU.")
    rep.add_argument("--out", default="jmse_output", help="output folder")
    rep.add_argument("--quick", action="store_true", help="coarse grids, for testing")
    rep.set_defaults(func=_cmd_reproduce)
    return parser


def compile_cache_dir() -> pathlib.Path:
    """Where the console script keeps compiled programs between runs (``$XDG_CACHE_HOME`` or
    ``~/.cache``, then ``jmse_jax/xla``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return pathlib.Path(base) / "jmse_jax" / "xla"


def _enable_compile_cache(jax) -> None:
    """Turn on JAX's persistent compilation cache for this process (the console script only:
    the library never changes a user's JAX configuration). The default preset's value and
    gradient take about 12 s to compile on a 2-core CPU and about 1 s to read back (the ~5 s
    of tracing before it are not cached). A cache
    location the user set (``JAX_COMPILATION_CACHE_DIR``) is used as it is; an unwritable
    location turns the cache off with a one-line note. Programs that compile in under 1 s
    are not kept, unless ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS`` says otherwise."""
    if jax.config.jax_compilation_cache_dir:
        return
    path = compile_cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        print(f"jmse-jax: note: compilation cache off ({path}: {e.strerror})", file=sys.stderr)
        return
    jax.config.update("jax_compilation_cache_dir", str(path))
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)
    if not args.no_compile_cache:
        _enable_compile_cache(jax)
    try:
        return args.func(args)
    except (ValueError, TypeError) as e:
        # UsageError and the library's validation errors (TypeError: a value of the wrong
        # kind, e.g. in a --json file): one line, exit status 2.
        message = " ".join(str(e).split())
        parser.exit(2, f"jmse-jax: error: {message}\n")
    except OSError as e:  # a file that cannot be read or written
        parser.exit(1, f"jmse-jax: error: {e}\n")


if __name__ == "__main__":
    sys.exit(main())
