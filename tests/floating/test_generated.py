"""The generated package of a floating-base robot (``symoro-gen generate`` of a ``base = "floating"`` file).

Checked against independent references: Pinocchio with a free-flyer root (RNEA for the rows,
``data.oMf`` for the contact frames' poses, ``getFrameJacobian(..., LOCAL)`` for their Jacobians; the
contact frames are added to the oracle's model as operational frames at the MDH placements of
:func:`tests.oracles.pinocchio_model.constant_placement`), and the in-memory
:class:`~symoro_gen.runtime.floating.FloatingModel`. The package's three printed forms (C, NumPy, CasADi)
agree with each other, and two generations write the same bytes.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from symoro_gen.cli import main
from symoro_gen.description import load_robot
from symoro_gen.description.model import FIXED
from symoro_gen.emit.package import emit_robot
from symoro_gen.errors import RobotFileError
from symoro_gen.identification.floating import wrench_at_base
from symoro_gen.loader import import_package, load_model
from symoro_gen.runtime import ccompile
from symoro_gen.runtime.floating import FloatingModel
from symoro_gen.runtime.floating_package import GeneratedFloatingModel
from tests.floating.pinocchio_floating import (
    build_floating_pinocchio,
    pin_floating_torque,
    random_floating_parameters,
    random_floating_states,
)
from tests.oracles.pinocchio_model import constant_placement

HERE = Path(__file__).resolve().parent
HAVE_CC = shutil.which("cc") is not None or shutil.which("gcc") is not None

#: a small floating tree: a revolute chain (one joint entering as -q with an offset, a gamma and b), a
#: prismatic joint and a revolute joint on it, two named fixed contact frames and a moving one
SMALL = '''
name = "floater_test"
base = "floating"
gravity = [0.3, -0.2, -9.81]
contacts = ["tip", "foot", 2]

[values]
L1 = 0.3
L2 = 0.25
H = 0.1

[[frames]]
j = 1
ant = 0
sigma = 0
gamma = "pi/6"
b = "H"
alpha = "pi/2"
d = "L1"
theta = "q"
r = 0.05

[[frames]]
j = 2
ant = 1
sigma = 0
alpha = 0
d = "L2"
theta = "-q + 0.4"
r = 0

[[frames]]
j = 3
ant = 0
sigma = 1
alpha = "-pi/2"
d = 0.1
theta = "pi/2"
r = "q"

[[frames]]
j = 4
ant = 3
sigma = 0
alpha = "pi/2"
d = 0
theta = "q"
r = 0.02

[[frames]]
j = 5
ant = 2
sigma = 2
name = "tip"
alpha = 0
d = 0.15
theta = 0
r = 0

[[frames]]
j = 6
ant = 4
sigma = 2
name = "foot"
alpha = "pi/2"
d = 0.12
theta = 0.2
r = 0.01
'''


def _quadruped_with_feet(path: Path) -> Path:
    """The quadruped fixture with a fixed foot frame under each knee (three named), contacts on three feet
    and on a knee frame (9)."""
    text = (HERE / "quadruped.toml").read_text()
    text = text.replace('base = "floating"\n', 'base = "floating"\ncontacts = ["fl_foot", "fr_foot", 9, "rr_foot"]\n', 1)
    for k, (ant, name) in enumerate([(3, "fl_foot"), (6, "fr_foot"), (9, None), (12, "rr_foot")]):
        text += (f"\n[[frames]]\nj = {13 + k}\nant = {ant}\nsigma = 2\n" + (f'name = "{name}"\n' if name else "")
                 + f'alpha = "pi/2"\nd = {0.2 + 0.01 * k}\ntheta = 0.3\nr = {0.02 * k}\n')
    path.write_text(text)
    return path


def _humanoid_with_contacts(path: Path) -> Path:
    """The humanoid fixture with contacts on its left sole (23), right hand (24) and left elbow (18)."""
    path.write_text((HERE / "humanoid.toml").read_text().replace('base = "floating"\n',
                                                                'base = "floating"\ncontacts = [23, 24, 18]\n', 1))
    return path


@pytest.fixture
def quick_c(monkeypatch, tmp_path):
    """C kernels compiled at -O0 in a private cache (the code is the same; -O3 only makes it faster)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("SYMORO_BACKEND", raising=False)
    flags = ccompile.compile_flags
    monkeypatch.setattr(ccompile, "compile_flags", lambda size, opt=None: flags(size, "-O0"))


