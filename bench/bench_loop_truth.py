"""Truth bench of the diagnosis loop: does ``diagnose`` name the effect a robot really has?

Recordings come from an independent simulator (``bench/truthsim.py``: Pinocchio's RNEA on the MDH
table, an analytic sum-of-sines excitation inside the robot file's limits, friction, noise and every
effect written from its physics; neither ``symoro_gen.simulate`` nor ``symoro_gen.diagnostics.inject``
is used). Each case is the KUKA LWR4 (``robots/lwr4.toml``, its nominal parameters, unloaded) with one
effect its declared model (Coulomb + viscous friction, rigid body) lacks; the loop identifies on one
recording and validates on another (a different excitation and noise):

 1. torque delay of 10 ms on every joint (bus delay: ``tau_meas(t) = tau(t - 0.01)``)
 2. load-dependent friction on joint 2 (``mu |tau_rigid| sign(dq)``, mu = 0.04)
 3. viscous friction of joint 1 growing linearly over the recording (x2 after ``--seconds``)
 4. cross-talk: 3 % of joint 2's torque read in joint 3's torque (the loop's ``crosstalk`` kind, from joint 2)
 5. Stribeck friction on joint 4 (extra static friction 0.8 N m, vs = 0.07 rad/s)
 6. torque gain error on joint 3 (x1.15)
 7. cogging on joint 6 (0.3 N m, 10 periods per revolution)
 8. elastic joint 4 with a motor-side encoder (K = 3000 N m/rad: ``q_meas = q_link + tau/K``)
 9. encoder zero offset of 1.5 deg on joint 2 (gravity evaluated at the true angle)
10. a 40 ms torque delay on joint 5 only
11. clean control (true friction = the declared law, noise only): nothing should be named
13. link 3 is 5 mm longer than the robot file says (r of frame 3: Pinocchio's arm built with RL3 + 5 mm); right:
    the ``link_length`` family of frame 3's r first, and its value within 3 sigma of 5 mm with sigma below 5/3 mm
12. "cobot" reproducer: RX-90 geometry (6 joints, random physical parameters), 100 Hz, the recorded
    "torque" is the motor current ``tau / k_t`` (k_t per joint), smooth Coulomb friction
    ``Fc tanh(dq / 0.03)``, 11-18 % of every file at rest (pauses), three files of 50 s (identify on 1-2,
    validate on 3); the loop against the plain expert model (``diagnostics/expert.py``: base parameters
    + per-joint tanh Coulomb + viscous + offset), per joint, with ``no_worse``.
13. LuGre friction on joint 4 where its pre-sliding regime is identifiable: LWR4 at 1 kHz (``--lugre-rate``),
    the Coulomb friction of joint 4 replaced by LuGre's bristles (Canudas de Wit, Olsson, Astrom & Lischinsky
    1995 eq. 1-4, ``sigma1 = 0``: ``Fc = 0.3``, ``Fs = 0.8`` N m, ``vs = 0.07`` rad/s, ``sigma0 = 4e3`` N m/rad),
    integrated here (:func:`lugre_torque`: 16 sub-steps per sample on the analytic excitation's velocity,
    not the package's state simulation); the loop with ``presliding_law`` on. Right: the first effect is the
    ``lugre`` friction law of joint 4, its ``Fs - Fc`` within 3 sigma of 0.5 with sigma below a third of it;
    and the same robot without the LuGre friction (the declared law, the clean control at 1 kHz, on
    ``--lugre-clean-seeds`` seeds) has nothing named.

For each case it prints the truth, the effects in the order reported (kind, joint, label, modulation,
``verdict`` when the report has one), whether the right cause - or, for a kind the loop has no name for
(none since cross-talk got its `crosstalk` kind), the right joint - is the FIRST effect, and the joints whose residual
holds unexplained structure. The score line counts the single-effect cases (1-10) whose first effect is
right, and those whose first effect with verdict ``cause`` is right (when the report has verdicts).

    PYTHONPATH=. python bench/bench_loop_truth.py [--cases 1,2,...] [--seconds 30] [--rate 500] [--seed 0]
                                                  [--json out.json [--force]]

``--clean-seeds N`` runs, instead of the cases, the clean control (case 11: friction = the declared law, noise
only) on N seeds (``--seed`` .. ``--seed + N - 1``; each its own excitations and noise) and prints how many
seeds named anything, and what: the false-positive rate of the loop on data its declared model explains.

    PYTHONPATH=. python bench/bench_loop_truth.py --clean-seeds 30 --seconds 15 --rate 250
    PYTHONPATH=. python bench/bench_loop_truth.py --cases 14 --lugre-seconds 60 --lugre-clean-seeds 2
"""
from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from truthsim import Rigid, Truth, drive_values, nominal_parameters, pauses_for, record, sum_of_sines

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics import DiagnoseSettings, diagnose
from symoro_gen.identification.geometry import perturbed_robot
from symoro_gen.observations import AssemblyOptions

#: validation recording length, as a share of the identification one
VALID_SHARE = 0.5


