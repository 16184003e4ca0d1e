"""The ``jmse-jax`` subcommands, run in-process through ``jmse_jax.cli.main``."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from conftest import FIG1_COEFFICIENTS

import jmse_jax as jj
from jmse_jax import cli

FIG1_FLAGS = [f"--{k}={v}" for k, v in FIG1_COEFFICIENTS.items()]


def run_cli(capsys, *argv):
    """(exit status, stdout, stderr) of ``jmse-jax argv``."""
    try:
        status = cli.main(list(argv))
    except SystemExit as e:
        status = e.code
    out, err = capsys.readouterr()
    return status, out, err


# --------------------------------------------------------------------------------------
# help and bad arguments
# --------------------------------------------------------------------------------------


@pytest.mark.parametrize("command, words", [
    ((), ("waves", "1/(lambda N)", "Nyquist")),
    (("eval",), ("waves", "1/(lambda N)", "Nyquist / optical cutoff")),
    (("optimise",), ("mm", "1/mm", "waves")),
    (("sweep",), ("waves", "Nyquist")),
    (("bench",), ("--builtin", "B = 64")),
    (("reproduce",), ("waves", "1/(lambda N)", "--out")),
])
def test_help_mentions_units(capsys, command, words):
    status, out, _ = run_cli(capsys, *command, "--help")
    assert status == 0
    text = " ".join(out.split())
    for word in words:
        assert word in text, (command, word)


@pytest.mark.parametrize("argv", [
    (),
    ("frobnicate",),
    ("eval", "--field", "abc"),
    ("eval", "--preset", "ultra"),
    ("eval", "--field", "1.5"),
    ("eval", "--u", "2"),
    ("eval", "--noise", "-1"),
    ("eval", "--signal", "gauss:1"),
    ("eval", "--signal", "markov:1"),
    ("eval", "--nu", "0.1,x"),
    ("eval", "--json", "/nonexistent/inputs.json"),
    ("optimise", "--front-curvature", "0.5"),
    ("optimise", "--stop-distance", "-1"),
    ("sweep", "--axis", "w999=0,1,3"),
    ("sweep", "--axis", "w020=0,1"),
    ("sweep", "--axis", "w020=0,1,2.5"),
    ("sweep", "--axis", "w020=-1,1,200", "--axis", "w222=-1,1,200"),
    ("sweep", "--workers", "0"),
    ("sweep", "--batch-size", "0"),
    ("bench", "--builtin", "--repeats", "0"),
    ("eval", "--out-json", "/proc/no/such/folder/x.json"),
])
def test_bad_arguments_exit_2_with_one_line(capsys, argv):
    status, out, err = run_cli(capsys, *argv)
    assert status == 2
    assert len(err.strip().splitlines()) == 1, err
    assert err.startswith("jmse-jax: error: ")


@pytest.mark.parametrize("nu", [[0.1, None], {"a": 1}, [0.1, "a"]])
def test_eval_json_with_bad_nu_exits_2_naming_nu(capsys, tmp_path, nu):
    path = tmp_path / "in.json"
    path.write_text(json.dumps({"w020": 1.0, "nu": nu}))
    status, _, err = run_cli(capsys, "eval", "--json", str(path))
    assert status == 2 and len(err.strip().splitlines()) == 1
    assert err.startswith("jmse-jax: error: nu must be a number or a list of numbers")


def test_eval_json_with_unknown_key_exits_2(capsys, tmp_path):
    path = tmp_path / "in.json"
    path.write_text(json.dumps({"w020": 1.0, "focus": 2.0}))
    status, _, err = run_cli(capsys, "eval", "--json", str(path))
    assert status == 2 and "focus" in err and len(err.strip().splitlines()) == 1


def test_bench_without_benchmarks_folder_is_a_clear_error(capsys, monkeypatch, tmp_path):
    monkeypatch.setattr(cli, "benchmarks_folder", lambda: tmp_path / "benchmarks")
    status, _, err = run_cli(capsys, "bench")
    assert status == 2 and "--builtin" in err


# --------------------------------------------------------------------------------------
# eval
# --------------------------------------------------------------------------------------


def test_eval_matches_library(capsys, tmp_path):
    out_json = tmp_path / "eval.json"
    status, out, _ = run_cli(capsys, "eval", *FIG1_FLAGS, "--field", "0.95", "--u", "0.2",
                             "--preset", "fast", "--nu", "0.1,0.2",
                             "--out-json", str(out_json))
    assert status == 0
    result = json.loads(out_json.read_text())
    ab = jj.Seidel(**FIG1_COEFFICIENTS)
    signal, noise = jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3)
    expected = float(jj.jmse(ab, 0.95, 0.2, signal, noise, preset="fast"))
    assert result["jmse"] == pytest.approx(expected, rel=1e-12)
    assert f"{expected:.10e}" in out
    assert set(result["gradient"]) == set(cli.COEFFICIENTS)
    assert result["gradient"]["w020"] != 0.0
    h = complex(jj.otf(ab, 0.1, 0.0, 0.95))
    assert result["otf"][0]["nu"] == 0.1
    assert result["otf"][0]["nu_x"]["re"] == pytest.approx(h.real, abs=1e-12)
    assert result["otf"][0]["nu_x"]["im"] == pytest.approx(h.imag, abs=1e-12)


def test_eval_json_input_and_flag_override(capsys, tmp_path):
    inputs = tmp_path / "in.json"
    inputs.write_text(json.dumps({**FIG1_COEFFICIENTS, "field": 0.5, "u": 0.3,
                                  "noise": 1e-2, "signal": "powerlaw:1,2,0.05",
                                  "preset": "fast"}))
    out_json = tmp_path / "eval.json"
    status, _, _ = run_cli(capsys, "eval", "--json", str(inputs), "--w020", "-1",
                           "--out-json", str(out_json))
    assert status == 0
    result = json.loads(out_json.read_text())
    assert result["inputs"]["w020"] == -1.0 and result["inputs"]["w222"] == 1.4089
    ab = jj.Seidel(**{**FIG1_COEFFICIENTS, "w020": -1.0})
    expected = float(jj.jmse(ab, 0.5, 0.3, jj.PowerLawSignal(1.0, 2.0, 0.05),
                             jj.WhiteNoise(1e-2), preset="fast"))
    assert result["jmse"] == pytest.approx(expected, rel=1e-12)


# --------------------------------------------------------------------------------------
# optimise, sweep, bench, reproduce
# --------------------------------------------------------------------------------------


def test_optimise_reduces_the_merit(capsys, tmp_path):
    out_json = tmp_path / "opt.json"
    status, out, _ = run_cli(capsys, "optimise", "--variables", "image_shift",
                             "--max-steps", "30", "--out-json", str(out_json))
    assert status == 0
    assert "JMSE (mean)" in out
    result = json.loads(out_json.read_text())
    assert result["jmse"] < result["start_jmse"]
    assert set(result["parameters"]) == {"image_shift"}


def test_sweep_writes_npz_and_json(capsys, tmp_path):
    status, out, _ = run_cli(capsys, "sweep", "--axis", "w020=-1,1,3", "--axis",
                             "field=0,1,2", "--w222", "0.5", "--quiet", "--workers", "2",
                             "--out", str(tmp_path))
    assert status == 0
    result = jj.SweepResult.load(tmp_path / "sweep.npz")
    assert result.n_designs == 6 and result.ok.all()
    assert result.metadata["workers"] == 2
    assert (tmp_path / "sweep.json").is_file()
    summary = json.loads((tmp_path / "sweep_summary.json").read_text())
    assert summary["n_designs"] == 6
    # Second design: w020 = -1, field = 1 (last axis fastest).
    expected = float(jj.jmse(jj.Seidel(w020=-1.0, w222=0.5), 1.0, 0.2,
                             jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3), preset="fast"))
    assert np.asarray(result.value)[1] == pytest.approx(expected, rel=1e-10)


# Slow: the float32 twin of test_sweep_writes_npz_and_json (about 50 s of compilation).
@pytest.mark.slow
def test_sweep_in_float32(capsys, tmp_path):
    """``--dtype float32`` runs the whole sweep in float32: values (and the stored inputs)
    are float32 and within 2e-6 of the float64 ones (the oracle: ``jmse`` in float64)."""
    status, out, _ = run_cli(capsys, "sweep", "--axis", "w020=-1,1,3", "--w222", "0.5",
                             "--field", "0.7", "--dtype", "float32", "--grad", "--quiet",
                             "--out", str(tmp_path))
    assert status == 0 and "float32" in out
    result = jj.SweepResult.load(tmp_path / "sweep.npz")
    assert result.ok.all() and np.asarray(result.value).dtype == np.float32
    assert np.asarray(result.grad["aberrations"].w020).dtype == np.float32
    assert result.metadata["user"]["dtype"] == "float32"
    assert result.metadata["dtypes"] == ["float32"]
    for i, w020 in enumerate((-1.0, 0.0, 1.0)):
        expected = float(jj.jmse(jj.Seidel(w020=w020, w222=0.5), 0.7, 0.2,
                                 jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3),
                                 preset="fast"))
        assert float(np.asarray(result.value)[i]) == pytest.approx(expected, rel=2e-6)


def test_bench_builtin(capsys, tmp_path):
    out_json = tmp_path / "bench.json"
    status, out, _ = run_cli(capsys, "bench", "--builtin", "--repeats", "1",
                             "--out-json", str(out_json))
    assert status == 0
    methods = json.loads(out_json.read_text())["methods"]
    assert set(methods) == {"baseline B=64", "jmse fast"}
    assert methods["jmse fast"]["jmse"] == pytest.approx(2.6539432e-3, rel=1e-5)


def test_reproduce_quick_writes_figures_and_report(capsys, tmp_path):
    status, out, _ = run_cli(capsys, "reproduce", "--quick", "--out", str(tmp_path))
    assert status == 0
    for name in ("fig1_comparison.json", "fig1.png", "fig4_right.png", "fig4_left.png",
                 "reproduce.json", "reproduce.md"):
        assert (tmp_path / name).stat().st_size > 0, name
    assert "[5/5]" in out
    report = json.loads((tmp_path / "reproduce.json").read_text())
    ours = report["fig1_comparison"]["methods"]["jmse default"]["jmse"]
    assert ours == pytest.approx(2.6539432e-3, rel=1e-6)
    rules = report["fig4_right"]["defocus"]["-2.75"]["rules"]
    assert rules["gauss"]["relative_error"]["16"] < rules["rectangle"]["relative_error"]["16"]
    assert "Fig. 4 right" in (tmp_path / "reproduce.md").read_text()
    # Even the quick run's times are the fastest of several warm calls, and say so.
    assert report["fig1_comparison"]["repeats"] == 5
    assert "fastest of 5 warm calls" in (tmp_path / "reproduce.md").read_text()
    # Fig. 4 left: Seidel terms are Zernike polynomials of order <= 4, so the projection from
    # the paper's 6 rings x 40 arms is exact to rounding; the paper's cubic interpolation
    # misses lambda/10 on the 2-ring grids and at the paper's grid is still ~0.05 waves.
    left = report["fig4_left"]
    assert left["zernike"]["d_at_paper_choice_L6_K40"] < 1e-12
    assert 0.01 < left["cubic"]["d_at_paper_choice_L6_K40"] < 0.1
    assert left["zernike"]["fewest_samples"]["samples"] < left["cubic"]["fewest_samples"][
        "samples"]
    assert min(left["d_cubic"][0]) > 0.1  # L = 2 rings
    assert "Fig. 4 left" in (tmp_path / "reproduce.md").read_text()


# --------------------------------------------------------------------------------------
# the console script's compilation cache
# --------------------------------------------------------------------------------------


def _eval_in_subprocess(tmp_path, *extra):
    """``jmse-jax eval`` (fast preset, Fig. 1 point) in a fresh process with its own
    ``XDG_CACHE_HOME`` and no ``JAX_COMPILATION_CACHE_DIR``; returns its JSON output."""
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    env["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    out_json = tmp_path / "eval.json"
    subprocess.run([sys.executable, "-m", "jmse_jax.cli", *extra, "eval", "--point", "fig1",
                    "--preset", "fast", "--nu", "0.1", "--out-json", str(out_json)],
                   env=env, check=True, capture_output=True, timeout=600)
    return json.loads(out_json.read_text())


@pytest.mark.slow
def test_compile_cache_is_kept_between_runs_and_can_be_turned_off(tmp_path):
    off = _eval_in_subprocess(tmp_path, "--no-compile-cache")
    assert not (tmp_path / "cache").exists()
    first = _eval_in_subprocess(tmp_path)
    folder = tmp_path / "cache" / "jmse_jax" / "xla"
    entries = sorted(p.name for p in folder.iterdir())
    assert entries, "the first run wrote no compiled program"
    second = _eval_in_subprocess(tmp_path)
    # The second run reads the programs back (writes nothing new) and gives the same numbers.
    assert sorted(p.name for p in folder.iterdir()) == entries
    assert first == second == off


def test_compile_cache_location_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cli.compile_cache_dir() == tmp_path / "jmse_jax" / "xla"
    monkeypatch.delenv("XDG_CACHE_HOME")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert cli.compile_cache_dir() == tmp_path / "home" / ".cache" / "jmse_jax" / "xla"
