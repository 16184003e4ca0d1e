"""Sweeps of a merit over a batch of designs: ``vmap`` in chunks, sharded over devices.

One code path serves a laptop, a GPU and many accelerators: the batch axis is laid on a 1-D
device mesh (``jax.sharding.Mesh`` over every device, across hosts after
``jax.distributed.initialize``); each device evaluates its share with
``lax.map(..., batch_size=batch_size)``, i.e. ``vmap`` over ``batch_size`` designs at a time
(on CPU one design at a time by default, which is fastest there), so memory stays bounded
however large the sweep. Results come back to the host in input
order, with the inputs kept beside them and a status per design.
"""

from __future__ import annotations

import contextlib
import dataclasses
import enum
import functools
import importlib
import json
import math
import os
import platform
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from ._aberrations import Seidel, Zernike
from ._merit import (
    _CHECKED_ALREADY,
    _GRID_OPTIONS,
    CHECKED_SNR,
    CHECKED_SNR_PEAKS,
    U_MAX,
    _beyond_checked,
    _cancellation_message,
    _checked_already,
    _chooses_counts,
    _concrete_choice,
    _peak_snr,
    _prepare,
    _slope_message,
    _snr_peaks,
    _strength_message,
    _validate,
    _warn_beyond_checked_snr,
    jmse,
    jmse_options,
)
from ._numerics import AccuracyWarning, all_finite, check_count, is_concrete

__all__ = ["SweepResult", "SweepStatus", "beyond_checked", "hypercube", "sweep", "sweep_jmse"]

#: Default ``batch_size`` of ``sweep`` on GPU and TPU (on CPU the default is 1). On an H100
#: the singlet sweep with ``jmse`` reached its best measured throughput at 64 designs per
#: ``vmap`` with both the fast and the default preset (``benchmarks/README.md``, "On a GPU");
#: the default's gradient holds about 93 MB per design in flight, 6 GB at 64.
DEFAULT_ACCELERATOR_BATCH = 64
#: Designs one call works through on a CPU (``chunks_per_call`` with ``batch_size=1``), at
#: most: each call from the host costs a fixed amount of host and runtime work (slicing and
#: transferring the designs, passing the program's constants, setting up the call's scratch
#: memory, collecting the results), which one ``jmse`` design (a few ms) does not hide.
#: 16 since 2026-11-25 (was 8): as designs got cheaper the calls' fixed cost grew in
#: proportion. See ``sweep``.
DEFAULT_CPU_CHUNKS = 16

#: Name of the mesh axis along which designs are sharded.
MESH_AXIS = "designs"

_FORMAT = "jmse_jax.sweep/1"


class SweepStatus(enum.IntEnum):
    """Outcome of one design in a sweep (stored as ``int8``; the first that applies wins).

    ``OK`` (0): value (and gradient) finite. ``NONFINITE_INPUT`` (1): a leaf of the design
    is NaN or infinite. ``INVALID`` (2): the ``valid`` predicate of the sweep returned False
    (e.g. a field or ``u`` out of range, a non-physical lens). ``NONFINITE_VALUE`` (3): the
    function returned NaN or infinity (``jmse`` returns ``+inf`` for non-finite input).
    ``NONFINITE_GRADIENT`` (4): the value is finite but the gradient is not.
    """

    OK = 0
    NONFINITE_INPUT = 1
    INVALID = 2
    NONFINITE_VALUE = 3
    NONFINITE_GRADIENT = 4


# --------------------------------------------------------------------------------------
# Result container, with .npz + JSON header persistence
# --------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True, eq=False)
class SweepResult:
    """Results of ``sweep``, on the host as NumPy arrays, in the order of the inputs.

    Attributes
    ----------
    inputs : pytree of ndarray, leading axis (n,)
        The batch as evaluated (scalar leaves broadcast, dtype as computed).
    value : pytree of ndarray, leading axis (n,)
        What ``fn`` returned for each design. Where ``status != 0`` it is whatever ``fn``
        gave (``jmse`` gives ``+inf``); select good designs with ``result.ok``.
    grad : pytree like ``inputs``, or None
        ``d value / d inputs`` per design when the sweep ran with ``grad=True``.
    aux : pytree of ndarray, or None
        The auxiliary output of ``fn`` when the sweep ran with ``has_aux=True``.
    status : ndarray of int8, shape (n,)
        ``SweepStatus`` code per design.
    metadata : dict
        JSON-serialisable description: devices, batch size, padding, timings, compiled
        memory, JAX version, and the user's own ``metadata``.
    beyond_checked : ndarray of bool, shape (n,), or None
        ``sweep_jmse`` with a preset's grids: True for each design beyond what its preset
        was checked at (the designs ``sweep_jmse``'s ``AccuracyWarning`` counts: strength,
        wavefront slope, cancelling terms, peak ``S_x / S_n``), whose value is finite but
        may be off by more than the preset's accuracy. False for the rest, and for designs
        whose status is not ``OK``. None where nothing was checked (``sweep``, or grid
        options given). ``in_checked_range`` selects the rest of the OK designs.
    """

    inputs: Any
    value: Any
    grad: Any
    aux: Any
    status: np.ndarray
    metadata: dict
    beyond_checked: np.ndarray | None = None

    @property
    def n_designs(self) -> int:
        """Number of designs in the sweep."""
        return int(self.status.shape[0])

    @property
    def ok(self) -> np.ndarray:
        """Boolean mask, shape (n,): designs whose status is ``SweepStatus.OK``."""
        return self.status == SweepStatus.OK

    @property
    def in_checked_range(self) -> np.ndarray:
        """Boolean mask, shape (n,): designs whose status is OK and that are not
        ``beyond_checked`` (the values held to the preset's accuracy); ``ok`` where nothing
        was checked (``beyond_checked`` is None)."""
        if self.beyond_checked is None:
            return self.ok
        return self.ok & ~np.asarray(self.beyond_checked, bool)

    def status_counts(self) -> dict[str, int]:
        """Number of designs per status name (only statuses that occur)."""
        codes, counts = np.unique(self.status, return_counts=True)
        return {SweepStatus(int(c)).name: int(k) for c, k in zip(codes, counts, strict=True)}

    def save(self, path) -> Path:
        """Write the result to ``path`` (``.npz`` appended if missing) plus a JSON header.

        Arrays go into an uncompressed ``.npz`` (no pickles); the header (tree structure of
        every group, status names and ``metadata``) is stored inside it as ``__header__``
        and also written beside it as ``<path>.json`` for people and other tools.

        Returns
        -------
        Path of the ``.npz`` file.
        """
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        arrays: dict[str, Any] = {}
        trees = {}
        for group in ("inputs", "value", "grad", "aux"):
            trees[group] = _encode_tree(getattr(self, group), group, arrays)
        arrays["status"] = np.asarray(self.status, dtype=np.int8)
        header = {
            "format": _FORMAT,
            "n_designs": self.n_designs,
            "status_names": {int(s): s.name for s in SweepStatus},
            "status_counts": self.status_counts(),
            "trees": trees,
            "metadata": self.metadata,
        }
        if self.beyond_checked is not None:
            arrays["beyond_checked"] = np.asarray(self.beyond_checked, dtype=bool)
            header["n_beyond_checked"] = int(arrays["beyond_checked"].sum())
        try:  # strict JSON: a non-finite metadata value is refused, not written as NaN
            text = json.dumps(header, indent=2, default=_json_default, allow_nan=False)
        except ValueError:
            raise ValueError("metadata must hold finite numbers only (JSON has no NaN or "
                             "inf); store such values as strings") from None
        arrays["__header__"] = np.array(text)
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savez(path, **arrays)
        path.with_name(path.name[: -len(".npz")] + ".json").write_text(text + "\n")
        return path

    @classmethod
    def load(cls, path) -> SweepResult:
        """Read a result written by ``save``; equinox Modules such as ``Seidel`` come back as such.

        Only NumPy's ``.npz`` reader is used (``allow_pickle=False``), and the classes the
        header names are rebuilt only when they are namedtuples or equinox Modules of
        ``jmse_jax`` or of a module the caller has already imported (a file never makes
        ``load`` import or call anything else).
        """
        path = Path(path)
        if path.suffix == ".json" and path.with_suffix(".npz").exists():
            path = path.with_suffix(".npz")  # the header's readable copy: read its .npz
        if not path.exists() and path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
        header = json.loads(str(arrays.pop("__header__")))
        if header.get("format") != _FORMAT:
            raise ValueError(
                f"{path} is not a jmse_jax sweep result (format {header.get('format')!r})"
            )
        groups = {g: _decode_tree(spec, arrays) for g, spec in header["trees"].items()}
        return cls(status=arrays["status"], metadata=header["metadata"],
                   beyond_checked=arrays.get("beyond_checked"), **groups)

    def __repr__(self) -> str:
        counts = ", ".join(f"{k}={v}" for k, v in self.status_counts().items())
        beyond = ("" if self.beyond_checked is None
                  else f", beyond_checked={int(np.sum(self.beyond_checked))}")
        return (f"SweepResult(n_designs={self.n_designs}, grad={self.grad is not None}, "
                f"{counts}{beyond})")


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, (np.ndarray, jax.Array)):
        return np.asarray(value).tolist()
    raise TypeError(
        f"metadata value {value!r} of type {type(value).__name__} is not JSON-serialisable"
    )


