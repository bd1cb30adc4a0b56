"""The friction-law stage's pre-sliding Dahl law: offered on data sampled at 1 kHz or more only
(docs/friction-dynamic.md), through the same acceptance and plausibility as the static laws; checked against
the state simulation of :mod:`symoro_gen.simulate.friction_state` (SCARA, exact Newton-Euler torques plus a
Dahl friction on joint 2, noise on q and torque)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from symoro_gen.description.parse import parse_robot_text
from symoro_gen.diagnostics import DiagnoseSettings, diagnose
from symoro_gen.diagnostics.friction import DAHL_MIN_RATE_HZ, LawSearch, dahl_column, law_declarations
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques
from symoro_gen.simulate.friction_state import dahl_friction
from tests.diagnostics.simdata import robot_and_model
from tests.diagnostics.test_declared_laws import with_line

FC, SIGMA0 = 1.5, 2e3


@pytest.mark.parametrize("fs, sigma0", [(1000.0, 1e4), (2000.0, 2e3), (500.0, 1e5)])
def test_dahl_column_is_the_simulated_dahl_state(fs, sigma0):
    """``Fc dahl_column(v, x0 fs)`` with ``x0 = Fc / sigma0`` is the Dahl friction the state simulation
    integrates (velocity held at the mean of each interval, state 0 at the start)."""
    t = np.arange(0.0, 4.0, 1.0 / fs)
    v = 0.3 * np.sin(2 * np.pi * 0.7 * t) + 0.05 * np.sin(2 * np.pi * 3.1 * t)
    ref = dahl_friction(t, v, fc=FC, sigma0=sigma0)
    got = FC * dahl_column(v, FC / sigma0 * fs)
    np.testing.assert_allclose(got, ref, atol=1e-9 * FC)


def test_dahl_is_offered_from_one_kilohertz_only():
    assert not LawSearch(laws=("dahl",), rate_hz=500.0).dahl
    assert not LawSearch(laws=("dahl",), rate_hz=None).dahl
    assert not LawSearch(rate_hz=2000.0).dahl            # not named
    assert LawSearch(laws=("dahl",), rate_hz=DAHL_MIN_RATE_HZ * (1 - 1e-12)).dahl
    assert LawSearch(laws=("dahl",), rate_hz=2000.0).dahl


def _dahl_recording(fs: float, duration: float = 40.0, seed: int = 5):
    robot, model = robot_and_model("scara")
    rng = np.random.default_rng(seed)
    n = model.N_JOINTS
    amp = np.ones(n)
    amp[2] = 0.1
    t, q, dq, ddq = fourier_trajectory(n, duration, 1.0 / fs, rng, base_frequency_hz=0.3, amplitude=amp)
    chi = np.asarray(random_physical_parameters(robot, rng), float)
    chi[list(robot.standard_names).index("FS2")] = 0.0          # the Coulomb friction of joint 2 is Dahl's
    tau = true_torques(model, q, dq, ddq, chi)
    tau[:, 1] += dahl_friction(t, dq[:, 1], fc=FC, sigma0=SIGMA0)
    tr = Trajectory(t=t, q=q + 1e-5 * rng.standard_normal(q.shape), tau=tau + 0.05 * rng.standard_normal(q.shape),
                    source=f"scara dahl joint 2 at {fs:g} Hz")
    return model, dataclasses.replace(robot, friction_laws={}), tr


@pytest.mark.slow
def test_dahl_law_named_at_one_kilohertz_and_not_at_500_hz():
    """With the Dahl law enabled (``presliding_law``), at 1 kHz the loop names it on joint 2 with ``sigma0``
    within 10 % of the truth, its validation error on the joint drops, and the robot-file line of the effect
    parses back to a Dahl law; the same motion at 500 Hz never offers it; not enabled, it is not offered."""
    settings = DiagnoseSettings(max_effects=2, presliding_law=True)
    model, robot, tr = _dahl_recording(1000.0)
    rep = diagnose(model, tr, settings)
    (law,) = [e for e in rep.effects if e.kind == "friction_law" and e.joint == 1]
    assert law.variant.startswith("dahl"), law.variant
    assert abs(law.physical["sigma0"] - SIGMA0) < 0.1 * SIGMA0, law.physical
    before = np.asarray(rep.before_validation_rel_err)
    after = np.asarray(rep.after_validation_rel_err)
    assert after[1] < 0.5 * before[1], (before, after)
    (decl,) = law_declarations(robot, rep.effects)
    parsed = parse_robot_text(with_line(decl.line, 2), "scara.toml").friction_laws[2]
    assert parsed.kind == "dahl" and abs(dict(parsed.presliding)["sigma0"] - SIGMA0) < 0.1 * SIGMA0

    off = diagnose(model, tr, DiagnoseSettings(max_effects=2))
    assert not [c for c in off.tried if "dahl" in (c.variant or "")]
    model, robot, tr = _dahl_recording(500.0)
    rep = diagnose(model, tr, settings)
    assert not [e for e in rep.effects if "dahl" in e.variant]
    assert not [c for c in rep.tried if "dahl" in (c.variant or "")]
