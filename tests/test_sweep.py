"""Tests of ``jmse_jax.sweep``: sweep == loop, statuses, padding and order, persistence, and
sharded == unsharded on 4 fake CPU devices (in a subprocess, see ``sweep_devices_worker``)."""

import collections
import json
import os
import socket
import subprocess
import sys
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

jax.config.update("jax_enable_x64", True)

import jmse_jax as jj  # noqa: E402
from jmse_jax import AccuracyWarning, SweepStatus  # noqa: E402

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from checked_range import eager_warns  # noqa: E402
from sweep_devices_worker import CHEAP, designs  # noqa: E402

SIGNAL, NOISE = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)


def _loop_jmse(aberrations, field, u, index):
    """Value and gradient of jmse for design ``index``, one design at a time (the oracle)."""
    n = field.shape[0]
    one = jax.tree_util.tree_map(lambda leaf: jnp.broadcast_to(leaf, (n,))[index], aberrations)

    def merit(ab, f, v):
        return jj.jmse(ab, f, v, SIGNAL, NOISE, **CHEAP)

    value, grads = jax.value_and_grad(merit, argnums=(0, 1, 2))(one, field[index], u[index])
    return float(value), grads


def test_sweep_jmse_equals_loop_with_bad_designs():
    aberrations, field = designs()  # design 4 has a NaN coefficient
    n = field.shape[0]
    field = field.copy()
    field[6] = 1.2  # out of range: INVALID, the sweep goes on
    u = np.full(n, 0.2)
    u[7] = np.inf
    result = jj.sweep_jmse(aberrations, field, u, SIGNAL, NOISE, grad=True, batch_size=2,
                           progress=False, **CHEAP)
    expected_status = np.zeros(n, dtype=np.int8)
    expected_status[[4, 7]] = SweepStatus.NONFINITE_INPUT
    expected_status[6] = SweepStatus.INVALID
    np.testing.assert_array_equal(result.status, expected_status)
    assert result.status_counts() == {"OK": 6, "NONFINITE_INPUT": 2, "INVALID": 1}
    # Every design a status flags has the value +inf, the out-of-range one too.
    assert np.isposinf(result.value[[4, 6, 7]]).all()
    for i in np.flatnonzero(result.ok):
        value, (d_ab, d_field, d_u) = _loop_jmse(aberrations, field, u, i)
        np.testing.assert_allclose(result.value[i], value, rtol=1e-12)
        for name in ("w020", "w222", "w131", "w040"):
            np.testing.assert_allclose(getattr(result.grad["aberrations"], name)[i],
                                       getattr(d_ab, name), rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(result.grad["field"][i], d_field, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(result.grad["u"][i], d_u, rtol=1e-9, atol=1e-15)
    # The inputs are kept beside the results, scalars broadcast to one per design.
    np.testing.assert_array_equal(result.inputs["aberrations"].w040, np.full(n, 0.4))
    np.testing.assert_array_equal(result.inputs["field"], field)
    assert result.metadata["padded_designs"] == 10 and result.metadata["n_devices"] == 1


def _toy(design):
    return jnp.sqrt(design["x"]) * design["y"]


def test_statuses_of_a_generic_function():
    x = np.array([4.0, -1.0, 0.0, np.nan, 9.0, 1.0])
    y = np.array([1.0, 1.0, 1.0, 1.0, 2.0, 50.0])
    result = jj.sweep(_toy, {"x": x, "y": y}, grad=True, valid=lambda d: d["y"] < 10.0,
                      batch_size=4, progress=False)
    np.testing.assert_array_equal(result.status, [
        SweepStatus.OK, SweepStatus.NONFINITE_VALUE, SweepStatus.NONFINITE_GRADIENT,
        SweepStatus.NONFINITE_INPUT, SweepStatus.OK, SweepStatus.INVALID])
    np.testing.assert_array_equal(result.ok, [True, False, False, False, True, False])
    np.testing.assert_allclose(result.value[[0, 4]], [2.0, 6.0], rtol=1e-15)
    np.testing.assert_allclose(result.grad["x"][[0, 4]], [0.25, 1.0 / 3.0], rtol=1e-15)
    np.testing.assert_allclose(result.grad["y"][[0, 4]], [2.0, 3.0], rtol=1e-15)


@pytest.mark.parametrize("n, batch_size, chunks_per_call, progress, workers", [
    (1, 1, 1, False, 1), (7, 3, 1, False, 1), (7, 2, 1, True, 1), (40, 3, 4, True, 1),
    (40, 64, 2, False, 1), (7, 1, 1, True, 3), (40, 3, 2, False, 4), (1, 1, 1, False, 2),
])
def test_padding_and_order(n, batch_size, chunks_per_call, progress, workers):
    index = np.arange(n, dtype=np.float64)
    batch = {"index": index, "pair": np.stack([index, -index], axis=1)}

    def fn(d):
        return {"sum": d["pair"][0] - 2.0 * d["pair"][1], "copy": d["index"]}

    result = jj.sweep(fn, batch, batch_size=batch_size, chunks_per_call=chunks_per_call,
                      workers=workers, progress=progress)
    np.testing.assert_array_equal(result.value["sum"], 3.0 * index)
    np.testing.assert_array_equal(result.value["copy"], index)
    np.testing.assert_array_equal(result.status, np.zeros(n))
    np.testing.assert_array_equal(result.inputs["pair"], batch["pair"])
    call_size = batch_size * chunks_per_call
    calls = -(-n // call_size)
    assert result.metadata["calls"] == calls
    assert result.metadata["padded_designs"] == calls * call_size
    assert result.metadata["workers"] == workers


def test_workers_do_not_change_the_results():
    """Calls issued from several host threads run the same compiled program: bit for bit
    the one-thread sweep, in input order, with gradients."""
    aberrations, field = designs()
    n = field.shape[0]
    u = np.linspace(0.15, 0.3, n)
    results = [jj.sweep_jmse(aberrations, field, u, SIGNAL, NOISE, grad=True, workers=w,
                             batch_size=1, progress=w == 3, **CHEAP) for w in (1, 3)]
    one, three = results
    assert (one.metadata["workers"], three.metadata["workers"]) == (1, 3)
    assert three.metadata["calls"] == n
    np.testing.assert_array_equal(one.status, three.status)
    np.testing.assert_array_equal(one.value, three.value)
    leaves = jax.tree_util.tree_leaves
    for a, b in zip(leaves(one.grad), leaves(three.grad), strict=True):
        np.testing.assert_array_equal(a, b)
    i = 5  # an OK design: the threaded sweep's entry equals the one-design loop (the oracle)
    value, (d_ab, _, d_u) = _loop_jmse(aberrations, field, u, i)
    np.testing.assert_allclose(three.value[i], value, rtol=1e-12)
    np.testing.assert_allclose(three.grad["u"][i], d_u, rtol=1e-9)
    np.testing.assert_allclose(three.grad["aberrations"].w020[i], d_ab.w020, rtol=1e-9)


def test_an_error_in_a_threaded_call_stops_the_sweep():
    """An error raised while a call runs reaches the caller, and calls not yet started are
    dropped rather than run to the end of the sweep."""
    seen = []

    def host(x):
        seen.append(float(x))
        if x == 3.0:
            raise RuntimeError("design 3 failed")
        return np.asarray(2.0 * x)

    def fn(design):
        return jax.pure_callback(host, jax.ShapeDtypeStruct((), jnp.float64), design["x"])

    n = 200
    with pytest.raises(Exception, match="design 3 failed"):
        jj.sweep(fn, {"x": np.arange(n, dtype=np.float64)}, workers=2, progress=False)
    assert 3.0 in seen and len(seen) < n


def test_default_workers_on_cpu():
    """On one CPU host the default issues calls from one thread per core and device."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    result = jj.sweep(_toy, {"x": np.ones(5), "y": np.ones(5)}, progress=False)
    assert result.metadata["workers"] == max(1, cores // jax.device_count())


@pytest.mark.parametrize("n, batch_size, chunks", [
    (300, 1, 16), (256, 1, 16), (255, 1, 15), (40, 1, 2), (5, 1, 1), (300, 2, 1),
])
def test_default_chunks_per_call_on_cpu(n, batch_size, chunks):
    """On a CPU with one design per chunk, a call works through up to 16 designs (n // 16
    for small batches); with a vmap it stays one chunk. The results do not change."""
    x = np.linspace(0.0, 1.0, n)
    result = jj.sweep(lambda d: d["x"] ** 2 + 1.0, {"x": x}, batch_size=batch_size,
                      progress=False)
    assert result.metadata["chunks_per_call"] == chunks
    calls = -(-n // (chunks * batch_size))
    assert result.metadata["calls"] == calls
    np.testing.assert_allclose(result.value, x**2 + 1.0, rtol=1e-15)


def test_has_aux_and_integer_leaves():
    batch = {"x": np.array([1.0, 2.0, 3.0]), "k": np.array([1, 2, 3])}
    result = jj.sweep(lambda d: (d["x"] * d["k"], {"half": 0.5 * d["x"]}), batch,
                      has_aux=True, batch_size=2, progress=False)
    np.testing.assert_array_equal(result.value, [1.0, 4.0, 9.0])
    np.testing.assert_array_equal(result.aux["half"], [0.5, 1.0, 1.5])
    assert result.grad is None


def test_save_and_load_round_trip(tmp_path):
    aberrations = jj.Seidel(w020=np.array([0.5, -0.5, 1.0]), w040=0.2)
    result = jj.sweep_jmse(aberrations, np.array([0.0, 0.5, 2.0]), 0.3, SIGNAL, NOISE,
                           grad=True, batch_size=2, progress=False,
                           metadata={"study": "round trip"}, **CHEAP)
    path = result.save(tmp_path / "study")
    assert path.name == "study.npz"
    header = json.loads((tmp_path / "study.json").read_text())
    assert header["metadata"]["user"] == {"study": "round trip"}
    assert header["status_counts"] == {"OK": 2, "INVALID": 1}
    loaded = jj.SweepResult.load(path)
    assert isinstance(loaded.inputs["aberrations"], jj.Seidel)
    assert isinstance(loaded.grad["aberrations"], jj.Seidel)
    for group in ("inputs", "value", "grad"):
        original, back = getattr(result, group), getattr(loaded, group)
        assert jax.tree_util.tree_structure(original) == jax.tree_util.tree_structure(back)
        for a, b in zip(jax.tree_util.tree_leaves(original), jax.tree_util.tree_leaves(back),
                        strict=True):
            np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(loaded.status, result.status)
    assert loaded.aux is None
    assert loaded.metadata == json.loads(json.dumps(result.metadata))
    # A reloaded design is usable as is.
    first = jax.tree_util.tree_map(lambda leaf: leaf[0], loaded.inputs)
    value = jj.jmse(first["aberrations"], first["field"], first["u"], SIGNAL, NOISE, **CHEAP)
    np.testing.assert_allclose(value, loaded.value[0], rtol=1e-12)
    # The readable header's path loads its .npz (NumPy's message was about pickles).
    np.testing.assert_array_equal(jj.SweepResult.load(tmp_path / "study.json").value,
                                  result.value)
    # JAX scalars in the metadata are written as numbers; NaN (not JSON) is refused.
    result.metadata["user"] = {"scale": jnp.float32(2.0)}
    result.save(tmp_path / "scaled")
    assert json.loads((tmp_path / "scaled.json").read_text())["metadata"]["user"] == {
        "scale": 2.0}
    result.metadata["user"] = {"scale": float("nan")}
    with pytest.raises(ValueError, match="metadata must hold finite numbers only"):
        result.save(tmp_path / "nan")


def test_save_keeps_static_fields(tmp_path):
    zernike = jax.vmap(lambda c: jj.Zernike(c, noll=(2, 4)))(jnp.array([[0.1, 0.2], [0.3, 0.4]]))
    result = jj.sweep(lambda d: jnp.sum(d.coefficients), zernike, progress=False)
    loaded = jj.SweepResult.load(result.save(tmp_path / "zernike.npz"))
    assert isinstance(loaded.inputs, jj.Zernike) and loaded.inputs.noll == (2, 4)
    np.testing.assert_allclose(loaded.value, [0.3, 0.7], rtol=1e-15)


Point = collections.namedtuple("Point", "x y")  # a user's own pytree of designs


def test_load_rebuilds_only_namedtuples_and_modules(tmp_path):
    """A file is data: a header naming any other callable (here ``subprocess.run`` with a
    shell command) is refused without calling it, and a module the caller has not imported
    is not imported."""
    result = jj.sweep(lambda d: d.x * d.y, Point(np.array([1.0, 2.0]), np.array([3.0, 4.0])),
                      progress=False)
    path = result.save(tmp_path / "point.npz")
    marker = tmp_path / "ran"

    def rewrite(class_path, fields):
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
        header = json.loads(str(arrays["__header__"]))
        spec = header["trees"]["inputs"]
        spec["class"], spec["fields"] = class_path, fields
        arrays["inputs.x"] = np.array([f"touch {marker}"])
        arrays["inputs.y"] = np.array(True)
        arrays["__header__"] = np.array(json.dumps(header))
        crafted = tmp_path / "crafted.npz"
        np.savez(crafted, **arrays)
        return crafted

    with pytest.raises(ValueError, match=r"names 'subprocess:run' as a namedtuple class"):
        jj.SweepResult.load(rewrite("subprocess:run", ["args", "shell"]))
    assert not marker.exists()
    with pytest.raises(ValueError, match=r"module 'antigravity' is not imported"):
        jj.SweepResult.load(rewrite("antigravity:Point", ["x", "y"]))
    assert "antigravity" not in sys.modules
    # The user's own namedtuple, its module imported, comes back as itself.
    loaded = jj.SweepResult.load(path)
    assert type(loaded.inputs) is Point
    np.testing.assert_array_equal(loaded.value, [3.0, 8.0])


def test_hypercube_order():
    cube = jj.hypercube(a=[1.0, 2.0], b=[10.0, 20.0, 30.0])
    np.testing.assert_array_equal(cube["a"], [1, 1, 1, 2, 2, 2])
    np.testing.assert_array_equal(cube["b"], [10, 20, 30, 10, 20, 30])


@pytest.mark.parametrize("kwargs, match", [
    (dict(batch_size=0), "batch_size must be an integer >= 1, got 0"),
    (dict(batch_size=2.5), "batch_size must be an integer >= 1"),
    (dict(chunks_per_call=0), "chunks_per_call must be an integer >= 1, got 0"),
    (dict(workers=0), "workers must be an integer >= 1, got 0"),
    (dict(workers=1.5), "workers must be an integer >= 1"),
    (dict(devices=0), r"devices must be in \[1, \d+\]"),
    (dict(devices=[]), "devices must be None"),
])
def test_bad_arguments(kwargs, match):
    with pytest.raises(ValueError, match=match):
        jj.sweep(_toy, {"x": np.ones(3), "y": np.ones(3)}, progress=False, **kwargs)


@pytest.mark.parametrize("batch, kwargs, match", [
    ({"x": np.ones(3), "y": np.ones(4)}, {}, r"same leading length; got batch\['x'\]: 3"),
    ({"x": 1.0, "y": 2.0}, {}, "every leaf is a scalar"),
    ({}, {}, "at least one array leaf"),
    ({"x": np.ones(0), "y": np.ones(0)}, {}, "leading length of 0"),
    ({"x": np.ones(2), "y": np.array([1, 2])}, {"grad": True}, r"batch\['y'\] has dtype int64"),
    ({"x": np.ones((2, 3)), "y": np.ones(2)}, {"grad": True}, "real scalar per design"),
])
def test_bad_batches(batch, kwargs, match):
    with pytest.raises(ValueError, match=match):
        jj.sweep(_toy, batch, progress=False, **kwargs)


def test_float32_designs_keep_float32_with_python_float_defaults():
    """A Seidel of float32 arrays keeps its other coefficients as Python floats (0.0); the
    batch takes float32 from its arrays, as jnp (and a single jmse call) does, instead of
    float64 from the Python floats."""
    from jmse_jax._sweep import _host_batch

    design = jj.Seidel(w020=np.linspace(-1.0, 1.0, 3).astype(np.float32), w131=np.float32(0.4))
    batch, n = _host_batch((design, np.float32(0.7)))
    assert n == 3
    assert {leaf.dtype for leaf in jax.tree_util.tree_leaves(batch)} == {np.dtype(np.float32)}
    assert jj.jmse(jj.Seidel(w020=np.float32(-1.0), w131=np.float32(0.4)), np.float32(0.7),
                   np.float32(0.25), SIGNAL, NOISE, preset="fast").dtype == np.float32
    mixed, _ = _host_batch({"a": np.ones(2, np.float32), "b": np.zeros(2), "c": 1.0})
    assert (mixed["a"].dtype, mixed["b"].dtype, mixed["c"].dtype) == (
        np.float32, np.float64, np.float64)


def test_bad_options_fail_before_compiling():
    with pytest.raises(ValueError, match="preset must be one of"):
        jj.sweep_jmse(jj.Seidel(w020=np.ones(2)), 0.5, 0.2, SIGNAL, NOISE, preset="slow")
    with pytest.raises(ValueError, match="unknown jmse option 'nodez'"):
        jj.sweep_jmse(jj.Seidel(w020=np.ones(2)), 0.5, 0.2, SIGNAL, NOISE, nodez=3)
    with pytest.raises(ValueError, match="axis w020 must be a non-empty 1-D array"):
        jj.hypercube(w020=[])


@pytest.fixture(scope="module")
def four_device_results(tmp_path_factory):
    """Results of ``sweep_devices_worker.py`` run on 4 fake CPU devices in a fresh process."""
    out_dir = tmp_path_factory.mktemp("four_devices")
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=4",
               JAX_PLATFORMS="cpu")
    completed = subprocess.run(
        [sys.executable, str(HERE / "sweep_devices_worker.py"), str(out_dir)],
        env=env, capture_output=True, text=True, timeout=600,
    )
    assert completed.returncode == 0, completed.stderr[-4000:]
    return {p.stem: jj.SweepResult.load(p) for p in out_dir.glob("*.npz")}


def _assert_identical(a, b):
    np.testing.assert_array_equal(a.status, b.status)
    for group in ("inputs", "value", "grad"):
        leaves_a = jax.tree_util.tree_leaves(getattr(a, group))
        leaves_b = jax.tree_util.tree_leaves(getattr(b, group))
        assert len(leaves_a) == len(leaves_b)
        for x, y in zip(leaves_a, leaves_b, strict=True):
            assert x.dtype == y.dtype == np.float64
            # Bit for bit, infinities included.
            np.testing.assert_array_equal(x.view(np.int64), y.view(np.int64))


def test_sharded_equals_unsharded_bit_for_bit(four_device_results):
    results = four_device_results
    assert [results[f"grad_{d}"].metadata["n_devices"] for d in (1, 2, 4)] == [1, 2, 4]
    # 9 designs, 2 per chunk: padded to 10, 12 and 16 designs.
    assert [results[f"grad_{d}"].metadata["padded_designs"] for d in (1, 2, 4)] == [10, 12, 16]
    # Values: one device and four devices agree bit for bit, with 2 lax.map chunks per call.
    _assert_identical(results["value_1"], results["value_4"])
    assert [results[f"value_{d}"].metadata["calls"] for d in (1, 4)] == [3, 1]
    assert [results[f"value_{d}"].metadata["padded_designs"] for d in (1, 4)] == [12, 16]
    np.testing.assert_allclose(results["value_1"].value, results["grad_1"].value, rtol=1e-14)
    # Values and gradients: 2 and 4 devices, with and without progress bar, bit for bit.
    _assert_identical(results["grad_2"], results["grad_4"])
    _assert_identical(results["grad_4"], results["grad_4_progress"])
    assert results["grad_4_progress"].metadata["calls"] == 2
    # One device: XLA may fuse the backward pass differently without the sharded wrapper
    # (see the Notes of sweep); the gradients then differ in the last few bits only.
    one, four = results["grad_1"], results["grad_4"]
    np.testing.assert_array_equal(one.status, four.status)
    for x, y in zip(jax.tree_util.tree_leaves((one.value, one.grad)),
                    jax.tree_util.tree_leaves((four.value, four.grad)), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-13, atol=1e-17)


def _free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@pytest.fixture(scope="module")
def two_host_results(tmp_path_factory):
    """``sweep_hosts_worker.py`` in two processes joined by ``jax.distributed`` (2 fake CPU
    devices each): one sweep on a 4-device mesh spanning both "hosts"."""
    out_dir = tmp_path_factory.mktemp("two_hosts")
    port = _free_port()
    script = str(HERE / "sweep_hosts_worker.py")  # its folder is on its sys.path
    workers = [subprocess.Popen([sys.executable, script, str(i), str(port), str(out_dir)],
                                stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
               for i in (0, 1)]
    logs = []
    try:
        for worker in workers:
            logs.append(worker.communicate(timeout=600)[0])
    finally:
        for worker in workers:
            worker.kill()
    for worker, log in zip(workers, logs, strict=True):
        assert worker.returncode == 0, log[-4000:]
    return [jj.SweepResult.load(out_dir / f"hosts_grad_{i}.npz") for i in (0, 1)]


def test_two_hosts_equal_one_host_bit_for_bit(two_host_results, four_device_results):
    first, second = two_host_results
    for result in (first, second):
        assert result.metadata["process_count"] == 2
        assert result.metadata["n_devices"] == 4
        assert result.metadata["padded_designs"] == 16  # 9 designs, 2 per chunk, 4 devices
    # Both processes hold the whole result, bit for bit the same.
    _assert_identical(first, second)
    # Against one process with 4 devices: values bit for bit; the multi-process program is
    # compiled on its own and XLA may fuse its backward pass differently (as for one device
    # against four), so gradients agree to the last few bits.
    one_host = four_device_results["grad_4"]
    np.testing.assert_array_equal(first.status, one_host.status)
    np.testing.assert_array_equal(first.value.view(np.int64), one_host.value.view(np.int64))
    for x, y in zip(jax.tree_util.tree_leaves(first.grad),
                    jax.tree_util.tree_leaves(one_host.grad), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-13, atol=1e-17)


def test_sharded_result_in_input_order_and_equal_to_loop(four_device_results):
    order = four_device_results["order_4"]
    assert order.metadata["n_devices"] == 4 and order.metadata["padded_designs"] == 24
    index = np.arange(13.0)
    np.testing.assert_array_equal(order.value, np.stack([index, 2 * index], axis=1))
    sharded = four_device_results["grad_4"]
    aberrations, field = designs()
    u = np.full(field.shape, 0.2)
    assert sharded.status.tolist() == [0, 0, 0, 0, SweepStatus.NONFINITE_INPUT, 0, 0, 0, 0]
    for i in np.flatnonzero(sharded.ok):
        value, (d_ab, d_field, _) = _loop_jmse(aberrations, field, u, i)
        np.testing.assert_allclose(sharded.value[i], value, rtol=1e-12)
        np.testing.assert_allclose(sharded.grad["aberrations"].w020[i], d_ab.w020, rtol=1e-9)
        np.testing.assert_allclose(sharded.grad["field"][i], d_field, rtol=1e-9, atol=1e-15)


def test_sweep_jmse_takes_lists_as_arrays():
    """Lists for the coefficients, field and u mean one value per design, as arrays do (a
    list leaf used to be read as separate scalar leaves); a 2-D leaf is a clear error."""
    w020, field = [0.5, -1.0], [0.5, 0.6]
    listed = jj.sweep_jmse(jj.Seidel(w020=w020, w222=0.3), field, [0.2, 0.25], SIGNAL, NOISE,
                           progress=False, **CHEAP)
    arrays = jj.sweep_jmse(jj.Seidel(w020=np.asarray(w020), w222=0.3), np.asarray(field),
                           np.asarray([0.2, 0.25]), SIGNAL, NOISE, progress=False, **CHEAP)
    np.testing.assert_array_equal(listed.value, arrays.value)
    assert listed.status_counts() == {"OK": 2}
    single = jj.jmse(jj.Seidel(w020=-1.0, w222=0.3), 0.6, 0.25, SIGNAL, NOISE, **CHEAP)
    assert listed.value[1] == pytest.approx(float(single), rel=1e-12)
    with pytest.raises(ValueError, match=r"aberrations\.w020 must be a scalar or a 1-D array"):
        jj.sweep_jmse(jj.Seidel(w020=np.ones((2, 2))), 0.5, 0.2, SIGNAL, NOISE, progress=False,
                      **CHEAP)


# --------------------------------------------------------------------------------------
# sweep_jmse gives jmse's warnings for concrete designs
# --------------------------------------------------------------------------------------


def _sweep_warnings(monkeypatch, *args, **options):
    """``sweep_jmse``'s warnings (as ``(message, filename)``), the sweep itself replaced by
    a stand-in: the warnings come before anything is swept."""
    import jmse_jax._sweep as sweep_module

    def stand_in(fn, batch, **options):  # all OK: the warnings are what is looked at
        n = sweep_module._host_batch(batch)[1]
        return jj.SweepResult(inputs=batch, value=None, grad=None, aux=None,
                              status=np.zeros(n, np.int8), metadata={})

    monkeypatch.setattr(sweep_module, "sweep", stand_in)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        jj.sweep_jmse(*args, progress=False, **options)
    return [(str(w.message), w.filename) for w in caught]


def test_sweep_jmse_warns_once_not_again_at_run_time(with_run_time_checks):
    """``sweep_jmse`` gives its designs' warnings before the sweep, and its program, traced
    with them given (``_checked_already``), carries no run-time check of its own
    (``jmse``'s ``_design_check``): one warning, not two."""
    ab = jj.Seidel(w020=np.array([1.0, 60.0]), w131=0.3)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = jj.sweep_jmse(ab, 0.5, 0.2, SIGNAL, NOISE, preset="fast", progress=False)
    assert np.all(np.isfinite(result.value))
    texts = [str(w.message) for w in caught if "aberration_strength" in str(w.message)]
    assert len(texts) == 1 and "(1 of 2 designs)" in texts[0]


def test_sweep_jmse_gives_the_eager_calls_warnings(monkeypatch):
    """Under ``vmap`` ``jmse`` cannot warn for a design beyond what the presets were checked
    at; ``sweep_jmse`` gives the eager call's warning before the sweep, once, with the
    largest value and the number of designs, attributed to the caller's line. Designs out
    of range or not finite are left out (the sweep marks them); with grid options, within
    the checked range, or when the command line has given them already: none."""
    from jmse_jax._sweep import _checked_already

    w020 = np.array([1.0, 50.0, 60.0, 90.0, np.nan])
    field = np.array([0.5, 0.5, 0.5, 2.0, 0.5])
    ab = jj.Seidel(w020=w020, w131=0.3)
    strength = [float(jj.aberration_strength(jj.Seidel(w020=w, w131=0.3), 0.5, 0.2))
                for w in w020[:3]]
    assert strength[0] < jj.CHECKED_STRENGTH < strength[1] < strength[2]
    with pytest.warns(AccuracyWarning) as eager:  # the oracle: the strongest design, eager
        jj.jmse(jj.Seidel(w020=60.0, w131=0.3), 0.5, 0.2, SIGNAL, NOISE, preset="fast")
    message = str(eager[0].message)
    assert f"aberration_strength {strength[2]:.3g} is beyond" in message
    expected = message.replace(f"{strength[2]:.3g}",
                               f"up to {strength[2]:.3g} (2 of 3 designs)", 1)
    assert _sweep_warnings(monkeypatch, ab, field, 0.2, SIGNAL, NOISE, preset="fast") == [
        (expected, __file__)]
    # Low noise: the peak ratio of the spectra, S_x(0) / S_n, past CHECKED_SNR (2e6).
    ratio = float(SIGNAL(jnp.zeros(()), jnp.zeros(()))) / 1e-9
    texts = _sweep_warnings(monkeypatch, jj.Seidel(w020=np.array([1.0, 2.0]), w131=0.3), 0.5,
                            0.2, SIGNAL, jj.WhiteNoise(1e-9))
    assert len(texts) == 1 and texts[0][0].startswith(
        f"the peak signal-to-noise ratio max S_x/S_n = {ratio:.3g} is beyond what the polar "
        f"grids of 'fast' and the default were checked at")
    assert _sweep_warnings(monkeypatch, ab, field, 0.2, SIGNAL, NOISE, preset="fast",
                           se_nodes=(200, 64)) == []
    assert _sweep_warnings(monkeypatch, jj.Seidel(w020=w020[:1], w131=0.3), 0.5, 0.2, SIGNAL,
                           NOISE, preset="fast") == []
    with _checked_already():
        assert _sweep_warnings(monkeypatch, ab, field, 0.2, SIGNAL, NOISE, preset="fast") == []


_CHECKED_RANGE_DESIGNS = [  # (w020, w040, w131, field, u)
    (1.0, 0.0, 0.3, 0.5, 0.2),     # inside
    (40.0, 0.0, 0.5, 0.5, 0.2),    # slope beyond CHECKED_SLOPE, strength inside
    (60.0, 0.0, 0.3, 0.5, 0.2),    # strength beyond CHECKED_STRENGTH
    (-6.0, 6.0, 0.3, 0.5, 0.3),    # terms that cancel ('fast' has no balanced grid)
    (1.0, 0.0, 0.0, 0.0, 0.2),     # on the axis
    (np.nan, 0.0, 0.3, 0.5, 0.2),  # not finite: NONFINITE_INPUT
    (60.0, 0.0, 0.3, 1.5, 0.2),    # field out of range: INVALID
]


def test_sweep_jmse_marks_the_designs_beyond_the_checked_range(monkeypatch, tmp_path):
    """``SweepResult.beyond_checked``: per design, whether a concrete ``jmse`` call on it
    warns (the oracle, ``checked_range.eager_warns``), for designs beyond the checked
    strength, slope and cancellation and inside it, on and off the axis, at a noise whose
    peak ratio is between ``CHECKED_SNR`` and ``CHECKED_SNR_PEAKS`` (beyond for designs
    off the axis only: on it the one-ray plans integrate the peaks in closed form); False
    for designs whose status is not OK; kept by ``save`` / ``load``; None with grid
    options."""
    designs = _CHECKED_RANGE_DESIGNS
    w020, w040, w131, field, u = (np.array(x) for x in zip(*designs, strict=True))
    ab = jj.Seidel(w020=w020, w040=w040, w131=w131)
    peak = float(SIGNAL(jnp.zeros(()), jnp.zeros(())))
    low = jj.WhiteNoise(peak / 1e7)  # a peak ratio of 1e7
    assert jj.CHECKED_SNR < 1e7 < jj.CHECKED_SNR_PEAKS
    for noise in (NOISE, low):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", AccuracyWarning)
            result = jj.sweep_jmse(ab, field, u, SIGNAL, noise, preset="fast", progress=False)
        expected = [bool(result.ok[i]) and eager_warns(
            monkeypatch, jj.Seidel(w020=w020[i], w040=w040[i], w131=w131[i]), field[i],
            u[i], SIGNAL, noise, preset="fast") for i in range(len(designs))]
        assert result.beyond_checked.tolist() == expected
        assert result.in_checked_range.tolist() == [
            bool(ok) and not beyond for ok, beyond in zip(result.ok, expected, strict=True)]
        if noise is NOISE:
            assert expected == [False, True, True, True, False, False, False]
        else:
            assert expected == [True, True, True, True, False, False, False]
        loaded = jj.SweepResult.load(result.save(tmp_path / "sweep"))
        assert loaded.beyond_checked.tolist() == expected
        assert f"beyond_checked={sum(expected)}" in repr(loaded)
    assert jj.sweep_jmse(ab, field, u, SIGNAL, NOISE, preset="fast", progress=False,
                         se_nodes=(200, 64)).beyond_checked is None
    plain = jj.sweep(lambda x: x ** 2, np.arange(3.0), progress=False)
    assert plain.beyond_checked is None and plain.in_checked_range.tolist() == [True] * 3
    assert jj.SweepResult.load(plain.save(tmp_path / "plain")).beyond_checked is None


@pytest.mark.parametrize("preset", ["fast", "default"])
def test_beyond_checked_answers_as_a_concrete_jmse_call_warns(monkeypatch, preset):
    """``jj.beyond_checked``: for one design, True exactly where a concrete ``jmse`` call on
    it warns (the oracle, ``checked_range.eager_warns``), for each in-range design of
    ``_CHECKED_RANGE_DESIGNS`` at two noise levels and a Zernike design; for the batch, the
    same per design, False for the designs ``jmse`` refuses. The default has the balanced
    grid, so the cancelling design is inside its range (beyond 'fast''s)."""
    w020, w040, w131, field, u = (np.array(x) for x in zip(*_CHECKED_RANGE_DESIGNS,
                                                            strict=True))
    low = jj.WhiteNoise(float(SIGNAL(jnp.zeros(()), jnp.zeros(()))) / 1e7)
    for noise in (NOISE, low):
        batch = jj.beyond_checked(jj.Seidel(w020=w020, w040=w040, w131=w131), field, u,
                                  SIGNAL, noise, preset=preset)
        expected = []
        for i in range(len(_CHECKED_RANGE_DESIGNS)):
            design = jj.Seidel(w020=w020[i], w040=w040[i], w131=w131[i])
            if not (np.isfinite(w020[i]) and 0.0 <= field[i] <= 1.0):
                expected.append(False)
                with pytest.raises(ValueError, match="must be finite|field must be in"):
                    jj.beyond_checked(design, field[i], u[i], SIGNAL, noise, preset=preset)
                continue
            one = jj.beyond_checked(design, float(field[i]), float(u[i]), SIGNAL, noise,
                                    preset=preset)
            assert isinstance(one, bool)
            assert one == eager_warns(monkeypatch, design, field[i], u[i], SIGNAL, noise,
                                       preset=preset), (i, noise)
            expected.append(one)
        assert batch.tolist() == expected
        assert expected[:5] == ([False, True, True, preset == "fast", False] if noise is NOISE
                                else [True, True, True, True, False])
    zernike = jj.Zernike([60.0, 0.3], noll=(4, 7))
    assert jj.beyond_checked(zernike, 0.5, 0.2, SIGNAL, NOISE, preset=preset) == eager_warns(
        monkeypatch, zernike, 0.5, 0.2, SIGNAL, NOISE, preset=preset) is True


def test_beyond_checked_refuses_what_has_no_checked_range():
    design = jj.Seidel(w020=1.0)
    with pytest.raises(ValueError, match=r"grid options \(nodes\) have no checked range"):
        jj.beyond_checked(design, 0.5, 0.2, SIGNAL, NOISE, nodes=(8, 8))
    with pytest.raises(ValueError, match="preset must be one of"):
        jj.beyond_checked(design, 0.5, 0.2, SIGNAL, NOISE, preset="bogus")
    with pytest.raises(ValueError, match=r"u must be in \(0.0, 1.5\], got 0.0"):
        jj.beyond_checked(design, 0.5, 0.0, SIGNAL, NOISE)
    with pytest.raises(TypeError, match="beyond_checked needs concrete values"):
        jax.jit(lambda w: jj.beyond_checked(jj.Seidel(w020=w), 0.5, 0.2, SIGNAL, NOISE))(1.0)