def _encode_static(value):
    if isinstance(value, tuple):
        return {"__tuple__": [_encode_static(v) for v in value]}
    if isinstance(value, list):
        return [_encode_static(v) for v in value]
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    raise ValueError(f"cannot save static field value {value!r} of type {type(value).__name__}")


def _decode_static(value):
    if isinstance(value, dict) and "__tuple__" in value:
        return tuple(_decode_static(v) for v in value["__tuple__"])
    if isinstance(value, list):
        return [_decode_static(v) for v in value]
    return value


def _encode_tree(tree, name: str, arrays: dict) -> dict:
    """JSON description of ``tree``; its array leaves go into ``arrays`` under ``name.*``."""
    if tree is None:
        return {"node": "none"}
    if isinstance(tree, dict):
        keys = list(tree)
        if not all(isinstance(k, str) for k in keys):
            raise ValueError(f"cannot save {name}: dict keys must be strings, got {keys!r}")
        return {"node": "dict", "keys": keys,
                "children": [_encode_tree(tree[k], f"{name}.{k}", arrays) for k in keys]}
    if isinstance(tree, tuple) and hasattr(tree, "_fields"):
        cls: type = type(tree)
        return {"node": "namedtuple", "class": f"{cls.__module__}:{cls.__qualname__}",
                "fields": list(tree._fields),
                "children": [_encode_tree(v, f"{name}.{f}", arrays)
                             for f, v in zip(tree._fields, tree, strict=True)]}
    if isinstance(tree, (list, tuple)):
        return {"node": type(tree).__name__,
                "children": [_encode_tree(v, f"{name}.{i}", arrays) for i, v in enumerate(tree)]}
    if isinstance(tree, eqx.Module):
        cls = type(tree)
        fields, static, children = [], {}, []
        for field in dataclasses.fields(tree):
            value = getattr(tree, field.name)
            if field.metadata.get("static", False):
                static[field.name] = _encode_static(value)
            else:
                fields.append(field.name)
                children.append(_encode_tree(value, f"{name}.{field.name}", arrays))
        return {"node": "module", "class": f"{cls.__module__}:{cls.__qualname__}",
                "fields": fields, "static": static, "children": children}
    if isinstance(tree, (np.ndarray, np.generic, jax.Array, float, int, complex, bool)):
        key = f"{name}"
        if key in arrays or key in ("status", "beyond_checked", "__header__"):
            raise ValueError(f"cannot save: two leaves would be stored under {key!r}")
        arrays[key] = np.asarray(tree)
        return {"node": "leaf", "key": key}
    raise ValueError(
        f"cannot save {name} of type {type(tree).__name__}: use dicts, lists, tuples, "
        "namedtuples or equinox Modules of arrays"
    )


def _import_class(path: str, kind: str):
    """The namedtuple (``kind="namedtuple"``) or equinox Module class named ``module:qualname``.

    A file is data, not code: a module is imported only when it belongs to ``jmse_jax``; any
    other must already be imported by the caller (``sys.modules``), and the object found must
    be a class of the expected kind (a crafted header could otherwise name any callable).
    """
    module_name, _, qualname = path.partition(":")
    obj: Any
    if module_name == "jmse_jax" or module_name.startswith("jmse_jax."):
        obj = importlib.import_module(module_name)
    elif module_name in sys.modules:
        obj = sys.modules[module_name]
    else:
        raise ValueError(
            f"the file names class {path!r}, whose module {module_name!r} is not imported; "
            f"import it before loading (load never imports a module a file names, except "
            f"jmse_jax's own)"
        )
    for part in qualname.split("."):
        obj = getattr(obj, part, None)
    expected = (isinstance(obj, type) and issubclass(obj, tuple) and hasattr(obj, "_fields")
                if kind == "namedtuple" else isinstance(obj, type) and issubclass(obj, eqx.Module))
    if not expected:
        raise ValueError(f"the file names {path!r} as a {kind} class, which it is not")
    return obj


