"""Drive gains per joint (RX-90 paper eq. 25-27) and torque-sensor gains by IDIM-TLS
(LWR4 paper eq. 8-16) on simulated data with known gains."""
import json

import numpy as np
import pytest

from symoro_gen.errors import IdentificationError
from symoro_gen.identification import ObservationSystem, drive_gains, fit_wls, identify_with_drive_gains, sensor_gains

from .simdata import joint_noise

RX90_GAINS = np.array([0.9238, 0.9533, 1.1032, 0.8737, 1.05, 0.97])     # Table 4 (+ two made up)
LWR4_GAINS = np.array([1.02, 1.01, 1.02, 1.02, 1.02, 1.05, 0.99])       # Table II


def measured(sim, gains, seed, rel=0.01, chi_payload=None):
    """Signals v = tau / g with per-joint noise rel * RMS on the torque."""
    rng = np.random.default_rng(seed)
    tb = sim.tau_b if chi_payload is None else sim.payload_torque(chi_payload)
    Ya = (sim.tau_a + joint_noise(rng, sim.tau_a, sim.joint_a, rel)) / gains[sim.joint_a]
    Yb = (tb + joint_noise(rng, tb, sim.joint_b, rel)) / gains[sim.joint_b]
    return sim.unloaded(Ya), sim.loaded(Yb)


# ---------------------------------------------------------------- drive gains (RX-90)
@pytest.mark.parametrize("seed", range(3))
def test_rx90_drive_gains_of_joints_1_to_4_within_half_percent(rx90_sim, seed):
    sim = rx90_sim
    un, lo = measured(sim, RX90_GAINS, seed)
    dg = drive_gains(un, lo, dict(zip(sim.payload_names, sim.chi_payload)), joints=[0, 1, 2, 3])
    assert dg.gains.joints == (0, 1, 2, 3) and dg.gains.names == ("g1", "g2", "g3", "g4")
    err = np.abs(dg.gains.values - RX90_GAINS[:4]) / RX90_GAINS[:4]
    assert np.all(err < 0.005), err
    assert np.all(np.abs(dg.gains.values - RX90_GAINS[:4]) < 4 * dg.gains.std)
    np.testing.assert_allclose(dg.gains.rel_std_pct, 100 * dg.gains.std / dg.gains.values, rtol=1e-9)
    # the per-joint LS uses only the columns of joint j's equations: joint 4 knows nothing of links 1-3
    names4 = dg.per_joint[3].names                       # e.g. ("XX4/g4", ..., "OFF6/g4", "1/g4")
    assert names4[-1] == "1/g4"
    assert all(int(n.split("/")[0][-1]) >= 4 for n in names4[:-1])
    assert any(n.startswith("MX6") for n in names4)
    json.dumps(dg.to_dict(), allow_nan=False)
    assert "joint 4" in dg.summary()


def test_drive_gain_is_the_inverse_of_the_last_coefficient_of_eq27(rx90_sim):
    """Independent check for one joint: eq. 27 solved by hand with numpy (OLS, then the
    unloaded/loaded equations weighted by their own sigma)."""
    sim = rx90_sim
    un, lo = measured(sim, RX90_GAINS, 7)
    chi_l = sim.chi_payload
    j = 1
    ra, rb = sim.joint_a == j, sim.joint_b == j
    Wr = np.vstack([sim.Wa[ra], sim.Wb[rb]])
    keep = np.linalg.norm(Wr, axis=0) > 1e-12 * np.linalg.norm(Wr, axis=0).max()
    gcol = np.r_[np.zeros(ra.sum()), sim.WL[rb] @ chi_l]
    A = np.column_stack([Wr[:, keep], gcol])
    V = np.r_[un.Y[ra], lo.Y[rb]]
    grp = np.r_[np.zeros(ra.sum(), int), np.ones(rb.sum(), int)]
    dg = drive_gains(un, lo, dict(zip(sim.payload_names, chi_l)), joints=[j])
    # (A may have columns dependent within joint j's equations: drive_gains leaves them out, the
    # minimum-norm WLS here keeps them; the coefficient of the independent 1/g column is the same)
    ref = fit_wls(ObservationSystem(A, V, tuple(f"c{i}" for i in range(A.shape[1])), grp))
    np.testing.assert_allclose(dg.gains.values[0], 1 / ref.values[-1], rtol=1e-8)
    x_ols = np.linalg.lstsq(A, V, rcond=None)[0]
    assert abs(1 / x_ols[-1] - RX90_GAINS[j]) / RX90_GAINS[j] < 0.005


