"""Floating-base robots (``base = "floating"``) against an independent oracle: Pinocchio's RNEA with a
free-flyer root (:mod:`tests.floating.pinocchio_floating`), all ``6 + n`` rows, on random states with random
unit quaternions; for a 12-joint quadruped-like tree and a 22-joint humanoid-like tree (with a fixed sole
frame and a payload frame).

Base parameters (closed form, [GK1990] on a free base): their number equals the numeric rank of the standard
regressor stacked over fresh states, and the count of the rules: nothing vanishes on a free base, so the base
link keeps its 10 parameters and every revolute joint regroups exactly three of its link's (YY, MZ, M) and
keeps its 4 drive terms. The relations equal those found numerically (Gram-Schmidt on sampled columns) and
hold for other values of the geometry.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings

import symoro_gen
from symoro_gen.baseparams.regroup import numeric_rank
from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.dynamics.floating import BASE_ROW_NAMES
from symoro_gen.runtime.floating import FloatingModel, numeric_base
from tests.oracles.pinocchio_model import max_relative_error, random_inertial
from tests.strategies import mdh_trees

from .pinocchio_floating import pin_floating_torque, random_floating_parameters, random_floating_states

HERE = Path(__file__).parent
RTOL = 1e-9


@pytest.fixture(scope="module")
def quadruped():
    robot = load_robot(HERE / "quadruped.toml")
    t0 = time.perf_counter()
    model = FloatingModel(robot)
    print(f"\nquadruped ({robot.n_joints} joints): model built in {time.perf_counter() - t0:.2f} s")
    return robot, model


def _check_against_pinocchio(robot, model, seed: int, with_payload: bool) -> None:
    rng = np.random.default_rng(seed)
    q, dq, ddq = random_floating_states(robot, 25, rng)
    chi = random_floating_parameters(robot, rng)
    pay = random_inertial(rng) if with_payload else None
    ref = pin_floating_torque(robot, q, dq, ddq, chi, pay)
    n = robot.n_joints
    W = model.standard_regressor(q, dq, ddq)
    assert W.shape == (25, 6 + n, len(robot.standard_names))
    y_std = W @ chi + (model.payload_regressor(q, dq, ddq) @ pay if with_payload else 0.0)
    y = model.torque(q, dq, ddq, chi, pay)
    assert y.shape == (25, 6 + n)
    for got in (y_std, y):
        err = max_relative_error(got, ref)
        print(f"{robot.name}: max relative error vs Pinocchio RNEA (free-flyer) {err:.2e}")
        assert err < RTOL
    # the base-wrench rows alone (force, then moment about the base origin, base axes) are not trivially small
    assert np.abs(ref[:, :6]).max() > 1.0
    assert max_relative_error(y[:, :6], ref[:, :6]) < RTOL
    # one sample as 1-D inputs gives one (6 + n,) row vector
    assert np.allclose(model.torque(q[0], dq[0], ddq[0], chi, pay), y[0], rtol=0, atol=1e-9 * np.abs(y).max())


def _check_base_parameters(robot, model, seed: int) -> None:
    rng = np.random.default_rng(seed)
    q, dq, ddq = random_floating_states(robot, 40, rng)
    W = model.standard_regressor(q, dq, ddq).reshape(-1, len(robot.standard_names))
    rank = numeric_rank(W)
    n_rev = sum(1 for r in robot.joints if r.sigma == 0)
    n_drive = sum(len(r.drive) for r in robot.joints)
    rules = 10 + 7 * n_rev + n_drive
    print(f"{robot.name}: {len(robot.standard_names)} standard parameters, numeric rank {rank}, "
          f"{len(model.BASE_NAMES)} base parameters, closed-form rule count {rules}")
    assert len(model.BASE_NAMES) == rank == rules
    assert rank < len(robot.standard_names)
    Wb = model.regressor(q, dq, ddq).reshape(-1, rank)
    assert numeric_rank(Wb) == rank  # the base regressor has full column rank on fresh states
    chi = random_floating_parameters(robot, rng)
    assert max_relative_error(Wb @ model.base_parameters(chi), W @ chi) < RTOL
    # the relations of [GK1990] on a free base: M0R is the total mass (every link's M regroups down to the
    # base link, which keeps it: coefficient 1), XXjR = XXj - YYj for every revolute joint j
    std, base = list(robot.standard_names), list(model.BASE_NAMES)
    unit = np.eye(len(std))
    for r in robot.joints:
        assert abs(model.base_parameters(unit[std.index(f"M{r.j}")])[base.index("M0R")] - 1.0) < 1e-9
        yy = model.base_parameters(unit[std.index(f"YY{r.j}")])
        assert abs(yy[base.index(f"XX{r.j}R")] + 1.0) < 1e-9
    # the closed-form relations are the numeric ones (independent columns in standard order, Gram-Schmidt)
    kept, K = numeric_base(W)
    assert tuple(std[c] for c in kept) == model.base_map.kept
    assert np.allclose(K, model.base_map.matrix(), rtol=0, atol=1e-8)


def test_quadruped_matches_pinocchio_free_flyer(quadruped):
    robot, model = quadruped
    assert model.FLOATING and model.N_ROWS == 18 and model.N_JOINTS == 12
    assert robot.standard_names[:10] == ("XX0", "XY0", "XZ0", "YY0", "YZ0", "ZZ0", "MX0", "MY0", "MZ0", "M0")
    _check_against_pinocchio(robot, model, seed=1, with_payload=False)


def test_quadruped_base_parameters_count_is_the_numeric_rank(quadruped):
    _check_base_parameters(*quadruped, seed=2)


def test_quadruped_relations_hold_for_other_geometry(quadruped):
    """The relations keep the lengths symbolic: with every length of the quadruped changed (a new robot
    file), the relations of the original model evaluated at the new lengths regroup the new model's columns."""
    robot, model = quadruped
    text = (HERE / "quadruped.toml").read_text()
    for k, v in robot.values.items():
        text = text.replace(f"{k} = {v}\n", f"{k} = {round(1.37 * v + 0.011, 4)}\n")
    other = parse_robot_text(text, "other.toml")
    assert all(other.values[k] != v for k, v in robot.values.items())
    rng = np.random.default_rng(8)
    q, dq, ddq = random_floating_states(other, 20, rng)
    W = FloatingModel(other).standard_regressor(q, dq, ddq).reshape(-1, len(other.standard_names))
    K = model.base_map.matrix(other.geometry_subs())
    chi = random_floating_parameters(other, rng)
    kept = [other.standard_names.index(k) for k in model.base_map.kept]
    assert max_relative_error(W[:, kept] @ (K @ chi), W @ chi) < RTOL
    assert max_relative_error(W[:, kept] @ (model.base_map.matrix() @ chi), W @ chi) > 1e-6  # lengths matter