def _decode_tree(spec: dict, arrays: dict):
    node = spec["node"]
    if node == "none":
        return None
    if node == "leaf":
        return arrays[spec["key"]]
    children = [_decode_tree(child, arrays) for child in spec.get("children", [])]
    if node == "dict":
        return dict(zip(spec["keys"], children, strict=True))
    if node == "list":
        return children
    if node == "tuple":
        return tuple(children)
    values = dict(zip(spec["fields"], children, strict=True))
    if node == "namedtuple":
        return _import_class(spec["class"], "namedtuple")(**values)
    if node != "module":
        raise ValueError(f"unknown node {node!r} in the file's header")
    # An equinox Module is a frozen dataclass: set its fields directly, without re-running
    # an __init__ that may not accept batched leaves (Zernike checks its shape).
    cls = _import_class(spec["class"], "module")
    module = object.__new__(cls)
    for key, value in values.items():
        object.__setattr__(module, key, value)
    for key, value in spec["static"].items():
        object.__setattr__(module, key, _decode_static(value))
    return module


# --------------------------------------------------------------------------------------
# The sweep
# --------------------------------------------------------------------------------------


def _host_batch(batch):
    """Validate ``batch`` and return it as NumPy leaves of a common leading length ``n``."""
    leaves_with_paths, treedef = jax.tree_util.tree_flatten_with_path(batch)
    if not leaves_with_paths:
        raise ValueError("batch must contain at least one array leaf, got an empty pytree")
    leaves, lengths, weak = [], {}, []
    for path, leaf in leaves_with_paths:
        # A Python float (e.g. a Seidel's zero coefficients) is weakly typed, as in jnp: it
        # takes the float dtype of the batch's arrays rather than making them float64.
        weak.append(isinstance(leaf, float) or bool(getattr(leaf, "weak_type", False)))
        arr = np.asarray(leaf)
        if arr.dtype == object or not (np.issubdtype(arr.dtype, np.number) or arr.dtype == bool):
            raise ValueError(
                f"batch{jax.tree_util.keystr(path)} must be numeric, got dtype {arr.dtype}"
            )
        arr = arr.astype(jax.dtypes.canonicalize_dtype(arr.dtype), copy=False)
        if arr.ndim >= 1:
            lengths[jax.tree_util.keystr(path)] = arr.shape[0]
        leaves.append(arr)
    if not lengths:
        raise ValueError(
            "batch must have at least one leaf with a leading (design) axis; every leaf is a scalar"
        )
    distinct = sorted(set(lengths.values()))
    if len(distinct) > 1:
        listing = ", ".join(f"batch{k}: {v}" for k, v in lengths.items())
        raise ValueError(f"every leaf of batch must have the same leading length; got {listing}")
    n = distinct[0]
    if n < 1:
        raise ValueError("batch must hold at least one design, got a leading length of 0")
    strong = [a.dtype for a, w in zip(leaves, weak, strict=True)
              if not w and np.issubdtype(a.dtype, np.floating)]
    if strong:
        common = np.result_type(*strong)
        leaves = [a.astype(common) if w and np.issubdtype(a.dtype, np.floating) else a
                  for a, w in zip(leaves, weak, strict=True)]
    # Scalars are shared by every design (e.g. the zero coefficients of a Seidel).
    leaves = [np.broadcast_to(a, (n,)).copy() if a.ndim == 0 else a for a in leaves]
    return jax.tree_util.tree_unflatten(treedef, leaves), n


def _resolve_devices(devices) -> list:
    if devices is None:
        return list(jax.devices())
    if isinstance(devices, (int, np.integer)) and not isinstance(devices, bool):
        available = jax.devices()
        if not 1 <= devices <= len(available):
            raise ValueError(
                f"devices must be in [1, {len(available)}] (the devices JAX sees), got {devices}"
            )
        return list(available[:devices])
    devices = list(devices)
    if not devices:
        raise ValueError("devices must be None, a count >= 1 or a non-empty list of jax devices")
    return devices


def _make_evaluate(fn, grad, has_aux, valid):
    """Per-design function: (value, grad, aux, status) for one unbatched design."""

    def evaluate(design):
        if grad:
            (value, aux), gradient = jax.value_and_grad(
                fn if has_aux else (lambda d: (fn(d), None)), has_aux=True
            )(design)
        else:
            value, aux = fn(design) if has_aux else (fn(design), None)
            gradient = None
        status = jnp.where(all_finite(gradient), SweepStatus.OK, SweepStatus.NONFINITE_GRADIENT)
        status = jnp.where(all_finite(value), status, SweepStatus.NONFINITE_VALUE)
        if valid is not None:
            status = jnp.where(jnp.asarray(valid(design), bool), status, SweepStatus.INVALID)
        status = jnp.where(all_finite(design), status, SweepStatus.NONFINITE_INPUT)
        return value, gradient, aux, status.astype(jnp.int8)

    return evaluate


def _default_chunks(devices, batch_size: int, n: int) -> int:
    """``sweep``'s default ``chunks_per_call`` (see ``DEFAULT_CPU_CHUNKS``). It depends on the
    batch's size only, not on the devices or workers, so a sweep gives the same bits on any
    number of devices."""
    if devices[0].platform != "cpu" or batch_size != 1:
        return 1
    return max(1, min(DEFAULT_CPU_CHUNKS, n // 16))


def _default_workers(devices) -> int:
    """``sweep``'s default ``workers``: a host thread per core and device on one CPU host."""
    if devices[0].platform != "cpu" or jax.process_count() > 1:
        return 1
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, cores // len(devices))


def _global_array(host: np.ndarray, sharding) -> jax.Array:
    """A global array laid out by ``sharding`` from data every process holds in full."""
    return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])


def _to_host(tree):
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        return multihost_utils.process_allgather(tree, tiled=True)
    return jax.tree_util.tree_map(np.asarray, tree)


