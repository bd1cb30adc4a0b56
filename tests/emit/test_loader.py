"""One loader: load_model(name | package folder | robot file | RobotDescription) -> IdentificationModel."""
import hashlib
import shutil
from pathlib import Path

import numpy as np
import pytest

from symoro_gen import load_model
from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.errors import ModelError
from symoro_gen.loader import model_for
from symoro_gen.model import IdentificationModel

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("SYMORO_BACKEND", "numpy")


def _repo_generated_snapshot():
    return {str(p.relative_to(ROOT)): p.stat().st_mtime_ns for p in (ROOT / "generated").rglob("*")
            if "_build" not in p.parts and "__pycache__" not in p.parts}


def _torque_ok(m, robot):
    rng = np.random.default_rng(0)
    q, dq, ddq = rng.normal(size=(3, 5, robot.n_joints))
    chi = rng.normal(size=len(robot.standard_names))
    ref = inverse_dynamics(robot, q, dq, ddq, chi)
    assert np.max(np.abs(m.torque(q, dq, ddq, chi) - ref)) <= 1e-9 * np.abs(ref).max()


def test_name_and_folder_give_the_same_module():
    a = load_model("scara")
    b = load_model(ROOT / "generated" / "scara")
    c = load_model(ROOT / "robots" / "scara.toml")  # same file hash as the committed package: reused
    assert a is b is c and isinstance(a, IdentificationModel)
    expected = "_symoro_generated_scara_" + hashlib.sha256(str((ROOT / "generated" / "scara").resolve()).encode()).hexdigest()[:12]
    assert a.__name__.startswith(expected + "_"), "module names from a sha256 of the path, not the per-process hash()"


def test_robot_file_outside_the_repository_is_generated_next_to_it(tmp_path):
    before = _repo_generated_snapshot()
    text = (ROOT / "robots" / "scara.toml").read_text().replace('name = "scara"', 'name = "my_scara"')
    f = tmp_path / "robots" / "my_scara.toml"
    f.parent.mkdir()
    f.write_text(text)
    m = load_model(f)
    assert m.ROBOT == "my_scara" and (tmp_path / "robots" / "generated" / "my_scara" / "manifest.json").is_file()
    _torque_ok(m, load_robot(f))
    assert load_model(f) is m  # second time: reused, not regenerated
    assert _repo_generated_snapshot() == before, "the repository's generated/ is never written"
    assert not (ROOT / "generated" / "my_scara").exists()


def test_robot_file_changed_is_regenerated(tmp_path):
    f = tmp_path / "two.toml"
    f.write_text((ROOT / "robots" / "scara.toml").read_text().replace('name = "scara"', 'name = "two"'))
    m1 = load_model(f)
    f.write_text(f.read_text().replace("name = \"two\"", "name = \"two\"\n# changed"))
    m2 = load_model(f)
    assert m1 is not m2 and load_robot(f).file_hash == m2.ROBOT_FILE_SHA256


def test_description_without_file_goes_to_the_user_cache(tmp_path):
    before = _repo_generated_snapshot()
    text = (ROOT / "robots" / "rx90.toml").read_text().replace("D3 = 0.45", "D3 = 0.5")
    robot = parse_robot_text(text, file="<string>")
    m = load_model(robot)
    assert Path(m.__file__).is_relative_to(tmp_path / "cache" / "symoro_gen" / "models")
    assert m.GEOMETRY["D3"] == 0.5
    _torque_ok(m, robot)
    assert _repo_generated_snapshot() == before


def test_model_for_returns_robot_and_model():
    robot, m = model_for("rx90")
    assert robot.name == m.ROBOT == "rx90" and m is load_model("rx90")


def test_stale_repository_package_is_not_used(tmp_path):
    """A robot file whose hash differs from generated/<name>/ gets its own package (cache), never a stale one."""
    text = (ROOT / "robots" / "scara.toml").read_text() + "\n# a comment changes the hash\n"
    robot = parse_robot_text(text, file="<string>")
    m = load_model(robot)
    assert m.ROBOT_FILE_SHA256 == robot.file_hash != load_model("scara").ROBOT_FILE_SHA256


def test_unknown_robot_lists_the_known_ones():
    with pytest.raises(ModelError, match=r"no_such_robot.*known: .*lwr4"):
        load_model("no_such_robot")
    with pytest.raises(ModelError, match="expected a robot name"):
        load_model(3.5)


def test_broken_package_is_a_model_error(tmp_path):
    dst = tmp_path / "scara"
    shutil.copytree(ROOT / "generated" / "scara", dst, ignore=shutil.ignore_patterns("_build", "__pycache__"))
    (dst / "_kernels.py").write_text("this is not python")
    with pytest.raises(ModelError, match="failed to import"):
        load_model(dst)
