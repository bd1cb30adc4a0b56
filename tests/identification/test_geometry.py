"""``identify --geometry joint_zero``: joint zeros identified with the dynamic parameters, the corrected robot file,
which zeros torque data can see.

Recordings come from the truth bench's independent simulator (``bench/truthsim.py``: Pinocchio's RNEA on the MDH
table, gravity at the true angle ``q_measured + q0``); the identifiability is checked against Pinocchio's torque.
"""
from __future__ import annotations

import dataclasses
import json
import math
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.cli import main
from symoro_gen.description import load_robot
from symoro_gen.errors import IdentificationError, OptionError, OutputError
from symoro_gen.identification.geometry import corrected_robot_text, zero_identifiability
from symoro_gen.workflows.identify import identify

pin = pytest.importorskip("pinocchio")
from tests.oracles.pinocchio_model import pin_torque, random_parameters  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
try:
    import bench_loop_truth as blt
    import truthsim as ts
finally:
    sys.path.remove(str(ROOT / "bench"))


def _record(offsets_deg: dict[int, float], seed: int, seconds: float, name: str):
    """A simulated LWR4 recording with encoder zero offsets (0-based joint -> degrees)."""
    robot = load_robot("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    rng = np.random.default_rng(seed)
    truth = blt.lwr4_truth(robot, chi, 0.05)
    for j, d in offsets_deg.items():
        truth.q_offset[j] = math.radians(d)
    tr, _ = ts.record(robot, ts.Rigid(robot, chi), ts.sum_of_sines(robot, rng), truth, seconds, 250.0, rng, name)
    return tr


@pytest.fixture(scope="module")
def offset_data():
    """Offsets of 1.5 deg on joint 2 and -0.8 deg on joint 3 (identification and validation recordings)."""
    offsets = {1: 1.5, 2: -0.8}
    return offsets, _record(offsets, 31, 8.0, "zero-ident"), _record(offsets, 32, 4.0, "zero-valid")


def test_identify_recovers_the_zeros(offset_data):
    """Every visible zero (LWR4: joints 2-6) within 3 sigma of the truth (0 where none was injected), the
    injected ones with sigma below a third of their value; the invisible joints (1, 7) reported as not
    identifiable and not fitted; the fit at the corrected angles validates as well as on clean data."""
    offsets, tr, va = offset_data
    res = identify("lwr4", [tr], validate=[va], geometry="joint_zero")
    g = res.geometry
    assert g is not None and g.converged
    assert g.joints == (1, 2, 3, 4, 5)
    for k, j in enumerate(g.joints):
        want = math.radians(offsets.get(j, 0.0))
        assert abs(g.offsets[k] - want) <= 3 * g.std[k], (j + 1, math.degrees(g.offsets[k]), math.degrees(g.std[k]))
        if j in offsets:
            assert g.std[k] < abs(want) / 3
    d = res.to_dict()["geometry"]
    assert [z["joint"] for z in d["zeros"]] == [2, 3, 4, 5, 6]
    assert [z["joint"] for z in d["not_identifiable"]] == [1, 7]
    assert d["zeros"][0]["offset_deg"] == pytest.approx(math.degrees(g.offsets[0]))
    text = res.summary()
    assert f"joint 2 zero offset {math.degrees(g.offsets[0]):+.4f} deg (sigma {math.degrees(g.std[0]):.4f} deg" in text
    assert "joint 1: not identifiable" in text and "joint 7: not identifiable" in text
    # without the zeros the same fit leaves the gravity error of joint 2 in the validation residual
    plain = identify("lwr4", [tr], validate=[va])
    assert res.validation["rel_err"][1] < 0.8 * plain.validation["rel_err"][1]


def test_invisible_joints_are_not_fitted():
    """A short clean recording: the visible zeros only (LWR4 2-6) are fitted, each within 3 sigma of 0; the JSON
    names joints 1 and 7 as not identifiable with their reason (no torque change / absorbed by the base
    parameters); --geometry with the closed-loop estimators is refused."""
    tr = _record({}, 7, 3.0, "clean")
    res = identify("lwr4", [tr], method="ols", geometry="joint_zero")
    g = res.geometry
    assert g.joints == (1, 2, 3, 4, 5)
    assert np.all(np.abs(g.offsets) <= 3 * g.std)
    why = {z["joint"]: z["reason"] for z in res.to_dict()["geometry"]["not_identifiable"]}
    assert set(why) == {1, 7}
    assert "is 0" in why[1] and "absorb" in why[7]
    with pytest.raises(OptionError, match="--geometry"):
        identify("lwr4", [tr], method="didim", geometry="joint_zero")


@pytest.mark.parametrize("name,visible", [("lwr4", (2, 3, 4, 5, 6)), ("rx90", (2, 3, 4, 5)), ("scara", (2,))])
def test_identifiability_per_robot(name, visible):
    """Which zeros torque data can see, per robot. Independent check with Pinocchio: a joint reported as having
    no torque column changes no torque when its angle moves (random consistent parameters, random states); a
    visible one does. The visible set is the expected one (LWR4 2-6, RX-90 2-5, SCARA 2: its vertical axes
    see no gravity, joint 2 through the inertial coupling)."""
    robot = load_robot(name)
    model = symoro_gen.load_model(name)
    vis = zero_identifiability(model)
    assert tuple(v.joint + 1 for v in vis if v.visible) == visible
    rng = np.random.default_rng(3)
    chi, _ = random_parameters(robot, rng)
    n = robot.n_joints
    q, dq, ddq = rng.uniform(-math.pi, math.pi, (6, n)), rng.standard_normal((6, n)), rng.standard_normal((6, n))
    no_fs = chi.copy()
    no_fs[[i for i, nm in enumerate(robot.standard_names) if nm.startswith(("FS", "OFF"))]] = 0.0
    tau = pin_torque(robot, q, dq, ddq, no_fs)
    scale = np.abs(tau).max()
    for v in vis:
        moved = pin_torque(robot, q + 0.2 * np.eye(n)[v.joint], dq, ddq, no_fs)
        change = np.abs(moved - tau).max()
        if v.visible:
            assert change > 1e-3 * scale, (name, v.joint + 1)
        elif "is 0" in v.reason:
            assert change <= 1e-9 * scale, (name, v.joint + 1)


def test_corrected_robot_text_adds_the_zeros(tmp_path):
    """The corrected text parses; each corrected joint's theta is the original one at ``q + q0`` (the parsed
    expressions, evaluated at random angles); every other frame field and the other joints are unchanged; the
    header names the source file."""
    import sympy as sp

    robot = load_robot("lwr4")
    zeros = {1: 0.02, 3: -0.01}
    text = corrected_robot_text(robot, zeros, note="a test")
    p = tmp_path / "corr.toml"
    p.write_text(text)
    new = load_robot(p)
    assert str(robot.file) in text.splitlines()[0]
    rng = np.random.default_rng(0)
    for k, (a, b) in enumerate(zip(robot.joints, new.joints)):
        q = a.theta.free_symbols.pop()
        for x in rng.uniform(-3, 3, 3):
            want = float(a.theta.subs(q, x + zeros.get(k, 0.0)))
            assert float(sp.sympify(b.theta).subs(q, x)) == pytest.approx(want, abs=1e-12)
        assert (a.alpha, a.d, a.r, a.sigma, a.ant) == (b.alpha, b.d, b.r, b.sigma, b.ant)
    assert new.nominal == robot.nominal


@pytest.mark.slow
def test_robot_out_round_trip(offset_data, tmp_path):
    """``identify --geometry joint_zero -o PATH`` (the command): writes the corrected robot file (never over the
    input robot file, never over an existing file without --force), records it in the JSON; identify with the
    corrected file on the same data finds every zero within 3 sigma of 0 (and within a fraction of the first
    fit's sigma of it)."""
    from symoro_gen.simulate.recording import write_recording_csv

    offsets, tr, _ = offset_data
    shutil.copy(ROOT / "robots" / "lwr4.toml", tmp_path / "lwr4.toml")
    data = tmp_path / "a.csv"
    write_recording_csv(data, tr)
    out = tmp_path / "lwr4_corrected.toml"
    js = tmp_path / "r.json"
    source = (tmp_path / "lwr4.toml").read_bytes()
    assert main(["identify", str(tmp_path / "lwr4.toml"), str(data), "--geometry", "joint_zero", "-o", str(out),
                 "--json", str(js), "--quiet"]) == 0
    assert (tmp_path / "lwr4.toml").read_bytes() == source
    full = json.loads(js.read_text())
    first = full["geometry"]
    assert first["robot_out"] == str(out) and Path(first["robot_file"]).name == "lwr4.toml"
    assert full["robot_out"]["path"] == str(out)
    assert full["robot_out"]["written"] == {"joint_zero": [z["joint"] for z in first["zeros"]]}
    assert load_robot(out).name == "lwr4"
    res = identify(out, [data], geometry="joint_zero")
    g = res.geometry
    for k in range(len(g.joints)):
        assert abs(g.offsets[k]) <= 3 * g.std[k]
        assert abs(g.offsets[k]) <= 0.1 * first["zeros"][k]["offset_rad_std"] + 1e-9
    # never onto the input robot file (even with --force), nor over an existing file without --force
    before = (tmp_path / "lwr4.toml").read_bytes()
    assert main(["identify", str(tmp_path / "lwr4.toml"), str(data), "--geometry", "joint_zero",
                 "-o", str(tmp_path / "lwr4.toml"), "--force", "--quiet"]) != 0
    assert (tmp_path / "lwr4.toml").read_bytes() == before
    assert main(["identify", str(tmp_path / "lwr4.toml"), str(data), "--geometry", "joint_zero", "-o", str(out),
                 "--quiet"]) != 0


def test_robot_out_needs_geometry_and_refuses_inputs(tmp_path):
    """-o/--robot-out without --geometry is refused; the API writer refuses the input robot file."""
    tr = _record({}, 8, 2.0, "short")
    res = identify("lwr4", [tr], method="ols")
    with pytest.raises(OptionError, match="--geometry"):
        res.write_robot(tmp_path / "x.toml")
    res = identify("lwr4", [tr], method="ols", geometry="joint_zero", geometry_joints=[2])
    assert res.geometry.joints == (1,)
    assert any(n.startswith("joint 2 zero offset") for n in res.report_content().notes)
    with pytest.raises(OutputError, match="input"):
        res.write_robot(ROOT / "robots" / "lwr4.toml", force=True)
    written = res.write_robot(tmp_path / "x.toml")
    assert written.geometry.robot_out == str(tmp_path / "x.toml")
    # the JSON with its geometry block validates against docs/schemas/identify.schema.json
    from tests.docs.jsonschema_lite import validate

    schema = json.loads((ROOT / "docs" / "schemas" / "identify.schema.json").read_text())
    d = json.loads(json.dumps(written.to_dict()))
    assert d["geometry"]["robot_out"] == str(tmp_path / "x.toml")
    assert validate(d, schema) == []
    bad = json.loads(json.dumps(d))
    bad["geometry"]["zeros"][0]["joint"] = "two"
    assert validate(bad, schema)
    with pytest.raises(OutputError, match="exists"):
        res.write_robot(tmp_path / "x.toml")
    # a zero beyond 20 deg is no encoder zero error: never written into a robot file
    wild = dataclasses.replace(res, geometry=dataclasses.replace(res.geometry, offsets=res.geometry.offsets + 0.5))
    with pytest.raises(IdentificationError, match=r"joint 2 zero .* beyond 20 deg"):
        wild.write_robot(tmp_path / "y.toml")
    assert not (tmp_path / "y.toml").exists()
    # the joints chosen: an invisible one is refused naming it
    with pytest.raises(IdentificationError, match=r"joint\(s\) \[1\]"):
        identify("lwr4", [tr], method="ols", geometry="joint_zero", geometry_joints=[1, 2])


@pytest.mark.parametrize("name,frame,fld", [("lwr4", 3, "r"), ("rx90", 3, "d")])
def test_length_sensitivity_is_pinocchios_at_the_perturbed_geometry(name, frame, fld):
    """The link-length sensitivity (central difference of the numeric Newton-Euler torque in the MDH length)
    equals Pinocchio's central difference, each model built at the perturbed geometry; and at a finite
    perturbation (1 cm) the numeric torque is Pinocchio's (the perturbed robot is a different arm: its torque
    changes)."""
    from symoro_gen.dynamics.numeric import inverse_dynamics
    from symoro_gen.identification.geometry import length_sensitivity, perturbed_robot

    robot = load_robot(name)
    rng = np.random.default_rng(5)
    chi, _ = random_parameters(robot, rng)
    n = robot.n_joints
    q, dq, ddq = rng.uniform(-math.pi, math.pi, (5, n)), rng.standard_normal((5, n)), rng.standard_normal((5, n))
    S = length_sensitivity(robot, chi, q, dq, ddq, frame, fld)
    h = 1e-5
    ref = (pin_torque(perturbed_robot(robot, frame, fld, h), q, dq, ddq, chi)
           - pin_torque(perturbed_robot(robot, frame, fld, -h), q, dq, ddq, chi)) / (2 * h)
    assert np.abs(ref).max() > 1.0
    np.testing.assert_allclose(S, ref, atol=1e-6 * np.abs(ref).max())
    moved = perturbed_robot(robot, frame, fld, 0.01)
    tau_moved = pin_torque(moved, q, dq, ddq, chi)
    np.testing.assert_allclose(inverse_dynamics(moved, q, dq, ddq, chi), tau_moved, atol=1e-9 * np.abs(tau_moved).max())
    assert np.abs(tau_moved - pin_torque(robot, q, dq, ddq, chi)).max() > 1e-3 * np.abs(tau_moved).max()


@pytest.mark.slow
def test_length_visibility():
    """A translation of the whole LWR4 along its base axes (d, r of frame 1) changes no torque under uniform
    gravity: invisible (share 0); the length of link 3 (r of frame 3) is visible."""
    from symoro_gen.identification.geometry import length_visibility

    robot = load_robot("lwr4")
    assert length_visibility(robot, 1, "r") == 0.0
    assert length_visibility(robot, 1, "d") == 0.0
    assert length_visibility(robot, 3, "r") > 0.05