def test_drive_gains_skip_joints_the_payload_does_not_act_on(rx90_sim):
    """A point mass at the wrist centre (frame 6 origin) does not load joints 4-6 (RX-90 paper:
    'the torques of joints 4 and 5 do not depend on M_L'): their gains are not identifiable."""
    sim = rx90_sim
    point = np.zeros(10)
    point[-1] = 7.0
    un, lo = measured(sim, RX90_GAINS, 3, chi_payload=point)
    dg = drive_gains(un, lo, dict(zip(sim.payload_names, point)))
    assert dg.gains.joints == (0, 1, 2)
    assert sum("does not act on this joint" in w for w in dg.warnings) == 3
    assert np.all(np.abs(dg.gains.values / RX90_GAINS[:3] - 1) < 0.005)


def test_identify_with_drive_gains_reidentifies_the_payload_mass(rx90_sim):
    """Table 3: with the identified gains the payload mass re-identified together with the robot is
    right; with the a-priori gains 1 it is biased (here by about -2 %, -3.5 sigma)."""
    from symoro_gen.identification import fit_with_known_payload
    sim = rx90_sim
    payload = dict(zip(sim.payload_names, sim.chi_payload))
    z_gain, z_one = [], []
    for seed in range(3):
        un, lo = measured(sim, RX90_GAINS, 4 + seed)
        res, dg = identify_with_drive_gains(un, lo, payload, joints=[0, 1, 2, 3])
        assert res.gains is dg.gains
        m = res.index("M7")
        z_gain.append((res.values[m] - 7.025) / res.std[m])
        res1 = fit_with_known_payload(un, lo, {}, method="wls")
        z_one.append((res1.values[m] - 7.025) / res1.std[m])
    assert np.all(np.abs(z_gain) < 3) and abs(np.mean(z_gain)) < 1.5, z_gain
    assert np.mean(z_one) < -2.5, z_one
    d = res.to_dict()
    assert d["gains"]["values"] == pytest.approx(list(dg.gains.values))
    assert set(d) >= {"parameters", "rel_err", "cond", "sigma", "gains"}


def test_drive_gains_errors(rx90_sim):
    sim = rx90_sim
    un, lo = measured(sim, RX90_GAINS, 5)
    with pytest.raises(IdentificationError, match=r"missing values for \['M7'\]"):
        drive_gains(un, lo, dict(zip(sim.payload_names[:-1], sim.chi_payload[:-1])))
    with pytest.raises(IdentificationError, match="needs equations in both"):
        drive_gains(un, lo, dict(zip(sim.payload_names, sim.chi_payload)), joints=[9])


# ---------------------------------------------------------------- sensor gains (LWR4)
@pytest.mark.parametrize("seed", range(3))
def test_lwr4_seven_sensor_gains_within_half_percent_by_tls(lwr4_sim, seed):
    sim = lwr4_sim
    un, lo = measured(sim, LWR4_GAINS, seed)
    res = sensor_gains(un, lo, {"M8": sim.chi_payload[-1]})
    assert res.method == "TLS-W" and res.gains.names == tuple(f"g{j}" for j in range(1, 8))
    err = np.abs(res.gains.values - LWR4_GAINS) / LWR4_GAINS
    assert np.all(err < 0.005), err
    assert np.all(res.gains.rel_std_pct < 0.5)
    # robot and unknown payload parameters come with them (Table II)
    truth = np.r_[sim.chi_base, sim.chi_payload[:-1]]
    assert res.names == sim.names + sim.payload_names[:-1]
    assert np.mean(np.abs(res.values - truth) < 3 * res.std) > 0.9
    assert dict(res.fixed) == {"M8": pytest.approx(4.6136)}
    # error norms are those of the torques g v: about the noise level (1 %)
    assert np.all(res.rel_err < 0.015)
    json.dumps(res.to_dict(), allow_nan=False)


