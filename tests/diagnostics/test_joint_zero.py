"""The loop's encoder zero offset (``joint_zero``) against independent references.

* its column, ``d tau / d q_j`` of the generated model at the fitted parameters, against a central
  difference of Pinocchio's RNEA (:mod:`tests.oracles.pinocchio_model`) at the perturbed angle, and its
  secant against the Pinocchio torque at the offset angle;
* which zeros torque data can see: the first LWR4 joint (vertical axis 1) changes no torque, and an offset
  of the last joint is exactly a rotation of its link's inertial parameters about its axis (checked with
  Pinocchio), hence absorbed by the base parameters; the joints in between are visible;
* the loop on the truth bench's independent simulator (``bench/truthsim.py``): an encoder offset of
  0.5-2 deg is named ``joint_zero`` on its joint with the offset within 3 sigma, the clean control names
  nothing.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics.candidates import KINDS, make_families
from symoro_gen.diagnostics.geometry import (
    joint_zero_column,
    joint_zero_secant,
    joint_zero_visibility,
    revolute_joints,
    visible_zero_joints,
)
from symoro_gen.diagnostics.plausibility import ArmScales, effect_plausibility

pin = pytest.importorskip("pinocchio")
from tests.oracles.pinocchio_model import pin_torque, random_parameters  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def _states(rng, N, n):
    return rng.uniform(-math.pi, math.pi, (N, n)), rng.standard_normal((N, n)), rng.standard_normal((N, n))


@pytest.mark.parametrize("name", ["lwr4", "rx90", "scara"])
def test_column_is_the_pinocchio_derivative(name):
    """``joint_zero_column`` (generated base regressor x base parameters, differentiated in q_j) equals the
    central difference of Pinocchio's torque in q_j, and the secant at c the Pinocchio torque change
    ``(tau(q + c e_j) - tau(q)) / c``, for random physically consistent parameters."""
    robot = load_robot(name)
    model = symoro_gen.load_model(name)
    rng = np.random.default_rng(11)
    chi, _ = random_parameters(robot, rng)
    theta = dict(zip(model.BASE_NAMES, model.base_parameters(chi)))
    n = robot.n_joints
    q, dq, ddq = _states(rng, 6, n)
    scale = np.abs(pin_torque(robot, q, dq, ddq, chi)).max()
    h, c = 1e-5, 0.03
    for j in range(n):
        e = np.zeros(n)
        e[j] = 1.0
        ref = (pin_torque(robot, q + h * e, dq, ddq, chi) - pin_torque(robot, q - h * e, dq, ddq, chi)) / (2 * h)
        ours = joint_zero_column(model, theta, q, dq, ddq, j)
        assert np.abs(ours - ref).max() <= 1e-6 * scale, f"{name} joint {j + 1}"
        sec = (pin_torque(robot, q + c * e, dq, ddq, chi) - pin_torque(robot, q, dq, ddq, chi)) / c
        assert np.abs(joint_zero_secant(model, theta, q, dq, ddq, j, c) - sec).max() <= 1e-8 * scale


def _rotate_link(robot, chi, j, a):
    """Standard parameters with link j's (1-based frame) inertial parameters rotated by ``a`` about its z axis
    (``J' = R J R^T``, ``MS' = R MS``)."""
    names = list(robot.standard_names)
    v = dict(zip(names, chi))
    J = np.array([[v[f"XX{j}"], v[f"XY{j}"], v[f"XZ{j}"]], [v[f"XY{j}"], v[f"YY{j}"], v[f"YZ{j}"]],
                  [v[f"XZ{j}"], v[f"YZ{j}"], v[f"ZZ{j}"]]])
    ms = np.array([v[f"MX{j}"], v[f"MY{j}"], v[f"MZ{j}"]])
    R = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    J2, ms2 = R @ J @ R.T, R @ ms
    for k, (r, s) in zip(("XX", "XY", "XZ", "YY", "YZ", "ZZ"), ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))):
        v[f"{k}{j}"] = J2[r, s]
    for k, x in zip(("MX", "MY", "MZ"), ms2):
        v[f"{k}{j}"] = x
    return np.array([v[nm] for nm in names])


def test_visibility_of_the_lwr4_zeros():
    """LWR4 (axis 1 vertical): Pinocchio's torque does not change with q1, and an offset of q7 is a rotation
    of link 7's inertial parameters (so the base parameters absorb it); the visibility measure says the same:
    joints 1 and 7 invisible, 2-6 visible, and the loop builds no candidate for them."""
    robot = load_robot("lwr4")
    model = symoro_gen.load_model("lwr4")
    rng = np.random.default_rng(4)
    chi, _ = random_parameters(robot, rng)
    q, dq, ddq = _states(rng, 6, 7)
    tau = pin_torque(robot, q, dq, ddq, chi)
    scale = np.abs(tau).max()
    e1, e7 = np.eye(7)[0], np.eye(7)[6]
    assert np.abs(pin_torque(robot, q + 0.3 * e1, dq, ddq, chi) - tau).max() <= 1e-10 * scale
    rotated = _rotate_link(robot, chi, robot.joints[6].j, 0.3)
    assert np.abs(pin_torque(robot, q + 0.3 * e7, dq, ddq, chi)
                  - pin_torque(robot, q, dq, ddq, rotated)).max() <= 1e-10 * scale
    # ... while an offset of joint 2 is no such rotation of link 2 (its children move with it)
    rotated2 = _rotate_link(robot, chi, robot.joints[1].j, 0.3)
    e2 = np.eye(7)[1]
    assert np.abs(pin_torque(robot, q + 0.3 * e2, dq, ddq, chi)
                  - pin_torque(robot, q, dq, ddq, rotated2)).max() > 1e-3 * scale
    share = joint_zero_visibility(model)
    assert share[0] <= 1e-6 and share[6] <= 1e-6
    assert np.all(share[1:6] > 1e-2)
    assert visible_zero_joints(model) == (1, 2, 3, 4, 5)
    assert revolute_joints(model).all()


def test_plausibility_of_an_offset():
    """The prior: 1.5 deg is plausible, 6 deg doubtful (below 0.5), the score falls with the offset."""
    sc = ArmScales(dt=0.002, tau98=np.ones(3), v98=np.ones(3), dq_noise=np.zeros(3), n_joints=3)
    s = [effect_plausibility("joint_zero", 1, {"q0": math.radians(d)}, {"offset_deg": d}, sc).score
         for d in (1.5, 4.0, 6.0, 12.0)]
    assert s[0] == 1.0 and 0.5 < s[1] < 1.0 and s[2] < 0.5 and s[3] < s[2]


# ---- the loop on the truth bench's simulator --------------------------------------------------------
sys.path.insert(0, str(ROOT / "bench"))
try:
    import bench_loop_truth as blt
    import truthsim as ts
finally:
    sys.path.remove(str(ROOT / "bench"))


def _diagnose_offset(j: int, deg: float, seed: int, seconds: float = 20.0, rate: float = 250.0):
    from symoro_gen.diagnostics import DiagnoseSettings, diagnose

    robot = load_robot("lwr4")
    model = symoro_gen.load_model("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    rigid = ts.Rigid(robot, chi)
    rng = np.random.default_rng(seed)
    truth = blt.lwr4_truth(robot, chi, 0.05)
    if deg:
        truth.q_offset[j] = math.radians(deg)
    ident, _ = ts.record(robot, rigid, ts.sum_of_sines(robot, rng), truth, seconds, rate, rng, "zero-ident")
    valid, _ = ts.record(robot, rigid, ts.sum_of_sines(robot, rng), truth, seconds / 2, rate, rng, "zero-valid")
    return diagnose(model, [ident], DiagnoseSettings(candidates=KINDS), validation=[valid],
                    rng=np.random.default_rng(seed))


@pytest.mark.slow
@pytest.mark.parametrize("j,deg", [(1, 1.5), (2, 1.0)])
def test_loop_names_the_offset(j, deg):
    """An encoder zero offset of joint j (truth simulator, gravity at the true angle) is the loop's first
    effect, ``joint_zero`` on joint j, a cause, with its offset within 3 sigma of the truth."""
    rep = _diagnose_offset(j, deg, seed=90 + j)
    assert rep.effects, "nothing named"
    e = rep.effects[0]
    assert (e.kind, e.joint) == ("joint_zero", j), [(x.kind, x.joint, x.label) for x in rep.effects]
    v, s = float(e.values[0]), float(e.std[0])
    assert abs(v - math.radians(deg)) <= 3 * s, (math.degrees(v), math.degrees(s), deg)
    assert e.verdict == "cause"
    assert e.physical["offset_deg"] == pytest.approx(math.degrees(v))


def test_families_only_for_visible_joints():
    """``make_families`` with the model builds joint_zero for the joints whose zero is visible (LWR4: 2-6), without
    it for every joint; the column of the family is the tangent of the fitted model on every joint's rows,
    decimated like ``W`` (compared with Pinocchio's central difference at full rate, decimated alike)."""
    from symoro_gen.diagnostics.candidates import FitContext
    from symoro_gen.diagnostics.frame import build_frame

    robot = load_robot("lwr4")
    model = symoro_gen.load_model("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    rng = np.random.default_rng(2)
    truth = blt.lwr4_truth(robot, chi, 0.05)
    tr, _ = ts.record(robot, ts.Rigid(robot, chi), ts.sum_of_sines(robot, rng), truth, 4.0, 250.0, rng, "frame")
    F = build_frame(model, [tr])
    with_model = [f for f in make_families(F, ("joint_zero",), model=model)]
    assert [f.joint for f in with_model] == [1, 2, 3, 4, 5]
    assert [f.joint for f in make_families(F, ("joint_zero",))] == list(range(7))
    theta = dict(zip(model.BASE_NAMES, model.base_parameters(chi)))
    ctx = FitContext(model=model, theta=theta)
    fam = with_model[0]
    X = fam.build(F, ctx)[0]
    e = np.eye(7)[1]
    h = 1e-5
    no_fs = chi.copy()
    no_fs[[i for i, nm in enumerate(robot.standard_names) if nm.startswith("FS")]] = 0.0

    def pin_derivative(ex):
        d = (pin_torque(robot, ex.q + h * e, ex.dq, ex.ddq, no_fs)
             - pin_torque(robot, ex.q - h * e, ex.dq, ex.ddq, no_fs)) / (2 * h)
        return {k: d[:, k:k + 1] for k in range(7)}

    # Pinocchio's derivative at full rate, decimated like W's rows
    ref = F.full_rate_columns(pin_derivative, 1)
    np.testing.assert_allclose(X, ref, atol=1e-6 * np.abs(ref).max())
    assert np.abs(ref).max() > 1.0


def test_fit_joint_zeros_with_the_dynamic_parameters():
    """Gauss-Newton on ``Y = W(q + q0) chi`` (truth simulator, offsets on LWR4 joints 2 and 3): converges, and
    each offset is within 3 sigma of the truth; without offsets, both are within 3 sigma of 0; an invisible
    joint (1) is refused naming it."""
    from symoro_gen.diagnostics.geometry import fit_joint_zeros

    robot = load_robot("lwr4")
    model = symoro_gen.load_model("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    rigid = ts.Rigid(robot, chi)
    for offsets in ({1: 1.5, 2: -0.7}, {}):
        rng = np.random.default_rng(21)
        truth = blt.lwr4_truth(robot, chi, 0.05)
        for j, d in offsets.items():
            truth.q_offset[j] = math.radians(d)
        tr, _ = ts.record(robot, rigid, ts.sum_of_sines(robot, rng), truth, 8.0, 250.0, rng, "gn")
        fit = fit_joint_zeros(model, [tr], joints=(1, 2))
        assert fit.converged
        for k, j in enumerate(fit.joints):
            want = math.radians(offsets.get(j, 0.0))
            assert abs(fit.offsets[k] - want) <= 3 * fit.std[k], (j, math.degrees(fit.offsets[k]), fit.std[k])
            assert fit.std[k] < math.radians(0.2)
    with pytest.raises(ValueError, match=r"joint\(s\) \[1\]"):
        fit_joint_zeros(model, [tr], joints=(0,))


def test_an_offset_of_tens_of_degrees_is_impossible():
    """Beyond 20 deg a revolute joint's zero offset is refused as a zero error (a wrong theta convention of the
    robot file), naming the joint; a few degrees are possible; a prismatic joint's length has no such bound."""
    from symoro_gen.diagnostics.candidates import MAX_ZERO_OFFSET_DEG, Family, implausible

    fam = Family("joint_zero", 1, ("q0",), lambda fr, ctx: [], info=(("revolute", True),))
    why = implausible(fam, [math.radians(MAX_ZERO_OFFSET_DEG + 5)], f_dyn=5.0)
    assert why is not None and "joint 2" in why and "theta" in why
    assert implausible(fam, [math.radians(-3.0)], f_dyn=5.0) is None
    lin = Family("joint_zero", 2, ("q0",), lambda fr, ctx: [], info=(("revolute", False),))
    assert implausible(lin, [1.0], f_dyn=5.0) is None
