"""Emission properties: deterministic, atomic, faithful to the committed generated/ folder."""
import json
from pathlib import Path

import numpy as np
import pytest

from symoro_gen import load_model
from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.emit import package
from symoro_gen.emit.check import compare_packages
from symoro_gen.emit.package import emit_robot

ROOT = Path(__file__).resolve().parents[2]


def _same_tree(a: Path, b: Path) -> list:
    names = sorted(p.name for p in a.iterdir() if p.name not in ("__pycache__", "_build"))
    assert names == sorted(p.name for p in b.iterdir() if p.name not in ("__pycache__", "_build"))
    return [n for n in names if (a / n).read_bytes() != (b / n).read_bytes()]


def test_regeneration_is_byte_identical(tmp_path):
    robot = load_robot("scara")
    emit_robot(robot, tmp_path / "a")
    emit_robot(robot, tmp_path / "b")
    assert _same_tree(tmp_path / "a" / "scara", tmp_path / "b" / "scara") == []


@pytest.mark.parametrize("name", sorted(p.stem for p in (ROOT / "robots").glob("*.toml")))
def test_committed_generated_matches_generator(tmp_path, name):
    """Runs on any tool versions: everything but manifest.json's tool_versions is compared (make check-generated)."""
    emit_robot(load_robot(name), tmp_path, source_base=ROOT)  # the robot file's path as recorded from generated/
    assert compare_packages(ROOT / "generated" / name, tmp_path / name) == [], "run `make robots` and commit generated/"


def test_compare_packages_ignores_only_tool_versions(tmp_path):
    emit_robot(load_robot("scara"), tmp_path / "a")
    emit_robot(load_robot("scara"), tmp_path / "b")
    a, b = tmp_path / "a" / "scara", tmp_path / "b" / "scara"
    man = json.loads((b / "manifest.json").read_text())
    man["tool_versions"] = {"sympy": "0.0", "numpy": "0.0"}
    (b / "manifest.json").write_text(json.dumps(man))
    assert compare_packages(a, b) == []
    man["counts"]["base"] += 1
    (b / "manifest.json").write_text(json.dumps(man))
    assert compare_packages(a, b) == ["manifest.json"]
    (b / "_kernels.py").write_text((b / "_kernels.py").read_text() + "\n")
    (b / "extra.txt").write_text("x")
    diffs = compare_packages(a, b)
    assert "_kernels.py" in diffs and any(d.startswith("extra.txt") for d in diffs)


def test_generated_files_carry_no_tool_version_and_no_numpy_repr(tmp_path):
    """The files depend on the robot file and the generator only (determinism)."""
    import numpy
    import sympy

    emit_robot(load_robot("lwr4"), tmp_path)
    for p in (tmp_path / "lwr4").iterdir():
        if p.name == "manifest.json":
            continue
        text = p.read_text()
        assert "np.float64(" not in text, p.name
        assert f"sympy {sympy.__version__}" not in text and f"numpy {numpy.__version__}" not in text, p.name


def test_failed_emission_leaves_previous_package_intact(tmp_path, monkeypatch):
    robot = load_robot("scara")
    emit_robot(robot, tmp_path)
    before = {p.name: p.read_bytes() for p in (tmp_path / "scara").iterdir()}

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(package, "relations_markdown", boom)
    with pytest.raises(RuntimeError):
        emit_robot(robot, tmp_path)
    after = {p.name: p.read_bytes() for p in (tmp_path / "scara").iterdir() if p.name not in ("__pycache__", "_build")}
    assert after == before
    assert [p.name for p in tmp_path.iterdir()] == ["scara"], "no temporary folder left behind"


@pytest.mark.slow   # over 5 s on this machine (CI runs the slow tests after `make test`)
def test_symbolic_geometry_is_substituted_in_code_but_kept_in_relations(tmp_path):
    text = (ROOT / "robots" / "rx90.toml").read_text().replace("D3 = 0.45", "D3 = 0.5")
    robot = parse_robot_text(text, file="rx90_variant.toml")
    emit_robot(robot, tmp_path)
    md = (tmp_path / "rx90" / "base_parameters.md").read_text()
    assert "D3" in md and "RL4" in md  # symbolic in relations
    m = load_model(tmp_path / "rx90")
    assert m.GEOMETRY["D3"] == 0.5
    from symoro_gen.dynamics.numeric import inverse_dynamics

    rng = np.random.default_rng(0)
    q, dq, ddq = rng.normal(size=(3, 10, 6))
    chi = rng.normal(size=len(m.STANDARD_NAMES))
    assert np.allclose(m.torque(q, dq, ddq, chi), inverse_dynamics(robot, q, dq, ddq, chi), atol=1e-10)


def test_written_files_have_ordinary_permissions(tmp_path):
    """Atomic writes go through mkstemp/mkdtemp (private); outputs must still be ordinary files."""
    import os

    from symoro_gen.atomic import write_text_atomic

    old = os.umask(0o022)
    try:
        emit_robot(load_robot("scara"), tmp_path)
        write_text_atomic(tmp_path / "x.json", "{}\n")
    finally:
        os.umask(old)
    assert (tmp_path / "scara").stat().st_mode & 0o777 == 0o755
    assert (tmp_path / "scara" / "__init__.py").stat().st_mode & 0o777 == 0o644
    assert (tmp_path / "x.json").stat().st_mode & 0o777 == 0o644


@pytest.mark.slow   # over 5 s on this machine (CI runs the slow tests after `make test`)
@pytest.mark.parametrize("alpha", ["pi/3", "pi/4", "-pi/6"])
def test_irrational_constant_angles_generate_in_every_backend(tmp_path, alpha):
    """alpha = pi/3 puts sqrt(3)/2 in the model: each backend prints it as a literal (the C vector
    code has no power function; generation used to fail with "not printable: sqrt(3)")."""
    from symoro_gen.dynamics.numeric import inverse_dynamics

    text = (ROOT / "robots" / "scara.toml").read_text()
    lines = text.splitlines()
    idx = [i for i, ln in enumerate(lines) if ln.strip() == "alpha = 0"]
    lines[idx[1]] = f'alpha = "{alpha}"'  # second frame tilted
    robot = parse_robot_text("\n".join(lines) + "\n", file="scara_tilted.toml")
    emit_robot(robot, tmp_path)
    m = load_model(tmp_path / robot.name)
    rng = np.random.default_rng(3)
    q, dq, ddq = rng.normal(size=(3, 25, robot.n_joints))
    chi = rng.normal(size=len(m.STANDARD_NAMES))
    ref = inverse_dynamics(robot, q, dq, ddq, chi)
    tau = m.torque(q, dq, ddq, chi)
    assert np.max(np.abs(tau - ref)) <= 1e-10 * max(1.0, np.abs(ref).max())
    mn = m._MODEL.numpy_only()
    assert np.max(np.abs(mn.regressor(q, dq, ddq) - m.regressor(q, dq, ddq))) <= 1e-12 * max(
        1.0, np.abs(mn.regressor(q, dq, ddq)).max())
    f = m.casadi_regressor()
    Yc = np.array(f(q[0], dq[0], ddq[0]))
    assert np.allclose(Yc, mn.regressor(q[:1], dq[:1], ddq[:1])[0], atol=1e-12)
