"""The elastic joint against an independent oracle: Pinocchio's dynamics with Spong's transmission
(:mod:`tests.elastic.pinsim`, nothing of the project's simulator), LWR4 joint 4 with K = 3000 N m/rad (the truth
bench's case 8) and D = 15 N m s/rad.

* two encoders (motor and link positions): ``identify`` with the joint declared elastic (declared K, D wrong on
  purpose) recovers K and D within 3 sigma, sigma below a third of the value;
* one motor-side encoder: ``diagnose`` on the rigid LWR4 names ``elasticity`` on joint 4, its K = 1/c within
  3 sigma (sigma_K = sigma_c / c^2, the first-order propagation of the loop's standard deviation of c).
"""
from __future__ import annotations

import numpy as np
import pytest

from tests.elastic.pinsim import D_TRUE, JOINT, K_TRUE, elastic_log, lwr4_elastic_file, write_csv


def test_simulated_deflection_obeys_the_spring_law():
    """The oracle itself: K delta + D d(delta)/dt = tau_J on the elastic joint, zero deflection elsewhere."""
    log = elastic_log(3, seconds=4.0, rate=1000.0)
    d = log.delta[:, JOINT]
    r = K_TRUE * d + D_TRUE * np.gradient(d, log.t) - log.tau_true[:, JOINT]
    assert np.linalg.norm(r[5:-5]) < 1e-3 * np.linalg.norm(log.tau_true[:, JOINT])
    assert np.all(np.delete(log.delta, JOINT, axis=1) == 0)
    assert np.abs(d).max() > 1e-3   # a deflection of several mrad: visible against the 1e-6 rad encoder noise


@pytest.mark.slow
def test_identify_two_encoders_recovers_K_and_D(tmp_path):
    from symoro_gen.preprocessing.readers.options import make_format
    from symoro_gen.workflows.identify import identify

    log = elastic_log(1, seconds=10.0)
    spec = write_csv(log, tmp_path / "two.csv", two_encoders=True)
    f = lwr4_elastic_file(tmp_path / "lwr4e.toml", K=1000.0)   # declared K, D wrong: the estimate must not use them
    res = identify(str(f), [tmp_path / "two.csv"], method="ols", data_format=make_format(columns=spec))
    est = res.elasticity
    assert est is not None and est.joints == (JOINT + 1,)
    (K,), (sK,), (D,), (sD,) = est.K, est.K_std, est.D, est.D_std
    assert 0 < sK < K_TRUE / 3 and 0 < sD < D_TRUE / 3, (sK, sD)
    assert abs(K - K_TRUE) <= 3 * sK, (K, sK)
    assert abs(D - D_TRUE) <= 3 * sD, (D, sD)


def one_encoder_diagnosis(seed: int = 1, seconds: float = 20.0):
    """The loop (every candidate, default settings) on the rigid LWR4 with joint 4 read by a motor-side encoder:
    identification recording of ``seconds``, validation of half as long."""
    import symoro_gen
    from symoro_gen.diagnostics import DiagnoseSettings, diagnose
    from symoro_gen.preprocessing.trajectory import Trajectory

    logs = [elastic_log(seed, seconds=seconds), elastic_log(seed + 1, seconds=seconds / 2)]
    trs = [Trajectory(t=lg.t, q=lg.theta, tau=lg.tau, source=f"motor-{k}") for k, lg in enumerate(logs)]
    return diagnose(symoro_gen.load_model("lwr4"), [trs[0]], DiagnoseSettings(), validation=[trs[1]],
                    rng=np.random.default_rng(seed))


@pytest.mark.slow
def test_diagnose_one_encoder_names_elasticity_with_K():
    rep = one_encoder_diagnosis()
    assert rep.effects, "nothing named"
    e = rep.effects[0]
    assert (e.kind, e.joint) == ("elasticity", JOINT), [(x.kind, x.joint) for x in rep.effects]
    c, sc = float(e.values[0]), float(e.std[0])
    K, sK = 1.0 / c, sc / c ** 2
    assert e.physical["K_Nm_per_rad"] == pytest.approx(K)
    assert 0 < sK < K_TRUE / 3, sK
    assert abs(K - K_TRUE) <= 3 * sK, (K, sK)
    # the validation error of joint 4 drops with it
    assert rep.after_validation_rel_err[JOINT] < rep.before_validation_rel_err[JOINT]