@dataclass(frozen=True)
class Case:
    """One single-effect case: ``set_up(truth)`` adds the effect; ``right(effect)`` says whether a reported
    effect is the right cause; ``joint`` (0-based, None: every joint) is where it acts; ``named``: the loop
    has a kind for it (else only the joint is judged)."""

    number: int
    title: str
    truth: str
    joint: int | None
    set_up: Callable[[Truth], None]
    right: Callable[[object], bool]
    named: bool = True
    geometry: tuple[int, str, float] | None = None   # (frame, field, error [m]): the simulated arm's length error


def _kind(e) -> str:
    return str(getattr(e, "kind", ""))


def _j(e):
    return getattr(e, "joint", None)


def _mod(e) -> str:
    return str(getattr(e, "modulation", None) or "")


def cases() -> list[Case]:
    """The single-effect cases 1-10 and the clean control 11 (LWR4, joints 0-based in code)."""
    def add(attr, j, value):
        def f(tr: Truth):
            getattr(tr, attr)[j] = value
        return f

    def all_delay(tr: Truth):
        for j in range(len(tr.FV)):
            tr.delay[j] = 0.010

    return [
        Case(1, "delay 10 ms, all joints", "tau_meas(t) = tau(t - 10 ms) on every joint (bus delay)", None,
             all_delay, lambda e: _kind(e) == "time_delay"),
        Case(2, "load-dependent friction j2", "+ 0.04 |tau_rigid,2| sign(dq2) (Coulomb friction growing with load)", 1,
             add("load_mu", 1, 0.04),
             lambda e: _j(e) == 1 and (_kind(e) == "load_friction" or (_kind(e) == "coulomb" and "tau" in _mod(e)))),
        Case(3, "viscous drift j1", "FV1 (1 + t/T) dq1: viscous friction of joint 1 doubling over the recording", 0,
             add("viscous_growth", 0, 1.0),
             lambda e: _j(e) == 0 and _kind(e) == "viscous"
             and (_mod(e) in ("time", "temperature") or _mod(e).startswith("step"))),
        Case(4, "cross-talk j2 -> j3", "tau_meas,3 += 0.03 tau_2 (3 % of joint 2's torque in joint 3's channel)", 2,
             add("crosstalk", 1, (0.03, 2)),
             lambda e: _kind(e) == "crosstalk" and _j(e) == 2 and getattr(e, "partner", None) == 1),
        Case(5, "Stribeck j4", "+ 0.8 exp(-(dq4/0.07)^2) sign(dq4) N m (Stribeck, vs = 0.07 rad/s)", 3,
             add("stribeck", 3, (0.8, 0.07)),
             lambda e: _j(e) == 3 and (_kind(e) == "stribeck"
                                       or (_kind(e) == "friction_law" and "stribeck" in str(getattr(e, "variant", ""))))),
        Case(6, "gain x1.15 j3", "tau_meas,3 = 1.15 tau_3 (torque-measurement gain error)", 2,
             add("gain", 2, 1.15), lambda e: _j(e) == 2 and _kind(e) == "gain"),
        Case(7, "cogging j6", "+ 0.3 sin(10 q6 + 0.7) N m (cogging, 10 periods per revolution)", 5,
             add("cogging", 5, (0.3, 10.0, 0.7)),
             lambda e: _j(e) == 5 and _kind(e) in ("position_ripple", "ripple")),
        Case(8, "elastic j4 (motor encoder)", "q_meas,4 = q_link,4 + tau_4/K, K = 3000 N m/rad (motor-side encoder)", 3,
             add("stiffness", 3, 3000.0), lambda e: _kind(e) == "elasticity" and _j(e) in (3, None)),
        Case(9, "encoder offset j2", "q_meas,2 = q_2 - 1.5 deg (zero offset; gravity at the true angle)", 1,
             add("q_offset", 1, math.radians(1.5)), lambda e: _j(e) == 1 and _kind(e) == "joint_zero"),
        Case(10, "delay 40 ms j5 only", "tau_meas,5(t) = tau_5(t - 40 ms), the other joints on time", 4,
             add("delay", 4, 0.040), lambda e: _kind(e) == "time_delay" and _j(e) == 4),
        Case(11, "clean control", "friction = the declared Coulomb + viscous law, white noise only", None,
             lambda tr: None, lambda e: False),
        Case(13, "link 3 length +5 mm", "r of frame 3 (RL3) 5 mm longer on the simulated arm than in the robot file",
             2, lambda tr: None, lambda e: _kind(e) == "link_length" and str(getattr(e, "label", "")) == "link_length3r",
             geometry=(3, "r", 0.005)),
    ]


def _physical(e) -> dict:
    """The effect's physical reading (K, delay, share...), floats only."""
    return {str(k): float(v) for k, v in (getattr(e, "physical", None) or {}).items()
            if isinstance(v, (int, float)) and not isinstance(v, bool)}


def verdict_of(e):
    """The effect's verdict (``cause``/``doubtful``/``rejected``) when the report has one, else None."""
    v = getattr(e, "verdict", None)
    if v is None:
        return None
    return str(getattr(v, "value", v))


