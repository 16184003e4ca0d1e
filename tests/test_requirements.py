"""The dependency floors: pyproject.toml and the import-time check state the same ones, and
the check names every dependency that is too old (jmse_jax/_requirements.py)."""

import importlib.metadata
import re
import tomllib
from pathlib import Path

import pytest

from jmse_jax import _requirements

ROOT = Path(__file__).resolve().parents[1]


def _pyproject_floors():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    floors = {}
    for requirement in project["dependencies"]:
        name, version = re.fullmatch(r"([A-Za-z0-9_.-]+)>=([0-9.]+)", requirement).groups()
        floors[name] = version
    return floors


def test_pyproject_and_the_import_check_state_the_same_floors():
    assert _pyproject_floors() == _requirements.MINIMUM_VERSIONS


def test_the_oldest_constraints_pin_the_floors():
    pins = {}
    for line in (ROOT / "constraints-oldest.txt").read_text().splitlines():
        if line and not line.startswith("#"):
            name, version = line.split("==")
            pins[name] = version
    def padded(version):
        release = _requirements.release(version)
        return release + (0,) * (3 - len(release))

    for name, floor in _requirements.MINIMUM_VERSIONS.items():
        assert padded(pins[name]) == padded(floor), name


@pytest.mark.parametrize(("version", "release"), [
    ("0.10.2", (0, 10, 2)), ("0.10.3.dev20261201", (0, 10, 3)), ("0.7.2rc1", (0, 7, 2)),
    ("2.0", (2, 0)), ("1.26.4", (1, 26, 4)), ("4.67.1", (4, 67, 1)), ("3.9.0.post1", (3, 9, 0)),
])
def test_release_reads_the_numeric_part(version, release):
    assert _requirements.release(version) == release


def test_the_installed_versions_pass():
    installed = {name: importlib.metadata.version(name) for name in _requirements.MINIMUM_VERSIONS}
    _requirements.check(installed)


def test_a_dependency_too_old_is_named_with_its_version_and_floor():
    with pytest.raises(ImportError, match=r"jax 0\.6\.2 \(needs >= 0\.7\.2\)"
                                          r".*optimistix 0\.0\.11 \(needs >= 0\.1\.0\)"
                                          r".*pip install --upgrade \"jax>=0\.7\.2\" "
                                          r"\"optimistix>=0\.1\.0\""):
        _requirements.check({"jax": "0.6.2", "optimistix": "0.0.11", "numpy": "2.0.0",
                             "equinox": None})
    # At the floor, above it, or not installed (a source tree): no error.
    _requirements.check({"jax": "0.7.2", "numpy": "2.0.0", "equinox": None,
                         "matplotlib": "3.10.1"})
