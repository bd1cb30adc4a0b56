"""The loop's LuGre friction law (:func:`symoro_gen.diagnostics.friction.lugre_columns`): the Stribeck law at
constant velocity, the Dahl state when ``Fs = Fc``, and close to the LuGre state simulation
(:func:`symoro_gen.simulate.friction_state.lugre_friction`, Canudas de Wit et al. 1995 eq. 1-4) with
``x0 = Fs / sigma0``; offered from 1 kHz only, as the Dahl law."""
from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest

from symoro_gen.description.friction_law import coulomb_columns
from symoro_gen.description.parse import parse_robot_text
from symoro_gen.diagnostics import DiagnoseSettings, diagnose
from symoro_gen.diagnostics.friction import (
    DAHL_MIN_RATE_HZ,
    FrictionChoice,
    LawFit,
    LawSearch,
    law_declarations,
    lugre_columns,
    select_friction,
)
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques
from symoro_gen.simulate.friction_state import dahl_friction, lugre_friction
from tests.diagnostics.simdata import robot_and_model
from tests.diagnostics.test_declared_laws import with_line

FS_RATE = 1000.0
FC, FS, VS = 1.0, 1.6, 0.05


def _motion(seconds: float = 8.0, fs: float = FS_RATE):
    t = np.arange(0.0, seconds, 1.0 / fs)
    v = 0.3 * np.sin(2 * np.pi * 0.7 * t) + 0.05 * np.sin(2 * np.pi * 3.1 * t)
    return t, v


def test_lugre_columns_are_the_stribeck_law_at_constant_velocity():
    """After a travel of many ``x0`` at one velocity the state has reached ``sign(v)``: the columns are the
    Stribeck law's ``sign(v)`` and ``exp(-(v/vs)^2) sign(v)`` (description.friction_law.coulomb_columns)."""
    for v0 in (-0.2, -0.03, 0.01, 0.08):
        v = np.full(4000, v0)
        got = lugre_columns(v, VS, 1e-3)[-1]
        want = coulomb_columns("stribeck", np.array([v0]), VS)[0]
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("sigma0", [2e3, 1e4, 1e5])
def test_lugre_columns_without_dip_are_the_simulated_dahl_friction(sigma0):
    t, v = _motion()
    C = lugre_columns(v, VS, FC / sigma0 * FS_RATE)
    np.testing.assert_allclose(FC * C[:, 0], dahl_friction(t, v, fc=FC, sigma0=sigma0), atol=1e-9)


@pytest.mark.parametrize("sigma0", [1e3, 1e4, 1e5])
def test_lugre_columns_are_the_simulated_lugre_friction(sigma0):
    """With ``x0 = Fs / sigma0`` and ``q = (Fs - Fc) / Fs``, ``Fc a + (Fs - Fc) b`` is the LuGre friction of the
    state simulation (``sigma1 = 0``; the static Stribeck law is 0.2-0.5 N m RMS off: the pre-sliding
    transients), and its rise after each reversal has LuGre's slope ``2 sigma0`` (first interval of the new
    sign, within 10 %; the interval's displacement small against ``x0``: not at ``sigma0 = 1e3`` here)."""
    t, v = _motion()
    ref = lugre_friction(t, v, fc=FC, fs=FS, vs=VS, sigma0=sigma0)
    C = lugre_columns(v, VS, FS / sigma0 * FS_RATE, (FS - FC) / FS)
    got = FC * C[:, 0] + (FS - FC) * C[:, 1]
    np.testing.assert_allclose(got, ref, atol=1e-9)
    static = FC * np.sign(v) + (FS - FC) * np.exp(-(v / VS) ** 2) * np.sign(v)
    assert float(np.sqrt(np.mean((static - ref) ** 2))) > 0.15
    if sigma0 < 1e4:
        return
    vm = 0.5 * (v[1:] + v[:-1])
    k = np.flatnonzero(np.sign(vm[1:]) != np.sign(vm[:-1])) + 1          # interval index of the new sign
    k = k[(k > 10) & (k < v.size - 2)]
    slope = np.abs(got[k + 1] - got[k]) / (np.abs(vm[k]) / FS_RATE)
    np.testing.assert_allclose(slope, 2 * sigma0, rtol=0.1)