def _pinocchio_frames(robot, chi):
    """Pinocchio's free-flyer model of ``robot`` with one operational frame per contact frame."""
    model, _ = build_floating_pinocchio(robot, chi)
    joint = {0: 1}  # frame -> Pinocchio joint id (1: the free flyer; moving rows follow in row order)
    placement = {0: pin.SE3.Identity()}
    nxt = 2
    for row in robot.rows:
        pl, _ = constant_placement(robot, row.j)
        where = placement[row.ant] * pl
        if row.sigma == FIXED:
            joint[row.j], placement[row.j] = joint[row.ant], where
        else:
            joint[row.j], placement[row.j] = nxt, pin.SE3.Identity()
            nxt += 1
    fids = [model.addFrame(pin.Frame(f"contact{j}", joint[j], placement[j], pin.FrameType.OP_FRAME))
            for j in robot.contacts]
    return model, model.createData(), fids


def _relative(a, b) -> float:
    return float(np.abs(np.asarray(a) - np.asarray(b)).max() / max(np.abs(np.asarray(b)).max(), 1e-300))


def _check_package(robot_file: Path, pkg, n_samples: int = 7, seed: int = 3) -> dict[str, float]:
    """The package against FloatingModel and Pinocchio, and its C, NumPy and CasADi forms against each
    other; returns the largest errors (asserted here)."""
    robot = load_robot(robot_file)
    rng = np.random.default_rng(seed)
    q, dq, ddq = random_floating_states(robot, n_samples, rng)
    chi = random_floating_parameters(robot, rng)
    ref = FloatingModel(robot)
    errs: dict[str, float] = {}
    for fn in ("standard_regressor", "regressor"):
        errs[fn] = _relative(getattr(pkg, fn)(q, dq, ddq), getattr(ref, fn)(q, dq, ddq))
    errs["base_parameters"] = _relative(pkg.base_parameters(chi), ref.base_parameters(chi))
    errs["rnea"] = _relative(pkg.torque(q, dq, ddq, chi), pin_floating_torque(robot, q, dq, ddq, chi))
    model, data, fids = _pinocchio_frames(robot, chi)
    T = {k: pkg.frame_transform(name, q) for k, name in enumerate(pkg.CONTACT_FRAMES)}
    J = {k: pkg.frame_jacobian(k, q) for k in range(len(fids))}
    eT = eJ = 0.0
    for s in range(n_samples):
        pin.computeJointJacobians(model, data, q[s])
        pin.updateFramePlacements(model, data)
        for k, fid in enumerate(fids):
            eT = max(eT, _relative(T[k][s], data.oMf[fid].homogeneous))
            eJ = max(eJ, _relative(J[k][s], pin.getFrameJacobian(model, data, fid, pin.LOCAL)))
    errs["oMf"], errs["jacobian_local"] = eT, eJ
    for k in range(len(fids)):  # the in-memory model's contact kernels too
        errs["oMf"] = max(errs["oMf"], _relative(ref.frame_transform(k, q), T[k]))
        errs["jacobian_local"] = max(errs["jacobian_local"], _relative(ref.frame_jacobian(k, q), J[k]))
    for name, e in errs.items():
        assert e <= 1e-9, (name, e)
    assert pkg.BACKEND == "c"
    num = pkg._MODEL.numpy_only()
    Wc, Wn = pkg.regressor(q, dq, ddq), num.regressor(q, dq, ddq)
    Wx = np.array([np.array(pkg.casadi_regressor()(q[s], dq[s], ddq[s])) for s in range(n_samples)])
    errs["c_numpy"] = _relative(Wc, Wn)
    errs["casadi_numpy"] = _relative(Wx, Wn)
    for k in range(len(fids)):
        for what, shape in (("transform", (4, 4)), ("jacobian", (6, 6 + robot.n_joints))):
            c, n_ = getattr(pkg, f"frame_{what}")(k, q), getattr(num, f"frame_{what}")(k, q)
            f = getattr(pkg, f"casadi_frame_{what}")(k)
            x = np.array([np.array(f(q[s])).reshape(shape) for s in range(n_samples)])
            errs["c_numpy"] = max(errs["c_numpy"], _relative(c, n_))
            errs["casadi_numpy"] = max(errs["casadi_numpy"], _relative(x, n_))
    assert errs["c_numpy"] <= 1e-10 and errs["casadi_numpy"] <= 1e-10, errs
    return errs


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """``(robot file, package folder)``: the small tree generated once by ``symoro-gen generate``, into the
    ``generated/`` folder beside its file."""
    d = tmp_path_factory.mktemp("floater")
    f = d / "floater.toml"
    f.write_text(SMALL)
    assert main(["generate", str(f), "--out", str(d / "generated"), "--quiet"]) == 0
    return f, d / "generated" / "floater_test"


