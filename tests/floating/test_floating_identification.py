"""Floating-base identification (:mod:`symoro_gen.identification.floating`) on data simulated by an independent
oracle: Pinocchio's RNEA with a free-flyer root (:mod:`tests.floating.pinocchio_floating`) gives, at random
states of the quadruped-like tree, the base wrench and joint torques; the base wrench is split into two contact
wrenches at two knee frames (Pinocchio's ``LOCAL`` joint Jacobians), whose joint-row share is taken off the
torques. Noise is added to the contact wrenches, the torques and the IMU-like base acceleration.

Checked (Ayusawa, Venture & Nakamura 2014): the base rows alone identify every inertial combination the whole
model identifies and none of the drive terms; the joint rows alone do not see the base link's parameters; each
kind, and both with per-kind WLS, recover ``K @ chi_true`` within 3 sigma (and their Mahalanobis distance is
that of a chi-square), and exactly without noise.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from symoro_gen.description import load_robot
from symoro_gen.errors import IdentificationError
from symoro_gen.identification.floating import (
    ContactWrench,
    FloatingMeasurements,
    identify_floating,
    measured_rows,
    spatial_base_acceleration,
)
from symoro_gen.params import INERTIAL_KINDS
from symoro_gen.runtime.floating import FloatingModel

from .pinocchio_floating import (
    build_floating_pinocchio,
    pin_floating_torque,
    random_floating_parameters,
    random_floating_states,
)

HERE = Path(__file__).parent
DRIVE = ("IA", "FV", "FS", "OFF")
SIGMA_WRENCH = 0.3     # N and N m on each contact wrench component
SIGMA_TAU = 0.2        # N m on each joint torque
SIGMA_IMU = 1e-3       # on the base's 6 accelerations given to the identification


@pytest.fixture(scope="module")
def quadruped():
    robot = load_robot(HERE / "quadruped.toml")
    return robot, FloatingModel(robot)


def _contact_jacobians(robot, chi, q, joints):
    """Pinocchio ``LOCAL`` Jacobians ``(N, 6, 6 + n)`` of the frames of the joints named ``joints``."""
    model, data = build_floating_pinocchio(robot, chi)
    out = {name: [] for name in joints}
    for k in range(q.shape[0]):
        pin.computeJointJacobians(model, data, q[k])
        for name in joints:
            out[name].append(pin.getJointJacobian(model, data, model.getJointId(name), pin.ReferenceFrame.LOCAL))
    return {name: np.array(v) for name, v in out.items()}


def _simulate(robot, n_samples: int, seed: int, noisy: bool):
    rng = np.random.default_rng(seed)
    q, dq, ddq = random_floating_states(robot, n_samples, rng)
    chi = random_floating_parameters(robot, rng)
    rows = pin_floating_torque(robot, q, dq, ddq, chi)
    J = _contact_jacobians(robot, chi, q, ("joint3", "joint9"))
    fa = rng.normal(scale=20.0, size=(n_samples, 6))
    ja, jb = J["joint3"], J["joint9"]
    # the second contact carries the rest of the base wrench: J_b,base^T f_b = base - J_a,base^T f_a
    rest = rows[:, :6] - np.einsum("kri,kr->ki", ja[:, :, :6], fa)
    fb = np.linalg.solve(np.transpose(jb[:, :, :6], (0, 2, 1)), rest[:, :, None])[:, :, 0]
    tau = rows[:, 6:] - np.einsum("kri,kr->ki", ja[:, :, 6:], fa) - np.einsum("kri,kr->ki", jb[:, :, 6:], fb)
    if noisy:
        fa = fa + rng.normal(scale=SIGMA_WRENCH, size=fa.shape)
        fb = fb + rng.normal(scale=SIGMA_WRENCH, size=fb.shape)
        tau = tau + rng.normal(scale=SIGMA_TAU, size=tau.shape)
        ddq = ddq.copy()
        ddq[:, :6] += rng.normal(scale=SIGMA_IMU, size=(n_samples, 6))
    data = FloatingMeasurements(q, dq, ddq, tau=tau, contacts=(ContactWrench("foot_a", fa, ja),
                                                               ContactWrench("foot_b", fb, jb)))
    return data, chi


def _within_3_sigma(fit, chi) -> None:
    res = fit.result
    err = res.values - fit.combinations(chi)
    z = err / res.std
    d2 = float(err @ np.linalg.solve(res.cov, err))
    p = err.size
    print(f"{fit.kind}: {p} combinations, {np.mean(np.abs(z) < 3):.3f} within 3 sigma, max |z| {np.abs(z).max():.2f}, "
          f"Mahalanobis^2 / p {d2 / p:.2f}")
    assert np.mean(np.abs(z) < 3) >= 0.97      # 3-sigma coverage of a Gaussian: 0.9973
    assert np.abs(z).max() < 5
    assert abs(d2 / p - 1) < 4 * np.sqrt(2 / p)  # chi-square(p) / p: mean 1, std sqrt(2 / p)


def test_what_each_kind_identifies(quadruped):
    robot, model = quadruped
    data, chi = _simulate(robot, 40, seed=1, noisy=False)
    names = model.STANDARD_NAMES
    drive = {n for n in names if n.rstrip("0123456789") in DRIVE}
    base_link = {f"{k}0" for k in INERTIAL_KINDS}
    fits = {kind: identify_floating(model, data, kind, method="ols") for kind in ("base", "joints", "both")}
    # base rows: every identifiable inertial combination, no drive term (Ayusawa et al. 2014)
    assert set(fits["base"].not_identifiable) == drive
    assert len(fits["base"].result.names) == len(model.BASE_NAMES) - len(drive)
    # joint rows: the base link's parameters are absent
    assert base_link <= set(fits["joints"].not_identifiable)
    assert len(fits["joints"].result.names) < len(model.BASE_NAMES)
    # both kinds: the model's base parameters (closed form, counted independently)
    assert len(fits["both"].result.names) == len(model.BASE_NAMES)
    assert fits["both"].not_identifiable == ()
    for kind, fit in fits.items():  # noise-free: exact
        truth = fit.combinations(chi)
        err = np.abs(fit.result.values - truth).max() / np.abs(truth).max()
        print(f"{kind}: {len(fit.result.names)} combinations, max relative error {err:.1e}")
        assert err < 1e-7


@pytest.mark.slow
@pytest.mark.parametrize(("kind", "weighting"), [("base", "kind"), ("joints", "kind"), ("both", "kind"),
                                                ("both", "row")])
def test_recovered_within_3_sigma(quadruped, kind, weighting):
    robot, model = quadruped
    data, chi = _simulate(robot, 150, seed=7, noisy=True)
    fit = identify_floating(model, data, kind, method="wls", weighting=weighting)
    _within_3_sigma(fit, chi)
    if (kind, weighting) == ("both", "kind"):  # each kind weighted by its own sigma: that of its noise (the IMU's is neglected)
        assert fit.result.joint_sigma is not None
        J = np.concatenate([c.jacobian for c in data.contacts], axis=1)  # (N, 12, 6 + n)
        expected = np.sqrt(SIGMA_WRENCH ** 2 * np.mean(np.sum(J ** 2, axis=1), axis=0))  # per row position
        expected[6:] = np.sqrt(expected[6:] ** 2 + SIGMA_TAU ** 2)
        by_kind = [np.sqrt(np.mean(expected[:6] ** 2)), np.sqrt(np.mean(expected[6:] ** 2))]
        print(f"kind sigmas {fit.result.joint_sigma}, expected from the noise {by_kind}")
        assert fit.result.joint_sigma == pytest.approx(by_kind, rel=0.15)


def test_contact_transform_equals_jacobian_base_rows(quadruped):
    """A contact given by its pose in base axes (Pinocchio's placements, base^-1 * frame) carries its wrench
    to the base rows as its Jacobian's base columns do."""
    robot, model = quadruped
    data, chi = _simulate(robot, 6, seed=4, noisy=False)
    pmodel, pdata = build_floating_pinocchio(robot, chi)
    poses = {"foot_a": "joint3", "foot_b": "joint9"}
    contacts = []
    for c in data.contacts:
        T = []
        for k in range(data.q.shape[0]):
            pin.forwardKinematics(pmodel, pdata, data.q[k])
            T.append((pdata.oMi[1].inverse() * pdata.oMi[pmodel.getJointId(poses[c.frame])]).homogeneous)
        contacts.append(ContactWrench(c.frame, c.wrench, transform=np.array(T)))
    by_pose = measured_rows(model, FloatingMeasurements(data.q, data.dq, data.ddq, contacts=tuple(contacts)), False)
    by_jacobian = measured_rows(model, data, True)
    assert np.abs(by_pose[:, :6] - by_jacobian[:, :6]).max() < 1e-9 * np.abs(by_jacobian[:, :6]).max()
    with pytest.raises(IdentificationError, match=r"foot_a.*jacobian"):
        identify_floating(model, FloatingMeasurements(data.q, data.dq, data.ddq, tau=data.tau,
                                                      contacts=tuple(contacts)), "both")


def test_imu_acceleration_galilean(quadruped):
    """The model does not depend on the base's linear velocity once the acceleration is the spatial one of
    the same classical acceleration: an IMU's classical acceleration may be given with ``v = 0``."""
    robot, model = quadruped
    rng = np.random.default_rng(3)
    q, dq, ddq = random_floating_states(robot, 5, rng)
    classical = rng.normal(size=(5, 3))
    ddq_moving = ddq.copy()
    ddq_moving[:, :3] = spatial_base_acceleration(dq, classical)
    dq_still, ddq_still = dq.copy(), ddq.copy()
    dq_still[:, :3] = 0.0
    ddq_still[:, :3] = classical
    a = model.standard_regressor(q, dq, ddq_moving)
    b = model.standard_regressor(q, dq_still, ddq_still)
    assert np.abs(a - b).max() < 1e-9 * np.abs(a).max()


def test_errors_name_the_field(quadruped):
    robot, model = quadruped
    data, _ = _simulate(robot, 3, seed=2, noisy=False)
    with pytest.raises(IdentificationError, match="tau"):
        identify_floating(model, FloatingMeasurements(data.q, data.dq, data.ddq, contacts=data.contacts), "joints")
    bad = ContactWrench("foot_a", np.zeros((3, 5)), data.contacts[0].jacobian)
    with pytest.raises(IdentificationError, match=r"foot_a.*wrench"):
        identify_floating(model, FloatingMeasurements(data.q, data.dq, data.ddq, contacts=(bad,)), "base")
    with pytest.raises(IdentificationError, match="kind"):
        identify_floating(model, data, "legs")
