"""Identification with a payload: known/unknown partition (LWR4 eq. 5, 7) and payload
identification with the robot known (Table IV)."""
import json

import numpy as np
import pytest

from symoro_gen.errors import IdentificationError
from symoro_gen.identification import (
    ObservationSystem,
    apply_gains,
    fit_with_known_payload,
    fix_parameters,
    identify_payload,
    stack_systems,
)

from .simdata import joint_noise, payload_parameters

GAINS = np.array([1.02, 1.01, 1.02, 0.98, 1.03, 1.05, 0.99])


def noisy(sim, seed, rel=0.01, chi_payload=None, gains=None):
    rng = np.random.default_rng(seed)
    tb = sim.tau_b if chi_payload is None else sim.payload_torque(chi_payload)
    Ya = sim.tau_a + joint_noise(rng, sim.tau_a, sim.joint_a, rel)
    Yb = tb + joint_noise(rng, tb, sim.joint_b, rel)
    if gains is not None:                       # measured signals v = tau / g
        Ya, Yb = Ya / gains[sim.joint_a], Yb / gains[sim.joint_b]
    return sim.unloaded(Ya), sim.loaded(Yb)


def test_stack_and_fix_build_eq7():
    rng = np.random.default_rng(0)
    Wa, Wb, WL = rng.normal(size=(6, 2)), rng.normal(size=(5, 2)), rng.normal(size=(5, 3))
    a = ObservationSystem(Wa, np.arange(6.0), ("c1", "c2"), np.zeros(6, int))
    b = ObservationSystem(np.column_stack([Wb, WL]), np.arange(5.0), ("c1", "c2", "L1", "L2", "L3"),
                          np.ones(5, int))
    s = stack_systems(a, b)
    assert s.names == ("c1", "c2", "L1", "L2", "L3")
    np.testing.assert_array_equal(s.W, np.block([[Wa, np.zeros((6, 3))], [Wb, WL]]))
    f = fix_parameters(s, {"L2": 2.0})
    assert f.names == ("c1", "c2", "L1", "L3")
    np.testing.assert_allclose(f.Y, np.r_[np.arange(6.0), np.arange(5.0) - 2.0 * WL[:, 1]])
    np.testing.assert_array_equal(s.Y, np.r_[np.arange(6.0), np.arange(5.0)])        # input untouched
    with pytest.raises(IdentificationError, match=r"known parameter\(s\) \['M9'\] are not columns"):
        fix_parameters(s, {"M9": 1.0})


def test_known_payload_partition_matches_manual_eq7(lwr4_sim):
    sim = lwr4_sim
    un, lo = noisy(sim, 1)
    known = {"M8": sim.chi_payload[-1], "MZ8": sim.chi_payload[-2]}
    res = fit_with_known_payload(un, lo, known, method="ols")
    # eq. 7 by hand: [[W_a, 0], [W_b, W_ul]] [chi; chi_ul] = [Y_a; Y_b - W_kl chi_kl]
    ul = [i for i, n in enumerate(sim.payload_names) if n not in known]
    kl = [sim.payload_names.index(n) for n in known]
    A = np.block([[sim.Wa, np.zeros((sim.Wa.shape[0], len(ul)))], [sim.Wb, sim.WL[:, ul]]])
    y = np.r_[un.Y, lo.Y - sim.WL[:, kl] @ np.array(list(known.values()))]
    ref = np.linalg.lstsq(A, y, rcond=None)[0]
    np.testing.assert_allclose(res.values, ref, rtol=1e-9, atol=1e-12)
    assert res.names == sim.names + tuple(sim.payload_names[i] for i in ul)
    assert dict(res.fixed) == pytest.approx(known)
    json.dumps(res.to_dict(), allow_nan=False)


def test_known_payload_recovers_robot_and_payload_within_3_sigma(lwr4_sim):
    """LWR4 with only the payload mass known (as the paper): robot base parameters and the 9 other
    payload parameters covered by their WLS 3-sigma bands, over noise seeds."""
    sim = lwr4_sim
    truth = np.r_[sim.chi_base, sim.chi_payload[:-1]]
    z = []
    for seed in range(5):
        un, lo = noisy(sim, 10 + seed)
        res = fit_with_known_payload(un, lo, {"M8": sim.chi_payload[-1]}, method="wls")
        z.append((res.values - truth) / res.std)
    z = np.abs(np.concatenate(z))
    assert np.mean(z < 3) > 0.98 and 0.6 < np.mean(z < 1) < 0.77, (np.mean(z < 3), np.mean(z < 1))


