"""Static friction at rest (TX40 joint 3): the rest-segment detector
(:func:`symoro_gen.diagnostics.friction.rest_segments`) and the rule that evaluates the sliding-friction
laws as 0 inside the segments, in identification and validation alike.

Simulated SCARA recordings (known base parameters, noise on q and torque). A *stop-and-go* motion runs a
random Fourier path on a clock whose rate falls smoothly to 0 and back (``q(s(t))``: the robot stops,
rests, and goes on), so the rest samples (rate exactly 0, ``dq = 0``) are known. At rest the true torque
is gravity plus a static friction torque, a constant drawn in ``[-FS/2, FS/2]`` for each rest and joint
(set-valued Coulomb friction: any value the others leave, unknown from the velocity)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics import DiagnoseSettings, diagnose, friction
from symoro_gen.diagnostics.frame import build_frame
from symoro_gen.diagnostics.friction import rest_mask, rest_segments
from symoro_gen.errors import IdentificationError
from symoro_gen.observations import AssemblyOptions
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques

DT = 0.002
NOISE_Q = 1e-5
NOISE_TAU = 0.05


def clock(t: np.ndarray, t_go: float, move: float, rest: float, ramp: float) -> tuple[np.ndarray, ...]:
    """Path clock ``s(t)``, its rate ``r = ds/dt`` and ``dr/dt``: rate 1 until ``t_go``, then cycles of
    ``move`` s at rate 1 and ``rest`` s at rate 0, joined by ``ramp``-long half-cosine ramps (C^1 rate)."""
    r = np.ones_like(t)
    dr = np.zeros_like(t)
    period = move + rest + 2 * ramp
    u = np.where(t > t_go, (t - t_go) % period, -1.0)
    down = (u >= 0) & (u < ramp)
    off = (u >= ramp) & (u < ramp + rest)
    up = (u >= ramp + rest) & (u < 2 * ramp + rest)
    x = np.where(down, u / ramp, 0.0)
    r[down] = 0.5 * (1 + np.cos(math.pi * x[down]))
    dr[down] = -0.5 * math.pi / ramp * np.sin(math.pi * x[down])
    r[off] = 0.0
    x = np.where(up, (u - ramp - rest) / ramp, 0.0)
    r[up] = 0.5 * (1 - np.cos(math.pi * x[up]))
    dr[up] = 0.5 * math.pi / ramp * np.sin(math.pi * x[up])
    s = np.concatenate([[0.0], np.cumsum(0.5 * (r[1:] + r[:-1]) * np.diff(t))])
    return s, r, dr, off


def stop_and_go(seed: int, duration: float = 36.0, t_go: float = 20.0, move: float = 2.0, rest: float = 2.0,
                ramp: float = 0.4, at_rest: str = "random"):
    """(model, moving part, stop-and-go part, rest mask of the stop-and-go part, FS of each joint).

    ``at_rest``: ``"random"`` a static torque drawn in ``[-FS/2, FS/2]`` per rest and joint, ``"zero"`` none."""
    robot, model = load_robot("scara"), symoro_gen.load_model("scara")
    rng = np.random.default_rng(seed)
    amp = np.array([1.0, 1.0, 0.1, 1.0])
    path = fourier_trajectory(4, duration, DT, rng, base_frequency_hz=0.1, amplitude=amp)
    t = path.t
    s, r, dr, off = clock(t, t_go, move, rest, ramp)
    P = path.series.evaluate(s)
    q, dq = P.q, P.dq * r[:, None]
    ddq = P.ddq * (r ** 2)[:, None] + P.dq * dr[:, None]
    chi = np.asarray(random_physical_parameters(robot, rng))
    tau = np.asarray(true_torques(model, q, dq, ddq, chi), float)
    theta = dict(zip(model.BASE_NAMES, np.asarray(model.base_parameters(chi))))
    fs = np.array([abs(theta.get(f"FS{j + 1}", 0.0)) for j in range(4)])
    # static friction at rest: one constant in [-FS/2, FS/2] per rest and joint (sign(0) = 0 above)
    edges = np.diff(np.r_[0, off.astype(int), 0])
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        draw = rng.uniform(-0.5, 0.5, 4) * fs
        tau[a:b] += draw if at_rest == "random" else 0.0
    qm = q + NOISE_Q * rng.standard_normal(q.shape)
    taum = tau + NOISE_TAU * rng.standard_normal(q.shape)
    k = int(round(t_go / DT))
    a = Trajectory(t=t[:k], q=qm[:k], tau=taum[:k], source=f"scara seed {seed} moving")
    b = Trajectory(t=t[k:], q=qm[k:], tau=taum[k:], source=f"scara seed {seed} stop-and-go")
    return model, a, b, off[k:], dq[k:], fs


# ------------------------------------------------------------------------------------------------
# the detector
# ------------------------------------------------------------------------------------------------
def test_rest_segments_of_a_noisy_stop_and_go_velocity_and_none_on_a_sinusoid():
    """The bare function: rests of 1 s in a noisy velocity are found whole; a sinusoid of the same noise
    whose reversals are as slow as 0.5 rad/s^2 gives no segment."""
    fs, sigma, f_dyn = 1000.0, 1e-3, 2.0
    rng = np.random.default_rng(0)
    t = np.arange(0, 10, 1 / fs)
    _, r, _, off = clock(t, 1.0, 1.0, 1.0, 0.2)
    v = np.sin(1.3 * t) * r + sigma * rng.standard_normal(t.size)
    m = rest_segments(v, fs, sigma, f_dyn)
    assert m.shape == v.shape and m.dtype == bool
    assert m[off].mean() > 0.97                       # the rests, nearly whole
    assert np.all(np.abs(np.sin(1.3 * t) * r)[m] < 12 * sigma)   # nothing that slides faster than the band
    # a sinusoid: reversals every 1/(2 f) s, |ddq| there = A w = 0.5 rad/s^2 (slow), no rest
    w = 2 * math.pi * 0.5
    sinus = 0.5 / w * np.sin(w * t) + sigma * rng.standard_normal(t.size)
    assert not rest_segments(sinus, fs, sigma, f_dyn).any()
    # shorter than 1/f_dyn: not a rest; 2-D input: per joint
    short = np.ones(t.size)
    short[1000:1000 + int(0.4 * fs)] = 0.0
    both = rest_segments(np.column_stack([short, v]), fs, [sigma, sigma], f_dyn)
    assert not both[:, 0].any() and np.array_equal(both[:, 1], m)


def test_rest_segments_bad_input_is_named():
    with pytest.raises(IdentificationError, match=r"run\.csv: rest segments: sampling rate"):
        rest_segments(np.zeros(10), 0.0, 1e-3, 2.0, source="run.csv")
    with pytest.raises(IdentificationError, match="velocity noise"):
        rest_segments(np.zeros((10, 2)), 100.0, [1e-3, np.nan], 2.0)


def test_rest_mask_of_a_simulated_recording_finds_the_rests_and_no_reversal():
    """Through the observations stage (band-pass velocity, noise estimated from the data): the rests of the
    stop-and-go part are detected; the moving part, with its velocity reversals, has no segment."""
    model, moving, sg, off, dq_true, _ = stop_and_go(1)
    for tr, rests in ((moving, None), (sg, off)):
        F = build_frame(model, [tr], dynamics_bandwidth_hz=1.0)
        (ex,) = F.experiments
        m = rest_mask(ex)
        assert m.shape == ex.dq.shape
        if rests is None:
            # the path reverses its joints many times here (dq crosses 0), none of it is a rest
            crossings = int(np.sum(np.diff(np.sign(ex.dq), axis=0) != 0))
            assert crossings > 20 and not m.any(), crossings
            continue
        idx = np.rint(ex.t / DT).astype(int)   # samples of the experiment (times from its start, edges dropped)
        assert idx.min() >= 0 and idx.max() < rests.size
        true_rest = rests[idx]
        e = np.diff(np.r_[0, true_rest.astype(int), 0])
        runs = [(a, b) for a, b in zip(np.flatnonzero(e == 1), np.flatnonzero(e == -1))]
        # every rest longer than 1/f_dyn (the one cut by the end of the recording is shorter: not a rest)
        whole = [(a, b) for a, b in runs if (b - a) * DT > 1.0 / ex.settings.dynamics_bandwidth_hz]
        assert len(whole) == 3 and len(runs) == 4, runs
        for j in range(4):
            for a, b in whole:
                assert m[a:b, j].mean() > 0.95, (j, a, b, m[a:b, j].mean())
            # what is flagged is a rest or the last millimetres per second of a stop
            band = friction.REST_NOISE_MULTIPLE * ex.dq_noise[j]
            assert np.all(np.abs(dq_true[idx, j])[m[:, j]] < 2 * band + 1e-9), j


# ------------------------------------------------------------------------------------------------
# the rule in the loop
# ------------------------------------------------------------------------------------------------
def _no_rest(dq, fs, noise, f_dyn, **kw):
    """The detector switched off (the loop as before the rule)."""
    return np.zeros(np.shape(dq), bool)


def _run(model, ident, valid):
    cfg = DiagnoseSettings(method="ols", candidates=("friction_law", "stribeck"), max_effects=1, structure=False,
                           unexplained=False, stability=False, n_placebo=0)
    return diagnose(model, ident, cfg, validation=valid, assembly=AssemblyOptions(dynamics_bandwidth_hz=1.0))


def _following_the_velocity_sign(model, tr: Trajectory, fs: np.ndarray) -> Trajectory:
    """``tr`` whose torque at rest (in the segments the detector finds) is ``FS sign(dq)`` of the assembly's
    band-pass velocity - the declared law's own prediction there - instead of 0: a robot on which "static
    (0) at rest" is wrong by ``FS`` at every rest sample."""
    F = build_frame(model, [tr], dynamics_bandwidth_hz=1.0)
    (ex,) = F.experiments
    idx = np.rint(ex.t / DT).astype(int)   # samples of the experiment (times from its start, edges dropped)
    rest = rest_mask(ex)
    tau = tr.tau.copy()
    for j in range(tau.shape[1]):
        m = rest[:, j]
        tau[idx[m], j] += fs[j] * np.sign(ex.dq[m, j])
    return Trajectory(t=tr.t, q=tr.q, tau=tau, source=tr.source + " (friction at rest = FS sign(dq))")


