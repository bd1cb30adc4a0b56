"""IdentificationResult: immutability, JSON contract, summary tables, cross-validation."""
import dataclasses
import json

import numpy as np
import pytest

from symoro_gen.errors import IdentificationError
from symoro_gen.identification import Gains, IdentificationResult, ObservationSystem, fit_ols, fit_wls


def system(seed=0, x=(2.0, -1.0, 0.5), sig=0.05):
    rng = np.random.default_rng(seed)
    W = rng.normal(size=(300, 3))
    joint = np.repeat([0, 1, 2], 100)
    return ObservationSystem(W, W @ np.array(x) + sig * rng.normal(size=300), ("XX1", "MY2", "FS3"), joint)


def test_result_is_immutable():
    res = fit_ols(system())
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.sigma = 1.0
    for f in ("values", "std", "cov", "rel_err", "residual"):
        with pytest.raises(ValueError):
            getattr(res, f)[0] = 0.0


def test_json_contract():
    res = fit_ols(system())
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert d["parameters"]["names"] == ["XX1", "MY2", "FS3"]
    for k in ("values", "std", "rel_std_pct"):
        assert len(d["parameters"][k]) == 3
    assert d["parameters"]["values"] == pytest.approx(list(res.values))
    assert len(d["rel_err"]) == 3 and d["cond"] == pytest.approx(res.cond) and d["sigma"] == pytest.approx(res.sigma)
    assert "gains" not in d
    g = Gains((0, 2), [1.01, 0.98], [0.001, 0.002], [0.1, 0.2])
    d2 = dataclasses.replace(res, gains=g).to_dict()
    assert d2["gains"]["values"] == [1.01, 0.98] and d2["gains"]["rel_std_pct"] == [0.1, 0.2]
    assert d2["gains"]["names"] == ["g1", "g3"]


def test_non_finite_numbers_become_null():
    s = system()
    W = np.column_stack([s.W, s.W[:, 0] + s.W[:, 1]])
    res = fit_ols(ObservationSystem(W, s.Y, s.names + ("XX4",), s.joint))
    d = res.to_dict()
    json.dumps(d, allow_nan=False)
    assert None in d["parameters"]["std"]


def test_summary_tables_and_numbered_warnings():
    s = system(x=(2.0, -1.0, 1e-4))
    res = fit_wls(s)
    text = res.summary()
    assert "IDIM-WLS identification: 300 equations, 3 parameters" in text
    assert "cond(W)" in text and "%sigma" in text
    for n in ("XX1", "MY2", "FS3"):
        assert n in text
    assert "Rel. err. norm ||rho_j||/||Y_j||" in text and "joint 3:" in text
    assert "[1] 1 parameter(s) poorly identified" in text and "FS3" in text.split("Warnings:")[1]
    assert "row weights 1/sigma_j" in text


def test_cross_validation_error_norms():
    x = (2.0, -1.0, 0.5)
    res = fit_ols(system(0, x))
    val = system(1, x)
    e = res.rel_err_on(val)
    rho = val.Y - val.W @ res.values
    for j in range(3):
        m = val.joint == j
        assert e[j] == pytest.approx(np.linalg.norm(rho[m]) / np.linalg.norm(val.Y[m]), rel=1e-12)
    np.testing.assert_allclose(res.predict(val), val.W @ res.values)
    # gains scale the measurements (tau = g v) before comparison
    g = Gains((0, 1, 2), [2.0, 1.0, 1.0], [0, 0, 0], [0, 0, 0])
    rg = dataclasses.replace(res, gains=g)
    vg = ObservationSystem(val.W, val.Y / np.array([2.0, 1.0, 1.0])[val.joint], val.names, val.joint)
    np.testing.assert_allclose(rg.rel_err_on(vg), e, rtol=1e-12)


def test_predict_matches_columns_by_name_and_uses_fixed_and_eliminated_values():
    res = fit_ols(system())
    res = dataclasses.replace(res, fixed=(("M8", 4.0),), eliminated=("ZZ9",))
    rng = np.random.default_rng(3)
    W = rng.normal(size=(5, 4))
    s = ObservationSystem(W, np.zeros(5), ("M8", "FS3", "XX1", "ZZ9"), np.zeros(5, int))
    np.testing.assert_allclose(res.predict(s), W @ [4.0, res.value("FS3"), res.value("XX1"), 0.0])
    with pytest.raises(IdentificationError, match=r"columns \['YY5'\] that this OLS result does not know"):
        res.predict(ObservationSystem(W, np.zeros(5), ("M8", "FS3", "XX1", "YY5"), np.zeros(5, int)))
    with pytest.raises(IdentificationError, match="no parameter 'YY5'"):
        res.value("YY5")


def test_inconsistent_result_fields_are_rejected():
    with pytest.raises(IdentificationError, match="values has 2 entries for 3 names"):
        IdentificationResult("OLS", ("a", "b", "c"), [1, 2], [1, 1, 1], [1, 1, 1], np.eye(3), 1, 1, 1, [0.1], 10)