def sweep(
    fn: Callable,
    batch,
    *,
    grad: bool = False,
    has_aux: bool = False,
    valid: Callable | None = None,
    batch_size: int | None = None,
    chunks_per_call: int | None = None,
    devices: int | Sequence | None = None,
    workers: int | None = None,
    progress: bool | None = None,
    metadata: dict | None = None,
) -> SweepResult:
    """Evaluate ``fn`` on every design of ``batch``, vectorised, chunked and sharded.

    ``fn`` is written for one design; the sweep ``vmap``s it over ``batch_size`` designs at a
    time per device (``lax.map(fn, ..., batch_size=batch_size)``) and lays the design axis
    on a 1-D mesh over ``devices`` with ``jax.shard_map``. The padded tail is dropped and
    the results are returned in input order. The same call runs on one CPU, on several
    GPUs, and on several hosts after ``jax.distributed.initialize()`` (every process calls
    ``sweep`` with the same ``batch``; every process receives the whole result).

    Parameters
    ----------
    fn : callable ``design -> value`` (or ``-> (value, aux)`` with ``has_aux``)
        Pure and traceable. It must report a failed design through its value (NaN or
        infinity, as ``jmse`` does) rather than by raising: a Python exception or a runtime
        error check stops the whole sweep.
    batch : pytree of arrays, leading axis (n,)
        The designs, e.g. ``{"aberrations": Seidel(w020=array(n), ...), "field": array(n)}``
        (see ``hypercube``). Scalar leaves are shared by every design. Leaves with a
        leading axis must all have the same length ``n >= 1``.
    grad : bool
        Also return ``d value / d design`` (``jax.value_and_grad``); the value must then be
        a real scalar and every leaf of ``batch`` floating point.
    has_aux : bool
        ``fn`` returns ``(value, aux)``; ``aux`` (a pytree of arrays) is kept per design.
    valid : callable ``design -> bool``, optional
        Traceable predicate; designs for which it is False get ``SweepStatus.INVALID``.
    batch_size : int >= 1, optional
        Designs evaluated together (one ``vmap``) on each device. Default: 1 on CPU, where
        ``jmse`` is fastest one design at a time (a vectorised ``vmap`` of many designs
        multiplies its working set past the caches: 2-3x slower per design, measured in
        ``benchmarks/sweep_bench.py``; ``jmse`` under ``vmap`` on CPU now runs its designs
        one at a time anyway, ``_merit.SEQUENTIAL_VMAP_BACKENDS``, but the rest of ``fn``
        would be vectorised), and ``DEFAULT_ACCELERATOR_BATCH`` on GPU/TPU.
        With ``batch_size=1`` the designs go through ``lax.map`` without ``vmap``, so
        data-dependent branches (``lax.cond``) stay branches. Memory per device is
        about ``batch_size`` times the memory of one design in flight, which
        ``result.metadata["memory"]["temp_bytes"] / batch_size`` reports (XLA's temporary
        buffers of the compiled sweep). For the singlet lens + ``jmse`` in float64 on CPU
        (``benchmarks/sweep_bench.py``) it is about 9 MB (value) and 10 MB (value and
        gradient) with ``preset="fast"``, and 13 MB and 32 MB with ``"default"``; on an
        H100 under ``vmap``, 4.4 and 6.7 MB (fast) and 7.4 and 93 MB (default).
    chunks_per_call : int >= 1, optional
        Chunks of ``batch_size`` designs each device works through (``lax.map``) per call
        from the host. The host loops over calls, updating the progress bar after each; more
        chunks per call means fewer round trips but coarser progress and more padding.
        Default: on a CPU with ``batch_size=1``, ``DEFAULT_CPU_CHUNKS`` (16), or
        ``n // 16`` for a batch of ``n < 256`` designs (at least 1), so that a small sweep is
        not padded by much and still spreads over the ``workers``; otherwise 1. Each call
        costs a fixed amount of host and runtime work on top of its designs: on 2 cores the
        1875-design singlet value-and-gradient sweep with ``preset="fast"`` took 4.3-4.6 s
        with 8 designs per call against 5.8-7.3 s with 1 (alternated runs, 2026-11-25), and
        later, in float32, 1.61-1.65 s with 16 against 1.78-1.91 s with 8 (same day;
        ``benchmarks/README.md``).
    devices : None, int or sequence of jax devices
        ``None``: every device JAX sees (all hosts); an int ``k``: the first ``k``.
    workers : int >= 1, optional
        Host threads that issue calls at the same time. On a CPU, calls issued from one
        thread run one after the other and XLA spreads each over the cores only partly;
        calls issued from several threads run side by side. Default: on a CPU in a single
        process, the cores available to the process divided by the number of devices (at
        least 1); otherwise 1 (a GPU runs its calls in order anyway). Every call runs the
        same compiled program, so the results do not depend on ``workers``; the memory in
        flight is ``workers`` times one call's.
    progress : bool, optional
        Show a tqdm progress bar, updated after each call. Default: on when stderr is a
        terminal and the sweep takes more than one call.
    metadata : dict, optional
        JSON-serialisable values stored in ``result.metadata["user"]``. ``save`` writes
        them as JSON, so after ``load`` tuples and arrays come back as lists and dictionary
        keys as strings.

    Returns
    -------
    SweepResult
        ``value``, ``grad``, ``aux`` and ``status`` per design, ``inputs`` beside them.

    Notes
    -----
    The batch is padded, by repeating its last design, to a whole number of calls of
    ``devices * chunks_per_call * batch_size`` designs, so every device runs the same
    program on the same shapes whatever the number of devices, and no data moves between
    devices. For given ``batch_size`` and ``chunks_per_call`` the results on 2, 4, ...
    devices, with or without a progress bar, are the same bit for bit (the tests check this
    in float64 on fake CPU devices). On one device XLA compiles the program without the
    sharded wrapper and may lay out and fuse a few operations differently: values then agree
    bit for bit in the tests, gradients to a few ulp. Another ``batch_size`` or
    ``chunks_per_call`` may also change the last bits.

    On a multi-core CPU, XLA spreads one call's work over the cores only partly, so by
    default ``sweep`` issues calls from one host thread per core (``workers``): on 2 cores
    the 1875-design singlet value-and-gradient sweep with ``preset="fast"`` takes 7.8 s
    instead of 10.1 s with one thread (``benchmarks/results/sweep_bench_workers_fast.md``).
    Starting Python with ``XLA_FLAGS=--xla_force_host_platform_device_count=<cores>`` (one
    CPU device per core) does a similar job through the mesh (8.7 s there). Those figures
    are from 2026-11-24; with the leaner kernels since, the same sweep takes 2.85 s in
    float64 and 1.70 s in float32 (``benchmarks/results/sweep_bench_s24_fast*.md``).

    Precision: ``sweep`` computes in the batch's dtype. Given float32 designs, ``jmse`` runs
    in float32 throughout (its own cosine polynomial, and the overlap engine's order along
    the chords rounded up to a multiple of 8); on the singlet sweep the float32 values were
    within 1.5e-6 of float64's and the gradients within 1.9e-6 of each design's largest
    component (median; 8.2e-4 at worst, where a gradient nearly vanishes).

    Several hosts: start every process with ``jax.distributed.initialize(...)`` (on CPU also
    ``jax.config.update("jax_cpu_collectives_implementation", "gloo")``), then call ``sweep``
    with the same arguments everywhere; the mesh spans every process's devices. The tests
    run two processes of 2 fake CPU devices each (``tests/sweep_hosts_worker.py``): both
    receive the same result bit for bit, with values equal bit for bit to one process with
    4 devices and gradients to a few ulp.

    Examples
    --------
    >>> import jax, numpy as np
    >>> import jmse_jax as jj
    >>> designs = jj.hypercube(x=np.linspace(0.0, 1.0, 3), y=np.array([1.0, 2.0]))
    >>> result = jj.sweep(lambda d: d["x"] * d["y"], designs, batch_size=2, progress=False)
    >>> result.value.tolist()
    [0.0, 0.0, 0.5, 1.0, 1.0, 2.0]
    """
    if not callable(fn):
        raise ValueError(f"fn must be callable, got {type(fn).__name__}")
    devices = _resolve_devices(devices)
    if batch_size is None:
        batch_size = 1 if devices[0].platform == "cpu" else DEFAULT_ACCELERATOR_BATCH
    check_count("batch_size", batch_size)
    host_batch, n = _host_batch(batch)
    if chunks_per_call is None:
        chunks_per_call = _default_chunks(devices, batch_size, n)
    check_count("chunks_per_call", chunks_per_call)
    if workers is None:
        workers = _default_workers(devices)
    check_count("workers", workers)
    if workers > 1 and jax.process_count() > 1:
        raise ValueError(f"workers must be 1 when the sweep spans {jax.process_count()} "
                         f"processes, got {workers}")
    if grad:
        for path, leaf in jax.tree_util.tree_leaves_with_path(host_batch):
            if not np.issubdtype(leaf.dtype, np.floating):
                raise ValueError(
                    f"grad=True needs floating-point designs; batch{jax.tree_util.keystr(path)} "
                    f"has dtype {leaf.dtype}"
                )
    n_devices = len(devices)
    evaluate = _make_evaluate(fn, grad, has_aux, valid)

    if grad:  # check fn's output on one design before compiling the sweep
        example = jax.tree_util.tree_map(lambda a: jax.ShapeDtypeStruct(a.shape[1:], a.dtype),
                                         host_batch)
        value_shape = jax.eval_shape(fn, example)
        if has_aux:
            value_shape = value_shape[0]
        if not (isinstance(value_shape, jax.ShapeDtypeStruct) and value_shape.shape == ()
                and jnp.issubdtype(value_shape.dtype, jnp.floating)):
            raise ValueError(
                f"grad=True needs fn to return a real scalar per design, got {value_shape}"
            )

    call_size = chunks_per_call * n_devices * batch_size
    n_calls = math.ceil(n / call_size)
    if progress is None:
        progress = n_calls > 1 and sys.stderr.isatty()
    progress = bool(progress) and jax.process_index() == 0
    padded = n_calls * call_size

    def pad(leaf):
        return np.concatenate([leaf, np.repeat(leaf[-1:], padded - n, axis=0)], axis=0)

    padded_batch = jax.tree_util.tree_map(pad, host_batch)

    mesh = Mesh(np.asarray(devices, dtype=object), (MESH_AXIS,))
    sharding = NamedSharding(mesh, PartitionSpec(MESH_AXIS))

    def local_sweep(designs):
        if batch_size == 1:  # no vmap: a lax.cond in fn then runs one branch only
            return jax.lax.map(evaluate, designs)
        return jax.lax.map(evaluate, designs, batch_size=batch_size)

    # Trace the per-device program once and pass its array constants (quadrature nodes,
    # interpolation matrices) as replicated arguments. Otherwise XLA optimises the one-device
    # program, whose body it sees inline with the constants, differently from the sharded
    # one, whose body receives them as operands, and the two differ in the last bits.
    started = time.perf_counter()
    local_shape = jax.tree_util.tree_map(
        lambda a: jax.ShapeDtypeStruct((chunks_per_call * batch_size, *a.shape[1:]), a.dtype),
        host_batch)
    closed, out_shape = jax.make_jaxpr(local_sweep, return_shape=True)(local_shape)
    out_tree = jax.tree_util.tree_structure(out_shape)
    replicated = NamedSharding(mesh, PartitionSpec())
    consts = [_global_array(np.asarray(c), replicated) for c in closed.consts]

    def local_program(consts, designs):
        flat = jax.core.eval_jaxpr(closed.jaxpr, consts, *jax.tree_util.tree_leaves(designs))
        return jax.tree_util.tree_unflatten(out_tree, flat)

    sharded_sweep = jax.jit(
        jax.shard_map(local_program, mesh=mesh,
                      in_specs=(PartitionSpec(), PartitionSpec(MESH_AXIS)),
                      out_specs=PartitionSpec(MESH_AXIS)),
    )

    def device_block(start):
        return jax.tree_util.tree_map(
            lambda leaf: _global_array(leaf[start:start + call_size], sharding), padded_batch)

    first = device_block(0)
    compiled = sharded_sweep.lower(consts, first).compile()
    compile_s = time.perf_counter() - started
    memory = _memory_stats(compiled)

    outputs = []
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=n, unit="design", desc="sweep")
    def block_of(call):
        return first if call == 0 else device_block(call * call_size)

    if workers == 1 or n_calls == 1:
        pending = None
        for call in range(n_calls):
            result = compiled(consts, block_of(call))
            if pending is not None:  # dispatch is asynchronous: wait for the previous call
                outputs.append(_to_host(pending))
                if bar is not None:
                    bar.update(min(call * call_size, n) - bar.n)
            pending = result
        outputs.append(_to_host(pending))
    else:
        pool = ThreadPoolExecutor(max_workers=min(workers, n_calls))
        futures = [pool.submit(lambda c: _to_host(compiled(consts, block_of(c))), call)
                   for call in range(n_calls)]
        try:
            finished = 0
            for future in as_completed(futures):
                future.result()  # an error in a call stops the sweep here
                finished += 1
                if bar is not None:
                    bar.update(min(finished * call_size, n) - bar.n)
        finally:  # on an error or Ctrl-C, drop the calls not yet started
            pool.shutdown(wait=True, cancel_futures=True)
        outputs = [future.result() for future in futures]
    if bar is not None:
        bar.update(n - bar.n)
        bar.close()
    elapsed_s = time.perf_counter() - started

    def assemble(*parts):
        return np.concatenate(parts, axis=0)[:n]

    value, gradient, aux, status = jax.tree_util.tree_map(assemble, *outputs)
    run_s = elapsed_s - compile_s
    info = {
        "n_designs": n,
        "grad": bool(grad),
        "has_aux": bool(has_aux),
        "batch_size": batch_size,
        "n_devices": n_devices,
        "device_kind": devices[0].device_kind,
        "platform": devices[0].platform,
        "process_count": jax.process_count(),
        "padded_designs": padded,
        "calls": n_calls,
        "chunks_per_call": chunks_per_call,
        "workers": workers,
        "compile_s": compile_s,
        "run_s": run_s,
        "designs_per_second": n / run_s if run_s > 0 else None,
        "memory": memory,
        "dtypes": sorted({str(leaf.dtype) for leaf in jax.tree_util.tree_leaves(host_batch)}),
        "jax_version": jax.__version__,
        "python": platform.python_version(),
        "user": dict(metadata or {}),
    }
    json.dumps(info, default=_json_default)  # fail now, not at save time
    return SweepResult(inputs=host_batch, value=value, grad=gradient, aux=aux, status=status,
                       metadata=info)


