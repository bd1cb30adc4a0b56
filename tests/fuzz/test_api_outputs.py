"""Fuzz: the Python API's writers never clobber their inputs. ``Results.write_json``, ``Results.report``,
``ExciteResults.write_csv``, ``ExportResults.write`` (``export_urdf/export_mjcf/export_par``) given as output
the robot file or the data they were computed from (the path itself, or a symlink to it) refuse, with ``force``
too, and leave it byte for byte; an existing file symoro-gen did not write is refused unless ``force``; a new
path is written. Small robots (the SCARA), short recordings, few examples."""
from __future__ import annotations

import functools
import hashlib
import os
import shutil
from pathlib import Path

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import symoro_gen
from symoro_gen.errors import OutputError
from symoro_gen.loader import model_for
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording, write_recording_csv

from .helpers import FUZZ

ROOT = Path(__file__).resolve().parents[2]
WRITERS = ("identify.write_json", "identify.report", "excite.write_csv", "excite.write_json", "export_urdf",
           "export_mjcf", "export_par")
TARGETS = ("robot file", "data file", "symlink to the robot file", "symlink to the data file", "foreign file",
           "new path")


@functools.cache
def _results(folder: str):
    """The results the writers belong to, computed once from a private robot file and a 4 s recording."""
    d = Path(folder)
    robot = d / "scara.toml"
    shutil.copy(ROOT / "robots" / "scara.toml", robot)
    desc, model = model_for("scara")
    rng = np.random.default_rng(1)
    mo = fourier_trajectory(model.N_JOINTS, 4.0, 0.005, rng, vmax=1.5, amax=8.0)
    chi = np.asarray(random_physical_parameters(desc, rng), float)
    rec = simulate_recording(model, mo.t, np.array(mo.q), np.array(mo.dq), np.array(mo.ddq), chi, noise_q=1e-5,
                             noise_tau=0.02, rng=rng, source="log.csv")
    data = d / "log.csv"
    write_recording_csv(data, rec)
    ident = symoro_gen.identify(str(robot), str(data))
    exc = symoro_gen.excite(str(robot), duration=2.0, rate=50.0, refine=0, starts=1)
    return robot, data, ident, exc


def _write(which: str, ident, exc, robot: Path, path: Path, force: bool):
    if which == "identify.write_json":
        return ident.write_json(path, force=force)
    if which == "identify.report":
        return ident.report(path, force=force)
    if which == "excite.write_csv":
        return exc.write_csv(path, force=force)
    if which == "excite.write_json":
        return exc.write_json(path, force=force)
    return getattr(symoro_gen, which)(str(robot)).write(path, force=force)


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def made(tmp_path_factory):
    pytest.importorskip("matplotlib", reason="reports need the plots extra")
    return _results(str(tmp_path_factory.mktemp("api-inputs")))


@pytest.mark.slow
@FUZZ
@given(which=st.sampled_from(WRITERS), target=st.sampled_from(TARGETS), force=st.booleans(),
       suffix=st.sampled_from([".json", ".html", ".csv", ".urdf"]))
def test_api_writers_never_clobber_their_inputs(made, tmp_path_factory, which, target, force, suffix):
    robot, data, ident, exc = made
    # an export or a design reads only the robot file: the recording is not its input (and the examples share it)
    assume(not ("data" in target and not which.startswith("identify")))
    names_input = target not in ("foreign file", "new path")
    work = tmp_path_factory.mktemp("out")
    if which == "identify.report" and suffix not in (".html",):
        suffix = ".html"
    before = {robot: _digest(robot), data: _digest(data)}
    if target in ("robot file", "data file"):
        path = robot if target == "robot file" else data
    elif target.startswith("symlink"):
        path = work / f"link{suffix}"
        os.symlink(robot if "robot" in target else data, path)
    elif target == "foreign file":
        path = work / f"theirs{suffix}"
        path.write_text("a user's file\n")
    else:
        path = work / f"new{suffix}"
    if names_input or (target == "foreign file" and not force):
        with pytest.raises(OutputError) as err:
            _write(which, ident, exc, robot, path, force)
        assert str(path) in str(err.value) or os.path.realpath(path) in str(err.value), str(err.value)
        if names_input:
            assert "input" in str(err.value), str(err.value)
        else:
            assert path.read_text() == "a user's file\n"
    else:
        _write(which, ident, exc, robot, path, force)
        assert path.exists() and path.stat().st_size > 0
    assert {robot: _digest(robot), data: _digest(data)} == before, f"{which} -> {target} changed an input"