def test_lugre_is_offered_from_one_kilohertz_only():
    assert not LawSearch(laws=("lugre",), rate_hz=500.0).lugre
    assert not LawSearch(laws=("lugre",), rate_hz=None).lugre
    assert not LawSearch(rate_hz=2000.0).lugre                   # not named
    assert LawSearch(laws=("lugre",), rate_hz=DAHL_MIN_RATE_HZ * (1 - 1e-12)).lugre


@pytest.mark.slow
def test_selection_finds_the_lugre_law_and_its_scales():
    """On one joint's friction simulated by LuGre (1 kHz, noise 0.01 N m), the selection with every law picks
    LuGre over the static laws and Dahl, with vs within 10 %, the pre-sliding displacement x0 = Fs / sigma0 and
    q = (Fs - Fc) / Fs within 10 % of the truth and the magnitudes within 2 %; without the pre-sliding laws it
    picks the Stribeck law."""
    rng = np.random.default_rng(3)
    t, v = _motion(20.0)
    sigma0, fv = 2e4, 0.5
    y = lugre_friction(t, v, fc=FC, fs=FS, vs=VS, sigma0=sigma0, fv=fv) + 0.01 * rng.standard_normal(v.size)
    A = np.zeros((v.size, 0))
    joint = np.zeros(v.size, int)
    blocks = (np.arange(v.size) * 5) // v.size
    laws = ("sign", "tanh", "stribeck", "linear", "power", "dahl", "lugre")
    ch = select_friction(A, y, joint, 0, v, blocks, search=LawSearch(laws=laws, rate_hz=FS_RATE))
    assert ch.coulomb.law == "lugre", [c.label for c in ch.candidates]
    assert ch.coulomb.param == pytest.approx(VS, rel=0.1)
    assert ch.x0 == pytest.approx(FS / sigma0, rel=0.1)
    assert ch.coulomb.q == pytest.approx((FS - FC) / FS, rel=0.1)
    assert ch.coefficients["Fs"] == pytest.approx(FS, rel=0.02)
    assert ch.coefficients["Fc"] == pytest.approx(FC, rel=0.02)
    static = select_friction(A, y, joint, 0, v, blocks, search=LawSearch(rate_hz=FS_RATE))
    assert static.coulomb.law == "stribeck"
    assert ch.names() == ("FS1", "FSS1", "FV1")
    assert isinstance(ch, FrictionChoice) and isinstance(ch.coulomb, LawFit)


def test_lugre_effect_declares_a_lugre_line_that_parses_back():
    """A ``friction_law`` effect of the LuGre law (its ``vs`` and ``sigma0``) gets the robot-file line
    ``{kind = "lugre", vs = ..., sigma0 = ...}``, which parses back to the same law (3 significant digits)."""
    robot, _ = robot_and_model("scara")
    robot = dataclasses.replace(robot, friction_laws={})
    eff = SimpleNamespace(kind="friction_law", joint=1, modulation=None, names=("FS2", "FSS2", "FV2"),
                          physical={"vs": 0.0712, "x0": 4.1e-5, "sigma0": 20345.0}, search={}, verdict="cause",
                          label="friction_law2")
    (decl,) = law_declarations(robot, [eff])
    assert decl.law == "lugre" and decl.scale == pytest.approx(0.0712)
    law = parse_robot_text(with_line(decl.line, 2), "scara.toml").friction_laws[2]
    assert law.kind == "lugre" and law.scale == pytest.approx(0.0712)
    assert dict(law.presliding)["sigma0"] == pytest.approx(20300.0)