def _memory_stats(compiled) -> dict | None:
    """XLA's memory figures for the compiled sweep, per device (bytes), when it gives them."""
    try:
        stats = compiled.memory_analysis()
    except Exception:  # not every backend implements it
        return None
    if stats is None:
        return None
    return {
        "argument_bytes": int(stats.argument_size_in_bytes),
        "output_bytes": int(stats.output_size_in_bytes),
        "temp_bytes": int(stats.temp_size_in_bytes),
        "generated_code_bytes": int(stats.generated_code_size_in_bytes),
    }


def hypercube(**axes) -> dict[str, np.ndarray]:
    """Every combination of the given 1-D axes, flattened in C order (the last axis fastest).

    Parameters
    ----------
    **axes : 1-D array_like, each non-empty
        One axis per name, e.g. ``w020=np.linspace(-3, 3, 25)``.

    Returns
    -------
    dict of ndarray, each of shape ``(prod(len(axis)),)``

    Examples
    --------
    >>> import jmse_jax as jj
    >>> cube = jj.hypercube(w020=[0.0, 1.0], field=[0.0, 0.5, 1.0])
    >>> cube["w020"].tolist(), cube["field"].tolist()
    ([0.0, 0.0, 0.0, 1.0, 1.0, 1.0], [0.0, 0.5, 1.0, 0.0, 0.5, 1.0])
    """
    if not axes:
        raise ValueError("hypercube needs at least one axis, e.g. hypercube(w020=[0.0, 1.0])")
    arrays = {}
    for name, values in axes.items():
        arr = np.asarray(values)
        if arr.ndim != 1 or arr.size == 0:
            raise ValueError(f"axis {name} must be a non-empty 1-D array, got shape {arr.shape}")
        arrays[name] = arr
    grids = np.meshgrid(*arrays.values(), indexing="ij")
    return {name: grid.reshape(-1) for name, grid in zip(arrays, grids, strict=True)}


