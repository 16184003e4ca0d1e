"""The README's Example block runs as written and gives the documented Fig. 1 value."""

from __future__ import annotations

import pathlib
import re

README = pathlib.Path(__file__).resolve().parent.parent / "README.md"


def example_code() -> str:
    text = README.read_text()
    section = text.split("\n## Example", 1)[1].split("\n## ", 1)[0]
    blocks = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert blocks, "no python block under '## Example' in README.md"
    return blocks[0]


def test_readme_example_runs_and_matches_fig1_value():
    code = example_code()
    assert len(code.strip().splitlines()) <= 15
    namespace: dict = {}
    exec(compile(code, str(README), "exec"), namespace)
    assert abs(float(namespace["value"]) / 2.6539432e-3 - 1.0) < 1e-6
    assert abs(float(namespace["baseline"]) / float(namespace["value"]) - 1.0 + 0.08) < 0.01
    assert abs(complex(namespace["h"])) <= 1.0
