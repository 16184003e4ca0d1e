"""The README's Example block runs as written and gives the documented Fig. 1 value; and the
library's numbers do not depend on the suite's unoptimised compilation (conftest)."""

from __future__ import annotations

import json
import os
import pathlib
import re
import subprocess
import sys

import jax
import numpy as np

import jmse_jax as jj

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


def _fig1_numbers():
    """The Fig. 1 point's value and gradient (``jmse``, the derivative taken outside
    ``jit``), its baseline at B = 64 and one OTF value. The coefficients are written out
    rather than taken from ``conftest.FIG1_COEFFICIENTS``: the witness's subprocess imports
    this module, and importing conftest would put it back at the suite's level 0."""
    ab = jj.Seidel(w020=-2.75, w040=1.5578, w131=-1.2602, w222=1.4089, w220=2.7198)
    design = (ab, 0.95, 0.2, jj.MarkovSignal(1.0, 5.0), jj.WhiteNoise(1e-3))
    value, grad = jax.value_and_grad(jj.jmse)(*design)
    h = complex(jj.otf(ab, 0.1, 0.05, 0.95))
    return dict(value=float(value), baseline=float(jj.baseline_jmse(*design, B=64)),
                grad=[float(g) for g in jax.tree_util.tree_leaves(grad)], h=[h.real, h.imag])


def test_optimised_code_users_get_gives_the_suite_numbers():
    """The suite compiles with LLVM's optimisations off (conftest). With XLA's default
    optimisation, as users run the library (a process without the flag), the value,
    gradient, baseline and OTF agree with the suite's to rounding: the flag changes how the
    arithmetic is scheduled, not what it computes. (Where the caller runs the suite at
    XLA's default level, conftest, the two processes compile alike.) The users' process has
    ``jmse``'s run-time checks on, as users get them (the suite has them off: conftest)."""
    flags = [f for f in os.environ.get("XLA_FLAGS", "").split()
             if not f.startswith("--xla_backend_optimization_level")]
    script = ("import json, jax\njax.config.update('jax_enable_x64', True)\n"
              "import test_readme\nprint(json.dumps(test_readme._fig1_numbers()))\n")
    # As users run it: their XLA level, and jmse's run-time checks on (off in the suite).
    env = dict(os.environ, XLA_FLAGS=" ".join(flags), JMSE_JAX_RUN_TIME_CHECKS="1",
               PYTHONPATH=os.pathsep.join([str(pathlib.Path(__file__).parent),
                                           os.environ.get("PYTHONPATH", "")]))
    out = subprocess.run([sys.executable, "-c", script], env=env, check=True,
                         capture_output=True, text=True, timeout=600).stdout
    users = json.loads(out.strip().splitlines()[-1])
    suite = _fig1_numbers()
    assert abs(users["value"] / 2.6539432e-3 - 1.0) < 1e-6
    assert abs(users["value"] / suite["value"] - 1.0) < 1e-12
    assert abs(users["baseline"] / suite["baseline"] - 1.0) < 1e-12
    grad = np.array(suite["grad"])
    assert np.max(np.abs(grad - users["grad"])) < 1e-11 * np.max(np.abs(grad))
    assert abs(complex(*users["h"]) - complex(*suite["h"])) < 1e-13