#: Designs per evaluation of ``_concrete_choice`` in ``warn_like_jmse`` (batches of fewer
#: take the next power of two, so that few programs are compiled).
_CHECK_CHUNK = 1024


def beyond_message(message, value: float, beyond: int = 1, n: int = 1) -> str:
    """``message`` (``_merit``'s strength, slope or cancellation warning) for the largest
    ``value`` among ``beyond`` of ``n`` designs."""
    return message(f"{value:.3g}" if n == 1 else f"up to {value:.3g} ({beyond} of {n} designs)")


@functools.lru_cache(maxsize=16)
def _choice_program(static):
    """The compiled batch of ``_concrete_choice`` for ``jmse``'s static ``static``:
    ``(one-ray plan, strength, cancellation)`` per design."""

    def one(*design):
        _, _, symmetric, strength, cancellation = _concrete_choice(static, *design)
        return symmetric, strength, cancellation

    return jax.jit(jax.vmap(one))


def warn_like_jmse(aberrations, field, u, signal, noise, options, stacklevel: int = 2,
                   warn: bool = True):
    """The warnings an eager ``jmse`` call gives a concrete design, for a batch of designs
    that run traced (under ``vmap`` ``jmse`` gives them only when the program runs, without
    the values: ``_design_check``): ``aberration_strength``
    beyond ``CHECKED_STRENGTH``, the wavefront slope beyond ``CHECKED_SLOPE``, terms that
    cancel beyond what the preset was checked at (``BALANCED_CANCELLATION``, or
    ``CHECKED_CANCELLATION`` with a preset's balanced grid: the default's and ``"high"``'s),
    and the peak ``S_x / S_n`` beyond ``CHECKED_SNR`` (``CHECKED_SNR_PEAKS`` with the
    closed-form peaks and for designs on the axis). One warning per kind, with the largest
    value and how many designs; nothing where grid options are given (as ``jmse``).

    ``aberrations``, ``field``, ``u``: leaves of leading axis (n,) or scalars (shared), as in
    ``sweep``; designs out of range or not finite are left out (``jmse`` refuses those).
    ``options``: ``jmse``'s keyword options, ``preset`` among them. The strength and
    symmetry of each design are the library's own choice of plan (``_concrete_choice``,
    compiled once per static and batch size), the bounds ``_beyond_checked``'s, the noise
    check ``_warn_beyond_checked_snr``'s. ``stacklevel``: ``warnings.warn``'s, here (2 names
    the line that called this). ``warn=False``: the mask only.

    Returns the designs beyond a bound (``SweepResult.beyond_checked``): bool, shape (n,),
    False for those left out; the peak ratio per design by its own ``u`` and symmetry, as
    the run-time check of a traced call has it (``_design_check``). None with grid
    options."""
    if any(options.get(name) is not None for name in _GRID_OPTIONS):
        return None  # the caller's own grids: jmse gives no such warning either
    designs, n_all = _host_batch({"aberrations": aberrations, "field": field, "u": u})
    field, u = designs["field"], designs["u"]
    finite = np.all([np.isfinite(leaf).reshape(leaf.shape[0], -1).all(axis=1)
                     for leaf in jax.tree_util.tree_leaves(designs)], axis=0)
    keep = finite & (field >= 0.0) & (field <= 1.0) & (u > 0.0) & (u <= U_MAX)
    mask = np.zeros(n_all, bool)
    n = int(keep.sum())
    if n == 0:
        return mask
    designs = jax.tree_util.tree_map(lambda x: x[keep], designs)
    ordered = (designs["aberrations"], designs["field"], designs["u"])
    resolved = jmse_options(**options)
    static, _ = _prepare((*jax.tree_util.tree_map(lambda x: x[0], ordered), signal, noise),
                         resolved)
    choice = _choice_program(static)
    size = min(_CHECK_CHUNK, 1 << (n - 1).bit_length())
    parts = []
    for start in range(0, n, size):  # fixed-size blocks: one compiled program
        index = np.minimum(np.arange(start, start + size), n - 1)
        block = jax.tree_util.tree_map(lambda x, index=index: x[index], ordered)
        parts.append([np.asarray(x)[: n - start] for x in choice(*block)])
    symmetric, strength, cancellation = (np.concatenate(x) for x in zip(*parts, strict=True))
    symmetric = symmetric.astype(bool)
    u = designs["u"]
    balanced = static.value[4] is not None
    strong, steep, cancelling, slope = _beyond_checked(strength, u, symmetric, cancellation,
                                                       balanced=balanced)
    snr_peaks = _snr_peaks(resolved["peaks"], resolved["tiers"])
    values, inverse = np.unique(u, return_inverse=True)
    ratios = jax.vmap(_peak_snr, (0, None, None))
    # In chunks: a sweep may hold a million distinct u, each a 17 x 17 grid here.
    peak = np.concatenate([np.asarray(ratios(values[i:i + _PEAK_CHUNK], signal, noise))
                           for i in range(0, values.size, _PEAK_CHUNK)])[inverse.reshape(-1)]
    noisy = peak > np.where(symmetric | snr_peaks, CHECKED_SNR_PEAKS, CHECKED_SNR)
    mask[keep] = strong | steep | cancelling | noisy
    if not warn:
        return mask
    cancelling_message = functools.partial(_cancellation_message, balanced=balanced)
    for message, beyond, values in ((_strength_message, strong, strength),
                                    (_slope_message, steep, slope),
                                    (cancelling_message, cancelling, cancellation)):
        if beyond.any():
            warnings.warn(beyond_message(message, float(values[beyond].max()),
                                         int(beyond.sum()), n),
                          AccuracyWarning, stacklevel=stacklevel)
    # The one-ray plans integrate the peaks in closed form, as peaks=True does.
    off_axis = ~symmetric
    u_max = jnp.asarray(np.max(u[off_axis] if off_axis.any() else u), u.dtype)
    peaks = (not off_axis.any()) or snr_peaks
    _warn_beyond_checked_snr(u_max, signal, noise, stacklevel=stacklevel + 1, peaks=peaks)
    return mask