def test_sensor_gains_tls_is_eq10_to_13(lwr4_sim):
    """The estimate is the normalised last right singular vector of the weighted W_tot of eq. 10."""
    sim = lwr4_sim
    un, lo = measured(sim, LWR4_GAINS, 8)
    res = sensor_gains(un, lo, {"M8": sim.chi_payload[-1]})
    n = 7
    joint = np.r_[un.joint, lo.joint]
    V = np.zeros((joint.size, n))
    V[np.arange(joint.size), joint] = np.r_[un.Y, lo.Y]
    ra = un.Y.size
    Wul = np.vstack([np.zeros((ra, 9)), sim.WL[:, :9]])
    wkl = np.r_[np.zeros(ra), sim.WL[:, 9] * sim.chi_payload[-1]]
    Wtot = np.column_stack([V, -np.vstack([sim.Wa, sim.Wb]), -Wul, -wkl])
    w = 1 / res.joint_sigma[joint]
    _, s, Vt = np.linalg.svd(Wtot * w[:, None], full_matrices=False)
    xtot = Vt[-1] / Vt[-1, -1]
    np.testing.assert_allclose(res.gains.values, xtot[:n], rtol=1e-9)
    np.testing.assert_allclose(res.values, xtot[n:-1], rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(res.sigma, s[-1] / np.sqrt(Wtot.shape[0] - Wtot.shape[1]), rtol=1e-9)


def test_sensor_gains_essential_keeps_all_gains(lwr4_sim):
    sim = lwr4_sim
    un, lo = measured(sim, LWR4_GAINS, 9)
    res = sensor_gains(un, lo, {"M8": sim.chi_payload[-1]}, essential=True)
    assert len(res.eliminated) > 0 and res.gains.values.size == 7
    assert np.all(np.abs(res.gains.values / LWR4_GAINS - 1) < 0.005)
    p = res.rel_std_pct
    assert p.max() / p.min() < 30                         # gains are not in the ratio (Table II)


def test_sensor_gains_cross_validation(lwr4_sim):
    """Table III: error norms on validation data (fresh noise, another payload... here the same
    states) with the identified gains are at the noise level, and below those with gains 1."""
    sim = lwr4_sim
    un, lo = measured(sim, LWR4_GAINS, 10)
    res = sensor_gains(un, lo, {"M8": sim.chi_payload[-1]})
    _, val = measured(sim, LWR4_GAINS, 11)
    e = res.rel_err_on(val)
    assert e.shape == (7,) and np.all(e < 0.02)
    from symoro_gen.identification import fit_with_known_payload
    ref = fit_with_known_payload(un, lo, {"M8": sim.chi_payload[-1]}, method="wls")   # gains 1
    assert np.mean(ref.rel_err_on(val)) > np.mean(e)


def test_sensor_gains_errors(lwr4_sim):
    sim = lwr4_sim
    un, lo = measured(sim, LWR4_GAINS, 12)
    with pytest.raises(IdentificationError, match="at least one known payload parameter"):
        sensor_gains(un, lo, {})
    with pytest.raises(IdentificationError, match=r"known parameters \['M7'\] are not payload columns"):
        sensor_gains(un, lo, {"M7": 1.0})


def test_gains_accept_the_combined_layout(lwr4_sim, rx90_sim):
    from symoro_gen.identification import stack_systems
    sim = lwr4_sim
    un, lo = measured(sim, LWR4_GAINS, 13)
    ref = sensor_gains(un, lo, {"M8": sim.chi_payload[-1]})
    res = sensor_gains(stack_systems(un, lo), None, {"M8": sim.chi_payload[-1]}, payload_names=sim.payload_names)
    np.testing.assert_allclose(res.gains.values, ref.gains.values, rtol=1e-9)
    sim = rx90_sim
    un, lo = measured(sim, RX90_GAINS, 14)
    payload = dict(zip(sim.payload_names, sim.chi_payload))
    ref = drive_gains(un, lo, payload, joints=[0, 1])
    res = drive_gains(stack_systems(un, lo), None, payload, joints=[0, 1], payload_names=sim.payload_names)
    np.testing.assert_allclose(res.gains.values, ref.gains.values, rtol=1e-10)