def describe_effect(e) -> str:
    j = _j(e)
    mod = f" [{_mod(e)}]" if _mod(e) else ""
    v = verdict_of(e)
    return (f"{_kind(e)} j{'-' if j is None else j + 1}{mod} ({getattr(e, 'label', '')})"
            + (f" verdict={v}" if v is not None else ""))


def lwr4_truth(robot, chi, sigma_tau: float) -> Truth:
    return Truth(FV=drive_values(robot, chi, "FV"), FS=drive_values(robot, chi, "FS"),
                 OFF=drive_values(robot, chi, "OFF"), sigma_tau=sigma_tau)


def run_case(case: Case, model, robot, chi, rigid: Rigid, a) -> dict:
    """Simulate one case (identification and validation recordings) and diagnose it."""
    seed = a.seed * 1000 + case.number
    rng = np.random.default_rng(seed)
    truth = lwr4_truth(robot, chi, a.sigma_tau)
    case.set_up(truth)
    arm = robot
    if case.geometry is not None:   # the simulated arm is built with the true (lengthened) geometry
        arm = perturbed_robot(robot, *case.geometry)
        rigid = Rigid(arm, chi)
    t0 = time.perf_counter()
    ident, _ = record(arm, rigid, sum_of_sines(robot, rng), truth, a.seconds, a.rate, rng,
                      f"case{case.number}-ident", growth_time=a.seconds)
    valid, _ = record(arm, rigid, sum_of_sines(robot, rng), truth, VALID_SHARE * a.seconds, a.rate, rng,
                      f"case{case.number}-valid", growth_time=a.seconds)
    t_sim = time.perf_counter() - t0
    rep = diagnose(model, [ident], DiagnoseSettings(), validation=[valid], rng=np.random.default_rng(seed))
    t_loop = time.perf_counter() - t0 - t_sim
    effects = list(rep.effects)
    first = effects[0] if effects else None
    right_first = bool(first is not None and case.right(first))
    causes = [e for e in effects if verdict_of(e) == "cause"]
    has_verdicts = any(verdict_of(e) is not None for e in effects)
    right_cause = bool(causes and case.right(causes[0])) if has_verdicts else None
    anywhere = [i + 1 for i, e in enumerate(effects) if case.right(e)]
    unexpl = [u.joint for u in rep.unexplained_flagged]
    within = None
    if case.geometry is not None and first is not None and case.right(first):
        v, s = float(np.ravel(first.values)[0]), float(np.ravel(first.std)[0])
        within = dict(value_mm=1e3 * v, sigma_mm=1e3 * s, within_3_sigma=bool(abs(v - case.geometry[2]) <= 3 * s),
                      sigma_below_third=bool(s < abs(case.geometry[2]) / 3))
    return dict(accuracy=within, case=case.number, title=case.title, truth=case.truth, seed=seed, named_kind=case.named,
                joint=None if case.joint is None else case.joint + 1,
                effects=[dict(kind=_kind(e), joint=None if _j(e) is None else _j(e) + 1, label=str(getattr(e, "label", "")),
                              modulation=_mod(e) or None, variant=str(getattr(e, "variant", "")), verdict=verdict_of(e),
                              description=str(getattr(e, "description", "")), physical=_physical(e))
                         for e in effects],
                first=None if first is None else describe_effect(first), right_first=right_first,
                right_first_cause=right_cause, right_at=anywhere, unexplained=unexpl,
                before_valid=[float(x) for x in rep.before_validation_rel_err],
                after_valid=[float(x) for x in rep.after_validation_rel_err],
                seconds_sim=t_sim, seconds_loop=t_loop)


def print_case(r: dict) -> None:
    print(f"\n== case {r['case']}: {r['title']} (seed {r['seed']})")
    print(f"   truth: {r['truth']}")
    if r["effects"]:
        for i, e in enumerate(r["effects"], 1):
            mod = f" [{e['modulation']}]" if e["modulation"] else ""
            v = f"  verdict={e['verdict']}" if e["verdict"] is not None else ""
            phys = ", ".join(f"{k} = {x:.4g}" for k, x in (e.get("physical") or {}).items())
            print(f"   {i}. {e['kind']} j{e['joint'] or '-'}{mod} ({e['label']}, {e['variant']}){v}: "
                  f"{e['description'][:160]}" + (f" [{phys}]" if phys else ""))
    else:
        print("   (no effect named)")
    what = "right cause" if r["named_kind"] else f"right joint (j{r['joint']}; no kind for it)"
    if r["case"] == 11:
        print(f"   clean control: nothing named: {'yes' if not r['effects'] else 'NO'}")
    else:
        extra = "" if r["right_first_cause"] is None else f"; first with verdict cause right: {r['right_first_cause']}"
        print(f"   {what} first: {'YES' if r['right_first'] else 'no'}{extra}"
              f" (right effect at position(s) {r['right_at'] or 'none'})")
    if r.get("accuracy"):
        acc = r["accuracy"]
        print(f"   value {acc['value_mm']:+.3f} mm, sigma {acc['sigma_mm']:.3f} mm: within 3 sigma of the truth "
              f"{'YES' if acc['within_3_sigma'] else 'no'}, sigma below a third {'YES' if acc['sigma_below_third'] else 'no'}")
    print(f"   unexplained joints: {r['unexplained'] or 'none'}")
    print("   validation rel. err. before: " + " ".join(f"{x:.4f}" for x in r["before_valid"]))
    print("   validation rel. err. after:  " + " ".join(f"{x:.4f}" for x in r["after_valid"]))
    print(f"   simulation {r['seconds_sim']:.1f} s, diagnose {r['seconds_loop']:.1f} s")


