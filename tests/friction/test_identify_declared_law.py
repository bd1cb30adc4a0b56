"""``identify`` with a declared friction law: the law's magnitudes are linear parameters, its scale is
refined by Gauss-Newton on the identification data; checked against the simulated truth (SCARA, exact
Newton-Euler torques plus the law, noise on q and torque)."""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description.friction_law import FrictionLaw
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques
from tests.diagnostics.simdata import robot_and_model
from tests.docs.jsonschema_lite import validate
from tests.docs.runner import DOCS

SCHEMA = json.loads((DOCS / "schemas" / "identify.schema.json").read_text())

NOISE_Q, NOISE_TAU = 1e-5, 0.05


class _Declared:
    """The SCARA model carrying a robot description with friction laws (``identify`` reads the laws from it)."""

    def __init__(self, model, robot):
        self._model, self.robot = model, robot

    def __getattr__(self, name):
        return getattr(self._model, name)

    def regressor(self, *a, **k):
        return self._model.regressor(*a, **k)


def simulate(law: FrictionLaw | None, truth: dict, seed: int, *, duration: float = 20.0, hold: int | None = None):
    """(model with ``law`` declared, Trajectory, standard parameters chi by name): the declared
    Coulomb + viscous terms of joint ``law.frame`` replaced by the law with magnitudes ``truth``."""
    robot, model = robot_and_model("scara")
    rng = np.random.default_rng(seed)
    n = model.N_JOINTS
    amp = np.ones(n)
    amp[2] = 0.1
    t, q, dq, ddq = fourier_trajectory(n, duration, 0.002, rng, base_frequency_hz=0.1, amplitude=amp)
    if hold is not None:
        q[:, hold], dq[:, hold], ddq[:, hold] = q[0, hold], 0.0, 0.0
    chi = np.asarray(random_physical_parameters(robot, rng), float)
    names = list(robot.standard_names)
    if law is not None:
        j = law.frame - 1
        for k in ("FS", "FV"):
            chi[names.index(f"{k}{law.frame}")] = 0.0
    tau = true_torques(model, q, dq, ddq, chi)
    if law is not None:
        tau[:, j] += law.columns(dq[:, j]) @ np.array([truth[nm] for nm in law.names()])
        robot = dataclasses.replace(robot, friction_laws={law.frame: law})
    qm = q + NOISE_Q * rng.standard_normal(q.shape)
    taum = tau + NOISE_TAU * rng.standard_normal(q.shape)
    return _Declared(model, robot), Trajectory(t=t, q=qm, tau=taum, source=f"scara seed {seed}"), dict(zip(names, chi))


@pytest.mark.parametrize("kind, true_scale, declared, truth", [
    ("stribeck", 0.05, 0.08, {"FS2": 1.5, "FSS2": 1.0, "FV2": 0.7}),
    ("tanh", 0.03, 0.015, {"FS2": 1.2, "FV2": 0.5}),
    ("power", 0.5, 0.8, {"FS2": 0.8, "FV2": 1.5}),
])
def test_declared_law_recovers_scale_and_magnitudes(kind, true_scale, declared, truth):
    """Scale and magnitudes within 3 sigma of the truth, starting from a declared scale away from it (and
    the declared law does better than the Coulomb + viscous model on the same data)."""
    model, tr, _ = simulate(FrictionLaw(2, kind, true_scale), truth, seed=11)
    start = dataclasses.replace(model.robot, friction_laws={2: FrictionLaw(2, kind, declared)})
    res = symoro_gen.identify(_Declared(model._model, start), [tr], method="wls")
    (fit,) = res.friction_laws
    assert fit.fitted and fit.iterations >= 1, fit
    assert abs(fit.scale - true_scale) <= 3 * fit.std, (fit.scale, fit.std)
    assert fit.std < 0.2 * true_scale, fit.std
    for nm, v in truth.items():
        assert abs(fit.magnitudes[nm] - v) <= 3 * fit.magnitude_std[nm] + 1e-9, (nm, fit.magnitudes, fit.magnitude_std)
    out = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert validate(out, SCHEMA) == []
    (entry,) = out["friction_laws"]
    assert entry["kind"] == kind and entry["declared"] == declared and entry["scale"] == pytest.approx(fit.scale)
    assert set(truth) <= set(out["parameters"]["names"]), out["parameters"]["names"]
    assert "Declared friction laws" in res.summary() and fit.law.scale_name in res.summary()
    plain = symoro_gen.identify(model._model, [tr], method="wls")
    assert res.result.rel_err[1] < plain.result.rel_err[1], (res.result.rel_err, plain.result.rel_err)


