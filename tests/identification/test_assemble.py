"""Observation-system assembly on simulated recordings with known truth."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.errors import DataFileError, ModelError
from symoro_gen.identification.assemble import assemble_observation, build_observation, iter_observation_chunks
from symoro_gen.preprocessing import decimate
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import (
    fourier_trajectory,
    numeric_model,
    ptp_trajectory,
    random_payload,
    random_physical_parameters,
    simulate_recording,
)

FS = 500.0


def _per_joint_rel_err(S, chi):
    r = S.Y - S.W @ chi
    return np.array([np.linalg.norm(r[S.joint == j]) / np.linalg.norm(S.Y[S.joint == j]) for j in range(S.n_joints)])


@pytest.fixture(scope="module")
def rx90_case():
    robot = load_robot("rx90")
    rng = np.random.default_rng(7)
    chi = random_physical_parameters(robot, rng)
    pl = random_payload(rng, robot=robot, mass_range=(3.0, 6.0))
    m1 = fourier_trajectory(6, 4.0, 1 / FS, rng, n_harmonics=3, amplitude=1.0, vmax=2.0, amax=8.0)
    P = rng.uniform(-1.2, 1.2, (4, 6))
    m2 = ptp_trajectory(P, 1.5, 6.0, 60.0, 1 / FS)
    unloaded = simulate_recording(robot, *m1, chi, source="unloaded")
    loaded = simulate_recording(robot, *m2, chi, chi_payload=pl, source="loaded")
    return robot, np.asarray(chi), np.asarray(pl), unloaded, loaded


def test_noiseless_assembly_satisfies_y_equals_w_chi(rx90_case):
    """Numeric (independent) regressor adapter, base = standard columns: Y == W chi to filtering accuracy."""
    robot, chi, pl, unloaded, loaded = rx90_case
    model = numeric_model(robot)
    # + PTP motion with the payload. Its acceleration has corners (jerk steps) that the central
    # differences at 500 Hz resolve to ~1e-4; it rests at its via-points, where sign(filtered dq) is not
    # the sign(0) of the Coulomb friction, so the rows whose filter sees |dq| < 0.02 rad/s are removed.
    A = assemble_observation(model, [unloaded, loaded], payload_columns=True, min_velocity=0.02,
                             dynamics_bandwidth_hz=2.0)
    S = A.system
    assert S.names == robot.standard_names + robot.payload_names
    x = np.concatenate([chi, pl])
    err = _per_joint_rel_err(S, x)
    assert err.max() < 5e-4, err
    # rows grouped per joint; payload columns zero on the unloaded experiment's rows
    assert np.all(np.diff(S.joint) >= 0)
    pay = S.W[:, len(chi):]
    assert np.all(pay[A.row_experiment == 0] == 0) and np.abs(pay[A.row_experiment == 1]).max() > 0
    # the per-experiment settings follow the rules and are reported
    for e in A.experiments:
        s = e.settings
        assert s.cutoff_hz == pytest.approx(10 * s.dynamics_bandwidth_hz)
        assert 0.8 * FS / (2 * s.n_d) >= 5 * s.dynamics_bandwidth_hz
        assert sum(e.rows_per_joint) == np.sum(A.row_experiment == e.index)
    assert "parallel decimation" in A.summary() and "loaded" in A.summary()


def test_generated_model_same_identity(rx90_case):
    """The emitted rx90 model (base columns) on the same data; what min_velocity and filtering are for."""
    robot, chi, pl, unloaded, loaded = rx90_case
    gen = symoro_gen.load_model("rx90")
    xb = np.concatenate([gen.base_parameters(chi), pl])
    # smooth Fourier motion, default rules
    assert _per_joint_rel_err(build_observation(gen, unloaded), xb[:-10]).max() < 1e-5
    with_rests = build_observation(gen, [unloaded, loaded], payload_columns=True, dynamics_bandwidth_hz=2.0)
    without = build_observation(gen, [unloaded, loaded], payload_columns=True, dynamics_bandwidth_hz=2.0,
                                min_velocity=0.02)
    assert _per_joint_rel_err(without, xb).max() < 5e-4
    assert _per_joint_rel_err(with_rests, xb).max() > 10 * _per_joint_rel_err(without, xb).max()
    # without filtering (true derivatives recorded), the identity is exact
    ex = [simulate_recording(robot, unloaded.t, unloaded.q, *_derivs(unloaded, robot), chi, keep_derivatives=True)]
    S2 = build_observation(gen, ex, use_recorded_derivatives=True, n_d=5, cutoff_hz=20.0)
    assert _per_joint_rel_err(S2, xb[:-10]).max() < 1e-12


def _derivs(tr, robot):
    # exact derivatives of the Fourier motion are not stored in the recording; rebuild them
    rng = np.random.default_rng(7)
    random_physical_parameters(robot, rng)
    random_payload(rng, robot=robot, mass_range=(3.0, 6.0))
    m1 = fourier_trajectory(6, 4.0, 1 / FS, rng, n_harmonics=3, amplitude=1.0, vmax=2.0, amax=8.0)
    np.testing.assert_array_equal(m1.q, tr.q)
    return m1.dq, m1.ddq


def test_rows_are_the_decimated_samples(rx90_case):
    """One column of W and Y are exactly the decimation of their full-rate samples (edges dropped)."""
    robot, chi, pl, unloaded, _ = rx90_case
    S = build_observation(symoro_gen.load_model("rx90"), [unloaded], n_d=4, cutoff_hz=15.0, edge_samples=25)
    j = 2
    Yj = S.Y[S.joint == j]
    np.testing.assert_allclose(Yj, decimate(unloaded.tau[25:-25, j], 4), atol=1e-12)
    assert Yj.shape[0] == -(-(unloaded.n_samples - 50) // 4)


def test_generated_model_and_streaming_agree():
    """The emitted lwr4 model: base columns, noisy data; streaming chunks == whole assembly."""
    robot = load_robot("lwr4")
    model = symoro_gen.load_model("lwr4")
    rng = np.random.default_rng(3)
    chi = random_physical_parameters(robot, rng)
    pl = random_payload(rng, robot=robot)
    recs = []
    for k, payload in enumerate((None, pl)):
        t, q, dq, ddq = fourier_trajectory(7, 6.0, 1e-3, rng, n_harmonics=4, amplitude=1.0, vmax=1.5, amax=6.0)
        recs.append(simulate_recording(robot, t, q, dq, ddq, chi, chi_payload=payload, noise_q=1e-6,
                                       noise_tau=0.05, rng=rng, source=f"exp{k}"))
    A = assemble_observation(model, recs, payload_columns=True, min_velocity=0.02)
    S = A.system
    assert S.names == tuple(model.BASE_NAMES) + tuple(model.PAYLOAD_NAMES)
    x = np.concatenate([model.base_parameters(np.asarray(chi)), np.asarray(pl)])
    # noise of 0.05 N m on tau, decimated: residual small compared to the torques
    assert _per_joint_rel_err(S, x).max() < 0.05
    reports = []
    chunks = list(iter_observation_chunks(model, recs, payload_columns=True, min_velocity=0.02, chunk_samples=1500,
                                          on_experiment=reports.append))
    assert len(chunks) > 4 and all(np.all(np.diff(c.joint) >= 0) for c in chunks)
    W = np.concatenate([c.W[c.joint == j] for j in range(7) for c in chunks])
    Y = np.concatenate([c.Y[c.joint == j] for j in range(7) for c in chunks])
    np.testing.assert_allclose(W, S.W, rtol=0, atol=1e-9 * np.abs(S.W).max())
    np.testing.assert_allclose(Y, S.Y, rtol=0, atol=1e-12)
    assert [r.rows_per_joint for r in reports] == [e.rows_per_joint for e in A.experiments]
    assert [r.removed_low_velocity for r in reports] == [e.removed_low_velocity for e in A.experiments]
    assert sum(sum(e.removed_low_velocity) for e in A.experiments) > 0


def test_min_velocity_removes_only_slow_rows():
    robot = load_robot("scara")
    model = symoro_gen.load_model("scara")
    rng = np.random.default_rng(5)
    chi = random_physical_parameters(robot, rng)
    P = np.array([[0, 0, 0, 0], [1.0, -1.0, 0.1, 2.0], [1.0, -1.0, 0.1, 2.0], [-0.5, 0.5, 0.0, -1.0]])
    m = ptp_trajectory(P, 1.0, 4.0, 40.0, 1 / FS, dwell=0.5)
    rec = simulate_recording(robot, *m, chi)
    vmin = np.array([0.05, 0.05, 0.005, 0.05])  # joint 3 (prismatic) moves 0.1 m only
    # (cut-off above the decimation low-pass, 40 Hz, so that the corners of the acceleration survive)
    full = assemble_observation(model, rec, n_d=5, cutoff_hz=50.0)
    cut = assemble_observation(model, rec, n_d=5, cutoff_hz=50.0, min_velocity=vmin)
    removed = np.array(cut.experiments[0].removed_low_velocity)
    kept = np.array(cut.experiments[0].rows_per_joint)
    assert np.all(removed > 0)  # the dwells at rest are removed
    np.testing.assert_array_equal(kept + removed, full.experiments[0].rows_per_joint)
    # the kept rows are a subset of the full rows; no slow sample near a kept row's centre (where the
    # decimation filter's weights exceed the 1 % tolerance), but slow samples in the far tails are tolerated
    core = 5 // 2
    tails_seen = False
    for j in range(4):
        tf = full.row_time[full.system.joint == j]
        tc = cut.row_time[cut.system.joint == j]
        assert tc.size > 50 and set(np.round(tc, 9)) <= set(np.round(tf, 9))
        for tk in tc:
            i = int(round(tk * FS))
            assert np.abs(m.dq[i - core:i + core + 1, j]).min() > 0.8 * vmin[j]
            tails_seen |= bool(np.abs(m.dq[max(0, i - 50):i + 51, j]).min() < 0.5 * vmin[j])
    assert tails_seen
    # rests and reversals removed: Y == W chi up to the differentiation accuracy of a jerk-limited profile
    xb = model.base_parameters(np.asarray(chi))
    assert _per_joint_rel_err(cut.system, xb).max() < 5e-4
    assert _per_joint_rel_err(full.system, xb).max() > 1e-2


def test_iir_option_matches_fir_consistency(rx90_case):
    robot, chi, pl, unloaded, _ = rx90_case
    gen = symoro_gen.load_model("rx90")
    S = build_observation(gen, unloaded, ftype="iir", n_d=8, cutoff_hz=20.0)
    assert _per_joint_rel_err(S, gen.base_parameters(chi)).max() < 1e-5


def test_errors():
    model = symoro_gen.load_model("scara")
    t = np.arange(60) / FS
    short = Trajectory(t=t, q=np.zeros((60, 4)), tau=np.zeros((60, 4)), source="short.csv")
    with pytest.raises(DataFileError, match=r"short\.csv.*too short to filter and decimate: 60 samples"):
        build_observation(model, short, cutoff_hz=10.0, n_d=4)
    with pytest.raises(ModelError, match="no payload frame"):
        build_observation(model, short, payload_columns=True, cutoff_hz=10.0, n_d=1)
    with pytest.raises(DataFileError, match="no recorded velocities"):
        build_observation(model, short, use_recorded_derivatives=True, cutoff_hz=10.0, n_d=1, edge_samples=0)
    loaded = Trajectory(t=np.arange(2000) / FS, q=np.zeros((2000, 4)), tau=np.zeros((2000, 4)), loaded=True,
                        source="L")
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        build_observation(model, loaded, cutoff_hz=10.0, n_d=10)
    assert any("payload is mounted but payload_columns=False" in str(w.message) for w in rec)


def test_experiments_never_mix(rx90_case):
    """Two files = two experiments: their rows are exactly those of each file assembled alone."""
    robot, chi, pl, unloaded, loaded = rx90_case
    gen = symoro_gen.load_model("rx90")
    kw = dict(payload_columns=True, cutoff_hz=20.0, n_d=10)
    both = assemble_observation(gen, [unloaded, loaded], **kw)
    alone = [build_observation(gen, tr, **kw) for tr in (unloaded, loaded)]
    for j in range(6):
        rows = both.system.joint == j
        expect = np.concatenate([a.W[a.joint == j] for a in alone])
        np.testing.assert_array_equal(both.system.W[rows], expect)
        np.testing.assert_array_equal(both.row_experiment[rows],
                                      np.repeat([0, 1], [np.sum(a.joint == j) for a in alone]))