# ------------------------------------------------------------------------------------------------
# case 12: the cobot reproducer
# ------------------------------------------------------------------------------------------------
#: torque constants of the cobot case (joint side, gear included) [N m/A]
COBOT_KT = np.array([11.0, 11.0, 6.5, 2.2, 2.0, 1.4])


def run_cobot(a) -> dict:
    """Case 12: the loop against the plain expert model on current-as-torque recordings with pauses."""
    from symoro_gen.diagnostics.expert import expert_residuals, filtered_data, fit_expert, no_worse
    from symoro_gen.preprocessing.filtering import estimate_dynamics_bandwidth

    seed = a.seed * 1000 + 12
    rng = np.random.default_rng(seed)
    robot = load_robot("rx90")
    model = symoro_gen.load_model("rx90")
    chi, _ = nominal_parameters(robot, rng)
    rigid = Rigid(robot, chi)
    kt = np.broadcast_to(np.asarray(a.cobot_kt, float), (robot.n_joints,)).copy()
    truth = Truth(FV=drive_values(robot, chi, "FV"), FS=drive_values(robot, chi, "FS"),
                  OFF=drive_values(robot, chi, "OFF"), coulomb_v=0.03, k_t=kt, sigma_tau=0.05,
                  lugre_sigma0=1e4 if a.cobot_friction == "lugre" else None)
    law = ("LuGre Coulomb (sigma0 = 1e4 N m/rad: the friction holds at rest)" if a.cobot_friction == "lugre"
           else "Fc tanh(dq/0.03)")
    rate = 100.0
    seconds = a.cobot_seconds
    files, shares = [], []
    t0 = time.perf_counter()
    for i in range(3):
        share = rng.uniform(0.11, 0.18)
        pauses = pauses_for(seconds, share, rng)
        exc = sum_of_sines(robot, rng, pauses=pauses)
        tr, sig = record(robot, rigid, exc, truth, seconds, rate, rng, f"cobot-file{i + 1}")
        files.append(tr)
        shares.append(float(np.mean(np.all(np.abs(sig["dq"]) < 1e-12, axis=1))))
    t_sim = time.perf_counter() - t0
    ident, valid = files[:2], files[2:]
    n = robot.n_joints
    fdyn = max(estimate_dynamics_bandwidth(tr.q, 1.0 / tr.dt) for tr in ident)
    data = filtered_data(ident, dynamics_bandwidth_hz=fdyn)
    vdata = filtered_data(valid, dynamics_bandwidth_hz=fdyn)
    ex = fit_expert(model, data)
    e_f, e_r = ex.errors(model, vdata)
    ex_filt, ex_raw = expert_residuals(model, ex, vdata)
    rep = diagnose(model, ident, DiagnoseSettings(), validation=valid,
                   assembly=AssemblyOptions(dynamics_bandwidth_hz=fdyn), rng=np.random.default_rng(seed))
    t_loop = time.perf_counter() - t0 - t_sim
    ok_f, d_f, se_f = no_worse(rep.plot_data["valid_filtered"], ex_filt, n)
    ok_r, d_r, se_r = no_worse(rep.plot_data["valid_raw"], ex_raw, n)
    return dict(case=12, title="cobot reproducer (RX-90 geometry, currents, pauses)", seed=seed,
                truth=f"tau/k_t with k_t = {kt.tolist()} N m/A; {law} + Fv dq + offset; "
                      f"3 files of {seconds:g} s at 100 Hz; identify on files 1-2, validate on file 3",
                rest_share=shares,
                effects=[dict(kind=_kind(e), joint=None if _j(e) is None else _j(e) + 1, label=str(getattr(e, "label", "")),
                              modulation=_mod(e) or None, variant=str(getattr(e, "variant", "")), verdict=verdict_of(e),
                              description=str(getattr(e, "description", "")), physical=_physical(e))
                         for e in rep.effects],
                held_truth=[float(x) for x in truth.FS / kt],
                expert_v=[float(v) for v in ex.v],
                declared_filt=[float(x) for x in rep.before_validation_rel_err],
                expert_filt=[float(x) for x in e_f], loop_filt=[float(x) for x in rep.after_validation_rel_err],
                declared_raw=[float(x) for x in rep.before_validation_rel_err_raw],
                expert_raw=[float(x) for x in e_r], loop_raw=[float(x) for x in rep.after_validation_rel_err_raw],
                loop_worse_filt=[j + 1 for j in range(n) if not ok_f[j]],
                loop_worse_raw=[j + 1 for j in range(n) if not ok_r[j]],
                diff_filt=[float(x) for x in d_f], se_filt=[float(x) for x in se_f],
                diff_raw=[float(x) for x in d_r], se_raw=[float(x) for x in se_r],
                unexplained=[u.joint for u in rep.unexplained_flagged],
                static_at_rest=list(rep.settings.get("static_at_rest") or []),
                friction_law_choices=list(rep.settings.get("friction_law_choices") or []),
                seconds_sim=t_sim, seconds_loop=t_loop)


