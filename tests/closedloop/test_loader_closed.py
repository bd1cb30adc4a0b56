"""load_model on a closed-loop robot: every way in returns the projected model, never the bare tree."""
from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from symoro_gen import load_model
from symoro_gen.closedloop import ClosedLoopModel
from symoro_gen.errors import ModelError

ROOT = Path(__file__).resolve().parents[2]


def test_every_way_in_gives_the_closed_loop_model():
    for source in ("palletizer", ROOT / "robots" / "palletizer.toml", ROOT / "generated" / "palletizer"):
        m = load_model(source)
        assert isinstance(m, ClosedLoopModel) and m.N_JOINTS == 4 and m.ACTUATED_JOINTS == (1, 2, 4, 5)
        assert m.tree.N_JOINTS == 6


def test_a_copied_tree_package_without_its_robot_file_is_one_error(tmp_path, monkeypatch):
    monkeypatch.setenv("SYMORO_BACKEND", "numpy")  # no C compilation for the copy
    pkg = tmp_path / "somewhere" / "palletizer"
    shutil.copytree(ROOT / "generated" / "palletizer", pkg, ignore=shutil.ignore_patterns("_build", "__pycache__"))
    assert isinstance(load_model(pkg), ClosedLoopModel)  # the robot file is found in robots/ (same sha256)
    monkeypatch.setenv("SYMORO_ROBOTS", str(tmp_path / "no_robots"))
    with pytest.raises(ModelError, match=r"tree model of the closed-loop robot 'palletizer'.*palletizer\.toml"):
        load_model(pkg)