def test_quadruped_at_rest_the_base_carries_the_weight(quadruped):
    """At rest (no velocity, no acceleration) the base force is the total weight, rotated into base axes
    by the quaternion (checked here with a rotation about z by 90 degrees then one about x), and the joint
    rows do not depend on the base's position."""
    robot, model = quadruped
    rng = np.random.default_rng(3)
    chi = random_floating_parameters(robot, rng)
    mass = sum(chi[robot.standard_names.index(f"M{j}")] for j in [0] + [r.j for r in robot.joints])
    n = robot.n_joints
    # base axes -> world: 90 degrees about world x (quaternion x y z w = sin 45, 0, 0, cos 45)
    s = np.sqrt(0.5)
    q = np.concatenate([[1.0, -2.0, 3.0, s, 0.0, 0.0, s], rng.uniform(-1, 1, n)])
    y = model.torque(q, np.zeros(6 + n), np.zeros(6 + n), chi)
    # gravity (0, 0, -9.81) in world axes is (0, -9.81, 0) in base axes (R^T g with R = Rot(x, 90 deg)):
    # the base must push up (+9.81 along base y) with the whole weight
    assert np.allclose(y[:3], [0.0, 9.81 * mass, 0.0], atol=1e-9 * 9.81 * mass)
    q2 = q.copy()
    q2[:3] = [-5.0, 0.5, 0.0]
    assert np.allclose(model.torque(q2, np.zeros(6 + n), np.zeros(6 + n), chi), y, rtol=0, atol=1e-12)