def _lists_as_arrays(aberrations, field, u):
    """Lists and tuples among the leaves become float arrays (a list would be read as a
    pytree of separate scalar leaves)."""
    def as_array(x):
        return np.asarray(x, float) if isinstance(x, (list, tuple)) else x

    aberrations = jax.tree_util.tree_map(as_array, aberrations,
                                         is_leaf=lambda x: isinstance(x, (list, tuple)))
    return aberrations, as_array(field), as_array(u)


def beyond_checked(aberrations, field, u, signal, noise, *, preset: str = "default",
                   **options):
    """Whether designs lie beyond what ``preset``'s grids were checked at, without
    computing their JMSE: the designs a concrete ``jmse`` call warns about
    (``AccuracyWarning``: ``aberration_strength`` beyond ``CHECKED_STRENGTH``, the wavefront
    slope beyond ``CHECKED_SLOPE``, terms that cancel beyond ``CHECKED_CANCELLATION``, or
    ``BALANCED_CANCELLATION`` for a preset without the balanced grid, a peak ``S_x / S_n``
    beyond ``CHECKED_SNR``, or ``CHECKED_SNR_PEAKS`` with the closed-form peaks and on the
    axis), for one design or a batch, as ``sweep_jmse`` marks them
    (``SweepResult.beyond_checked``). For an optimiser's constraint, a screen before a
    sweep, or a notebook that wants the answer as a value rather than a warning.

    Parameters
    ----------
    aberrations, field, u, signal, noise
        As in ``jmse`` for one design; as in ``sweep_jmse`` for a batch (leaves of leading
        axis (n,), scalars shared). Concrete values (not traced: under ``jit`` ``jmse``
        checks its designs when the program runs).
    preset, **options
        ``jmse``'s options. Grid options (``nodes``, ``se_nodes``, ...) have no checked range
        and are refused.

    Returns
    -------
    bool for one design (``field`` and ``u`` scalars, the aberrations one design's), else
    ndarray of bool, shape (n,). In a batch, designs that ``jmse`` refuses (not finite,
    ``field`` outside [0, 1], ``u`` outside (0, 1.5]) are False; one design alone is
    checked as ``jmse`` checks it, with its errors.

    Examples
    --------
    >>> import jmse_jax as jj
    >>> signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
    >>> jj.beyond_checked(jj.Seidel(w020=1.0, w131=0.3), 0.5, 0.2, signal, noise)
    False
    >>> jj.beyond_checked(jj.Seidel(w020=[1.0, 60.0], w131=0.3), 0.5, 0.2, signal, noise)
    array([False,  True])
    """
    jmse_options(preset, **options)  # ValueError now for a bad option
    given = [name for name in _GRID_OPTIONS if options.get(name) is not None]
    if given:
        raise ValueError(f"beyond_checked: grid options ({', '.join(given)}) have no checked "
                         f"range; the bounds are those of the presets' own grids")
    if not is_concrete((aberrations, field, u, signal, noise)):
        raise TypeError("beyond_checked needs concrete values, got traced ones (under jit, "
                        "vmap or grad jmse checks its designs when the program runs)")
    aberrations, field, u = _lists_as_arrays(aberrations, field, u)
    one = 1 if isinstance(aberrations, Zernike) else 0  # a single design's leaf ndim
    single = (np.ndim(field) == 0 and np.ndim(u) == 0
              and all(np.ndim(x) <= one for x in jax.tree_util.tree_leaves(aberrations)))
    if single:
        _validate(aberrations, field, u, signal, noise)  # jmse's own checks and errors
        aberrations, field, u = jax.tree_util.tree_map(
            lambda x: np.asarray(x)[None], (aberrations, field, u))
    mask = warn_like_jmse(aberrations, field, u, signal, noise, dict(options, preset=preset),
                          warn=False)
    return bool(mask[0]) if single else mask


#: Distinct ``u`` per evaluation of the peak ratios in ``_with_sweep_counts``.
_PEAK_CHUNK = 4096


