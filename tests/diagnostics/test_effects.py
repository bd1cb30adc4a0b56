"""Every effect kind, injected into a simulated recording (only t, q and tau given to the tool, noise on
q and torque), is found first, on the right joint, and lowers the validation error of that joint.

Two magnitudes/joints per kind, each with its own seed; LWR4 cases use LWR-like friction. The
identified parameter is compared with the injected one where the candidate's column is the exact
(or first-order) model of the injected effect.
"""
from __future__ import annotations

import numpy as np
import pytest

from symoro_gen.diagnostics import KINDS, diagnose

from .simdata import recording

#: (robot, kind, 0-based joint or None, injected parameters, seed, check of the identified parameters)
CASES = [
    ("scara", "stribeck", 1, dict(Fst=1.0, vs=0.1), 11, lambda e: (e.values[0], 1.0, 0.1)),
    ("scara", "stribeck", 3, dict(Fst=0.5, vs=0.05), 12, lambda e: (e.physical["vs"], 0.05, 0.2)),
    ("scara", "load_friction", 0, dict(mu=0.1), 11, lambda e: (e.values[0], 0.1, 0.1)),
    ("lwr4", "load_friction", 1, dict(mu=0.05), 12, lambda e: (e.values[0], 0.05, 0.1)),
    # the branched toy (joint 1 carries both branches), LWR-like friction (see the test below)
    ("tree_toy", "load_friction", 0, dict(mu=0.1), 11, lambda e: (e.values[0], 0.1, 0.1)),
    ("scara", "position_ripple", 1, dict(amplitude=0.5, k=6), 11, lambda e: (e.physical["amplitude"], 0.5, 0.05)),
    ("scara", "position_ripple", 3, dict(amplitude=0.2, k=10), 12, lambda e: (e.physical["k"], 10, 0.0)),
    ("scara", "spring", 0, dict(stiffness=-5.0, q0=0.2), 11, lambda e: (e.physical["dtau_dq_at_center"], -5.0, 0.05)),
    ("scara", "spring", 3, dict(stiffness=2.0), 12, lambda e: (e.physical["dtau_dq_at_center"], 2.0, 0.05)),
    ("lwr4", "elasticity", 2, dict(K=2000.0), 11, lambda e: (e.physical["K_Nm_per_rad"], 2000.0, 0.25)),
    ("lwr4", "elasticity", 3, dict(K=2000.0), 12, lambda e: (e.physical["K_Nm_per_rad"], 2000.0, 0.25)),
    ("scara", "time_delay", 0, dict(delay=0.01), 11, lambda e: (e.values[0], 0.01, 0.1)),
    ("scara", "time_delay", None, dict(delay=0.005), 12, lambda e: (e.values[0], 0.005, 0.15)),
    ("lwr4", "gain", 1, dict(g=1.1), 11, lambda e: (e.physical["g"], 1.1, 0.01)),
    ("lwr4", "gain", 3, dict(g=0.95), 12, lambda e: (e.physical["g"], 0.95, 0.01)),
    ("scara", "drift", 1, dict(rate=0.02), 11, None),
    ("scara", "drift", 3, dict(rate=0.01, quadratic=0.0005), 12, None),
    ("scara", "coupling", 1, dict(partner=3, ia=0.05, fv=0.3), 11, lambda e: (e.values[0], 0.05, 0.1)),
    ("scara", "coupling", 1, dict(partner=3, ia=0.02, fv=0.2, fs=0.5, shared=True), 12,
     lambda e: (e.values[2], 0.5, 0.1)),
    ("scara_bare", "rotor_inertia", 1, dict(ia=0.2), 11, None),
    ("scara_bare", "rotor_inertia", 3, dict(ia=0.05), 12, lambda e: (e.values[0], 0.05, 0.2)),
    ("scara_bare", "offset", 3, dict(offset=0.3), 11, lambda e: (e.values[0], 0.3, 0.05)),
    ("scara_bare", "offset", 0, dict(offset=-0.5), 12, lambda e: (e.values[0], -0.5, 0.05)),
    ("lwr4", "joint_zero", 1, dict(q0=0.026), 11, lambda e: (e.values[0], 0.026, 0.05)),
    ("lwr4", "joint_zero", 2, dict(q0=-0.015), 12, lambda e: (e.values[0], -0.015, 0.05)),
]


#: kinds whose end-to-end tests run on the independent simulator of the truth bench instead (bench/truthsim.py:
#: a neighbour's torque in a channel; a LuGre friction that holds at rest, which needs recordings with pauses;
#: a link-length error, which needs the arm built with the true geometry)
COVERED_ELSEWHERE = {"crosstalk": "test_crosstalk_held.py", "held_friction": "test_crosstalk_held.py",
                     "link_length": "test_link_length.py"}


def test_every_kind_is_covered():
    assert {c[1] for c in CASES} | set(COVERED_ELSEWHERE) == set(KINDS)
    for k in KINDS:
        if k not in COVERED_ELSEWHERE:
            assert sum(c[1] == k for c in CASES) >= 2, k


def _id(c):
    return f"{c[1]}-{c[0]}-j{'all' if c[2] is None else c[2] + 1}"


#: known regressions (measured, with the reason); the spring of SCARA joint 1 (slope -4.59 after a third-round
#: composed ripple under the acceptance split) passes since the friction-law stage competes in the loop's rounds;
#: the load-dependent friction of LWR4 joint 2, found as the composed Coulomb x |tau_hat2|, is reported as
#: load_friction with mu (compose.as_load_friction)
XFAIL: dict[str, str] = {}