def print_cobot(r: dict) -> None:
    print(f"\n== case 12: {r['title']} (seed {r['seed']})")
    print(f"   truth: {r['truth']}")
    print("   samples at rest (every joint): " + ", ".join(f"file {i + 1} {100 * s:.1f} %"
                                                          for i, s in enumerate(r["rest_share"])))
    for i, e in enumerate(r["effects"], 1):
        mod = f" [{e['modulation']}]" if e["modulation"] else ""
        v = f"  verdict={e['verdict']}" if e["verdict"] is not None else ""
        phys = ", ".join(f"{k} = {x:.4g}" for k, x in (e.get("physical") or {}).items())
        held = (f" (truth Fc/k_t = {r['held_truth'][e['joint'] - 1]:.4g})"
                if e["kind"] == "held_friction" and e["joint"] else "")
        print(f"   {i}. {e['kind']} j{e['joint'] or '-'}{mod} ({e['label']}, {e['variant']}){v}: {e['description'][:160]}"
              + (f" [{phys}]" if phys else "") + held)
    if not r["effects"]:
        print("   (no effect named)")
    for line in r["static_at_rest"]:
        print(f"   static at rest: {line}")
    print("   expert tanh scales v: " + " ".join(f"{v:.3g}" for v in r["expert_v"]) + " rad/s (truth 0.03)")
    n = len(r["expert_filt"])
    print(f"   {'validation ||rho_j||/||Y_j||':28s}" + "".join(f"    j{j + 1:<3d}" for j in range(n)))
    for lab, key in (("declared (before)  filt", "declared_filt"), ("expert             filt", "expert_filt"),
                     ("loop (after)       filt", "loop_filt"), ("declared (before)  raw ", "declared_raw"),
                     ("expert             raw ", "expert_raw"), ("loop (after)       raw ", "loop_raw")):
        print(f"   {lab:28s}" + "".join(f" {x:7.4f}" for x in r[key]))
    print("   loop - expert (rel^2) filt / 2 SE: " + " ".join(f"{d:+.1e}/{2 * s:.1e}"
                                                             for d, s in zip(r["diff_filt"], r["se_filt"])))
    print("   loop - expert (rel^2) raw  / 2 SE: " + " ".join(f"{d:+.1e}/{2 * s:.1e}"
                                                             for d, s in zip(r["diff_raw"], r["se_raw"])))
    print(f"   loop worse than the expert beyond 2 SE: filtered {r['loop_worse_filt'] or 'none'}, "
          f"raw {r['loop_worse_raw'] or 'none'}")
    print(f"   unexplained joints: {r['unexplained'] or 'none'}")
    print(f"   simulation {r['seconds_sim']:.1f} s, expert + diagnose {r['seconds_loop']:.1f} s")


# ------------------------------------------------------------------------------------------------
# case 14: LuGre friction where its pre-sliding regime is identifiable (1 kHz)
# ------------------------------------------------------------------------------------------------
#: the last case number
LAST_CASE = 14
#: case 14: joint (0-based) and its LuGre friction (Fc, Fs [N m], vs [rad/s], sigma0 [N m/rad])
LUGRE_JOINT = 3
LUGRE = (0.3, 0.8, 0.07, 4e3)
#: sub-steps per sample interval of :func:`lugre_torque`
LUGRE_SUBSTEPS = 16


def lugre_torque(t: np.ndarray, v: np.ndarray, fc: float, fs: float, vs: float, sigma0: float) -> np.ndarray:
    """LuGre friction ``sigma0 z`` (Canudas de Wit, Olsson, Astrom & Lischinsky 1995, eq. 1-4 with
    ``sigma1 = 0``): ``dz/dt = v - sigma0 |v| z / g(v)``, ``g(v) = Fc + (Fs - Fc) exp(-(v/vs)^2)``, ``z(0) = 0``.
    Each sample interval is cut into :data:`LUGRE_SUBSTEPS` sub-steps with the velocity interpolated linearly
    and held at each sub-step's centre, where the equation is linear in ``z`` and integrated exactly."""
    z = 0.0
    out = np.zeros(v.size)
    frac = (np.arange(LUGRE_SUBSTEPS) + 0.5) / LUGRE_SUBSTEPS
    for k in range(1, v.size):
        h = (t[k] - t[k - 1]) / LUGRE_SUBSTEPS
        for vv in v[k - 1] + (v[k] - v[k - 1]) * frac:
            g = fc + (fs - fc) * math.exp(-(vv / vs) ** 2)
            target = g * math.copysign(1.0, vv) / sigma0 if vv != 0 else z
            z = target + (z - target) * math.exp(-sigma0 * abs(vv) * h / g)
        out[k] = sigma0 * z
    return out