def _lugre_recording(fs: float, lugre: bool, duration: float = 40.0, seed: int = 5):
    """SCARA, exact Newton-Euler torques, joint 2's Coulomb friction replaced by LuGre (state simulation) or
    kept (the declared law: the clean control), noise on q and torque."""
    robot, model = robot_and_model("scara")
    rng = np.random.default_rng(seed)
    n = model.N_JOINTS
    amp = np.ones(n)
    amp[2] = 0.1
    t, q, dq, ddq = fourier_trajectory(n, duration, 1.0 / fs, rng, base_frequency_hz=0.3, amplitude=amp)
    chi = np.asarray(random_physical_parameters(robot, rng), float)
    if lugre:
        chi[list(robot.standard_names).index("FS2")] = 0.0
    tau = true_torques(model, q, dq, ddq, chi)
    if lugre:
        tau[:, 1] += lugre_friction(t, dq[:, 1], fc=LOOP_FC, fs=LOOP_FS, vs=LOOP_VS, sigma0=LOOP_SIGMA0)
    tr = Trajectory(t=t, q=q + 1e-5 * rng.standard_normal(q.shape), tau=tau + 0.05 * rng.standard_normal(q.shape),
                    source=f"scara {'lugre' if lugre else 'clean'} joint 2 at {fs:g} Hz")
    return model, tr


LOOP_FC, LOOP_FS, LOOP_VS, LOOP_SIGMA0 = 1.0, 1.6, 0.1, 4e3


@pytest.mark.slow
def test_lugre_law_named_at_one_kilohertz_with_its_values_and_clean_data_name_nothing():
    """With the pre-sliding laws on, at 1 kHz the loop names the LuGre law on joint 2 first, ``Fs - Fc``, ``vs`` and
    ``sigma0`` within 10 % of the truth, ``Fs - Fc`` with sigma below a third of it and within 3 sigma of the truth
    with the sigma the loop reports, which includes the uncertainty of the searched shape ``(vs, x0)``
    (:func:`symoro_gen.diagnostics.friction.shape_uncertainty`); the shape's own sigma is reported and ``vs`` and
    ``sigma0`` are within 3 of it; the same motion with the declared law (clean) names nothing.

    The case is inside what the identifiability analysis calls visible (1 kHz): at the true shape, on the loop's
    band-pass velocity, the magnitudes come out unbiased (``Fs - Fc`` 0.602 +- 0.006 at full rate), so neither the
    simulation's integration of the state nor the rate biases them. The loop's ``Fs - Fc`` follows its searched
    shape: ``vs`` a few % high, and ``Fs - Fc`` falls with ``vs`` (-6 N m per rad/s, correlation -0.7), which the
    sigma with the shape held (1.65 times narrower here) leaves out (docs/friction-dynamic.md, "Fs - Fc of the
    SCARA case")."""
    settings = DiagnoseSettings(max_effects=2, presliding_law=True)
    model, tr = _lugre_recording(1000.0, True)
    rep = diagnose(model, tr, settings)
    first = rep.effects[0]
    assert (first.kind, first.joint) == ("friction_law", 1) and first.variant.startswith("lugre"), first.variant
    k = list(first.names).index("FSS2")
    val, sd = float(first.values[k]), float(first.std[k])
    assert val == pytest.approx(LOOP_FS - LOOP_FC, rel=0.1) and sd < (LOOP_FS - LOOP_FC) / 3, (val, sd)
    assert abs(val - (LOOP_FS - LOOP_FC)) <= 3 * sd, (val, sd)
    ph = first.physical
    assert abs(ph["vs"] - LOOP_VS) <= 3 * ph["vs_std"], (ph["vs"], ph["vs_std"])
    assert abs(ph["sigma0"] - LOOP_SIGMA0) <= 3 * ph["sigma0_std"], (ph["sigma0"], ph["sigma0_std"])
    assert first.physical["vs"] == pytest.approx(LOOP_VS, rel=0.1)
    assert first.physical["sigma0"] == pytest.approx(LOOP_SIGMA0, rel=0.1)
    model, tr = _lugre_recording(1000.0, False)
    assert not diagnose(model, tr, settings).effects
