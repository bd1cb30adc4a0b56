"""symoro_gen.runtime: generated packages compile nothing at import; C is built by `symoro-gen build`
or on first use, and every failure (no compiler, compile error, timeout) falls back to NumPy with one
warning, kills the compiler and leaves no partial library."""
import json
import os
import shutil
import stat
import warnings
from pathlib import Path

import numpy as np
import pytest

from symoro_gen.cli import main
from symoro_gen.description import load_robot
from symoro_gen.dynamics.numeric import numeric_regressor
from symoro_gen.emit.package import build_in_memory
from symoro_gen.loader import import_package
from symoro_gen.model import IdentificationModel
from symoro_gen.runtime import ccompile
from symoro_gen.runtime.model import CBackendWarning
from symoro_gen.simulate import NumericModel

ROOT = Path(__file__).resolve().parents[2]
HAVE_CC = ccompile.compiler() is not None


@pytest.fixture
def pkg(tmp_path, monkeypatch):
    """A private copy of generated/scara (no build products) and a private user cache."""
    dst = tmp_path / "pkgs" / "scara"
    shutil.copytree(ROOT / "generated" / "scara", dst, ignore=shutil.ignore_patterns("_build", "__pycache__"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("SYMORO_BACKEND", raising=False)
    return dst


def _fake_cc(tmp_path: Path, body: str) -> str:
    cc = tmp_path / "fakecc"
    cc.write_text("#!/bin/sh\n" + body + "\n")
    cc.chmod(cc.stat().st_mode | stat.S_IEXEC)
    return str(cc)


def _states(n, N=9, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-3, 3, (N, n)), rng.normal(size=(N, n)), rng.normal(size=(N, n))


def _products(pkg: Path, tmp_path: Path) -> list:
    """Every file the runtime may have left: in _build/ and in the user cache."""
    out = []
    for d in (pkg / "_build", tmp_path / "cache"):
        if d.exists():
            out += sorted(str(p.relative_to(d)) for p in d.rglob("*"))
    return out


def _reference(m, q, dq, ddq):
    Ws, _ = numeric_regressor(load_robot("scara"), q, dq, ddq)
    return Ws


def test_import_compiles_nothing(pkg, tmp_path, monkeypatch):
    calls = tmp_path / "calls"
    monkeypatch.setenv("CC", _fake_cc(tmp_path, f'echo "$@" >> {calls}; exit 1'))
    m = import_package(pkg)
    assert not calls.exists() and _products(pkg, tmp_path) == []
    assert m.BACKEND == "c"  # before the first call: what the first call will try (a compiler is there)
    assert not calls.exists(), "reading BACKEND compiles nothing either"


@pytest.mark.skipif(not HAVE_CC, reason="no C compiler on this machine")
def test_first_call_compiles_into_build_folder_then_reuses(pkg, tmp_path):
    m = import_package(pkg)
    q, dq, ddq = _states(m.N_JOINTS)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no fallback warning
        Ws = m.standard_regressor(q, dq, ddq)
    assert m.BACKEND == "c"
    libs = list((pkg / "_build").glob("*.so"))
    assert len(libs) == 1 and libs[0].stat().st_size > 0
    assert [p.name for p in (pkg / "_build").iterdir()] == [libs[0].name], "no temporary folder left"
    assert np.max(np.abs(Ws - _reference(m, q, dq, ddq))) <= 1e-9 * max(1, np.abs(Ws).max())
    res = ccompile.build_library(pkg / "regressor_scara.c")
    assert res.path == libs[0] and not res.compiled


@pytest.mark.parametrize("case", ["compile error", "no compiler", "timeout"])
def test_failure_falls_back_to_numpy_with_one_warning(pkg, tmp_path, monkeypatch, case):
    pidfile = tmp_path / "pid"
    if case == "compile error":
        monkeypatch.setenv("CC", _fake_cc(tmp_path, 'echo "x.c:1: error: something is wrong" >&2; : > "$7"; exit 1'))
        why = "the C compiler failed"
    elif case == "no compiler":
        empty = tmp_path / "empty"
        empty.mkdir()
        monkeypatch.setenv("PATH", str(empty))
        monkeypatch.delenv("CC", raising=False)
        why = "no C compiler found"
    else:
        monkeypatch.setenv("CC", _fake_cc(tmp_path, f'echo $$ > {pidfile}; : > "$7"; exec sleep 60'))
        monkeypatch.setenv("SYMORO_CC_TIMEOUT", "1")
        why = "did not finish within 1 s"
    m = import_package(pkg)
    q, dq, ddq = _states(m.N_JOINTS)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        Ws = [m.standard_regressor(q, dq, ddq) for _ in range(3)]
        m.regressor(q, dq, ddq)
    msgs = [str(x.message) for x in w if issubclass(x.category, CBackendWarning)]
    assert len(msgs) == 1, msgs
    assert why in msgs[0] and "symoro-gen build" in msgs[0] and "SYMORO_BACKEND=numpy" in msgs[0]
    assert m.BACKEND == "numpy"
    assert np.max(np.abs(Ws[0] - _reference(m, q, dq, ddq))) <= 1e-9 * max(1, np.abs(Ws[0]).max())
    assert "using the NumPy kernels (same results, slower)" in msgs[0]
    assert _products(pkg, tmp_path) == [] and not (pkg / "_build").exists() and not (tmp_path / "cache").exists(), \
        "no partial or 0-byte library, no temporary folder, not even an empty _build/ or cache folder"
    if case != "no compiler":
        assert f"{pkg.resolve() / 'regressor_scara.c'}: " in msgs[0] and "nothing was left behind" in msgs[0]
    if case == "compile error":
        assert f"To fix: `symoro-gen build {pkg.resolve()}` retries and shows the compiler's error" in msgs[0]
    if case == "timeout":
        assert f"To fix: retry with more time: `symoro-gen build {pkg.resolve()} --timeout 2`" in msgs[0]
        pid = int(pidfile.read_text())
        assert not Path(f"/proc/{pid}").exists() or "Z" in Path(f"/proc/{pid}/stat").read_text().split()[2], \
            "the compiler was killed"


def test_symoro_backend_numpy_is_silent(pkg, monkeypatch):
    monkeypatch.setenv("SYMORO_BACKEND", "numpy")
    m = import_package(pkg)
    assert m.BACKEND == "numpy"
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m.regressor(*_states(m.N_JOINTS))
    assert m.BACKEND == "numpy" and not (pkg / "_build").exists()


def test_large_sources_compile_at_O1(pkg, tmp_path, monkeypatch):
    calls = tmp_path / "calls"
    monkeypatch.setenv("CC", _fake_cc(tmp_path, f'echo "$@" >> {calls}; exit 1'))
    monkeypatch.setattr(ccompile, "LARGE_SOURCE", 10)
    with pytest.raises(ccompile.CBuildError, match="compiler failed"):
        ccompile.build_library(pkg / "regressor_scara.c")
    args = calls.read_text().split()
    assert "-O1" in args and "-O3" not in args
    monkeypatch.setattr(ccompile, "LARGE_SOURCE", 10**9)
    with pytest.raises(ccompile.CBuildError):
        ccompile.build_library(pkg / "regressor_scara.c")
    assert "-O3" in calls.read_text().splitlines()[-1].split()


@pytest.mark.skipif(os.name != "posix" or os.geteuid() == 0, reason="root writes into read-only folders")
@pytest.mark.skipif(not HAVE_CC, reason="no C compiler on this machine")
def test_read_only_package_builds_into_user_cache(pkg, tmp_path):
    pkg.chmod(0o555)
    try:
        m = import_package(pkg)
        m.regressor(*_states(m.N_JOINTS))
        assert m.BACKEND == "c" and not (pkg / "_build").exists()
        assert len(list((tmp_path / "cache" / "symoro_gen" / "build").glob("*.so"))) == 1
    finally:
        pkg.chmod(0o755)


@pytest.mark.skipif(not HAVE_CC, reason="no C compiler on this machine")
def test_build_command(pkg, capsys):
    assert main(["build", str(pkg)]) == 0
    assert "compiled" in capsys.readouterr().out and len(list((pkg / "_build").glob("*.so"))) == 1
    assert main(["build", str(pkg)]) == 0
    assert "already built" in capsys.readouterr().out


@pytest.mark.skipif(not HAVE_CC, reason="no C compiler on this machine")
def test_build_command_on_a_closed_loop_robot_builds_its_tree_package(capsys):
    """``make robot ROBOT=palletizer`` ends with ``symoro-gen build palletizer``: load_model returns the
    closed-loop model, whose tree package carries the kernels (it used to say "not a generated package")."""
    assert main(["build", "palletizer"]) == 0
    assert "palletizer: C kernels" in capsys.readouterr().out


def test_build_command_reports_a_compile_error(pkg, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("CC", _fake_cc(tmp_path, 'echo "x.c:3: error: boom" >&2; exit 1'))
    assert main(["build", str(pkg)]) == 2
    err = capsys.readouterr().err
    assert "error: boom" in err and len(err.strip().splitlines()) == 2  # message + hint
    assert err.splitlines()[1] == f"hint: `symoro-gen build {pkg.resolve()}` retries and shows the compiler's error"
    assert not (pkg / "_build").exists()


def test_every_model_satisfies_the_contract():
    """Generated package, InMemoryModel and NumericModel: one IdentificationModel contract."""
    robot = load_robot("scara")
    gen = import_package(ROOT / "generated" / "scara")
    mem = build_in_memory(robot)
    num = NumericModel(robot)
    q, dq, ddq = _states(robot.n_joints)
    chi = np.random.default_rng(1).normal(size=len(robot.standard_names))
    for m in (gen, mem, num):
        assert isinstance(m, IdentificationModel), type(m)
    ref = num.torque(q, dq, ddq, chi)
    for m in (gen, mem):
        assert np.max(np.abs(m.torque(q, dq, ddq, chi) - ref)) <= 1e-9 * np.abs(ref).max()
    assert not isinstance(object(), IdentificationModel)


def test_casadi_built_from_graph_equals_generated_package():
    """InMemoryModel's CasADi function walks the sympy graph; the package's comes from its printed _casadi.py."""
    mem = build_in_memory(load_robot("rx90"))
    gen = import_package(ROOT / "generated" / "rx90")
    f, g = mem.casadi_regressor(), gen.casadi_regressor()
    q, dq, ddq = _states(gen.N_JOINTS, N=3)
    for k in range(3):
        a, b = np.array(f(q[k], dq[k], ddq[k])), np.array(g(q[k], dq[k], ddq[k]))
        assert a.shape == b.shape == (6, len(gen.BASE_NAMES))
        assert np.max(np.abs(a - b)) <= 1e-12 * max(1, np.abs(b).max())
        assert np.max(np.abs(b - gen.regressor(q[k], dq[k], ddq[k]))) <= 1e-12 * max(1, np.abs(b).max())


def test_generated_package_source_has_no_runtime_copies():
    """The runtime lives in symoro_gen.runtime only: packages hold data, kernels and a thin __init__."""
    for pkg in (ROOT / "generated").iterdir():
        if not (pkg / "__init__.py").exists():
            continue
        names = sorted(p.name for p in pkg.iterdir() if p.name not in ("_build", "__pycache__"))
        loops = (["closed_loop_base_parameters.md", "_closed_loop.py"]  # a closed-loop robot with a linear closure
                 if "closed_loops" in json.loads((pkg / "manifest.json").read_text()) else [])
        geo = ([] if "omitted" in json.loads((pkg / "manifest.json").read_text())["geometry_derivative"]
               else ["_geometry.py", f"geometry_{pkg.name}.c"])  # the geometry derivative
        assert names == sorted(["__init__.py", "_casadi.py", "_kernels.py", "base_parameters.md", "manifest.json",
                                f"regressor_{pkg.name}.c", *loops, *geo])
        init = (pkg / "__init__.py").read_text()
        assert "from symoro_gen.runtime import GeneratedModel" in init
        assert "def _evaluate" not in init and "ctypes" not in init and "subprocess" not in init


@pytest.mark.skipif(not HAVE_CC, reason="no C compiler on this machine")
def test_a_length_with_a_number_added_compiles_and_matches_the_numeric_model(tmp_path, monkeypatch):
    """``d = "D2 + 0.005"`` (what ``identify -o`` writes for a fitted link-length error) makes a definition of the
    generated code a pure number: the SIMD kernel must broadcast it to every lane (a plain ``double`` does not
    initialise a vector) and the compiled regressor equals the numeric Newton-Euler regressor."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("SYMORO_BACKEND", raising=False)
    text = (ROOT / "robots" / "scara.toml").read_text()
    text = text.replace('name = "scara"', 'name = "scara_len"').replace('d = "D2"', 'd = "D2 + 0.005"')
    robot_file = tmp_path / "scara_len.toml"
    robot_file.write_text(text)
    assert main(["generate", str(robot_file), "--out", str(tmp_path / "pkgs")]) == 0
    assert main(["build", str(tmp_path / "pkgs" / "scara_len")]) == 0
    m = import_package(tmp_path / "pkgs" / "scara_len")
    robot = load_robot(str(robot_file))
    q, dq, ddq = _states(robot.n_joints)
    with warnings.catch_warnings():
        warnings.simplefilter("error", CBackendWarning)
        W = np.asarray(m.standard_regressor(q, dq, ddq))
    assert m.BACKEND == "c"
    W_num, _ = numeric_regressor(robot, q, dq, ddq)
    assert np.allclose(W.reshape(W_num.shape), W_num, atol=1e-10)
