"""The loop's ``link_length`` candidate: an MDH length error named with its value and sigma.

The end-to-end check simulates the LWR4 on the truth bench's independent simulator (``bench/truthsim.py``:
Pinocchio's RNEA on the MDH table of the arm built with the true, lengthened geometry) and diagnoses it with the
generated model of the robot file.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics import DiagnoseSettings, diagnose
from symoro_gen.diagnostics.candidates import MAX_LINK_LENGTH_M, Family, implausible
from symoro_gen.diagnostics.frame import build_frame, common_bandwidth
from symoro_gen.diagnostics.geometry import (
    LengthColumns,
    describe_length,
    description_of,
    emitted_length_column,
    length_column,
    length_joint,
    link_length_ready,
    visible_lengths,
)
from symoro_gen.diagnostics.plausibility import fits_like
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.identification.geometry import LENGTH_FIELDS, perturbed_robot

from .simdata import recording

ROOT = Path(__file__).resolve().parents[2]


def _fam(frame: int, fld: str) -> Family:
    return Family("link_length", frame - 1, (fld,), lambda fr, ctx: [np.zeros((1, 1))], variant=fld,
                  info=(("frame", frame), ("field", fld)))


def test_label_bounds_and_wording():
    """The label names frame and field (``link_length3r``); beyond 50 mm the error is impossible, with a message
    naming the frame and the field; the effect reads ``link 3 length +4.0 mm (r3)``."""
    fam = _fam(3, "r")
    assert fam.label == "link_length3r" and fam.names() == ("link_length3r.r",)
    assert implausible(fam, [0.004], f_dyn=1.0) is None
    assert implausible(fam, [-0.99 * MAX_LINK_LENGTH_M], f_dyn=1.0) is None
    why = implausible(fam, [0.06], f_dyn=1.0)
    assert why is not None and "frame 3 field r" in why and "+60 mm" in why
    phys = describe_length(3, "r", 0.004, 0.0005)
    assert phys["length_mm"] == pytest.approx(4.0) and phys["length_mm_std"] == pytest.approx(0.5)
    assert fits_like("link_length", 2, phys, "") == "link 3 length +4.0 mm (r3)"
    assert fits_like("link_length", 4, describe_length(5, "d", -0.0021, 0.0003), "") == "link 5 length -2.1 mm (d5)"


def test_the_models_robot_file_is_found():
    """A generated model of a robot file: its description (same geometry), the joint of each frame."""
    model = symoro_gen.load_model("lwr4")
    robot = description_of(model)
    assert robot is not None and robot.n_joints == 7
    assert link_length_ready(model)
    assert length_joint(model, 3) == 2 and length_joint(model, 1) == 0


def test_one_pass_serves_every_length():
    """The loop's link-length families share one full-rate pass per frame and fit (``LengthColumns``): each
    column equals the column built for that length alone (``length_column``) to rounding, a second family of the
    same round reuses the pass, and a new fit rebuilds it."""
    model, tr = recording("rx90", 21, noise_q=1e-4, duration=3.0)
    F = build_frame(model, [tr], dynamics_bandwidth_hz=common_bandwidth([tr]))
    robot = description_of(model)
    assert robot is not None
    lengths = visible_lengths(model)
    assert len(lengths) >= 2 and all(fld in LENGTH_FIELDS for _, fld in lengths)
    rng = np.random.default_rng(2)
    theta = {nm: float(v) for nm, v in zip(model.BASE_NAMES, rng.normal(size=len(model.BASE_NAMES)))}
    shared = LengthColumns(model, lengths)
    cols = [shared.column(F, theta, i) for i in range(len(lengths))]
    first = shared._held[-1][2]
    for (f, fld), col in list(zip(lengths, cols))[:3]:
        alone = length_column(F, model, theta, f, fld)
        assert col.shape == alone.shape == (F.n_rows, 1)
        scale = max(1.0, float(np.abs(alone).max()))
        assert np.abs(col - alone).max() <= 1e-12 * scale, (f, fld)
    assert shared.column(F, theta, 0) is not first and len(shared._held) == 1   # reused: same frame, same fit
    theta2 = {nm: 2 * v for nm, v in theta.items()}
    again = shared.column(F, theta2, 0)
    assert len(shared._held) == 2 and shared._held[-1][2] is not first
    assert np.abs(again - length_column(F, model, theta2, *lengths[0])).max() <= 1e-12 * max(1.0, float(np.abs(again).max()))


@pytest.mark.slow
@pytest.mark.parametrize("robot_name", ["lwr4", "rx90"])
def test_the_emitted_length_column_is_the_numeric_newton_euler_difference(robot_name):
    """The loop's length column from the generated package's emitted derivative (``geometry_columns``) equals the
    central difference of the numeric Newton-Euler torque at the perturbed geometry (an independent route: no
    generated code) for every length of the robot, dropped ones included (zero both ways)."""
    model = symoro_gen.load_model(robot_name)
    robot = description_of(model)
    assert robot is not None
    rng = np.random.default_rng(3)
    n = robot.n_joints
    q, dq, ddq = rng.uniform(-2, 2, (7, n)), rng.normal(size=(7, n)), rng.normal(size=(7, n))
    chi = rng.normal(size=len(robot.standard_names))
    h = 1e-6
    for row in robot.rows:
        f = int(row.j)
        for fld in ("d", "r"):
            if fld == "r" and int(row.sigma) == 1:
                continue
            col = emitted_length_column(model, robot, chi, f, fld)
            assert col is not None, (robot_name, f, fld)
            fd = (inverse_dynamics(perturbed_robot(robot, f, fld, h), q, dq, ddq, chi)
                  - inverse_dynamics(perturbed_robot(robot, f, fld, -h), q, dq, ddq, chi)) / (2 * h)
            got = col(q, dq, ddq)
            scale = max(1.0, float(np.abs(fd).max()))
            assert np.abs(got - fd).max() <= 1e-6 * scale, (robot_name, f, fld, np.abs(got - fd).max())


@pytest.mark.slow
def test_the_loop_names_a_link_length():
    """r of frame 3 of the LWR4 5 mm longer on the simulated arm: the loop names ``link_length3r`` first, verdict
    cause, the value within 3 sigma of 5 mm and sigma below a third of it."""
    sys.path.insert(0, str(ROOT / "bench"))
    try:
        import bench_loop_truth as blt
        import truthsim as ts
    finally:
        sys.path.remove(str(ROOT / "bench"))
    robot, model = load_robot("lwr4"), symoro_gen.load_model("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    arm = perturbed_robot(robot, 3, "r", 0.005)
    rigid = ts.Rigid(arm, chi)
    rng = np.random.default_rng(13)
    truth = blt.lwr4_truth(robot, chi, 0.05)
    ident, _ = ts.record(arm, rigid, ts.sum_of_sines(robot, rng), truth, 15.0, 250.0, rng, "i", growth_time=15.0)
    valid, _ = ts.record(arm, rigid, ts.sum_of_sines(robot, rng), truth, 7.5, 250.0, rng, "v", growth_time=15.0)
    rep = diagnose(model, [ident], DiagnoseSettings(), validation=[valid], rng=np.random.default_rng(13))
    first = rep.effects[0]
    assert first.kind == "link_length" and first.label == "link_length3r"
    v, s = float(np.ravel(first.values)[0]), float(np.ravel(first.std)[0])
    assert abs(v - 0.005) <= 3 * s and s < 0.005 / 3, (v, s)
    assert str(getattr(first.verdict, "value", first.verdict)) == "cause"