def test_floating_inputs_are_checked(quadruped):
    robot, model = quadruped
    n = robot.n_joints
    q, dq, ddq = random_floating_states(robot, 3, np.random.default_rng(4))
    with pytest.raises(ValueError, match=rf"quadruped_test: q must have shape \(N, {7 + n}\)"):
        model.standard_regressor(q[:, 1:], dq, ddq)
    with pytest.raises(ValueError, match=rf"quadruped_test: dq must have shape \(N, {6 + n}\)"):
        model.standard_regressor(q, dq[:, :n], ddq)
    bad = q.copy()
    bad[1, 3:7] *= 1.1
    with pytest.raises(ValueError, match=r"unit quaternion.*sample 1"):
        model.torque(bad, dq, ddq, np.ones(len(robot.standard_names)))
    assert tuple(BASE_ROW_NAMES) == ("FX0", "FY0", "FZ0", "MX0", "MY0", "MZ0")


def test_casadi_regressor_equals_the_numpy_kernels(quadruped):
    pytest.importorskip("casadi")
    robot, model = quadruped
    f = model.casadi_regressor()
    q, dq, ddq = random_floating_states(robot, 3, np.random.default_rng(7))
    Y = model.regressor(q, dq, ddq)
    for k in range(3):
        Yc = np.asarray(f(q[k], dq[k], ddq[k]))
        assert Yc.shape == (6 + robot.n_joints, len(model.BASE_NAMES))
        assert np.allclose(Yc, Y[k], rtol=0, atol=1e-10 * np.abs(Y[k]).max())


def test_load_model_of_a_floating_robot_file():
    model = symoro_gen.load_model(HERE / "quadruped.toml")
    assert model.FLOATING is True
    assert model.STANDARD_NAMES[0] == "XX0" and model.N_JOINTS == 12


@pytest.mark.slow
def test_humanoid_matches_pinocchio_and_generates_in_time():
    """The 22-joint humanoid-like tree: generation (symbolic model, kernels, numeric base parameters) well
    within 60 s; Pinocchio's free-flyer RNEA with a payload on the right hand; base-parameter count."""
    robot = load_robot(HERE / "humanoid.toml")
    assert robot.n_joints >= 20
    t0 = time.perf_counter()
    model = FloatingModel(robot)
    elapsed = time.perf_counter() - t0
    print(f"\nhumanoid ({robot.n_joints} joints): model built in {elapsed:.2f} s")
    assert elapsed < 60.0
    _check_against_pinocchio(robot, model, seed=5, with_payload=True)
    _check_base_parameters(robot, model, seed=6)


@pytest.mark.slow
@settings(max_examples=12, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(text=mdh_trees(2, 8, random_gravity=True))
def test_random_floating_trees_match_pinocchio(text):
    """Random trees (revolute and prismatic joints, -q joints, branches anywhere, fixed payload frames, drive
    subsets, any gravity) on a floating base: all 6 + n rows equal Pinocchio's free-flyer RNEA; the base
    regressor reproduces them through the closed-form relations; base count == numeric rank."""
    robot = parse_robot_text('base = "floating"\n' + text, "random_floating_tree.toml")
    model = FloatingModel(robot)
    rng = np.random.default_rng(0)
    q, dq, ddq = random_floating_states(robot, 12, rng)
    chi = random_floating_parameters(robot, rng)
    pay = random_inertial(rng) if robot.payload is not None else None
    ref = pin_floating_torque(robot, q, dq, ddq, chi, pay)
    assert max_relative_error(model.torque(q, dq, ddq, chi, pay), ref) < RTOL
    Ws = model.standard_regressor(q, dq, ddq).reshape(-1, len(robot.standard_names))
    assert numeric_rank(Ws) == len(model.BASE_NAMES)
