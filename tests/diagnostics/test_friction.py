"""Friction-law selection by time-blocked cross-validation (symoro_gen.diagnostics.friction).

Simulated SCARA torques (known base parameters, random Fourier excitation) in which the Coulomb or the
viscous law of one joint is replaced by a known one; the rows are the samples themselves (no filtering),
so the truth is exact up to the added white noise."""
from __future__ import annotations

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics.expert import stacked_regressor
from symoro_gen.diagnostics.friction import (
    FrictionChoice,
    LawFit,
    LawSearch,
    coulomb_columns,
    friction_column_indices,
    law_errors,
    select_friction,
    viscous_columns,
)
from symoro_gen.diagnostics.stability import time_blocks
from symoro_gen.errors import IdentificationError
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters

NOISE = 0.05


def scara_rows(seed: int, duration: float = 30.0, dt: float = 0.01):
    robot, model = load_robot("scara"), symoro_gen.load_model("scara")
    rng = np.random.default_rng(seed)
    amp = np.ones(4)
    amp[2] = 0.1
    t, q, dq, ddq = fourier_trajectory(4, duration, dt, rng, base_frequency_hz=0.1, amplitude=amp)
    theta = np.asarray(model.base_parameters(np.asarray(random_physical_parameters(robot, rng))))
    W, J, S = stacked_regressor(model, q, dq, ddq)
    return {"model": model, "rng": rng, "t": t, "q": q, "dq": dq, "ddq": ddq, "theta": theta, "W": W, "J": J, "S": S}


def case(seed, j, coulomb=("sign", None), viscous=("linear", None), **kw):
    d = scara_rows(seed)
    W, J, S, th = d["W"], d["J"], d["S"], d["theta"]
    fs, fv = friction_column_indices(d["model"].BASE_NAMES, j)
    rows = j == J
    Wt = W.copy()
    dqj = d["dq"][S[rows], j]
    C = coulomb_columns(coulomb[0], dqj, coulomb[1])
    Wt[rows, fs[0]] = C[:, 0]
    Wt[rows, fv[0]] = viscous_columns(viscous[0], dqj, viscous[1])[:, 0]
    y = Wt @ th + NOISE * d["rng"].standard_normal(W.shape[0])
    if C.shape[1] == 2:      # Stribeck: Fs = 2.5 Fc
        y[rows] += 1.5 * th[fs[0]] * C[:, 1]
    A = np.delete(W, fs + fv, axis=1)
    blocks = time_blocks(np.zeros(y.size, int), S, 5)
    return select_friction(A, y, J, j, d["dq"][S, j], blocks, search=LawSearch(**kw)), th[fs[0]], th[fv[0]]


def test_tanh_friction_is_chosen_with_its_velocity_scale():
    ch, fc, _ = case(1, 1, coulomb=("tanh", 0.05))
    assert ch.coulomb.law == "tanh" and ch.viscous.law == "linear", ch.describe()
    assert ch.coulomb.param == pytest.approx(0.05, rel=0.15)
    assert ch.coefficients["Fc"] == pytest.approx(fc, rel=0.05)
    assert ch.replaced and "Coulomb \u2192 tanh, v = 0.0" in ch.describe()
    errs = law_errors(ch)
    assert errs["sign"] > 1.5 * ch.cv_rel_err     # the declared law predicts held-out blocks worse


@pytest.mark.parametrize("seed", [2, 3])
def test_sign_friction_is_kept(seed):
    ch, fc, _ = case(seed, 1)
    assert ch.coulomb.law == "sign" and ch.viscous.law == "linear" and not ch.replaced, ch.describe()
    assert "kept" in ch.describe()
    assert ch.coefficients["Fc"] == pytest.approx(fc, rel=0.05)


def test_stribeck_friction_is_chosen():
    ch, fc, _ = case(4, 0, coulomb=("stribeck", 0.1))
    assert ch.coulomb.law == "stribeck", ch.describe()
    assert ch.coulomb.param == pytest.approx(0.1, rel=0.35)     # grid only (no refinement)
    assert ch.coefficients["Fs"] == pytest.approx(2.5 * fc, rel=0.1)


def test_power_viscous_law_is_chosen():
    ch, _, fv = case(5, 1, viscous=("power", 0.5))
    assert ch.coulomb.law == "sign" and ch.viscous.law == "power", ch.describe()
    assert ch.viscous.param == pytest.approx(0.5, abs=0.08)
    assert ch.coefficients["Fv"] == pytest.approx(fv, rel=0.1)
    assert "viscous \u2192 |dq|^\u03b4" in ch.describe()


def test_bad_input_is_named():
    d = scara_rows(6, duration=10.0)
    y = d["W"] @ d["theta"]
    blocks = time_blocks(np.zeros(y.size, int), d["S"], 5)
    with pytest.raises(ValueError, match="one entry per row"):
        select_friction(d["W"], y[:-1], d["J"], 0, d["dq"][d["S"], 0], blocks)
    with pytest.raises(IdentificationError, match="joint 9 has no rows"):
        select_friction(d["W"], y, d["J"], 8, d["dq"][d["S"], 0], blocks)
    with pytest.raises(IdentificationError, match="does not move"):
        select_friction(d["W"], y, d["J"], 0, np.zeros(y.size), blocks)
    with pytest.raises(ValueError, match="unknown laws"):
        select_friction(d["W"], y, d["J"], 0, d["dq"][d["S"], 0], blocks, search=LawSearch(laws=("coulomb",)))


def test_v_floor_smooths_sign_and_bounds_the_search():
    ch, _, _ = case(1, 1, coulomb=("tanh", 0.05), v_floor=0.002)
    sign = [c for c in ch.candidates if c.law == "sign"]
    assert sign and all(c.smooth == 0.002 for c in sign)
    assert all(c.param >= 0.002 for c in ch.candidates if c.law == "tanh")
    kept = FrictionChoice(1, sign[0], LawFit("linear", None, sign[0].cv_rel_err), tuple(sign))
    assert "sign smoothed at v = 0.002" in kept.describe()
    np.testing.assert_allclose(kept.columns(np.array([-1.0, 0.0, 0.001]))[:, 0], np.tanh([-500.0, 0.0, 0.5]))
    ch, _, _ = case(1, 1, coulomb=("tanh", 0.05), v_floor=0.002)
    assert ch.coulomb.law == "tanh" and ch.coulomb.param == pytest.approx(0.05, rel=0.15)
    with pytest.raises(ValueError, match="v_floor"):
        case(1, 1, v_floor=0.0)