@dataclass
class LuGreTruth(Truth):
    """:class:`truthsim.Truth` with LuGre friction added on some joints (their ``FS`` set to 0 by the caller)."""

    lugre: dict = field(default_factory=dict)             # j -> (Fc, Fs, vs, sigma0)

    def friction(self, t: np.ndarray, dq: np.ndarray, tau_r: np.ndarray, T: float) -> np.ndarray:
        f = super().friction(t, dq, tau_r, T)
        for j, (fc, fs, vs, s0) in self.lugre.items():
            f[:, j] += lugre_torque(t, dq[:, j], fc, fs, vs, s0)
        return f


def _lugre_run(a, model, robot, chi, rigid: Rigid, seed: int, lugre: bool) -> dict:
    """One identification + validation pair at ``a.lugre_rate`` (LuGre on joint 4 or the clean control) and
    the loop with the pre-sliding laws on."""
    rng = np.random.default_rng(seed)
    base = lwr4_truth(robot, chi, a.sigma_tau)
    truth = LuGreTruth(FV=base.FV, FS=base.FS.copy(), OFF=base.OFF, sigma_tau=a.sigma_tau)
    if lugre:
        truth.FS[LUGRE_JOINT] = 0.0
        truth.lugre[LUGRE_JOINT] = LUGRE
    t0 = time.perf_counter()
    ident, _ = record(robot, rigid, sum_of_sines(robot, rng), truth, a.lugre_seconds, a.lugre_rate, rng,
                      "case13-ident")
    valid, _ = record(robot, rigid, sum_of_sines(robot, rng), truth, VALID_SHARE * a.lugre_seconds, a.lugre_rate,
                      rng, "case13-valid")
    t_sim = time.perf_counter() - t0
    rep = diagnose(model, [ident], DiagnoseSettings(presliding_law=True), validation=[valid],
                   rng=np.random.default_rng(seed))
    effects = []
    for e in rep.effects:
        d = dict(kind=_kind(e), joint=None if _j(e) is None else _j(e) + 1, label=str(getattr(e, "label", "")),
                 variant=str(getattr(e, "variant", "")), verdict=verdict_of(e), physical=_physical(e),
                 params={str(nm): (float(v), float(s)) for nm, v, s in zip(e.names, e.values, e.std)})
        effects.append(d)
    return dict(seed=seed, effects=effects, seconds_sim=t_sim, seconds_loop=time.perf_counter() - t0 - t_sim,
                before_valid=[float(x) for x in rep.before_validation_rel_err],
                after_valid=[float(x) for x in rep.after_validation_rel_err])


def lugre_right(r: dict) -> tuple[bool, str]:
    """Case 14's judgement of the injected run: the first effect is joint 4's ``lugre`` law, ``Fs - Fc`` (its
    ``FSS4``) within 3 sigma of the truth and sigma below a third of the truth."""
    if not r["effects"]:
        return False, "nothing named"
    e = r["effects"][0]
    if not (e["kind"] == "friction_law" and e["joint"] == LUGRE_JOINT + 1 and e["variant"].startswith("lugre")):
        return False, f"first effect {e['kind']} j{e['joint']} ({e['variant']})"
    fc, fs, _, s0 = LUGRE
    val, sd = e["params"].get(f"FSS{LUGRE_JOINT + 1}", (math.nan, math.nan))
    ok = abs(val - (fs - fc)) <= 3 * sd and sd < (fs - fc) / 3
    return ok, (f"Fs - Fc = {val:.4g} ± {sd:.2g} (truth {fs - fc:g}: {abs(val - (fs - fc)) / sd:.1f} sigma), "
                f"vs = {e['physical'].get('vs', math.nan):.3g} ± {e['physical'].get('vs_std', math.nan):.2g} "
                f"(truth {LUGRE[2]:g}), sigma0 = {e['physical'].get('sigma0', math.nan):.4g} ± "
                f"{e['physical'].get('sigma0_std', math.nan):.2g} (truth {s0:g})")


def run_lugre(a, model, robot, chi, rigid: Rigid) -> dict:
    """Case 14: LuGre on joint 4 at ``a.lugre_rate``, and the clean control at that rate on
    ``a.lugre_clean_seeds`` seeds."""
    inj = _lugre_run(a, model, robot, chi, rigid, a.seed * 1000 + 13, True)
    ok, why = lugre_right(inj)
    print(f"case 14, injected (diagnose {inj['seconds_loop']:.0f} s): right {'YES' if ok else 'no'}: {why}", flush=True)
    clean = []
    for k in range(a.lugre_clean_seeds):
        c = _lugre_run(a, model, robot, chi, rigid, (a.seed + k) * 1000 + 113, False)
        clean.append(c)
        named = "; ".join(f"{e['kind']} j{e['joint'] or '-'} ({e['variant']}, {e['verdict']})" for e in c["effects"])
        print(f"case 14, clean {k + 1}/{a.lugre_clean_seeds} (rng seed {c['seed']}, diagnose "
              f"{c['seconds_loop']:.0f} s): {named or 'nothing named'}", flush=True)
    fc, fs, vs, s0 = LUGRE
    return dict(case=14, title=f"LuGre friction j{LUGRE_JOINT + 1} at {a.lugre_rate:g} Hz (pre-sliding laws on)",
                truth=f"joint {LUGRE_JOINT + 1}: LuGre Fc = {fc:g}, Fs = {fs:g} N m, vs = {vs:g} rad/s, sigma0 = "
                      f"{s0:g} N m/rad in place of its Coulomb friction; {a.lugre_seconds:g} s + "
                      f"{VALID_SHARE * a.lugre_seconds:g} s at {a.lugre_rate:g} Hz",
                injected=inj, right=ok, why=why, clean=clean, rate=a.lugre_rate,
                clean_named=sum(bool(c["effects"]) for c in clean), right_first=ok)


