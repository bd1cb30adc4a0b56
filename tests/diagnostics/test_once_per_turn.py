"""A torque once per turn of one joint (``position_ripple`` of order 1, ``sin q_j, cos q_j``).

Order 1 is offered when the joint's samples tell ``sin q_j, cos q_j`` apart from a constant (condition
index of ``[1, sin q_j, cos q_j]`` at most 30, Belsley, Kuh & Welsch 1980), not by the half-period rule of the
higher orders: on the LWR4 recording joint 7 moves +-73 deg, less than half a turn, and carries such a
torque (docs/results.md, "The LWR4 wrist convention").
"""
from __future__ import annotations

import numpy as np
import pytest

from symoro_gen.diagnostics import diagnose
from symoro_gen.diagnostics.candidates import ONCE_PER_TURN_CONDITION, make_families
from symoro_gen.diagnostics.frame import build_frame, common_bandwidth
from symoro_gen.diagnostics.plausibility import ArmScales, effect_plausibility, fits_like
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques

from .simdata import NOISE_Q, NOISE_TAU, robot_and_model

#: the LWR4 joint-7 term of docs/results.md: 0.43 N m sin(q7 + 46 deg)
AMPLITUDE, PHASE = 0.43, np.deg2rad(46.0)


def _lwr4(seed: int, j7_deg: float, amplitude: float, duration: float = 40.0):
    """(model, Trajectory, true q) of the LWR4 along a random excitation, joint 7 within +-``j7_deg``, with
    ``amplitude sin(q7 + 46 deg)`` added to joint 7's torque."""
    robot, model = robot_and_model("lwr4")
    rng = np.random.default_rng(seed)
    amp = np.ones(7)
    amp[6] = np.deg2rad(j7_deg)
    t, q, dq, ddq = fourier_trajectory(7, duration, 0.002, rng, base_frequency_hz=0.1, amplitude=amp)
    chi = np.asarray(random_physical_parameters(robot, rng, fs_range=(0.1, 0.5), fv_range=(0.1, 1.0)))
    tau = true_torques(model, q, dq, ddq, chi)
    tau[:, 6] += amplitude * np.sin(q[:, 6] + PHASE)
    tr = Trajectory(t=t, q=q + NOISE_Q * rng.standard_normal(q.shape),
                    tau=tau + NOISE_TAU * rng.standard_normal(q.shape), source=f"lwr4 seed {seed}")
    return model, tr, q


def _ripple_orders(model, tr, j: int) -> tuple[float, ...]:
    F = build_frame(model, [tr], dynamics_bandwidth_hz=common_bandwidth([tr]))
    fams = [f for f in make_families(F, ("position_ripple",)) if f.joint == j]
    return tuple(fams[0].grid) if fams else ()


@pytest.mark.parametrize("j7_deg, offered", [(73.0, True), (10.0, False)])
def test_order_one_offered_where_the_samples_tell_it_from_a_constant(j7_deg, offered):
    model, tr, q = _lwr4(3, j7_deg, 0.0, duration=20.0)
    span = np.ptp(q[:, 6])
    assert span < np.pi                          # less than half a turn: the k * span >= pi rule excludes k = 1
    orders = _ripple_orders(model, tr, 6)
    assert (1.0 in orders) is offered, orders
    # independent reference: the documented rule evaluated with numpy on the simulated (noise-free) angles
    x = q[:, 6]
    A = np.stack([np.ones_like(x), np.sin(x), np.cos(x)], 1)
    assert bool(np.linalg.cond(A / np.linalg.norm(A, axis=0)) <= ONCE_PER_TURN_CONDITION) is offered
    # the higher orders keep their half-period rule
    assert all(k * span >= np.pi for k in orders if k != 1.0)


@pytest.mark.slow
def test_once_per_turn_torque_is_named_on_its_joint_as_a_function_of_its_angle():
    """0.43 N m sin(q7 + 46 deg) on joint 7 moving +-73 deg: the first effect of the loop on joint 7 is a
    function of q7 alone - order 1 or the spring, not a ripple of order 2 or more - and order 1 explains as
    much of the held-out residual as the best candidate; joint 7's validation error falls to the noise."""
    model, tr, _ = _lwr4(5, 73.0, AMPLITUDE)
    rep = diagnose(model, tr)
    loop = [e for e in rep.effects if e.kind != "friction_law" and e.joint == 6]
    assert loop, [e.label for e in rep.effects]
    first = loop[0]
    assert first.kind in ("position_ripple", "spring"), first.label
    if first.kind == "position_ripple":
        assert float(first.physical["k"]) == 1.0
        assert float(first.physical["amplitude"]) == pytest.approx(AMPLITUDE, rel=0.1)
    assert not [e for e in rep.effects if e.kind == "position_ripple" and e.joint == 6
                and float(e.physical["k"]) != 1.0], [e.label for e in rep.effects]
    best = max(c.score for c in rep.tried if c.round == first.round and c.joint == 6 and c.score is not None)
    ripple = [c for c in rep.tried if c.round == first.round and c.label == "position_ripple7"]
    assert ripple and ripple[0].score > 0.999 * best, (ripple, best)
    assert rep.after_validation_rel_err[6] < 0.2 * rep.before_validation_rel_err[6]


def test_once_per_turn_prior_has_no_gear_ratio_factor_and_names_its_causes():
    """Order 1 is once per turn of the joint's output, not a tooth order of its gear: a known gear ratio of
    100 lowers an order-7 ripple (neither multiple nor divisor) but not order 1; both keep the amplitude
    prior against the joint's torque range, and the description of order 1 names its possible causes."""
    scales = ArmScales(dt=0.001, tau98=np.full(7, 2.0), v98=np.ones(7), dq_noise=np.full(7, 1e-4), n_joints=7,
                       gear_ratios={6: 100.0})
    small = {"amplitude": 0.43}
    one = effect_plausibility("position_ripple", 6, {}, {**small, "k": 1.0}, scales)
    seven = effect_plausibility("position_ripple", 6, {}, {**small, "k": 7.0}, scales)
    assert one.score == pytest.approx(1.0) and seven.score < 0.99, (one, seven)
    large = effect_plausibility("position_ripple", 6, {}, {"amplitude": 2.0, "k": 1.0}, scales)
    assert large.score < 0.5, large                          # a once-per-turn torque as large as the joint's range
    text = fits_like("position_ripple", 6, {"k": 1.0, "amplitude": 0.43}, "position_ripple7")
    assert "once per turn" in text and "joint 7" in text and "cable" in text, text