@pytest.mark.skipif(not HAVE_CC, reason="no C compiler")
def test_small_floating_package_equals_pinocchio_and_floating_model(small, quick_c):
    """``load_model`` of the robot file returns the package ``generate`` wrote beside it (the floating
    contract, C kernels); rows, base parameters, contact poses and LOCAL Jacobians equal Pinocchio's and
    FloatingModel's to 1e-9, C == NumPy == CasADi to 1e-10."""
    f, _ = small
    pkg = load_model(f)
    assert isinstance(pkg._MODEL, GeneratedFloatingModel)
    assert pkg.FLOATING and pkg.N_ROWS == 6 + pkg.N_JOINTS == 10
    assert pkg.CONTACT_FRAMES == ("tip", "foot", "frame2")
    errs = _check_package(f, pkg)
    print("floater_test:", ", ".join(f"{k} {v:.1e}" for k, v in errs.items()))


def test_manifest_files_and_relations(small):
    """The package has the fixed-base layout; ``manifest.json`` says ``floating``, the input sizes and the
    contact frames; ``base_parameters.md`` has the relations and the floating-base section."""
    _, path = small
    man = json.loads((path / "manifest.json").read_text())
    assert set(man["files"]) == {"__init__.py", "_kernels.py", "_casadi.py", "regressor_floater_test.c",
                                 "base_parameters.md", "manifest.json"}
    assert man["floating"] is True and man["n_rows"] == 10
    assert man["input_sizes"] == {"q": 11, "dq": 10, "ddq": 10}
    assert [(c["name"], c["frame"]) for c in man["contact_frames"]] == [("tip", 5), ("foot", 6), ("frame2", 2)]
    md = (path / "base_parameters.md").read_text()
    assert "## Regrouping relations" in md and "## Floating base" in md
    regrouped = [n for n in man["base_names"] if n.endswith("R")]
    assert regrouped and all(f"{n} = " in md for n in regrouped)
    assert "XX0R" in regrouped  # the base link keeps what regroups onto frame 0


def test_generation_is_deterministic(small):
    """A second generation of the same robot file writes the same files, byte for byte."""
    f, path = small
    again = emit_robot(load_robot(f), f.parent / "again", source_base=f.parent).path
    names = json.loads((path / "manifest.json").read_text())["files"]
    assert names == sorted(p.name for p in again.iterdir())
    for n in names:
        assert (path / n).read_bytes() == (again / n).read_bytes(), n


def test_unknown_contact_frame_is_named(small, monkeypatch):
    monkeypatch.setenv("SYMORO_BACKEND", "numpy")
    pkg = import_package(small[1])
    q = np.r_[np.zeros(3), 0, 0, 0, 1, np.zeros(4)]
    assert pkg.frame_transform("tip", q).shape == (4, 4)
    with pytest.raises(KeyError, match=r"'hand' is not a contact frame.*tip, foot, frame2"):
        pkg.frame_jacobian("hand", q)


@pytest.mark.parametrize("line, field, message", [
    ('contacts = ["tip", "wing"]', "contacts[1]", "'wing' is not a frame number"),
    ("contacts = [5, 5]", "contacts[1]", "frame 5 is listed twice"),
    ("contacts = [7]", "contacts[0]", "not a frame number (1..6)"),
    ('contacts = "tip"', "contacts", "must be a list"),
])
def test_contacts_errors_name_the_file_and_field(tmp_path, line, field, message):
    f = tmp_path / "floater.toml"
    f.write_text(SMALL.replace('contacts = ["tip", "foot", 2]', line))
    with pytest.raises(RobotFileError) as exc:
        load_robot(f)
    text = str(exc.value)
    assert "floater.toml" in text and field in text and message in text


def test_contacts_need_a_floating_base(tmp_path):
    f = tmp_path / "fixed.toml"
    f.write_text(SMALL.replace('base = "floating"', 'base = "fixed"'))
    with pytest.raises(RobotFileError, match=r"contacts.*floating base"):
        load_robot(f)


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_CC, reason="no C compiler")
def test_quadruped_package(tmp_path, quick_c):
    """The 12-joint quadruped with four contact frames (three feet and a knee)."""
    f = _quadruped_with_feet(tmp_path / "quadruped.toml")
    t = time.perf_counter()
    pkg = import_package(emit_robot(load_robot(f), tmp_path / "out").path)
    print(f"quadruped_test: generated in {time.perf_counter() - t:.1f} s")
    errs = _check_package(f, pkg)
    print("quadruped_test:", ", ".join(f"{k} {v:.1e}" for k, v in errs.items()))