def _with_sweep_counts(preset, options, resolved, u, signal, noise):
    """``options`` with the counts ``"high"`` takes by itself at low noise (``jmse``'s
    ``otf_radial`` and ``grad_se_angular``: ``_optimise._with_gradient_counts``, as
    ``lens_merit`` passes them), chosen here from the sweep's concrete ``u``: inside the
    sweep ``u`` is one of the batched inputs, traced, so ``jmse`` could not choose them
    and would take its own grid's (a value up to 6.2e-5 off past ``CHECKED_SNR``, and a
    gradient that warns at run time). The counts are those of the in-range ``u`` with the
    largest peak ``S_x / S_n``, so every design gets at least the counts it needs.
    Anything else (a traced ``u``, no ``u`` in range, options without the choice) is
    returned as it is; bad arguments are then refused by ``jmse``'s own checks.
    ``resolved``: ``jmse_options(preset, **options)``."""
    from ._optimise import _with_gradient_counts  # _optimise imports the merit, not this

    if not _chooses_counts(resolved, resolved["tiers"]):
        return options  # not "high"-like: nothing to choose (spares the ratio's program)
    try:
        values = np.unique(np.asarray(u, float).reshape(-1))
    except (TypeError, ValueError):  # a traced u (jax's conversion errors are TypeErrors)
        return options
    values = values[np.isfinite(values) & (values > 0.0) & (values <= U_MAX)]
    if values.size == 0:
        return options
    ratios = jax.vmap(_peak_snr, (0, None, None))
    try:
        # In chunks: a sweep may hold a million distinct u, each a 17 x 17 grid here.
        snr = np.concatenate([np.asarray(ratios(values[i:i + _PEAK_CHUNK], signal, noise))
                              for i in range(0, values.size, _PEAK_CHUNK)])
    except (TypeError, ValueError):
        return options  # spectra jmse refuses, with its own message
    worst = values[int(np.argmax(np.where(np.isfinite(snr), snr, -np.inf)))]
    chosen = _with_gradient_counts({"preset": preset, **options}, worst, signal, noise,
                                   prefix="grad_")
    return {key: value for key, value in chosen.items() if key != "preset"}


def sweep_jmse(
    aberrations,
    field,
    u,
    signal,
    noise,
    *,
    grad: bool = False,
    preset: str = "default",
    batch_size: int | None = None,
    chunks_per_call: int | None = None,
    devices: int | Sequence | None = None,
    workers: int | None = None,
    progress: bool | None = None,
    metadata: dict | None = None,
    **options,
) -> SweepResult:
    """``jmse`` over a batch of aberrations, fields and Nyquist ratios ``u`` (see ``sweep``).

    Parameters
    ----------
    aberrations : Seidel or Zernike with leaves of leading axis (n,) [waves]
        Scalar leaves are shared by every design.
    field : float or array, shape (n,) [fraction of the full field]
    u : float or array, shape (n,) [sensor Nyquist / optical cutoff]
    signal, noise : fixed for the whole sweep (as in ``jmse``)
    grad : bool
        Also return the gradient with respect to the aberrations, ``field`` and ``u``.
    preset, **options
        ``jmse`` options, checked before anything is compiled. For ``preset="high"`` with
        none of the counts (``se_angular``, ``otf_radial``, their ``grad_`` twins) nor grid
        options given, the sweep takes the counts an eager ``jmse`` call takes by itself
        at low noise (``otf_radial_for``; ``se_angular_for`` for the gradient) for the
        in-range ``u`` with the largest peak ``S_x / S_n``, so every design gets at least
        the counts it needs (inside the sweep ``u`` is traced and ``jmse`` could not).
        Before the sweep the designs get the warnings an eager ``jmse`` call gives
        (``warn_like_jmse``: strength, wavefront slope, cancelling terms, peak ``S_x /
        S_n`` beyond what the preset was checked at), one per kind with the largest value
        and the number of designs; none with grid options given, as in ``jmse``. Which
        designs they concern is the result's ``beyond_checked``.
    batch_size, chunks_per_call, devices, workers, progress, metadata
        As in ``sweep``.

    Returns
    -------
    SweepResult
        ``inputs`` is ``{"aberrations": ..., "field": ..., "u": ...}``. Designs with a
        field outside ``[0, 1]`` or ``u`` outside ``(0, 1.5]`` get ``SweepStatus.INVALID``
        and non-finite ones ``NONFINITE_INPUT``; the value of both is ``+inf``.
        ``beyond_checked`` marks the designs beyond the preset's checked range (with a
        preset's grids): ``result.in_checked_range`` selects the values held to the
        preset's accuracy.

    Examples
    --------
    >>> import numpy as np
    >>> import jmse_jax as jj
    >>> cube = jj.hypercube(w020=np.linspace(-1.0, 1.0, 3), field=[0.0, 1.0])
    >>> result = jj.sweep_jmse(jj.Seidel(w020=cube["w020"], w222=0.5), cube["field"], 0.2,
    ...                        jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3), preset="fast",
    ...                        progress=False)
    >>> result.value.shape, result.status_counts()
    ((6,), {'OK': 6})
    """
    resolved = jmse_options(preset, **options)  # ValueError now for a bad option
    aberrations, field, u = _lists_as_arrays(aberrations, field, u)
    named = [("field", field), ("u", u)]
    if isinstance(aberrations, Seidel):
        named += [(f"aberrations.{name}", getattr(aberrations, name))
                  for name in Seidel.__dataclass_fields__]
    for name, value in named:
        if isinstance(value, (list, tuple)):
            value = np.asarray(value, float)
        if np.ndim(value) > 1:
            raise ValueError(f"{name} must be a scalar or a 1-D array (one value per design), "
                             f"got shape {np.shape(value)}")
    options = _with_sweep_counts(preset, options, resolved, u, signal, noise)
    checked = _CHECKED_ALREADY.get()
    beyond = None
    if is_concrete((aberrations, field, u)):
        # Under vmap jmse gives its warnings only when the program runs, without the
        # designs' values: given here, with them, before anything is compiled (unless the
        # caller gave them), and which designs they concern kept in the result.
        beyond = warn_like_jmse(aberrations, field, u, signal, noise,
                                dict(options, preset=preset), stacklevel=3, warn=not checked)
        checked = True

    def in_range(design):
        f, v = design["field"], design["u"]
        return (f >= 0.0) & (f <= 1.0) & (v > 0.0) & (v <= U_MAX)

    def merit(design):
        # Given above, the warnings are not checked again at run time (jmse's
        # _design_check); the context is set where the program is traced, on any thread.
        with _checked_already() if checked else contextlib.nullcontext():
            value = jmse(design["aberrations"], design["field"], design["u"], signal, noise,
                         preset=preset, **options)
        # An out-of-range design's value is +inf, as its status says, not a finite number
        # that a filter on np.isfinite would keep.
        return jnp.where(in_range(design), value, jnp.inf)

    batch = {"aberrations": aberrations, "field": field, "u": u}
    result = sweep(merit, batch, grad=grad, valid=in_range, batch_size=batch_size,
                   chunks_per_call=chunks_per_call, devices=devices, workers=workers,
                   progress=progress, metadata=metadata)
    if beyond is None:
        return result
    return dataclasses.replace(result, beyond_checked=beyond & result.ok)
