"""The diagnosis reports its errors on both metrics: the filtered, decimated system and the raw
measured validation torque, the latter with the model and its effects at full rate."""
from __future__ import annotations

import numpy as np
import pytest

from symoro_gen.diagnostics import DiagnoseSettings, diagnose

from .simdata import recording


@pytest.fixture(scope="module")
def stribeck():
    model, tr = recording("scara", 11, "stribeck", 1, Fst=1.0, vs=0.1)
    return model, tr, diagnose(model, tr, DiagnoseSettings(method="ols", max_effects=2))


def test_json_has_both_metrics_and_says_what_they_are_on(stribeck):
    _, _, rep = stribeck
    d = rep.to_dict()
    for part in ("before", "after"):
        assert len(d[part]["validation_rel_err_raw"]) == len(d[part]["validation_rel_err"]) == 4
    b = d["error_basis"]
    assert b["cutoff_hz"] == pytest.approx(rep.settings["cutoff_hz"]) and b["n_d"] == rep.settings["n_d"]
    assert b["samples_validation"] > b["rows_validation"] / 4    # full rate: more samples than decimated rows
    assert "raw torque" in rep.summary() or "raw before" in rep.summary()


def test_raw_error_of_the_declared_model_matches_the_observations_stage(stribeck):
    """Before: the frame's full-rate path equals the observations stage's raw error of the declared fit."""
    model, _, rep = stribeck
    V = rep.plot_data["vframe"]
    ref = rep.result_before.rel_err_raw_on(model, V.assembly)
    np.testing.assert_allclose(rep.before_validation_rel_err_raw, ref, rtol=1e-10)


def test_effect_at_full_rate_cuts_the_raw_error_of_its_joint(stribeck):
    """The Stribeck effect found on joint 2 lowers that joint's raw-torque validation error too, and the
    raw error stays above the filtered one (torque noise outside the decimated band)."""
    _, _, rep = stribeck
    first = rep.effects[0]
    # found by the friction-law stage (a Stribeck law replacing Coulomb) or by the loop's candidate
    assert first.joint == 1 and (first.kind == "stribeck" or (
        first.kind == "friction_law" and first.variant.startswith("stribeck"))), [e.label for e in rep.effects]
    assert rep.after_validation_rel_err_raw[1] < 0.6 * rep.before_validation_rel_err_raw[1]
    assert np.all(rep.after_validation_rel_err_raw >= rep.after_validation_rel_err - 1e-12)