@pytest.mark.slow
@pytest.mark.parametrize("case", [pytest.param(c, id=_id(c), marks=[pytest.mark.xfail(strict=True, reason=XFAIL[_id(c)])]
                                               if _id(c) in XFAIL else []) for c in CASES])
def test_injected_effect_found_first(case):
    name, kind, joint, params, seed, check = case
    model, tr = recording(name, seed, kind, joint, **params)
    rep = diagnose(model, tr)
    assert rep.effects, f"nothing found; best candidates: {[(c.label, c.score, c.reason) for c in rep.best_tried(1, 4)]}"
    # the friction-law stage (round 0) comes first; a Stribeck law chosen there on the joint *is* the
    # injected Stribeck friction (its Fs - Fc is the FSS column, its vs the searched scale)
    law = [e for e in rep.effects if e.kind == "friction_law" and e.joint == joint and e.variant.startswith("stribeck")]
    if kind == "stribeck" and law:
        first = law[0]
        if params["Fst"] == 1.0:   # case 1 checks the Stribeck excess Fs - Fc, case 2 the velocity scale
            got, want, rel = first.values[1], params["Fst"], 0.1
        else:
            got, want, rel = first.physical["vs"], params["vs"], 0.2
        assert got == pytest.approx(want, rel=rel), (got, want)
        assert rep.after_validation_rel_err[joint] < 0.98 * rep.before_validation_rel_err[joint]
        return
    loop = [e for e in rep.effects if e.kind != "friction_law"]
    assert loop, [e.label for e in rep.effects]
    first = loop[0]
    assert (first.kind, first.joint) == (kind, joint), [e.label for e in rep.effects]
    if kind == "coupling":
        assert first.partner == params["partner"]
        assert first.variant == ("shared" if params.get("shared") else "one-way")
    # the validation error of that joint drops (all joints for an effect on all joints)
    js = range(rep.n_joints) if joint is None else [joint]
    for j in js:
        assert rep.after_validation_rel_err[j] < 0.98 * rep.before_validation_rel_err[j], (
            j, rep.before_validation_rel_err, rep.after_validation_rel_err)
    # the JSON contract names it the same way
    d = rep.to_dict()["effects"][rep.effects.index(first)]
    assert d["kind"] == kind and d["joint"] == (None if joint is None else joint + 1)
    assert set(d["params"]) == set(first.names)
    if check is not None:
        got, want, rel = check(first)
        assert got == pytest.approx(want, rel=rel) if rel else got == want, (got, want)


def _stacked_share_outside(model, q, dq, ddq, col, j):
    """Share of the norm of ``col`` (on joint ``j``'s rows, zeros elsewhere) outside the span of the
    model's stacked regressor (all joints' rows: the parameters are shared between joints)."""
    R = np.asarray(model.regressor(q, dq, ddq), float)          # (N, n, k)
    N, n, k = R.shape
    W = np.transpose(R, (1, 0, 2)).reshape(n * N, k)
    c = np.zeros((n, N))
    c[j] = col
    c = c.reshape(-1)
    return float(np.linalg.norm(c - W @ np.linalg.lstsq(W, c, rcond=None)[0]) / np.linalg.norm(c))


def test_load_friction_on_friction_dominated_joints_is_a_gain():
    """Why ``load_friction`` injected on the tree toy recording of
    ``tests/identification/test_tree_identification.py`` (seed 7, default random parameters: Coulomb friction
    0.1-5 N m) is not named: there every joint's torque has the sign of its velocity at (almost) every
    sample, so ``mu |tau_j| sign(dq_j) = mu tau_j`` - a gain error of joint j, which the declared model
    absorbs except through the dynamic coupling (the column is almost in the span of the stacked
    regressor). With LWR-like friction (the CASES above) the torque reverses against the velocity and the
    same column, built the same way on the tree, lies well outside it (and is found, mu within 10 %)."""
    from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques

    from .simdata import robot_and_model

    robot, model = robot_and_model("tree_toy")
    shares = {}
    for label, seed, kw in (("default", 7, {}), ("lwr-like", 11, dict(fs_range=(0.1, 0.5), fv_range=(0.1, 1.0)))):
        rng = np.random.default_rng(seed)
        t, q, dq, ddq = fourier_trajectory(4, 40.0, 0.002, rng, base_frequency_hz=0.1,
                                           amplitude=np.array([1.0, 1.0, 0.1, 1.0]))
        chi = np.asarray(random_physical_parameters(robot, rng, **kw))
        tau = true_torques(model, q, dq, ddq, chi)
        agree = np.mean(np.sign(tau[:, 0]) == np.sign(dq[:, 0]))
        col = np.abs(tau[:, 0]) * np.sign(dq[:, 0])
        share = _stacked_share_outside(model, q, dq, ddq, col, 0)
        shares[label] = (share, agree)
        if agree == 1.0:   # the column is the joint's own torque: a gain error
            np.testing.assert_allclose(col, tau[:, 0], rtol=1e-12, atol=1e-12)
    assert shares["default"][1] > 0.99 and shares["default"][0] < 0.02, shares
    assert shares["lwr-like"][1] < 0.5 and shares["lwr-like"][0] > 0.2, shares
