"""The kernel and model tests hold for any valid robot a user adds to ``robots/``.

README "Adding a robot" says: write ``robots/<name>.toml``, run ``symoro-gen generate <name>``. In a
copy of the checkout, this test does exactly that with a robot unlike the shipped ones (an R-P-R arm
with a twisted prismatic joint, no drive terms but viscous friction, a payload frame), then runs the
test modules that loop over ``robots/*.toml`` (generated model against numeric Newton-Euler and
Pinocchio, C against NumPy backends, the SIMD kernel at every alignment and sample count, the
committed package against a fresh generation, base-parameter evaluation) on it. The documentation
side is ``tests/docs/test_added_robots.py``.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

MYARM = '''# A user's arm: R-P-R with a twisted prismatic joint and a payload frame.
name = "myarm"
source = "test robot of tests/emit/test_added_robot.py"
gravity = [0, 0, -9.81]
payload = 4
drive = ["FV", "OFF"]

[values]
L1 = 0.4
L3 = 0.25

[[frames]]
j = 1
ant = 0
sigma = 0
alpha = 0
d = 0
theta = "q"
r = "L1"

[[frames]]
j = 2
ant = 1
sigma = 1
alpha = "-pi/2"
d = 0.1
theta = "pi/2"
r = "q"

[[frames]]
j = 3
ant = 2
sigma = 0
alpha = "pi/2"
d = "L3"
theta = "q"
r = 0

[[frames]]
j = 4
ant = 3
sigma = 2
alpha = 0
d = 0.05
theta = 0
r = 0.02
'''

#: the modules that take their robots from robots/*.toml (selected with -k myarm), and the
#: module-level checks over that list
MODULES = ["tests/emit/test_generated_models.py", "tests/emit/test_emission.py", "tests/baseparams/test_evaluate.py",
           "tests/baseparams/test_exact_relations.py"]


def _run(args, cwd, timeout):
    env = {k: v for k, v in os.environ.items() if not k.startswith(("PYTEST_", "SYMORO_"))}
    env["PYTHONPATH"] = str(cwd)
    if (ROOT.parent / "shared").is_dir():  # keep the real-data location of the checkout (unused here)
        env["SYMORO_SHARED_DATA"] = str(ROOT.parent / "shared" / "data")
    return subprocess.run([sys.executable, *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.slow
def test_kernel_and_model_tests_pass_for_an_added_robot(tmp_path):
    pytest.importorskip("pinocchio")
    copy = tmp_path / "checkout"
    copy.mkdir()
    ignore = shutil.ignore_patterns("__pycache__", "_build", ".*")
    for name in ("symoro_gen", "tests", "robots", "generated"):
        shutil.copytree(ROOT / name, copy / name, ignore=ignore)
    for name in ("conftest.py", "pyproject.toml"):
        shutil.copy(ROOT / name, copy / name)
    (copy / "robots" / "myarm.toml").write_text(MYARM)
    gen = _run(["-m", "symoro_gen", "-q", "generate", "myarm"], copy, 300)
    assert gen.returncode == 0, gen.stderr
    assert (copy / "generated" / "myarm" / "manifest.json").is_file()
    res = _run(["-m", "pytest", "-q", "-p", "no:cacheprovider", "-x", "-k", "myarm or every_robot", *MODULES],
               copy, 600)
    tail = "\n".join((res.stdout + res.stderr).splitlines()[-30:])
    assert res.returncode == 0, tail
    assert " passed" in res.stdout and "failed" not in res.stdout, tail
    # the robot was really exercised: the model tests of each module ran on it (12 + the exact relations)
    assert int(res.stdout.split(" passed")[0].split()[-1]) >= 13, tail
