"""docs/api.md is the package's reference as it is now, every public name is documented, and
the names SPEC §4 promises keep their signatures."""

from __future__ import annotations

import inspect
import pathlib
import sys

import jmse_jax as jj
from jmse_jax import lens as jl

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent.parent / "docs"))
import make_api  # noqa: E402


def test_api_reference_is_current():
    # On failure: python docs/make_api.py, and read the diff.
    assert make_api.API.read_text() == make_api.render()


def test_every_public_name_is_documented():
    assert make_api.undocumented() == []


def test_the_reference_lists_every_public_name_once_per_module():
    text = make_api.API.read_text()
    for module_name in make_api.MODULES:
        section = text.split(f"## `{module_name}`\n", 1)[1].split("\n## `", 1)[0]
        for name, _ in make_api.public_names(module_name):
            headings = section.count(f"### `{name}`") + section.count(f"### `{name}(")
            assert headings == 1, (module_name, name)
    assert len(make_api.public_names("jmse_jax")) >= 60


def _parameters(function) -> list[tuple[str, object]]:
    return [(p.name, p.default) for p in inspect.signature(function).parameters.values()]


def test_spec_public_names_keep_their_signatures():
    empty = inspect.Parameter.empty
    coefficients = ["w020", "w040", "w131", "w222", "w220", "w311", "w111"]
    assert _parameters(jj.Seidel) == [(name, 0.0) for name in coefficients]
    assert _parameters(jj.wavefront)[:4] == [
        ("aberrations", empty), ("x", empty), ("y", empty), ("field", 0.0)]
    assert _parameters(jj.otf)[:5] == [
        ("aberrations", empty), ("nu_x", empty), ("nu_y", empty), ("field", 0.0),
        ("method", "overlap")]
    assert _parameters(jj.MarkovSignal) == [("variance", 1.0), ("correlation_length", 5.0)]
    assert [name for name, _ in _parameters(jj.PowerLawSignal)] == [
        "amplitude", "exponent", "knee"]
    assert [name for name, _ in _parameters(jj.WhiteNoise)] == ["variance"]
    merit = ["aberrations", "field", "u", "signal", "noise"]
    assert _parameters(jj.jmse)[:5] == [(name, empty) for name in merit]
    assert all(p.kind is p.KEYWORD_ONLY
               for p in list(inspect.signature(jj.jmse).parameters.values())[5:])
    assert _parameters(jj.baseline_jmse) == [(name, empty) for name in merit] + [("B", 64)]
    assert isinstance(jl.seidel_waves(jl.paper_singlet()), jj.Seidel)