def print_lugre(r: dict) -> None:
    print(f"\n== case 14: {r['title']}")
    print(f"   truth: {r['truth']}")
    inj = r["injected"]
    for i, e in enumerate(inj["effects"], 1):
        phys = ", ".join(f"{k} = {x:.4g}" for k, x in e["physical"].items())
        print(f"   {i}. {e['kind']} j{e['joint'] or '-'} ({e['label']}, {e['variant']}) verdict={e['verdict']}"
              + (f" [{phys}]" if phys else ""))
    if not inj["effects"]:
        print("   (no effect named)")
    print(f"   right (lugre law of joint {LUGRE_JOINT + 1} first, Fs - Fc within 3 sigma, sigma < a third): "
          f"{'YES' if r['right'] else 'no'}: {r['why']}")
    print("   validation rel. err. before: " + " ".join(f"{x:.4f}" for x in inj["before_valid"]))
    print("   validation rel. err. after:  " + " ".join(f"{x:.4f}" for x in inj["after_valid"]))
    for c in r["clean"]:
        named = "; ".join(f"{e['kind']} j{e['joint'] or '-'} ({e['variant']})" for e in c["effects"]) or "nothing named"
        print(f"   clean control (rng seed {c['seed']}): {named}   [diagnose {c['seconds_loop']:.0f} s]")
    print(f"   simulation {inj['seconds_sim']:.1f} s, diagnose {inj['seconds_loop']:.1f} s")
    if r["clean"]:
        cause = sum(any(e["verdict"] == "cause" for e in c["effects"]) for c in r["clean"])
        print(f"   clean controls at {r['rate']:g} Hz: {r['clean_named']}/{len(r['clean'])} seeds named anything "
              f"({cause} with verdict cause)")


# ------------------------------------------------------------------------------------------------
# the clean bench: the clean control on many seeds
# ------------------------------------------------------------------------------------------------
def run_clean_seeds(a, model, robot, chi, rigid: Rigid) -> dict:
    """Case 11 on seeds ``a.seed`` .. ``a.seed + a.clean_seeds - 1``: what each seed names (nothing is right)."""
    clean = next(c for c in cases() if c.number == 11)
    rows = []
    base_seed = a.seed
    try:
        for k in range(a.clean_seeds):
            a.seed = base_seed + k
            r = run_case(clean, model, robot, chi, rigid, a)
            named = [f"{e['kind']} j{e['joint'] or '-'}" + (f" [{e['modulation']}]" if e["modulation"] else "")
                     + (f" ({e['verdict']})" if e["verdict"] else "") for e in r["effects"]]
            print(f"   seed {a.seed:3d} (rng seed {r['seed']}): " + ("; ".join(named) if named else "nothing named")
                  + f"   [diagnose {r['seconds_loop']:.1f} s]")
            sys.stdout.flush()
            rows.append(dict(seed=a.seed, rng_seed=r["seed"], named=named, unexplained=r["unexplained"],
                             causes=[x for x in named if x.endswith("(cause)")]))
    finally:
        a.seed = base_seed
    kinds: dict[str, int] = {}
    for row in rows:
        for x in row["named"]:
            key = x.split(" [")[0].split(" (")[0]
            kinds[key] = kinds.get(key, 0) + 1
    return dict(seeds=rows, n=len(rows), n_named=sum(bool(r["named"]) for r in rows),
                n_cause=sum(bool(r["causes"]) for r in rows), named_counts=kinds)


