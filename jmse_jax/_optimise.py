"""JMSE-driven lens optimisation (optimistix; jaxopt's L-BFGS-B when box bounds are given).

The objective is the JMSE of the lens (SPEC §2, Eq. 7 of Berkner & Shroff) averaged over
field points and, optionally, wavelengths; the alternative ``merit="rms"`` is the classical
optical merit (mean-square wavefront error over the same fields), so the two designs can be
compared from the same start.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import re
import time
import warnings
from collections.abc import Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ._merit import (
    _FLOOR_OPTIONS,
    _GRID_OPTIONS,
    _VALUE_FLOORS,
    _auto_counts,
    _own_counts,
    _snr_peaks,
    _warn_beyond_checked_snr,
    jmse,
    jmse_options as _full_jmse_options,
)
from ._numerics import all_finite, check_choice, check_count, check_range, is_concrete
from ._spectra import AbstractNoise, AbstractSignal, MarkovSignal, WhiteNoise
from ._sweep import beyond_checked
from .lens import (
    Lens,
    paraxial_trace,
    rms_wavefront_error,
    solve_last_curvature,
)
from .lens._paraxial import _raise_for, _status
from .lens._seidel import _waves_from_traces

__all__ = ["MERITS", "SOLVERS", "OptimisationResult", "lens_beyond_checked", "lens_merit",
           "optimise"]

#: Names accepted by ``lens_merit`` / ``optimise`` for ``merit``.
MERITS = ("jmse", "rms")
#: Named optimistix minimisers (``"lbfgsb"`` is jaxopt's, used whenever bounds are given).
SOLVERS = ("bfgs", "nonlinear_cg", "lbfgs", "lbfgsb")

#: Default variable scales (the size of a unit step of the normalised optimisation variable).
#: A 0.1 mm image shift is about one wave of defocus at F/4.6 in the visible.
_DEFAULT_SCALES = {
    "curvatures": 0.01,
    "thicknesses": 1.0,
    "stop_position": 1.0,
    "image_shift": 0.1,
    "conics": 1.0,
    "aspheric4": 1e-5,
    "ep_radius": 0.1,
    "field_angle": 1.0,
}


class _RescaledSignal(AbstractSignal):
    """``S_x`` seen in the frequency units of another wavelength: ``S(nu / s) / s²``."""

    base: AbstractSignal
    scale: jax.Array

    def radial(self, r):
        return self.base.radial(r / self.scale) / (self.scale * self.scale)


class _RescaledNoise(AbstractNoise):
    """``S_n`` seen in the frequency units of another wavelength: ``S(nu / s) / s²``."""

    base: AbstractNoise
    scale: jax.Array

    def __call__(self, nu_x, nu_y):
        return self.base(nu_x / self.scale, nu_y / self.scale) / (self.scale * self.scale)

    @property
    def x_symmetric(self) -> bool:
        return self.base.x_symmetric


def _f_number_of(trace):
    slope = trace.u[-1]
    slope = jnp.where(slope == 0, -jnp.ones_like(slope), slope)
    return -1.0 / (2.0 * trace.n[-1] * slope)


def lens_merit(
    lens: Lens,
    *,
    merit: str = "jmse",
    u=0.2,
    signal: AbstractSignal | None = None,
    noise: AbstractNoise | None = None,
    fields=(0.0, 0.7, 1.0),
    field_weights=None,
    wavelengths=None,
    reference_scale=None,
    jmse_options: dict | None = None,
):
    """Field- (and wavelength-) averaged JMSE, or mean-square wavefront error, of ``lens``.

    .. math::

        M = \\frac{1}{N_\\lambda} \\sum_\\lambda \\frac{\\sum_f w_f\\,
            \\mathrm{JMSE}(\\mathrm{Seidel}(\\lambda), h_f, u_\\lambda)}{\\sum_f w_f}

    Parameters
    ----------
    lens : Lens
    merit : {"jmse", "rms"}
        ``"rms"`` averages the wavefront variance [waves²] instead (piston and tilt removed).
    u : float [Nyquist / cutoff] at the reference wavelength and ``reference_scale``
    signal, noise : spectra in the frequency units of ``reference_scale`` (defaults
        ``MarkovSignal(1, 5)``, ``WhiteNoise(1e-3)``, the paper's Fig. 1 setting)
    fields : sequence of float in [0, 1] [fraction of full field]
    field_weights : sequence of float >= 0, optional (equal by default)
    wavelengths : sequence of float [µm], optional (default: ``lens.wavelength`` only)
    reference_scale : float [µm], optional
        ``lambda N`` that the frequency unit of ``u``, ``signal`` and ``noise`` refers to
        (default: this lens at its reference wavelength). At wavelength ``lambda`` with
        working F-number ``N`` the pixel pitch and the scene are fixed in physical units, so
        ``u`` becomes ``u s`` and the spectra ``S(nu / s) / s²`` with
        ``s = lambda N / reference_scale``.
    jmse_options : dict, optional, keyword options of ``jmse`` (e.g. ``{"preset": "fast"}``)
        With ``"high"`` at a concrete peak ``S_x / S_n`` beyond ``CHECKED_SNR`` and none
        of the counts (``se_angular``, ``otf_radial``, their ``grad_`` twins) nor grid
        options given, it takes ``otf_radial=otf_radial_for(u, signal, noise)`` and, for
        the gradient, ``grad_se_angular=se_angular_for(u, signal, noise)`` (``jmse``'s
        note): inside, ``u`` and the spectra are traced, so ``jmse`` cannot choose them
        there.

    Returns
    -------
    scalar. ``+inf`` (with a zero gradient, never NaN) when the lens is non-physical under
    tracing (``lens_status(lens).ok`` false); a concrete non-physical lens raises
    ``ValueError``.
    """
    if not isinstance(lens, Lens):
        raise TypeError(f"lens must be a jmse_jax.lens.Lens, got {type(lens)}")
    check_choice("merit", merit, MERITS)
    dtype = lens.ep_radius.dtype
    # Concrete arguments are checked now even inside a caller's jit, where the checks' own
    # array operations would otherwise be staged out and give tracers.
    with jax.ensure_compile_time_eval():
        fields, weights, wavelengths = _check_merit_arguments(
            dtype, u, signal, noise, fields, field_weights, wavelengths, jmse_options,
            warn=merit == "jmse")
        if is_concrete(lens):
            _check_lens_at(lens, wavelengths)
        if merit == "jmse":
            # "high"'s counts at low noise (jmse's otf_radial, grad_se_angular), as jmse
            # takes them by itself. Inside _lens_merit_jit u and the spectra are traced
            # (the band follows lambda N), so jmse cannot choose them there itself.
            jmse_options = _with_gradient_counts(jmse_options, u, signal, noise,
                                                 prefix="grad_")
    if reference_scale is not None:
        check_range("reference_scale", reference_scale, 0.0, None, low_inclusive=False)
        reference_scale = jnp.asarray(reference_scale, dtype)
    return _lens_merit_jit(
        lens, merit, jnp.asarray(u, dtype), signal, noise, fields, weights, wavelengths,
        reference_scale, _freeze(jmse_options),
    )


def _with_gradient_counts(jmse_options, u, signal, noise, prefix=""):
    """``jmse_options`` with the counts of ``_auto_counts`` (``otf_radial``, which
    holds values too, and ``se_angular`` named with ``prefix``: ``""`` for ``optimise``,
    whose every value comes with a gradient; ``"grad_"`` for ``lens_merit``, whose value
    keeps the preset's angular count, as ``jmse``'s own choice does) where they are more
    than the preset's own grid has: ``"high"`` (the peaks without the default's tiers) at
    a concrete peak ``S_x / S_n`` beyond ``CHECKED_SNR``, with none of these counts nor
    grid options given; within it,
    ``grad_se_angular`` at the grid's own count (checked: no run-time check then).
    Anything else (bad arguments included, which the checks then refuse) is returned as
    it is."""
    if (jmse_options is None or not isinstance(jmse_options, dict)
            or any(name in jmse_options for name in _FLOOR_OPTIONS + _GRID_OPTIONS)
            or not isinstance(signal, AbstractSignal) or not isinstance(noise, AbstractNoise)
            or not is_concrete((u, signal, noise))):
        return jmse_options
    try:
        options = _full_jmse_options(**jmse_options)
        counts, _ = _auto_counts(options, options["tiers"], (u, signal, noise))
    except (TypeError, ValueError):
        return jmse_options  # refused with its own message by the checks that follow
    if counts is None:
        return jmse_options  # not "high"-like: the choice does not apply
    if counts:
        # The radial OTF nodes hold the value too (jmse takes them for both by itself).
        return {**jmse_options, **{("" if k in _VALUE_FLOORS else prefix) + k: n
                                   for k, n in counts.items()}}
    # Within CHECKED_SNR the grid's own counts hold the gradient (se_angular_for gives
    # "high"'s 960 there, more than the 48 of "fast" with peaks=True, which holds it as it
    # is). Saying so spares the gradients a run-time check of the ratio: inside
    # _lens_merit_jit jmse sees u and the spectra traced (_merit._auto_counts's watch).
    return {**jmse_options, "grad_se_angular": _own_counts(options)["se_angular"]}


def _check_merit_arguments(dtype, u, signal, noise, fields, field_weights, wavelengths,
                           jmse_options, gradient=False, warn=True):
    """Checks of the arguments ``lens_merit`` and ``optimise`` share; returns ``fields``,
    the field weights and ``wavelengths`` (None or a 1-D array) as arrays of ``dtype``.
    ``gradient`` (``optimise`` of the JMSE): the noise check holds the gradient to
    ``CHECKED_SNR``. ``warn``: the noise check runs (not for ``lens_merit``'s ``"rms"``,
    which computes no JMSE; ``optimise``'s reports the JMSE, so it checks the value)."""
    check_range("u", u, 0.0, 1.5, low_inclusive=False)
    if np.ndim(u) != 0:
        raise ValueError(f"u must be a scalar, got shape {np.shape(u)}")
    if signal is not None and not isinstance(signal, AbstractSignal):
        raise TypeError(f"signal must be a jmse_jax signal model, got {type(signal)}")
    if noise is not None and not isinstance(noise, AbstractNoise):
        raise TypeError(f"noise must be a jmse_jax noise model, got {type(noise)}")
    if jmse_options is not None and not isinstance(jmse_options, dict):
        raise TypeError(f"jmse_options must be a dict of jmse keyword options, "
                        f"got {jmse_options!r}")
    if (warn and signal is not None and noise is not None and is_concrete((u, signal, noise))
            and not any(key in (jmse_options or {}) for key in _GRID_OPTIONS)):
        # lens_merit -> _check_merit_arguments -> here -> warn: the user's call is 4 up.
        options = _full_jmse_options(**(jmse_options or {}))
        _warn_beyond_checked_snr(u, signal, noise, stacklevel=4,
                                 peaks=_snr_peaks(options["peaks"], options["tiers"]),
                                 gradient=gradient, **{
                                     floor: max(options[floor] or 0,
                                                options["grad_" + floor] or 0) or None
                                     for floor in ("se_angular", "otf_radial")})
    check_range("fields", fields, 0.0, 1.0)
    fields = jnp.asarray(fields, dtype)
    if fields.ndim != 1 or fields.shape[0] == 0:
        raise ValueError(f"fields must be a non-empty 1-D sequence, got shape "
                         f"{tuple(fields.shape)}")
    if field_weights is None:
        weights = jnp.ones_like(fields)
    else:
        check_range("field_weights", field_weights, 0.0, None)
        weights = jnp.asarray(field_weights, dtype)
        if weights.shape != fields.shape:
            raise ValueError(
                f"field_weights must have one weight per field ({fields.shape[0]}), "
                f"got shape {tuple(weights.shape)}"
            )
        if is_concrete(weights) and not float(jnp.sum(weights)) > 0:
            raise ValueError(f"field_weights must have a positive sum, got {field_weights!r}")
    if wavelengths is not None:
        check_range("wavelengths", wavelengths, 0.2, 20.0)
        # jnp.asarray first: a list of traced scalars (wavelengths as variables of a jitted
        # caller) has no NumPy shape.
        array = jnp.asarray(wavelengths, dtype)
        if array.ndim != 1 or array.shape[0] == 0:
            raise ValueError(f"wavelengths must be a non-empty sequence of floats [µm], "
                             f"got {wavelengths!r}")
        wavelengths = array
    return fields, weights, wavelengths


def _check_bound(name, pair):
    """``bounds[name]`` as ``(low, high)`` floats or None; ``ValueError`` for anything else."""
    if not isinstance(pair, (tuple, list)) or len(pair) != 2:
        raise ValueError(f"bounds[{name!r}] must be a pair (low, high) of floats or None, "
                         f"got {pair!r}")
    out = []
    for side, value in zip(("low", "high"), pair, strict=True):
        if value is not None:
            if isinstance(value, bool) or not isinstance(value, numbers.Real) \
                    or math.isnan(value):
                raise ValueError(f"bounds[{name!r}]'s {side} must be a real number or None, "
                                 f"got {value!r}")
            value = float(value)
        out.append(value)
    return tuple(out)


def _freeze(options) -> tuple:
    """``jmse`` keyword options as a hashable (static) tuple of pairs."""
    items = []
    for key, value in sorted((options or {}).items()):
        if isinstance(value, (list, np.ndarray)):
            # A NumPy array (e.g. nodes=np.array([24, 16])) would be traced, not static.
            value = tuple(np.asarray(value).tolist())
        items.append((key, value))
    return tuple(items)


@eqx.filter_jit
def _status_jit(lens, wavelength=None):
    return _status(lens, paraxial_trace(lens, wavelength))


def lens_beyond_checked(
    lens: Lens,
    *,
    u=0.2,
    signal: AbstractSignal | None = None,
    noise: AbstractNoise | None = None,
    fields=(0.0, 0.7, 1.0),
    wavelengths=None,
    reference_scale=None,
    jmse_options: dict | None = None,
) -> np.ndarray:
    """Per field, whether the designs ``lens_merit`` hands to ``jmse`` lie beyond what the
    preset's grids were checked at (``beyond_checked``): the lens's Seidel waves at that
    field and wavelength, the band ``u`` and the spectra referred to the wavelength's
    ``lambda N``, as ``lens_merit`` passes them. For an optimiser's loop or a notebook that
    wants to know, as a value, whether the JMSE of a design is held to the preset's
    accuracy (``jmse``'s ``AccuracyWarning`` says the same at run time).

    Parameters
    ----------
    lens : Lens, concrete and physical at every wavelength (else ``ValueError``)
    u, signal, noise, fields, wavelengths, reference_scale, jmse_options
        As in ``lens_merit`` (``jmse_options`` default: the default preset). Grid options
        (``nodes``, ``se_nodes``, ...) have no checked range and are refused.

    Returns
    -------
    ndarray of bool, shape ``(len(fields),)``: True where the design at that field is
    beyond the checked range at any of the wavelengths.
    """
    if not isinstance(lens, Lens):
        raise TypeError(f"lens must be a jmse_jax.lens.Lens, got {type(lens)}")
    if not is_concrete((lens, u, signal, noise, fields, wavelengths, reference_scale)):
        raise TypeError("lens_beyond_checked needs concrete values, got traced ones (under "
                        "jit, vmap or grad jmse checks its designs when the program runs)")
    dtype = lens.ep_radius.dtype
    fields, _, wavelengths = _check_merit_arguments(
        dtype, u, signal, noise, fields, None, wavelengths, jmse_options, warn=False)
    given = [name for name in _GRID_OPTIONS if (jmse_options or {}).get(name) is not None]
    if given:
        raise ValueError(f"lens_beyond_checked: grid options ({', '.join(given)}) have no "
                         f"checked range; the bounds are those of the presets' own grids")
    _check_lens_at(lens, wavelengths)
    if reference_scale is not None:
        check_range("reference_scale", reference_scale, 0.0, None, low_inclusive=False)
    options = _with_gradient_counts(dict(jmse_options or {}), u, signal, noise,
                                    prefix="grad_")
    return _lens_beyond(lens, u, signal, noise, fields, wavelengths, reference_scale, options)


def _wavelength_traces(lens, wavelengths, reference_scale):
    """What ``lens_merit`` takes per wavelength: the reference wavelength's trace, the
    ``(wavelength, trace)`` pairs averaged over (None: the reference alone), and the
    ``lambda N`` that ``u`` and the spectra refer to: None where they are the lens's own
    (one wavelength, no ``reference_scale``), else ``reference_scale`` or the lens's own
    ``lambda N``. ``_wavelength_scale`` gives each wavelength's factor."""
    reference = paraxial_trace(lens)
    if wavelengths is None:
        return reference, [(lens.wavelength, reference)], reference_scale
    if reference_scale is None:
        reference_scale = lens.wavelength * _f_number_of(reference)
    return reference, [(wl, paraxial_trace(lens, wl)) for wl in wavelengths], reference_scale


def _wavelength_scale(wl, trace, reference_scale):
    """``lambda N / reference_scale`` at a wavelength of ``_wavelength_traces`` (None where
    ``u`` and the spectra are the lens's own)."""
    return None if reference_scale is None else wl * _f_number_of(trace) / reference_scale


def _lens_designs(lens, u, signal, noise, fields, wavelengths, reference_scale):
    """The designs ``lens_merit`` hands to ``jmse`` (``_merit_table``), one batch per
    wavelength: ``(aberrations, fields, band, signal, noise)``, the aberrations' leaves and
    the band of shape ``fields.shape``, the spectra referred to the wavelength's
    ``lambda N``. For a concrete, physical ``lens``; ``reference_scale`` None: its own."""
    signal = MarkovSignal(1.0, 5.0) if signal is None else signal
    noise = WhiteNoise(1e-3) if noise is None else noise
    fields = np.asarray(fields, float)
    dtype = lens.ep_radius.dtype
    reference, per_wavelength, reference_scale = _wavelength_traces(lens, wavelengths,
                                                                    reference_scale)
    for wl, trace in per_wavelength:
        aberrations = _waves_from_traces(lens, trace, reference, wl)
        scale = _wavelength_scale(wl, trace, reference_scale)
        scale = jnp.ones((), dtype) if scale is None else jnp.asarray(scale, dtype)
        yield (jax.tree_util.tree_map(lambda a: np.full(fields.shape, float(a)), aberrations),
               fields, np.full(fields.shape, float(u * scale)),
               _RescaledSignal(signal, scale), _RescaledNoise(noise, scale))


def _lens_beyond(lens, u, signal, noise, fields, wavelengths, reference_scale, options):
    """``lens_beyond_checked`` on checked arguments (a concrete, physical ``lens``; the
    options ``lens_merit`` or ``optimise`` pass to ``jmse``, without grid options)."""
    options = dict(options)
    preset = options.pop("preset", "default")
    beyond = np.zeros(np.shape(fields), bool)
    for design in _lens_designs(lens, u, signal, noise, fields, wavelengths, reference_scale):
        beyond |= beyond_checked(*design, preset=preset, **options)
    return beyond


def _check_lens_at(lens, wavelengths):
    """Raise ``ValueError`` when the concrete ``lens`` is non-physical at its reference
    wavelength or at any of ``wavelengths`` (None: the reference only), naming the
    wavelength. Inside a caller's jit, call it under ``jax.ensure_compile_time_eval()``
    (as ``lens_merit`` does), or ``_status_jit`` gives tracers."""
    _raise_for(_status_jit(lens), lens)
    if wavelengths is None or not is_concrete(wavelengths):
        return  # traced wavelengths: the merit says +inf where the lens fails
    for wl in wavelengths:
        try:
            _raise_for(_status_jit(lens, wl), lens, wl)
        except ValueError as error:
            raise ValueError(f"at wavelength {float(wl)!r} µm: {error}") from None


@eqx.filter_jit
def _lens_merit_jit(lens, merit, u, signal, noise, fields, weights, wavelengths,
                    reference_scale, jmse_items):
    wavelengths = None if wavelengths is None else list(wavelengths)
    table, ok = _merit_table(lens, merit, u, signal, noise, fields, wavelengths,
                             reference_scale, dict(jmse_items))
    value = jnp.mean(jnp.sum(weights * table, axis=1)) / jnp.sum(weights)
    return jnp.where(ok, value, jnp.inf)


def _merit_table(lens, merit, u, signal, noise, fields, wavelengths, reference_scale,
                 jmse_options):
    """Per-(wavelength, field) merit, shape ``(n_wavelengths, n_fields)``, and validity.

    A non-physical lens is evaluated with zero aberrations (finite values and gradients)
    and flagged by ``ok``; callers check concrete lenses beforehand.
    """
    signal = MarkovSignal(1.0, 5.0) if signal is None else signal
    noise = WhiteNoise(1e-3) if noise is None else noise
    dtype = lens.ep_radius.dtype
    # A NaN or inf in a traced lens (a diverging optimiser): compute with finite stand-ins
    # (flagged by ``ok`` below), which the gradient does not reach, so that the merit is
    # +inf with a zero gradient rather than NaN.
    finite = all_finite(lens)
    lens = jax.tree_util.tree_map(
        lambda a: jnp.where(finite, a, jax.lax.stop_gradient(
            jnp.where(jnp.isfinite(a), a, jnp.ones_like(a))))
        if eqx.is_inexact_array(a) else a, lens)
    reference, per_wavelength, reference_scale = _wavelength_traces(lens, wavelengths,
                                                                    reference_scale)
    # Valid at the reference wavelength and at every wavelength averaged over.
    ok = _status(lens, reference).ok & finite
    if wavelengths is not None:
        for _, trace in per_wavelength:
            ok = ok & _status(lens, trace).ok
    u = jnp.asarray(u, dtype)
    # The default's tiers pick a grid per field. One field at a time (lax.map), each field
    # runs only its own grid; under a vectorised vmap every grid that any field picks runs
    # for all of them (the paper singlet's value_and_grad at 3 fields: 16 against 24-40 ms).
    # A fixed grid goes through vmap, which on CPU runs the fields one at a time too
    # (``_merit.SEQUENTIAL_VMAP_BACKENDS``; fast, value_and_grad: 13.0 ms against 22.0
    # vectorised, one core) and on accelerators vectorises them.
    tiered = _full_jmse_options(**jmse_options)["tiers"] is not None

    rows = []
    for wl, trace in per_wavelength:
        aberrations = _waves_from_traces(lens, trace, reference, wl)
        aberrations = jax.tree_util.tree_map(
            lambda a: jnp.where(ok, a, jnp.zeros_like(a)), aberrations
        )
        if merit == "rms":
            rows.append(jax.vmap(lambda h, ab=aberrations: rms_wavefront_error(ab, h) ** 2)(
                fields))
            continue
        scale = _wavelength_scale(wl, trace, reference_scale)
        if scale is None:
            scale = jnp.ones((), dtype)
        else:
            scale = jnp.where(ok & (scale > 0), scale, jnp.ones_like(scale))
        band = u * scale
        spectra = (_RescaledSignal(signal, scale), _RescaledNoise(noise, scale))

        def one_field(h, ab=aberrations, band=band, spectra=spectra):
            return jmse(ab, h, band, *spectra, **jmse_options)

        if tiered:
            rows.append(jax.lax.map(one_field, fields))
        else:
            rows.append(jax.vmap(one_field)(fields))
    return jnp.stack(rows), ok


@eqx.filter_jit
def _report(lens, u, signal, noise, fields, wavelengths, reference_scale, jmse_items):
    """Per-field JMSE and wavefront variance (wavelength-averaged) of a design, jitted."""
    wavelengths = None if wavelengths is None else list(wavelengths)
    options = dict(jmse_items)
    jmse_table, ok = _merit_table(lens, "jmse", u, signal, noise, fields, wavelengths,
                                  reference_scale, options)
    rms_table, _ = _merit_table(lens, "rms", u, signal, noise, fields, wavelengths,
                                reference_scale, options)
    return jnp.mean(jmse_table, axis=0), jnp.mean(rms_table, axis=0), ok


# --------------------------------------------------------------------------------------
# Optimisation variables: "name", "name[i]" or dotted paths such as "media[0].nd"
# --------------------------------------------------------------------------------------

_TOKEN = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?$")


def _parse(path: str, lens: Lens):
    """Tokens of ``path`` and the trailing array index; ValueError when it names no float."""
    node: Any = lens
    tokens: list[tuple[str, int | None]] = []
    trailing = None
    parts = path.split(".")
    for position, part in enumerate(parts):
        match = _TOKEN.match(part)
        if match is None or not hasattr(node, match.group(1)):
            names = ", ".join(f.name for f in dataclasses.fields(Lens))
            raise ValueError(
                f"variable {path!r} does not name a lens parameter; use a field of Lens "
                f"({names}), optionally indexed, e.g. 'curvatures[1]' or 'media[0].nd'"
            )
        name, index = match.group(1), match.group(2)
        node = getattr(node, name)
        tokens.append((name, None))
        if index is not None:
            index = int(index)
            if isinstance(node, tuple):
                if index >= len(node):
                    raise ValueError(f"variable {path!r}: index {index} out of range "
                                     f"[0, {len(node) - 1}]")
                node = node[index]
                tokens[-1] = (name, index)
            else:
                size = int(np.size(node))
                if position != len(parts) - 1 or index >= size:
                    raise ValueError(f"variable {path!r}: index {index} out of range "
                                     f"[0, {size - 1}]")
                trailing = index
                node = node[index]
    is_float = isinstance(node, float) or (
        hasattr(node, "dtype") and jnp.issubdtype(node.dtype, jnp.floating)
    )
    if not (is_float and np.ndim(node) == 0):
        raise ValueError(f"variable {path!r} must name a scalar float parameter of the lens")
    return tuple(tokens), trailing


def _node_getter(tokens):
    def where(lens):
        node = lens
        for name, index in tokens:
            node = getattr(node, name)
            if index is not None:
                node = node[index]
        return node

    return where


def _get(lens, parsed):
    tokens, trailing = parsed
    node = _node_getter(tokens)(lens)
    return node if trailing is None else node[trailing]


def _set(lens, parsed, value):
    tokens, trailing = parsed
    where = _node_getter(tokens)
    if trailing is None:
        return eqx.tree_at(where, lens, jnp.asarray(value, lens.ep_radius.dtype))
    return eqx.tree_at(where, lens, where(lens).at[trailing].set(value))


def _default_scale(path: str) -> float:
    head = path.split(".")[-1].split("[")[0]
    if path.startswith("media"):
        return {"nd": 0.01, "vd": 1.0, "n": 0.01, "a": 0.01, "b": 1e-3, "c": 1e-4}.get(head, 0.01)
    return _DEFAULT_SCALES.get(head, 1.0)


class _Problem(eqx.Module):
    """The objective ``log M(lens(p0 + scales * y))`` of normalised variables ``y``."""

    parsed: tuple = eqx.field(static=True)
    merit: str = eqx.field(static=True)
    jmse_items: tuple = eqx.field(static=True)
    scales: jax.Array
    fields: jax.Array
    field_weights: jax.Array
    wavelengths: jax.Array | None
    f_number: jax.Array | None
    u: jax.Array
    signal: AbstractSignal
    noise: AbstractNoise
    reference_scale: jax.Array

    def design(self, y, lens):
        for i, parsed in enumerate(self.parsed):
            lens = _set(lens, parsed, _get(lens, parsed) + self.scales[i] * y[i])
        if self.f_number is not None:
            lens = solve_last_curvature(lens, self.f_number)
        return lens

    def merit_value(self, lens):
        return lens_merit(
            lens, merit=self.merit, u=self.u, signal=self.signal, noise=self.noise,
            fields=self.fields, field_weights=self.field_weights,
            wavelengths=self.wavelengths,
            reference_scale=self.reference_scale, jmse_options=dict(self.jmse_items),
        )

    def __call__(self, y, lens):
        return jnp.log(self.merit_value(self.design(y, lens)))


@eqx.filter_jit
def _solve_optimistix(problem, lens, solver, max_steps):
    y0 = jnp.zeros(len(problem.parsed), problem.scales.dtype)
    return optx.minimise(problem, solver, y0, args=lens, max_steps=max_steps, throw=False)


@eqx.filter_jit
def _solve_lbfgsb(problem, lens, lower, upper, max_steps, tol):
    with warnings.catch_warnings():
        # jaxopt warns at import that it is no longer maintained; its L-BFGS-B is the box-
        # bounded solver this package depends on (pyproject), so the user cannot act on it.
        warnings.filterwarnings("ignore", message="JAXopt is no longer maintained",
                                category=DeprecationWarning)
        import jaxopt

    solver = jaxopt.LBFGSB(fun=problem, maxiter=max_steps, tol=tol)
    y0 = jnp.clip(jnp.zeros_like(lower), lower, upper)
    return solver.run(y0, (lower, upper), lens)


@dataclasses.dataclass(frozen=True)
class OptimisationResult:
    """Outcome of ``optimise``.

    Attributes
    ----------
    solution : optimistix.Solution (or jaxopt's OptStep for L-BFGS-B), in normalised
        variables ``y`` (parameter ``= start + scale * y``)
    lens : Lens, the optimised design (solves applied)
    start : Lens, the starting design
    parameters : dict name -> float, the optimised variables [lens units]
    merit : str; value : float, the optimised objective (mean JMSE, or mean wavefront
        variance [waves²])
    jmse : float, field-averaged JMSE of ``lens``, with ``u`` and the spectra referred to the
        starting design's ``lambda N`` (``reference_scale``), as the optimiser saw it:
        ``lens_merit(result.lens, reference_scale=result.reference_scale, ...)`` with the
        same arguments gives it; ``+inf`` if the final design is non-physical (then
        ``result`` says so); jmse_per_field : tuple of float
    rms_wavefront : float [waves], RMS over the fields of the RMS wavefront error
    start_jmse, start_rms_wavefront : float, the same for the starting design
    iterations : int; wall_time : float [s] (compilation included on the first call)
    result : str, the solver's termination message
    solver : str; fields : tuple of float
    reference_scale : float [µm], ``lambda N`` of the starting design (after any F-number
        solve), the frequency unit of ``u`` and the spectra for every design of the run
    jmse_options : dict, the keyword options of ``jmse`` the run used (``{"preset":
        "fast"}`` unless ``optimise`` was given others): confirm a ``"fast"`` optimum with
        the default (``lens_merit`` without ``jmse_options``)
    beyond_checked : tuple of bool, one per field, or None: whether ``lens``'s design at
        that field (at any wavelength) lies beyond what the preset's grids were checked at
        (``lens_beyond_checked`` with the run's arguments), so that ``jmse`` and
        ``jmse_per_field`` there are not held to the preset's accuracy; None where nothing
        was checked (grid options in ``jmse_options``, or a non-physical final design)
    """

    solution: object
    lens: Lens
    start: Lens
    parameters: dict
    merit: str
    value: float
    jmse: float
    jmse_per_field: tuple
    rms_wavefront: float
    start_jmse: float
    start_rms_wavefront: float
    iterations: int
    wall_time: float
    result: str
    solver: str
    fields: tuple
    reference_scale: float
    jmse_options: dict = dataclasses.field(default_factory=dict)
    beyond_checked: tuple | None = None

    def summary(self) -> str:
        """A readable multi-line report of the optimised design."""
        merit = self.merit
        if merit == "jmse":
            options = self.jmse_options or {"preset": "default"}
            merit += f" ({', '.join(f'{k}={v!r}' for k, v in options.items())})"
        lines = [f"optimise: merit={merit}, solver={self.solver}, {self.result}"]
        for name, value in self.parameters.items():
            lines.append(f"  {name:<18s} = {value: .8g}")
        for name in ("curvatures", "thicknesses"):
            values = np.array2string(np.asarray(getattr(self.lens, name)), precision=6)
            lines.append(f"  {name:<18s} = {values}")
        beyond = self.beyond_checked or (False,) * len(self.fields)
        per_field = ", ".join(f"h={h:g}: {v:.6e}" + (" (beyond the checked range)" if b else "")
                              for h, v, b in zip(self.fields, self.jmse_per_field, beyond,
                                                 strict=True))
        lines.append(f"  JMSE (mean)        = {self.jmse:.8e}   [{per_field}]"
                     f"   (start {self.start_jmse:.6e})")
        lines.append(f"  RMS wavefront      = {self.rms_wavefront:.6f} waves (RMS over fields;"
                     f" start {self.start_rms_wavefront:.6f})")
        lines.append(f"  iterations         = {self.iterations}")
        lines.append(f"  wall time          = {self.wall_time:.3f} s")
        return "\n".join(lines)


def _make_solver(solver, rtol, atol):
    if isinstance(solver, optx.AbstractMinimiser):
        return solver
    check_choice("solver", solver, SOLVERS[:-1])
    if solver == "bfgs":
        return optx.BFGS(rtol=rtol, atol=atol)
    if solver == "lbfgs":
        return optx.LBFGS(rtol=rtol, atol=atol)
    return optx.NonlinearCG(rtol=rtol, atol=atol)


def optimise(
    lens: Lens,
    variables: Sequence[str] = ("curvatures[0]", "image_shift"),
    *,
    merit: str = "jmse",
    u=0.2,
    signal: AbstractSignal | None = None,
    noise: AbstractNoise | None = None,
    fields=(0.0, 0.7, 1.0),
    field_weights=None,
    wavelengths=None,
    f_number=None,
    bounds: dict | None = None,
    solver="bfgs",
    scales: dict | None = None,
    rtol: float | None = None,
    atol: float = 1e-7,
    max_steps: int = 200,
    jmse_options: dict | None = None,
) -> OptimisationResult:
    """Optimise lens parameters (and focus) for the field-averaged JMSE (or RMS wavefront).

    Minimises ``log M`` (same minimiser as ``M``, better scaled) of ``lens_merit`` over the
    named ``variables``, each normalised as ``start + scale * y``.

    Parameters
    ----------
    lens : Lens, the starting design
    variables : sequence of str
        Scalar float parameters of ``Lens``: ``"curvatures[0]"``, ``"thicknesses[0]"``,
        ``"stop_position"``, ``"image_shift"`` (focus), ``"conics[1]"``,
        ``"media[0].nd"`` ...
    merit : {"jmse", "rms"}
    u, signal, noise, fields, field_weights, wavelengths
        As in ``lens_merit``. ``u`` and the spectra refer to the *starting* design's
        ``lambda N``: the pixel pitch and the scene stay fixed while the design changes.
    jmse_options : dict, optional
        Options of ``jmse`` for the objective. Default ``{"preset": "fast"}``: on the
        paper's singlet it reaches the optimum of ``preset="default"`` to 2e-7 in the
        parameters and 2e-8 in the JMSE (``benchmarks/optimise_singlet.py``, 2026-12-03),
        with a first call of 10 s against 81 s on a 2-core CPU (compilation included; later
        starts take about a second either way). Pass ``{}`` for the default preset. With
        ``"high"`` at a peak ``S_x / S_n`` beyond ``CHECKED_SNR`` (2e6) and none of the
        counts (``se_angular``, ``otf_radial``, their ``grad_`` twins) nor grid options
        given, ``se_angular=se_angular_for(u, signal, noise)`` and
        ``otf_radial=otf_radial_for(u, signal, noise)`` are added (up to 5760 angular fine
        S_e nodes at 2e8, where ``"high"``'s own 960 left the gradient up to 1e-1 off under
        flat spectra, and 160 radial OTF nodes, where its own 80 left it 3e-4 off); the
        result's ``jmse_options`` show them.
    f_number : float, optional
        Solve the last curvature at every step so the working F-number stays at this value
        (Zemax's F-number solve; the paper's "F/4.6 singlet"). Do not also vary that
        curvature.
    bounds : dict name -> (low, high), optional
        Box bounds in lens units for some variables (``None`` for an open side); when given,
        jaxopt's ``LBFGSB`` replaces the optimistix solver.
    solver : {"bfgs", "nonlinear_cg", "lbfgs"} or an ``optimistix.AbstractMinimiser``
    scales : dict name -> float, optional, variable scales [lens units per unit step]
    rtol, atol : float, optimistix termination tolerances (on ``y`` and ``log M``). With
        ``bounds``, jaxopt's ``LBFGSB`` stops when the norm of the projected gradient of
        ``log M`` in ``y`` is at most ``atol``; it has no relative tolerance, and giving
        ``rtol`` there is refused.
    max_steps : int >= 1

    Returns
    -------
    OptimisationResult (``.summary()`` gives the readable report)

    Examples
    --------
    >>> import jax
    >>> jax.config.update("jax_enable_x64", True)
    >>> from jmse_jax.lens import Singlet, N_BK7
    >>> from jmse_jax import optimise
    >>> start = Singlet(0.05, -0.15, 1.5, N_BK7, stop_distance=1.0, f_number=4.6,
    ...                 field_angle=10.0)
    >>> result = optimise(start, ("curvatures[0]", "image_shift"), f_number=4.6,
    ...                   jmse_options={"preset": "fast"})  # doctest: +SKIP
    >>> print(result.summary())  # doctest: +SKIP
    """
    if not isinstance(lens, Lens):
        raise TypeError(f"lens must be a jmse_jax.lens.Lens, got {type(lens)}")
    check_choice("merit", merit, MERITS)
    check_count("max_steps", max_steps)
    if rtol is not None and bounds:
        raise ValueError(f"rtol = {rtol!r} has no effect with bounds (jaxopt's LBFGSB stops on "
                         f"the projected gradient's norm, atol, alone); leave rtol out")
    rtol = 1e-7 if rtol is None else rtol
    check_range("rtol", rtol, 0.0, None)
    check_range("atol", atol, 0.0, None)
    if isinstance(variables, str):
        raise TypeError(f"variables must be a sequence of parameter names, got {variables!r}; "
                        f"write ({variables!r},)")
    variables = tuple(variables)
    if not variables:
        raise ValueError("variables must name at least one lens parameter")
    if len(set(variables)) != len(variables):
        raise ValueError(f"variables must be distinct, got {variables!r}")
    parsed = tuple(_parse(v, lens) for v in variables)
    if f_number is not None:
        check_range("f_number", f_number, 0.0, None, low_inclusive=False)
        last = f"curvatures[{lens.n_surfaces - 1}]"
        if _parse(last, lens) in parsed:
            raise ValueError(f"{last} is fixed by the f_number solve; remove it from variables")
        lens = solve_last_curvature(lens, f_number)
    scales = dict(scales or {})
    for name in scales:
        if name not in variables:
            raise ValueError(f"scales names {name!r}, which is not among variables {variables}")
        check_range(f"scales[{name!r}]", scales[name], 0.0, None, low_inclusive=False)
    dtype = lens.ep_radius.dtype
    if merit == "jmse":
        jmse_options = _with_gradient_counts(jmse_options, u, signal, noise)
    fields, field_weights, wavelengths = _check_merit_arguments(
        dtype, u, signal, noise, fields, field_weights, wavelengths, jmse_options,
        gradient=merit == "jmse")
    if bounds is not None and not isinstance(bounds, dict):
        raise TypeError(f"bounds must be a dict name -> (low, high), got {bounds!r}")
    for name, pair in (bounds or {}).items():
        if not (isinstance(pair, (tuple, list)) and len(pair) == 2):
            raise ValueError(f"bounds[{name!r}] must be a pair (low, high), got {pair!r}")
    scale_vector = jnp.asarray([scales.get(v, _default_scale(v)) for v in variables], dtype)
    signal = MarkovSignal(1.0, 5.0) if signal is None else signal
    noise = WhiteNoise(1e-3) if noise is None else noise
    jmse_items = _freeze({"preset": "fast"} if jmse_options is None else jmse_options)
    _check_lens_at(lens, wavelengths)
    reference_scale = lens.wavelength * _f_number_of(paraxial_trace(lens))
    problem = _Problem(
        parsed=parsed, merit=merit, jmse_items=jmse_items, scales=scale_vector,
        fields=fields, field_weights=field_weights, wavelengths=wavelengths,
        f_number=None if f_number is None else jnp.asarray(f_number, dtype),
        u=jnp.asarray(u, dtype), signal=signal, noise=noise,
        reference_scale=jnp.asarray(reference_scale, dtype),
    )

    start_time = time.perf_counter()
    if bounds:
        for name in bounds:
            if name not in variables:
                raise ValueError(f"bounds names {name!r}, which is not among variables "
                                 f"{variables}")
        lower: Any = []
        upper: Any = []
        for i, (name, p) in enumerate(zip(variables, parsed, strict=True)):
            low, high = _check_bound(name, bounds.get(name, (None, None)))
            start = float(_get(lens, p))
            if low is not None and high is not None and not low < high:
                raise ValueError(f"bounds[{name!r}] must satisfy low < high, got {(low, high)}")
            if (low is not None and start < low) or (high is not None and start > high):
                raise ValueError(f"the start's {name} = {start!r} lies outside bounds[{name!r}] "
                                 f"= {(low, high)}; start inside the bounds")
            step = float(scale_vector[i])
            lower.append(-np.inf if low is None else (low - start) / step)
            upper.append(np.inf if high is None else (high - start) / step)
        lower = jnp.asarray(lower, dtype)
        upper = jnp.asarray(upper, dtype)
        solution = _solve_lbfgsb(problem, lens, lower, upper, max_steps, atol)
        jax.block_until_ready(solution)
        y, iterations = solution.params, int(solution.state.iter_num)
        converged = float(solution.state.error) <= atol
        result = "converged" if converged else "stopped (max_steps or line search)"
        solver_name = "jaxopt.LBFGSB"
    else:
        opt = _make_solver(solver, rtol, atol)
        solution = _solve_optimistix(problem, lens, opt, max_steps)
        jax.block_until_ready(solution)
        y, iterations = solution.value, int(solution.stats["num_steps"])
        result = "converged" if bool(solution.result == optx.RESULTS.successful) else (
            # equinox's enumeration metaclass maps a result to its message (mypy cannot see it)
            "not converged: " + optx.RESULTS[solution.result])  # type: ignore[misc]
        solver_name = type(opt).__name__
    wall_time = time.perf_counter() - start_time

    final = problem.design(y, lens)
    parameters = {v: float(_get(final, p)) for v, p in zip(variables, parsed, strict=True)}
    weights = np.asarray(problem.field_weights)

    def report(design):
        per_field, variances, ok = _report(
            design, problem.u, signal, noise, problem.fields, problem.wavelengths,
            problem.reference_scale, jmse_items,
        )
        if not bool(ok):  # _report evaluated it unaberrated: say +inf, as lens_merit does
            return tuple(math.inf for _ in weights), math.inf, math.inf, False
        per_field = tuple(float(v) for v in np.asarray(per_field))
        mean_jmse = float(np.sum(weights * np.asarray(per_field)) / np.sum(weights))
        variance = float(np.sum(weights * np.asarray(variances)) / np.sum(weights))
        return per_field, mean_jmse, variance, True

    jmse_items_dict = dict(jmse_items)
    per_field, mean_jmse, variance, final_ok = report(final)
    _, start_jmse, start_variance, _ = report(lens)
    if not final_ok:
        result += "; the final design is non-physical (lens_status(result.lens).ok is False)"
    beyond = None
    if final_ok and all(jmse_items_dict.get(name) is None for name in _GRID_OPTIONS):
        beyond = tuple(bool(b) for b in _lens_beyond(
            final, problem.u, signal, noise, fields, wavelengths, problem.reference_scale,
            jmse_items_dict))
    value = mean_jmse if merit == "jmse" else variance
    return OptimisationResult(
        solution=solution, lens=final, start=lens, parameters=parameters, merit=merit,
        value=value, jmse=mean_jmse, jmse_per_field=per_field,
        rms_wavefront=math.sqrt(variance), start_jmse=start_jmse,
        start_rms_wavefront=math.sqrt(start_variance), iterations=iterations,
        wall_time=wall_time, result=result, solver=solver_name,
        fields=tuple(float(f) for f in np.asarray(fields)),
        reference_scale=float(problem.reference_scale),
        jmse_options=dict(jmse_items), beyond_checked=beyond,
    )