def test_law_on_a_joint_that_does_not_move_is_reported_not_fitted():
    """Joint 2 held still (``drop_unexcited``): its law's scale cannot be seen; it is reported with the
    declared value, ``fitted`` false and the reason, in the JSON and the text."""
    model, tr, _ = simulate(FrictionLaw(2, "stribeck", 0.05), {"FS2": 1.5, "FSS2": 1.0, "FV2": 0.7}, seed=5, hold=1)
    res = symoro_gen.identify(model, [tr], method="wls", drop_unexcited=True)
    (fit,) = res.friction_laws
    assert not fit.fitted and fit.scale == 0.05 and "does not move" in fit.note
    out = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert validate(out, SCHEMA) == [] and out["friction_laws"][0]["fitted"] is False
    assert "not fitted" in res.summary()


def test_scale_the_data_cannot_see_is_reported():
    """A Stribeck law declared on a joint whose torques have no dry friction at all (Fc = Fs = 0, viscous
    only): the dip's magnitude is not significant, so its scale is not determined; it is reported with the
    declared value, not fitted silently."""
    model, tr, _ = simulate(FrictionLaw(2, "stribeck", 0.05), {"FS2": 0.0, "FSS2": 0.0, "FV2": 0.7}, seed=8,
                             duration=10.0)
    res = symoro_gen.identify(model, [tr], method="wls")
    (fit,) = res.friction_laws
    assert not fit.fitted and fit.scale == 0.05 and "do not determine" in fit.note, fit
    assert abs(fit.magnitudes["FSS2"]) <= 3 * fit.magnitude_std["FSS2"]


@pytest.mark.parametrize("kind", ["lugre", "dahl"])
def test_dynamic_law_is_identified_by_its_sliding_part(kind):
    """Joint 2's friction simulated with its state (LuGre with a Stribeck dip, or Dahl; sigma0 = 1e6 N m/rad)
    at the recordings' 500 Hz: identify reports the sliding part (LuGre: the Stribeck law with vs refined;
    Dahl: Coulomb + viscous), says so, and recovers it within 5 %. (With a softer sigma0 = 1e4 the
    pre-sliding lag after each reversal, which the sliding part does not model, biases it: vs +14 %,
    Fs - Fc -26 %, Fv +6 % on these data; docs/friction-dynamic.md.)"""
    from symoro_gen.simulate.friction_state import lugre_friction

    fc, fs, vs, fv = 1.5, 2.5 if kind == "lugre" else 1.5, 0.05, 0.7
    robot, model = robot_and_model("scara")
    rng = np.random.default_rng(21)
    amp = np.array([1.0, 1.0, 0.1, 1.0])
    t, q, dq, ddq = fourier_trajectory(4, 20.0, 0.002, rng, base_frequency_hz=0.1, amplitude=amp)
    chi = np.asarray(random_physical_parameters(robot, rng), float)
    names = list(robot.standard_names)
    chi[names.index("FS2")] = chi[names.index("FV2")] = 0.0
    tau = true_torques(model, q, dq, ddq, chi)
    tau[:, 1] += lugre_friction(t, dq[:, 1], fc=fc, fs=fs, vs=vs, sigma0=1e6, fv=fv)
    tr = Trajectory(t=t, q=q + NOISE_Q * rng.standard_normal(q.shape),
                    tau=tau + NOISE_TAU * rng.standard_normal(q.shape), source="scara lugre")
    law = FrictionLaw(2, kind, 0.08 if kind == "lugre" else None, (("sigma0", 1e6),))
    res = symoro_gen.identify(_Declared(model, dataclasses.replace(robot, friction_laws={2: law})), [tr])
    (fit,) = res.friction_laws
    assert "sliding part only" in fit.note and fit.to_dict()["sliding_part_only"] is True
    assert fit.magnitudes["FS2"] == pytest.approx(fc, rel=0.05) and fit.magnitudes["FV2"] == pytest.approx(fv, rel=0.05)
    if kind == "lugre":
        assert fit.fitted and fit.scale == pytest.approx(vs, rel=0.05)
        assert fit.magnitudes["FSS2"] == pytest.approx(fs - fc, rel=0.05)
    else:
        assert not fit.fitted and fit.to_dict()["scale"] is None
    out = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert validate(out, SCHEMA) == [] and out["friction_laws"][0]["presliding"] == {"sigma0": 1e6}


def test_options_that_cannot_take_a_declared_law_are_refused_by_name():
    from symoro_gen.errors import OptionError

    model, tr, _ = simulate(FrictionLaw(2, "tanh", 0.03), {"FS2": 1.2, "FV2": 0.5}, seed=2, duration=5.0)
    for kw, flag in ((dict(physical=True), "--physical"), (dict(method="iv"), "--method iv")):
        with pytest.raises(OptionError, match=flag):
            symoro_gen.identify(model, [tr], **kw)