def _at_rest_rms(rep, j, rests_of=None):
    """RMS of the raw validation residual of joint ``j`` in its rest segments (those of ``rests_of``'s
    validation frame, default ``rep``'s), their sample count, and the RMS on the joint's moving samples."""
    raw = rep.plot_data["valid_raw"]
    e, jj, ridx = raw["e"], raw["joint"], raw["index"]
    (ex,) = (rests_of or rep).plot_data["vframe"].experiments
    rest = rest_mask(ex)[ridx, j]
    m, mv = (jj == j) & rest, (jj == j) & ~rest
    return float(np.sqrt(np.mean(e[m] ** 2))), int(m.sum()), float(np.sqrt(np.mean(e[mv] ** 2)))


@pytest.mark.slow   # over 5 s on this machine (CI runs the slow tests after `make test`)
def test_a_note_without_rests_to_test_it_on_is_applied_as_the_minimax_prior(monkeypatch):
    """Identification data without a rest (the moving part), validation data that stop and go: the note's
    static (0) at rest is untestable on the identification data (neither their fit nor their acceptance part
    rests), so it is applied as a prior - not accepted, not an effect, said so in the report - and it changes
    nothing identified (the fit equals the one with the rest detector switched off, where the columns are
    the same on every identification sample).

    At rest the truth is a static torque in ``[-FS/2, FS/2]`` (set-valued Coulomb friction): the loop's
    error there is that torque and the noise, below the detector-off model's (``FS sign(dq)`` of the velocity
    noise: +-FS at random). On a robot whose torque at rest followed ``FS sign(dq)`` instead (the declared
    law's own prediction; not a physical law, the worst case for the prior) the loop's error at rest stays
    within the minimax bound ``FS``."""
    model, ident, valid, off, _, fs = stop_and_go(2, at_rest="random")
    rep = _run(model, ident, valid)
    coulomb = [j for j in range(4) if fs[j] > 0.05]
    assert coulomb
    notes = {n["joint"] - 1: n for n in rep.acceptance["notes"]}
    for j in coulomb:
        n = notes[j]
        assert n["prior"] and not n["accepted"] and n["rest_share_fit"] == 0 and n["rest_share_acceptance"] == 0, n
        assert n["kind"] == "static_friction_at_rest"
    assert not [e for e in rep.effects if e.kind == "static_friction_at_rest"], rep.summary()
    lines = rep.settings["static_at_rest"]
    assert lines and all("untested" in ln and "validation samples" in ln for ln in lines), lines
    assert "Note: " + lines[0] in rep.summary()

    monkeypatch.setattr(friction, "rest_segments", _no_rest)
    off_rule = _run(model, ident, valid)
    np.testing.assert_allclose(rep.result_after.values, off_rule.result_after.values, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(rep.acceptance["final_rel_err"], off_rule.acceptance["final_rel_err"], rtol=1e-9)
    monkeypatch.undo()
    for j in coulomb:
        rms, k, _ = _at_rest_rms(rep, j)
        rms_off, _, _ = _at_rest_rms(off_rule, j, rests_of=rep)   # its frame was built with the detector off
        assert k > 1000
        assert rms < 0.5 * fs[j] + 3 * NOISE_TAU, (j, rms, fs[j])
        assert rms < rms_off, (j, rms, rms_off)

    # the worst case: the torque at rest is the declared law's FS sign(dq); 0 misses it by FS, never more (plus
    # the model's own error, the same as while moving: the prior does not touch the identified parameters)
    model, ident, valid, off, _, fs = stop_and_go(2, at_rest="zero")
    worst = _run(model, ident, _following_the_velocity_sign(model, valid, fs))
    for j in coulomb:
        rms, _, moving = _at_rest_rms(worst, j)
        assert rms < fs[j] + moving, (j, rms, fs[j], moving)


@pytest.mark.slow   # over 5 s on this machine (CI runs the slow tests after `make test`)
def test_static_at_rest_cuts_the_validation_error_where_the_robot_rests(monkeypatch):
    """Identification data that stop and go too (a moving part, then rests: the acceptance data at the end
    of each experiment hold rests), validation data that stop and go: with the rule the loop's Coulomb
    columns are 0 at rest, where the truth is an unknown static torque; without it sign(dq) of the
    velocity noise switches between +-FS there. The rule passes the acceptance test on (most of) the joints
    with Coulomb friction, is listed as an effect there, and lowers the raw validation error of those
    joints; at rest the loop's friction prediction is 0 on them."""
    model, moving, sg, off, _, fs = stop_and_go(2, duration=110.0)
    k = int(round(60.0 / DT))
    ident = [moving, Trajectory(t=sg.t[:k], q=sg.q[:k], tau=sg.tau[:k], source=sg.source + " first 60 s")]
    valid = Trajectory(t=sg.t[k:], q=sg.q[k:], tau=sg.tau[k:], source=sg.source + " after 60 s")
    off = off[k:]
    with_rule = _run(model, ident, valid)
    monkeypatch.setattr(friction, "rest_segments", _no_rest)
    without = _run(model, ident, valid)
    np.testing.assert_allclose(with_rule.before_validation_rel_err_raw, without.before_validation_rel_err_raw)
    a, b = with_rule.after_validation_rel_err_raw, without.after_validation_rel_err_raw
    named = {e.joint for e in with_rule.effects if e.kind == "static_friction_at_rest"}
    coulomb = [j for j in range(4) if fs[j] > 0.05]   # a Coulomb torque that the velocity noise can flip (N m)
    # about 4 rests in each joint's acceptance window: the held-out z of a joint can fall just short of the
    # critical value (2.8), so most - not necessarily all - Coulomb joints pass; each that does is better
    assert len(named & set(coulomb)) >= len(coulomb) - 1, with_rule.summary()
    # against the declared model (the detector switched off, the smoothing of sign(dq) that is then tested
    # alone takes most of the same gain: tanh of the velocity noise is near 0 at rest too)
    before = with_rule.before_validation_rel_err_raw
    for j in named:
        assert a[j] < 0.9 * before[j], (j, a, before)
        assert a[j] < 1.05 * b[j], (j, a, b)
    assert not [e for e in without.effects if e.kind == "static_friction_at_rest"]
    assert with_rule.settings["static_at_rest"], with_rule.settings
    assert "validation samples" in with_rule.settings["static_at_rest"][0]
    # the user sees the rule in the text and Markdown reports; a run without rests says nothing of it
    for text in (with_rule.summary(), with_rule.to_markdown()):
        assert "Note: " + with_rule.settings["static_at_rest"][0] in text
    assert not without.settings["static_at_rest"]
    assert "rest segments" not in without.summary()
    # on the joints named, the residual at rest is the static friction torque and the noise, nothing the laws
    # added: its RMS stays below that of the truth's static torque (<= FS/2) plus the torque noise
    raw = with_rule.plot_data["valid_raw"]
    e, jj, idx = raw["e"], raw["joint"], raw["index"]
    (ex,) = with_rule.plot_data["vframe"].experiments
    rest = rest_mask(ex)
    for j in named:   # the joints whose law is static at rest
        m = (jj == j) & rest[idx, j]
        assert m.sum() > 1000
        rms = float(np.sqrt(np.mean(e[m] ** 2)))
        assert rms < 0.5 * fs[j] + 3 * NOISE_TAU + 0.05 * float(np.sqrt(np.mean(raw["y"][jj == j] ** 2))), (j, rms)