def parse_cases(text: str) -> list[int]:
    out = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        if "-" in part:
            lo, hi = (int(x) for x in part.split("-"))
            out += list(range(lo, hi + 1))
        else:
            out.append(int(part))
    bad = [c for c in out if not 1 <= c <= LAST_CASE]
    if bad:
        raise SystemExit(f"--cases: unknown case(s) {bad}; the cases are 1-{LAST_CASE}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=f"1-{LAST_CASE}", help=f"e.g. 1,2,5 or 1-11 (default all, 1-{LAST_CASE})")
    ap.add_argument("--seconds", type=float, default=30.0,
                    help="identification recording [s] (validation: half as long); default 30")
    ap.add_argument("--rate", type=float, default=500.0, help="sampling rate [Hz] of cases 1-11 (default 500)")
    ap.add_argument("--cobot-seconds", type=float, default=50.0, help="length of each cobot file [s] (case 12)")
    ap.add_argument("--cobot-kt", default=",".join(f"{x:g}" for x in COBOT_KT),
                    help="torque constants [N m/A] of case 12, one per joint or one for all (default "
                         + ",".join(f"{x:g}" for x in COBOT_KT) + ")")
    ap.add_argument("--cobot-friction", choices=("tanh", "lugre"), default="tanh",
                    help="Coulomb law of case 12: tanh(dq/0.03) (0 at rest) or LuGre bristles (holds at rest)")
    ap.add_argument("--sigma-tau", type=float, default=0.05, help="torque noise [N m] (default 0.05)")
    ap.add_argument("--lugre-rate", type=float, default=1000.0, help="sampling rate [Hz] of case 14 (default 1000)")
    ap.add_argument("--lugre-seconds", type=float, default=60.0,
                    help="identification recording of case 14 [s] (validation: half as long); default 60")
    ap.add_argument("--lugre-clean-seeds", type=int, default=1,
                    help="case 14: clean controls (no LuGre) at the same rate, on this many seeds (default 1)")
    ap.add_argument("--seed", type=int, default=0, help="base seed (case k uses 1000 seed + k)")
    ap.add_argument("--clean-seeds", type=int, default=0,
                    help="run only the clean control (case 11) on this many seeds and count what is named")
    ap.add_argument("--json", default=None, help="write the results to this JSON file")
    ap.add_argument("--force", action="store_true", help="overwrite an existing --json file")
    a = ap.parse_args(argv)
    if a.json and Path(a.json).exists() and not a.force:
        print(f"{a.json} exists: not overwritten (use --force)", file=sys.stderr)
        return 2
    wanted = parse_cases(a.cases)
    try:
        a.cobot_kt = [float(x) for x in str(a.cobot_kt).split(",")]
    except ValueError:
        raise SystemExit(f"--cobot-kt: expected numbers separated by commas, got {a.cobot_kt!r}") from None
    if len(a.cobot_kt) not in (1, 6) or min(a.cobot_kt) <= 0:
        raise SystemExit(f"--cobot-kt: give 1 or 6 positive torque constants (joints 1-6), got {a.cobot_kt}")
    T0 = time.perf_counter()
    robot = load_robot("lwr4")
    model = symoro_gen.load_model("lwr4")
    chi, _ = nominal_parameters(robot)
    rigid = Rigid(robot, chi)
    print(f"loop truth bench: LWR4 nominal parameters (unloaded), identification {a.seconds:g} s + validation "
          f"{VALID_SHARE * a.seconds:g} s at {a.rate:g} Hz, torque noise {a.sigma_tau:g} N m, q noise 1e-5 rad")
    if a.clean_seeds > 0:
        print(f"clean bench: case 11 on {a.clean_seeds} seeds ({a.seed} .. {a.seed + a.clean_seeds - 1})")
        cb = run_clean_seeds(a, model, robot, chi, rigid)
        wall = time.perf_counter() - T0
        print(f"\nclean bench: {cb['n_named']}/{cb['n']} seeds named anything ({cb['n_cause']} with verdict cause); "
              + ("named: " + ", ".join(f"{k} x{v}" for k, v in sorted(cb["named_counts"].items()))
                 if cb["named_counts"] else "nothing named on any seed"))
        print(f"wall time {wall:.0f} s")
        if a.json:
            Path(a.json).write_text(json.dumps(dict(args=vars(a), clean_bench=cb, wall_s=wall), indent=1))
        return 0
    results = []
    for c in cases():
        if c.number in wanted:
            r = run_case(c, model, robot, chi, rigid, a)
            print_case(r)
            results.append(r)
            sys.stdout.flush()
    if 12 in wanted:
        r = run_cobot(a)
        print_cobot(r)
        results.append(r)
    if 14 in wanted:
        r = run_lugre(a, model, robot, chi, rigid)
        print_lugre(r)
        results.append(r)
    single = [r for r in results if 1 <= r["case"] <= 10 or r["case"] == 13]
    x = sum(r["right_first"] for r in single)
    with_v = [r for r in single if r["right_first_cause"] is not None]
    y = f"{sum(r['right_first_cause'] for r in with_v)}/{len(single)}" if with_v else "n/a (no verdicts in the report)"
    clean = [r for r in results if r["case"] == 11]
    clean_s = ("yes" if not clean[0]["effects"] else "no") if clean else "not run"
    wall = time.perf_counter() - T0
    print("\n| case | truth | first effect | right? |\n| --- | --- | --- | --- |")
    for r in results:
        if r["case"] <= 11 or r["case"] == 13:
            ok = ("yes" if not r["effects"] else "no") if r["case"] == 11 else ("yes" if r["right_first"] else "no")
            print(f"| {r['case']} | {r['title']} | {r['first'] or '(none)'} | {ok} |")
    print(f"\nright cause first: {x}/{len(single)} (with verdict cause: {y}); clean control: nothing named: {clean_s}")
    print(f"wall time {wall:.0f} s")
    if a.json:
        Path(a.json).write_text(json.dumps(dict(args=vars(a), results=results, right_first=x, n_single=len(single),
                                                clean_nothing_named=clean_s, wall_s=wall), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
