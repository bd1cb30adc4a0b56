"""The loop's ``crosstalk`` and ``held_friction`` candidates, and the elastic joint of the truth bench.

Fast tests: the priors against the bands ``docs/loop-plausibility.md`` states (cross-talk of a torque sensor up to
10 %, a held friction of the joint's Coulomb size) and the held-friction column against the simulator's analytic
motion (the sign of the velocity before each pause). Slow tests: the loop on recordings of the independent
simulator ``bench/truthsim.py`` (Pinocchio's RNEA, the effect written from its physics) finds the effect, on the
right joints, with its simulated value.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics import DiagnoseSettings, diagnose
from symoro_gen.diagnostics.candidates import Family, implausible, make_families
from symoro_gen.diagnostics.frame import build_frame, common_bandwidth
from symoro_gen.diagnostics.plausibility import PLAUSIBLE, ArmScales, effect_plausibility

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
try:
    import bench_loop_truth as blt
    import truthsim as ts
finally:
    sys.path.remove(str(ROOT / "bench"))


def _scales(n=7, tau=20.0):
    return ArmScales(dt=0.002, tau98=np.full(n, tau), v98=np.full(n, 1.0), dq_noise=np.full(n, 1e-4), n_joints=n)


def test_crosstalk_prior_and_impossible_share():
    """A torque sensor's cross-sensitivity of a few % is plausible, 30 % is not; beyond 50 % it is a mixed channel
    (impossible), and a negative held friction is impossible."""
    sc = _scales()
    for c, ok in ((0.03, True), (-0.08, True), (0.3, False)):
        pl = effect_plausibility("crosstalk", 2, {"c": c}, {"share": c, "percent": 100 * c, "from_joint": 2.0}, sc)
        assert (pl.score >= PLAUSIBLE) == ok, (c, pl)
    fam = Family("crosstalk", 2, ("c",), lambda fr, ctx: [], partner=1)
    assert fam.label == "crosstalk2>3"
    assert implausible(fam, [0.03], f_dyn=2.0) is None
    assert implausible(fam, [0.6], f_dyn=2.0) is not None
    held = Family("held_friction", 0, ("Fh",), lambda fr, ctx: [])
    assert implausible(held, [0.4], f_dyn=2.0) is None
    assert implausible(held, [-0.4], f_dyn=2.0) is not None
    # a held friction of the size of a Coulomb friction is plausible, one of the whole torque range is not
    assert effect_plausibility("held_friction", 0, {"Fh": 1.0}, {"Fh_Nm": 1.0}, sc).score == 1.0
    assert effect_plausibility("held_friction", 0, {"Fh": 40.0}, {"Fh_Nm": 40.0}, sc).score < PLAUSIBLE


@pytest.fixture(scope="module")
def cobot_recording():
    """RX-90 geometry, random physical parameters, LuGre Coulomb friction (holds at rest), two pauses."""
    robot = load_robot("rx90")
    model = symoro_gen.load_model("rx90")
    rng = np.random.default_rng(7)
    chi, _ = ts.nominal_parameters(robot, rng)
    rigid = ts.Rigid(robot, chi)
    truth = ts.Truth(FV=ts.drive_values(robot, chi, "FV"), FS=ts.drive_values(robot, chi, "FS"),
                     OFF=ts.drive_values(robot, chi, "OFF"), sigma_tau=0.05, lugre_sigma0=1e4)
    return robot, model, rigid, truth, rng


def test_held_friction_column_is_the_sign_before_each_pause(cobot_recording):
    """In a pause the column is the sign of the joint's (analytic) velocity before the pause, on every joint
    whose velocity keeps one sign over the ramp into it (a reversal inside the ramp, at a few microradians,
    is below what the band-pass velocity resolves); it is 0 while the joint slides."""
    robot, model, rigid, truth, rng = cobot_recording
    pauses = [(6.0, 8.0), (13.0, 15.5)]
    exc = ts.sum_of_sines(robot, rng, pauses=pauses)
    tr, _ = ts.record(robot, rigid, exc, truth, 20.0, 100.0, rng, "pauses")
    F = build_frame(model, [tr], dynamics_bandwidth_hz=common_bandwidth([tr]))
    t = F.samples()["t"]
    fams = {f.joint: f for f in make_families(F, ("held_friction",))}
    assert sorted(fams) == list(range(robot.n_joints))
    checked = 0
    for j, fam in fams.items():
        X = fam.build(F, None)[0][:, 0]
        col = X[F.rows_of(j)]
        for a, b in pauses:
            ramp = np.sign(exc.at(np.linspace(a - 0.45, a - 0.01, 45))[1][:, j])
            if not np.all(ramp == ramp[0]):
                continue
            checked += 1
            before = float(ramp[0])
            inside = (t > a + 0.3) & (t < b - 0.3)      # the plateau, away from the decimation filter's reach
            assert inside.sum() > 10
            np.testing.assert_allclose(col[inside], before, atol=0.03)   # (the decimation filter's ripple)
        moving = np.ones(t.size, bool)
        for a, b in pauses:
            moving &= (t < a - 1.0) | (t > b + 1.5)
        assert np.abs(col[moving]).max() < 0.03
    assert checked >= 8   # of the 12 joint-pauses


@pytest.mark.slow
def test_loop_names_the_held_friction_with_its_coulomb_value(cobot_recording):
    """On a LuGre arm with pauses the held friction of the joints with the largest Coulomb friction is named
    (verdict cause; at least two joints on these 80 s) and its value is the simulated Coulomb friction."""
    robot, model, rigid, truth, rng = cobot_recording
    files = []
    for i in range(3):
        pauses = ts.pauses_for(40.0, 0.15, rng)
        files.append(ts.record(robot, rigid, ts.sum_of_sines(robot, rng, pauses=pauses), truth, 40.0, 100.0, rng,
                               f"lugre{i}")[0])
    rep = diagnose(model, files[:2], DiagnoseSettings(candidates=("held_friction",)), validation=files[2:],
                   rng=np.random.default_rng(0))
    held = [e for e in rep.effects if e.kind == "held_friction"]
    assert len(held) >= 2, [e.label for e in rep.effects]
    for e in held:
        assert e.verdict == "cause", (e.label, e.verdict)
        fc = float(truth.FS[e.joint])
        assert abs(float(e.values[0]) - fc) < 0.25 * fc + 0.05, (e.label, float(e.values[0]), fc)
    # on the validation file the joints given a held friction predict better
    before, after = np.asarray(rep.before_validation_rel_err), np.asarray(rep.after_validation_rel_err)
    for e in held:
        assert after[e.joint] < 0.8 * before[e.joint], (e.label, before[e.joint], after[e.joint])


def _lwr4_case(number: int, seconds: float, rate: float):
    robot = load_robot("lwr4")
    model = symoro_gen.load_model("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    rigid = ts.Rigid(robot, chi)
    case = next(c for c in blt.cases() if c.number == number)
    rng = np.random.default_rng(number)
    truth = blt.lwr4_truth(robot, chi, 0.05)
    case.set_up(truth)
    ident, _ = ts.record(robot, rigid, ts.sum_of_sines(robot, rng), truth, seconds, rate, rng, "ident",
                         growth_time=seconds)
    valid, _ = ts.record(robot, rigid, ts.sum_of_sines(robot, rng), truth, seconds / 2, rate, rng, "valid",
                         growth_time=seconds)
    return model, ident, valid


@pytest.mark.slow
def test_loop_names_the_crosstalk_into_joint_3():
    """3 % of joint 2's torque read in joint 3's channel: the first effect is ``crosstalk2>3`` with c = 0.03."""
    model, ident, valid = _lwr4_case(4, 20.0, 250.0)
    rep = diagnose(model, [ident], DiagnoseSettings(), validation=[valid], rng=np.random.default_rng(4))
    first = rep.effects[0]
    assert (first.kind, first.joint, first.partner) == ("crosstalk", 2, 1), [e.label for e in rep.effects]
    assert abs(float(first.values[0]) - 0.03) < 0.003
    assert first.verdict == "cause"


@pytest.mark.slow
def test_elastic_joint_at_500_hz_is_found():
    """The motor-side encoder of an elastic joint 4 (K = 3000 N m/rad) at 500 Hz: the elasticity of joint 4 is the
    first effect, its stiffness within 10 % (a smoothed-sign nuisance column whose coefficient is beyond ten torque
    ranges of its joint is left out of the scoring design; with it the candidate predicted joint 3's acceptance
    data worse)."""
    model, ident, valid = _lwr4_case(8, 30.0, 500.0)
    rep = diagnose(model, [ident], DiagnoseSettings(candidates=("elasticity", "gain", "time_delay")),
                   validation=[valid], rng=np.random.default_rng(8))
    first = rep.effects[0]
    assert (first.kind, first.joint) == ("elasticity", 3), [e.label for e in rep.effects]
    assert abs(first.physical["K_Nm_per_rad"] - 3000.0) < 300.0
