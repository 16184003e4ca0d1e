"""The package ships its type annotations (``py.typed``), and they are right: mypy (pinned in
the test extras) finds nothing wrong in the package, in the README's example or in the
notebooks' code, and does find a wrong argument type in a user's call."""

from __future__ import annotations

import json
import os
import pathlib
import subprocess
import sys
import tomllib

from test_readme import example_code

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _mypy(*paths) -> subprocess.CompletedProcess:
    # MYPYPATH: this source tree's jmse_jax, not an installed copy; no cache between runs.
    env = dict(os.environ, MYPYPATH=str(ROOT))
    return subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", os.devnull, *map(str, paths)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
    )


def _notebook_code(path: pathlib.Path) -> str:
    cells = json.loads(path.read_text())["cells"]
    code = "\n\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
    # IPython's magics and shell escapes are not Python.
    return "\n".join(line for line in code.splitlines()
                     if not line.lstrip().startswith(("%", "!")))


def test_the_package_marks_itself_typed_and_ships_the_marker():
    assert (ROOT / "jmse_jax" / "py.typed").is_file()
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "py.typed" in setuptools["package-data"]["jmse_jax"]


def test_mypy_passes_on_the_package_and_what_users_write_and_flags_a_wrong_call(tmp_path):
    notebooks = sorted((ROOT / "notebooks").glob("*.ipynb"))
    assert len(notebooks) >= 4
    files = [tmp_path / "readme_example.py"]
    files[0].write_text(example_code())
    for notebook in notebooks:
        files.append(tmp_path / f"notebook_{notebook.stem}.py")
        files[-1].write_text(_notebook_code(notebook))
    # The oracle that the annotations are read at all (one mypy run, ~10 s): preset is a str.
    wrong = tmp_path / "wrong.py"
    wrong.write_text(
        "import jmse_jax as jj\n"
        "ab = jj.Seidel(w020=1.0)\n"
        "jj.jmse(ab, 0.5, 0.3, jj.MarkovSignal(), jj.WhiteNoise(), preset=3)\n"
    )
    package = len(list((ROOT / "jmse_jax").rglob("*.py")))
    result = _mypy("jmse_jax", *files, wrong)
    errors = [line for line in result.stdout.splitlines() if ": error: " in line]
    assert len(errors) == 1, result.stdout + result.stderr
    assert errors[0].startswith(f"{wrong}:3: error: ")
    assert 'Argument "preset" to "jmse" has incompatible type "int"; expected "str"' in errors[0]
    assert f"Found 1 error in 1 file (checked {package + len(files) + 1} source files)" in (
        result.stdout), result.stdout