def test_payload_identified_with_robot_known_and_gains(lwr4_sim):
    """Table IV: a second payload (1.7073 kg) identified by WLS with the robot model known; with
    the right sensor gains the mass is within 3 sigma, with a-priori gains 1 it is biased."""
    sim = lwr4_sim
    chi2 = payload_parameters(1.7073, com=(-0.05, 0.06, 0.10))
    robot = dict(zip(sim.names, sim.chi_base))
    hits, biased = [], []
    for seed in range(4):
        _, lo = noisy(sim, 20 + seed, chi_payload=chi2, gains=GAINS)
        res = identify_payload(lo, robot, sim.payload_names, gains=GAINS)
        m = res.index("M8")
        assert res.names == sim.payload_names
        hits.append(abs(res.values[m] - 1.7073) / res.std[m])
        assert res.rel_std_pct[m] < 1.0
        z_all = np.abs(res.values - chi2) / res.std
        assert np.all(z_all < 4.5), z_all
        res1 = identify_payload(lo, robot, sim.payload_names)                  # gains ignored
        biased.append(abs(res1.values[m] - 1.7073) / res1.std[m])
        # predict() uses the fixed robot values: it reconstructs the scaled torques
        np.testing.assert_allclose(res.rel_err_on(apply_gains(lo, GAINS)), res.rel_err, rtol=1e-9)
    assert max(hits) < 3, hits
    assert min(biased) > 5, biased


def test_payload_robot_from_result_and_identifiable_subset(lwr4_sim):
    sim = lwr4_sim
    un, lo = noisy(sim, 30)
    first = fit_with_known_payload(un, lo, {"M8": sim.chi_payload[-1]}, method="wls")
    # the first result's parameter map holds payload-1 values under the payload names: they must be
    # ignored when payload_names says which columns to identify
    _, lo2 = noisy(sim, 31, chi_payload=payload_parameters(2.5))
    res = identify_payload(lo2, first, sim.payload_names)
    assert abs(res.value("M8") - 2.5) < 3 * res.std[res.index("M8")]
    # a payload column that duplicates another is left out with a warning
    W = np.column_stack([lo2.W, lo2.W[:, lo2.names.index("MX8")]])
    dup = ObservationSystem(W, lo2.Y, lo2.names + ("MXdup",), lo2.joint)
    res2 = identify_payload(dup, first, sim.payload_names + ("MXdup",))
    assert any("not separately identifiable" in w and ("MXdup" in w or "MX8" in w) for w in res2.warnings)
    assert res2.n_params == 10


def test_payload_errors(lwr4_sim):
    sim = lwr4_sim
    un, lo = noisy(sim, 40)
    with pytest.raises(IdentificationError, match=r"known parameters \['M9'\] are not payload columns"):
        fit_with_known_payload(un, lo, {"M9": 1.0})
    with pytest.raises(IdentificationError, match="no payload column"):
        fit_with_known_payload(un, sim.unloaded(un.Y), {})
    robot = dict(zip(sim.names[1:], sim.chi_base[1:]))
    with pytest.raises(IdentificationError, match=rf"robot parameter\(s\) \['{sim.names[0]}'\] of the loaded system have no value"):
        identify_payload(lo, robot, sim.payload_names)
    with pytest.raises(IdentificationError, match="no payload parameter left"):
        identify_payload(lo, dict(zip(sim.names, sim.chi_base)), sim.payload_names,
                         known=dict(zip(sim.payload_names, sim.chi_payload)))


def test_combined_and_zero_column_layouts_give_the_same_result(lwr4_sim):
    """The assembler's layout (one system, payload columns zero on unloaded rows) and an unloaded
    system carrying all-zero payload columns are accepted and equivalent to the two-system form."""
    sim = lwr4_sim
    un, lo = noisy(sim, 50)
    known = {"M8": sim.chi_payload[-1]}
    ref = fit_with_known_payload(un, lo, known, method="wls")
    combined = stack_systems(un, lo)
    res = fit_with_known_payload(combined, None, known, payload_names=sim.payload_names, method="wls")
    np.testing.assert_allclose(res.values, ref.values, rtol=1e-10)
    np.testing.assert_allclose(res.rel_err, ref.rel_err, rtol=1e-10)
    un0 = ObservationSystem(np.column_stack([un.W, np.zeros((un.Y.size, 10))]), un.Y, lo.names, un.joint)
    res0 = fit_with_known_payload(un0, lo, known, payload_names=sim.payload_names, method="wls")
    np.testing.assert_allclose(res0.values, ref.values, rtol=1e-10)
    with pytest.raises(IdentificationError, match="needs payload_names"):
        fit_with_known_payload(combined, None, known)
    bad = ObservationSystem(np.column_stack([un.W, np.ones((un.Y.size, 10))]), un.Y, lo.names, un.joint)
    with pytest.raises(IdentificationError, match="unloaded system has non-zero payload columns"):
        fit_with_known_payload(bad, lo, known, payload_names=sim.payload_names)