@pytest.mark.slow
@pytest.mark.skipif(not HAVE_CC, reason="no C compiler")
def test_humanoid_package_generated_within_a_minute(tmp_path, quick_c):
    """The 22-joint humanoid tree (three contact frames): generated within 60 s, then as the quadruped."""
    f = _humanoid_with_contacts(tmp_path / "humanoid.toml")
    t = time.perf_counter()
    pkg = import_package(emit_robot(load_robot(f), tmp_path / "out").path)
    elapsed = time.perf_counter() - t
    print(f"humanoid_test: generated in {elapsed:.1f} s")
    assert elapsed < 60.0
    errs = _check_package(f, pkg, n_samples=5)
    print("humanoid_test:", ", ".join(f"{k} {v:.1e}" for k, v in errs.items()))


def test_contact_jacobian_and_transform_carry_a_wrench_alike(small, monkeypatch):
    """The two ways ``ContactWrench`` carries a contact wrench to the base rows agree on the package's
    kernels: ``J_c[:, :6]^T f`` (the LOCAL Jacobian) equals ``wrench_at_base`` of the frame's pose in base
    axes (``frame_transform`` with the base at the origin), [F2008] sec. 2.8; and the world pose is the base
    pose of ``q`` times that one."""
    monkeypatch.setenv("SYMORO_BACKEND", "numpy")
    robot_file, path = small
    pkg = import_package(path)
    robot = load_robot(robot_file)
    rng = np.random.default_rng(11)
    q, _, _ = random_floating_states(robot, 6, rng)
    at_origin = q.copy()
    at_origin[:, :7] = [0, 0, 0, 0, 0, 0, 1]
    f = rng.normal(size=(6, 6))
    for k in range(len(pkg.CONTACT_FRAMES)):
        J = pkg.frame_jacobian(k, q)
        T0 = pkg.frame_transform(k, at_origin)
        via_j = np.einsum("kij,ki->kj", J[:, :, :6], f)
        assert _relative(via_j, wrench_at_base(T0, f)) <= 1e-12
        base = np.array([pin.XYZQUATToSE3(x[:7]).homogeneous for x in q])
        assert _relative(pkg.frame_transform(k, q), base @ T0) <= 1e-12


def test_load_model_by_name_and_folder(small, monkeypatch):
    """``load_model("<name>")`` (the package in the generated folder) and ``load_model(<package folder>)``
    return the floating package; without a package, the robot file gives the in-memory FloatingModel."""
    monkeypatch.setenv("SYMORO_BACKEND", "numpy")
    robot_file, path = small
    monkeypatch.setenv("SYMORO_GENERATED", str(path.parent))
    for source in ("floater_test", path):
        m = load_model(source)
        assert isinstance(m._MODEL, GeneratedFloatingModel) and m.FLOATING and m.N_ROWS == 10
    other = robot_file.parent / "elsewhere" / "floater.toml"
    other.parent.mkdir()
    other.write_text(SMALL + "\n# another file, another hash\n")
    assert isinstance(load_model(other), FloatingModel)


@pytest.mark.slow
def test_generation_is_deterministic_across_processes(tmp_path):
    """Two ``symoro-gen generate`` processes with different hash seeds (set and dict orders) write the
    quadruped's package byte for byte alike (``manifest.json`` included: same tools)."""
    f = _quadruped_with_feet(tmp_path / "quadruped.toml")
    outs = []
    for seed in ("1", "2"):
        out = tmp_path / f"run{seed}"
        env = {**os.environ, "PYTHONHASHSEED": seed, "PYTHONPATH": str(HERE.parent.parent)}
        subprocess.run([sys.executable, "-m", "symoro_gen", "generate", str(f), "--out", str(out / "generated"),
                        "--quiet"], check=True, env=env, cwd=tmp_path, timeout=600)
        outs.append(out / "generated" / "quadruped_test")
    names = sorted(p.name for p in outs[0].iterdir())
    assert names == sorted(p.name for p in outs[1].iterdir())
    for n in names:
        assert (outs[0] / n).read_bytes() == (outs[1] / n).read_bytes(), n
