"""The effects ``diagnose`` names must not depend on OLS vs WLS; where the two weightings
disagree on an effect, only the common ones are kept and the others are reported as estimator-dependent.

The loop re-identifies with a fixed estimator (``core.SELECT_METHOD``) and the stability stage tests every
accepted effect under OLS and WLS weights, so the lists agree by construction; these tests check that on
simulated data with very different noise levels per joint (where OLS and WLS estimates really differ), and
that an effect one weighting rejects is dropped from the model and listed in ``estimator_dependent``."""
from __future__ import annotations

import numpy as np
import pytest

import symoro_gen.diagnostics.core as core
from symoro_gen.diagnostics import DiagnoseSettings, diagnose

from .simdata import recording

pytest.importorskip("sklearn", reason="scikit-learn (extra 'diagnose') is needed for the unexplained stage")

#: long enough for core.MIN_ACCEPTANCE_ROWS acceptance rows per joint (12 s keeps 22: the loop then names nothing)
DURATION = 16.0
DT = 0.004


def _heteroscedastic():
    """SCARA with a 10 ms delay on joint 1's torque, and torque noise 0.02 / 0.3 / 0.002 / 0.1 N m per joint
    (on top of the 0.05 N m of :func:`.simdata.recording`): the WLS weights differ by a factor > 10."""
    model, tr = recording("scara", 21, "time_delay", 0, delay=0.01, duration=DURATION, dt=DT)
    rng = np.random.default_rng(5)
    tau = tr.tau + rng.standard_normal(tr.tau.shape) * np.array([0.02, 0.3, 0.002, 0.1])
    return model, type(tr)(t=tr.t, q=tr.q, tau=tau, source=tr.source)


def _keys(rep):
    return [(e["kind"], e["joint"], e["modulation"]) for e in rep.to_dict()["effects"]]


@pytest.mark.slow
def test_same_effects_under_ols_and_wls_and_the_report_uses_the_chosen_estimator():
    model, tr = _heteroscedastic()
    ols = diagnose(model, tr, DiagnoseSettings(method="ols", structure=False, unexplained=False))
    wls = diagnose(model, tr, DiagnoseSettings(method="wls", structure=False, unexplained=False))
    assert ("time_delay", 1, None) in _keys(ols), _keys(ols)
    assert _keys(ols) == _keys(wls)
    assert ols.to_dict()["estimator_dependent"] == wls.to_dict()["estimator_dependent"]
    # the reported identification is the user's estimator: different numbers, same named effects
    assert ols.result_after.method.upper().startswith("OLS") and wls.result_after.method.upper().startswith("WLS")
    d = next(e for e in ols.effects if e.kind == "time_delay"), next(e for e in wls.effects if e.kind == "time_delay")
    assert d[0].values[0] != d[1].values[0]
    # both estimate the 10 ms delay (the parameter of the time_delay column is the delay in s)
    for e in d:
        assert e.values[0] == pytest.approx(0.01, rel=0.15)


def test_an_effect_one_weighting_rejects_is_dropped_and_reported(monkeypatch):
    """The keep-only-the-common-ones rule inside diagnose: make the WLS-weighted stability test reject
    every effect (as a WLS-only disagreement would); the effect is then dropped from the model, reported in
    ``estimator_dependent`` (JSON, text) with the weighting that named it, and the same under both methods."""
    model, tr = recording("scara", 11, "time_delay", 0, delay=0.01, duration=DURATION, dt=DT)
    real = core._effect_stability

    def ols_only(data, F, added, k, weights, level):
        st = real(data, F, added, k, weights, level)
        return st if weights is None else core._Stability(0.0, st.ci_low, st.ci_high, False)

    monkeypatch.setattr(core, "_effect_stability", ols_only)
    reps = [diagnose(model, tr, DiagnoseSettings(method=m, structure=False, unexplained=False)) for m in ("ols", "wls")]
    for rep in reps:
        d = rep.to_dict()
        assert not [e for e in d["effects"] if e["kind"] == "time_delay"], d["effects"]
        dep = d["estimator_dependent"]
        assert [(x["kind"], x["joint"], x["named_under"]) for x in dep] == [("time_delay", 1, "OLS")], dep
        assert dep[0]["selection_frequency"]["WLS"] == 0.0 and dep[0]["selection_frequency"]["OLS"] > 0.5
        assert "Estimator-dependent" in rep.summary() and "named under OLS weights only" in rep.summary()
        assert any("depend on the estimator" in w for w in d["warnings"])
        # dropped from the model: the final model has no delay column
        assert not any(nm.startswith("time_delay") for nm in rep.result_after.names), rep.result_after.names
    assert _keys(reps[0]) == _keys(reps[1])
