"""Coupled (mimic) joints, ``q_m = multiplier * q_s + offset``: the robot-file syntax and its
errors, the model (the tree projected on the actuated joints by the constant ``G``), the closed-form
groupings, identification, and a robot with both a loop and a coupling.

References, each computed here without symoro_gen's closure or projection:

* the numeric Newton-Euler of the tree at the coupled state written by hand, projected by hand
  (``tau_s + multiplier * tau_m``);
* sympy's Euler-Lagrange equation of a planar two-link toy with ``q2 = k q1 + b`` (energies of the links
  from their standard parameters at the frame origin, Khalil & Dombre 2002 ch. 9);
* simulated data with known parameters (identification within 3 sigma).
"""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from symoro_gen import load_model
from symoro_gen.baseparams.regroup import group_base_parameters
from symoro_gen.closedloop import ClosedLoopModel
from symoro_gen.closedloop.grouping import closed_form_base
from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.dynamics.newton_euler import build_regressor
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.emit.closedloop import closed_loop_files
from symoro_gen.emit.package import build_in_memory
from symoro_gen.errors import RobotFileError
from symoro_gen.identification import ObservationSystem
from symoro_gen.identification.estimators import fit_ols
from symoro_gen.simulate.parameters import random_physical_parameters

from .test_closed_form_base import check_against_numeric

#: a spatial toy: turret 1, shoulder 2, a revolute joint 3 geared to 2 (q3 = -2 q2 + pi/6), and two prismatic
#: fingers 4, 5 on the turret, finger 5 following finger 4 at half its stroke (q5 = q4 / 2)
TOY = """
name = "coupled_toy"
gravity = [0, 0, -9.81]
[values]
L2 = 0.4
[[frames]]
j = 1
ant = 0
sigma = 0
alpha = 0
d = 0
theta = "q"
r = 0
[[frames]]
j = 2
ant = 1
sigma = 0
alpha = "pi/2"
d = 0
theta = "q"
r = 0
[[frames]]
j = 3
ant = 2
sigma = 0
alpha = 0
d = "L2"
theta = "q"
r = 0
mimic = { joint = 2, multiplier = MULT, offset = OFF }
[[frames]]
j = 4
ant = 1
sigma = 1
alpha = "-pi/2"
d = 0.1
theta = 0
r = "q"
[[frames]]
j = 5
ant = 1
sigma = 1
alpha = "pi/2"
d = 0.1
theta = 0
r = "q"
mimic = { joint = 4, multiplier = 0.5 }
"""


def toy_text(mult: str = "-2", off: str = '"pi/6"') -> str:
    return TOY.replace("MULT", mult).replace("OFF", off)


@pytest.fixture(scope="module")
def toy():
    robot = parse_robot_text(toy_text(), file="coupled_toy.toml")
    return robot, ClosedLoopModel(robot, build_in_memory(robot))


def by_hand(q, dq, ddq):
    """The tree state of the toy written out: q3 = -2 q2 + pi/6, q5 = q4 / 2 (rates without the offset)."""
    def tree(x, off):
        return np.stack([x[:, 0], x[:, 1], -2 * x[:, 1] + off, x[:, 2], 0.5 * x[:, 2]], axis=1)
    return tree(q, np.pi / 6), tree(dq, 0.0), tree(ddq, 0.0)


def test_robot_file_couplings_and_the_model_joints(toy):
    robot, model = toy
    assert [(c.joint, c.source) for c in robot.couplings] == [(3, 2), (5, 4)]
    assert robot.couplings[0].multiplier == -2 and robot.couplings[0].offset == sp.pi / 6
    assert [r.mu for r in robot.joints] == [1, 1, 0, 1, 0]
    assert robot.row(3).drive == () and robot.row(5).drive == ()  # passive: no drive terms
    assert [r.j for r in robot.model_joints] == [1, 2, 4] == list(model.ACTUATED_JOINTS)


def test_actuated_torques_equal_the_tree_newton_euler_projected_by_hand(toy):
    robot, model = toy
    rng = np.random.default_rng(3)
    q, dq, ddq = rng.uniform(-1.5, 1.5, (3, 40, 3))
    qt, dqt, ddqt = by_hand(q, dq, ddq)
    st = model.closure(q, dq, ddq)
    np.testing.assert_allclose(st.q, qt, atol=1e-14)
    np.testing.assert_allclose(st.ddq, ddqt, atol=1e-14)
    for _ in range(3):
        chi = rng.normal(size=len(model.STANDARD_NAMES))
        t = inverse_dynamics(robot, qt, dqt, ddqt, chi)
        ref = np.stack([t[:, 0], t[:, 1] - 2 * t[:, 2], t[:, 3] + 0.5 * t[:, 4]], axis=1)
        tau = model.torque(q, dq, ddq, chi)
        np.testing.assert_allclose(tau, ref, atol=1e-9 * np.abs(ref).max())


# ---- sympy Lagrangian of a planar two-link toy with q2 = k q1 + b -------------------------------------------
L1 = 0.45
G_PLANE = (0.0, -9.81, 0.0)


def planar_text(k: str, b: str) -> str:
    return f"""
name = "planar_coupled"
gravity = [{G_PLANE[0]}, {G_PLANE[1]}, {G_PLANE[2]}]
[values]
L1 = {L1}
[[frames]]
j = 1
ant = 0
sigma = 0
alpha = 0
d = 0
theta = "q"
r = 0
[[frames]]
j = 2
ant = 1
sigma = 0
alpha = 0
d = "L1"
theta = "q"
r = 0
mimic = {{ joint = 1, multiplier = {k}, offset = {b} }}
"""


def lagrangian_torque(k: float, b: float):
    """tau1(q1, qd1, qdd1, parameters) of the one-degree-of-freedom chain, by sympy's Euler-Lagrange."""
    t = sp.Symbol("t")
    q1 = sp.Function("q1")(t)
    P = {n: sp.Symbol(n) for n in ("ZZ1", "MX1", "MY1", "M1", "ZZ2", "MX2", "MY2", "M2", "IA1", "FV1", "FS1", "OFF1")}
    g = sp.Matrix(G_PLANE)
    links = [(q1, sp.Matrix([0, 0, 0]), "1"),
             (q1 + (k * q1 + b), sp.Matrix([L1 * sp.cos(q1), L1 * sp.sin(q1), 0]), "2")]  # absolute angle, origin
    L = sp.S(0)
    for th, p, j in links:
        R = sp.Matrix([[sp.cos(th), -sp.sin(th), 0], [sp.sin(th), sp.cos(th), 0], [0, 0, 1]])
        w = sp.Matrix([0, 0, sp.diff(th, t)])
        v = sp.diff(p, t)
        MS = R * sp.Matrix([P["MX" + j], P["MY" + j], 0])
        T = P["M" + j] * v.dot(v) / 2 + v.dot(w.cross(MS)) + P["ZZ" + j] * w[2] ** 2 / 2
        U = -g.dot(P["M" + j] * p + MS)
        L += T - U
    qd = sp.diff(q1, t)
    tau = sp.diff(sp.diff(L, qd), t) - sp.diff(L, q1)
    x, v, a = sp.symbols("x v a")
    tau = tau.subs(sp.diff(q1, t, 2), a).subs(qd, v).subs(q1, x)
    tau += P["IA1"] * a + P["FV1"] * v + P["FS1"] * sp.sign(v) + P["OFF1"]
    return sp.lambdify([x, v, a, *P.values()], tau, "numpy"), list(P)


@pytest.mark.parametrize("k, b", [(2.0, 0.4), (-1.5, 0.3)])
def test_planar_two_link_coupled_equals_the_sympy_lagrangian(k, b):
    robot = parse_robot_text(planar_text(repr(k), repr(b)), file="planar_coupled.toml")
    model = ClosedLoopModel(robot, build_in_memory(robot))
    f, names = lagrangian_torque(k, b)
    rng = np.random.default_rng(5)
    q, dq, ddq = rng.uniform(-2, 2, (3, 30, 1))
    for _ in range(3):
        chi = rng.normal(size=len(model.STANDARD_NAMES))
        vals = [chi[model.STANDARD_NAMES.index(n)] for n in names]
        ref = f(q[:, 0], dq[:, 0], ddq[:, 0], *vals)
        tau = model.torque(q, dq, ddq, chi)[:, 0]
        np.testing.assert_allclose(tau, ref, atol=1e-9 * max(1.0, np.abs(ref).max()))


def test_closed_form_groupings_and_the_emitted_regressor_of_a_coupled_robot(toy):
    """The closure is exact by construction; the closed-form base parameters span the numeric base regressor
    and reproduce the projected Newton-Euler torques; ``_closed_loop.py`` equals the numeric model."""
    robot, model = toy
    bp = group_base_parameters(build_regressor(robot))
    cf = closed_form_base(robot, bp.base_names, bp.kept, bp.relations, bp.gravity)
    assert cf is not None and cf.closure.error == 0.0
    assert cf.closure.lines() == ["q3 = -2*q2 + pi/6", "q5 = q4/2"]
    rng = np.random.default_rng(8)
    q, dq, ddq = rng.uniform(-1.5, 1.5, (3, 60, 3))
    K = check_against_numeric(robot, model, cf, q, dq, ddq, seed=8)
    files = closed_loop_files(robot, bp)
    assert "exact by construction" in files["closed_loop_base_parameters.md"]
    ns: dict = {}
    exec(compile(files["_closed_loop.py"], "_closed_loop.py", "exec"), ns)  # noqa: S102 - generated code under test
    assert ns["BASE_NAMES"] == cf.names and ns["ACTUATED_JOINTS"] == (1, 2, 4)
    chi = rng.normal(size=len(model.STANDARD_NAMES))
    np.testing.assert_allclose(ns["regressor"](q, dq, ddq) @ (K @ chi), model.torque(q, dq, ddq, chi), atol=1e-9)


def test_casadi_regressor_of_a_coupled_robot_equals_the_projected_model(toy):
    """The CasADi form (``A^T W_tree(A q + b)``, the offset pi/6 included) that ``excite`` optimises on, against
    the numeric projection."""
    _, model = toy
    F = model.casadi_regressor()
    q, dq, ddq = np.random.default_rng(5).uniform(-1.5, 1.5, (3, 10, 3))
    Wc = np.array([np.array(F(q[i], dq[i], ddq[i])) for i in range(len(q))])
    np.testing.assert_allclose(Wc, model.regressor(q, dq, ddq), atol=1e-12)


def test_a_non_integer_revolute_multiplier_keeps_numeric_groupings_with_the_reason():
    robot = parse_robot_text(planar_text("-1.5", "0.3"), file="planar_coupled.toml")
    bp = group_base_parameters(build_regressor(robot))
    files = closed_loop_files(robot, bp)
    assert "_closed_loop.py" not in files
    assert "non-integer multiple" in files["closed_loop_base_parameters.md"]


def test_identification_on_simulated_data_of_a_coupled_robot_recovers_the_base_parameters(toy):
    robot, model = toy
    rng = np.random.default_rng(21)
    t = np.arange(0, 20, 0.01)
    n = 3
    scale = np.array([0.5, 0.5, 0.05])  # rad, rad, m
    q, dq, ddq = (np.zeros((t.size, n)) for _ in range(3))
    for k in range(1, 6):  # 5-harmonic Fourier motion per joint (Swevers 1997)
        wk = 2 * np.pi * 0.1 * k
        a, b = rng.uniform(-0.25, 0.25, (2, n)) * scale / k
        q += np.sin(wk * t)[:, None] * a - np.cos(wk * t)[:, None] * b
        dq += wk * (np.cos(wk * t)[:, None] * a + np.sin(wk * t)[:, None] * b)
        ddq += wk**2 * (-np.sin(wk * t)[:, None] * a + np.cos(wk * t)[:, None] * b)
    chi = np.asarray(random_physical_parameters(robot, rng))
    qt, dqt, ddqt = by_hand(q, dq, ddq)
    tt = inverse_dynamics(robot, qt, dqt, ddqt, chi)
    tau = np.stack([tt[:, 0], tt[:, 1] - 2 * tt[:, 2], tt[:, 3] + 0.5 * tt[:, 4]], axis=1)
    sigma = np.array([0.3, 0.3, 0.2])
    Y = tau + rng.normal(size=tau.shape) * sigma
    W = model.regressor(q, dq, ddq)
    system = ObservationSystem(np.transpose(W, (1, 0, 2)).reshape(-1, W.shape[2]), Y.T.reshape(-1),
                               model.BASE_NAMES, np.repeat(np.arange(n), t.size))
    res = fit_ols(system)
    z = (res.values - model.base_parameters(chi)) / res.std
    assert np.all(np.abs(z) < 3.0), dict(zip(model.BASE_NAMES, np.round(z, 2)))


# ---- a loop and a coupling together -------------------------------------------------------------------------
def palletizer_with_coupling() -> str:
    text = Path(load_robot("palletizer").file).read_text(encoding="utf-8").split("\n[limits]", 1)[0]  # 3 passive joints
    frame7 = ('[[frames]]  # a tool turned by a belt from the turret: q7 = 2 q1 - 0.5\nj = 7\nant = 4\nsigma = 0\n'
              'alpha = "pi/2"\nd = 0.2\ntheta = "q"\nr = 0.1\nmimic = { joint = 1, multiplier = 2, offset = -0.5 }\n\n')
    head, tail = text.split("[[loops]]", 1)
    return head + frame7 + "[[loops]]" + tail


def test_a_loop_and_a_coupling_together_equal_the_newton_euler_projected_by_hand():
    """The palletizer's parallelogram (q3 = q5 - q2, q6 = q2 - q5) and a coupled joint 7 on the wrist
    (q7 = 2 q1 - 0.5): the solver handles both constraint kinds; reference: the tree's numeric Newton-Euler
    at the hand-written closure, projected by the hand-written constant A."""
    robot = parse_robot_text(palletizer_with_coupling(), file="palletizer_coupled.toml")
    assert robot.loops and [c.joint for c in robot.couplings] == [7]
    model = ClosedLoopModel(robot, build_in_memory(robot))
    assert model.ACTUATED_JOINTS == (1, 2, 4, 5)
    A = np.zeros((7, 4))
    A[[0, 1, 3, 4], [0, 1, 2, 3]] = 1
    A[2, [1, 3]] = [-1, 1]   # q3 = q5 - q2
    A[5, [1, 3]] = [1, -1]   # q6 = q2 - q5
    A[6, 0] = 2              # q7 = 2 q1 - 0.5
    b = np.zeros(7)
    b[6] = -0.5
    rng = np.random.default_rng(4)
    q, dq, ddq = rng.uniform(-0.5, 0.5, (3, 30, 4))
    st = model.closure(q, dq, ddq)
    np.testing.assert_allclose(st.q, q @ A.T + b, atol=1e-10)
    chi = rng.normal(size=len(model.STANDARD_NAMES))
    ref = inverse_dynamics(robot, q @ A.T + b, dq @ A.T, ddq @ A.T, chi) @ A
    np.testing.assert_allclose(model.torque(q, dq, ddq, chi), ref, atol=1e-9 * np.abs(ref).max())


# ---- robot-file errors: one line naming the file, the frame and the field -----------------------------------
@pytest.mark.parametrize("edit, where, field, words", [
    (("joint = 2,", "joint = 9,"), "frame 3", "mimic.joint", "not a frame of this robot"),
    (("joint = 2,", "joint = 3,"), "frame 3", "mimic.joint", "cannot follow itself"),
    (("joint = 4, multiplier = 0.5", "joint = 3, multiplier = 0.5"), "frame 5", "mimic.joint", "itself coupled"),
    (("multiplier = -2", "multiplier = 0"), "frame 3", "mimic.multiplier", "non-zero"),
    (("multiplier = -2", "multiplier = inf"), "frame 3", "mimic.multiplier", "finite"),
    (("multiplier = -2", 'multiplier = "sqrt(-1)"'), "frame 3", "mimic.multiplier", "not real"),
    (('offset = "pi/6"', 'offset = "L2"'), "frame 3", "mimic.offset", "unknown name"),
    (('offset = "pi/6"', 'offset = "pi/6", gear = 2'), "frame 3", "mimic.gear", "unknown field"),
    (('theta = "q"\nr = 0\nmimic', 'theta = "q"\nr = 0\nmu = 1\nmimic'), "frame 3", "mu", "passive"),
    (("mimic = { joint = 2", "mimic = 2\nx = { joint = 2"), "frame 3", "mimic", "must be a table"),
])
def test_bad_couplings_are_one_line_naming_file_frame_and_field(edit, where, field, words):
    text = toy_text().replace(*edit)
    assert text != toy_text()
    if "x = {" in text:  # the table moved to an unknown key: drop it
        text = text.replace("\nx = { joint = 2, multiplier = -2, offset = \"pi/6\" }", "")
    with pytest.raises(RobotFileError) as info:
        parse_robot_text(text, file="arm.toml")
    probs = info.value.problems
    assert len(probs) == 1, [str(p) for p in probs]
    p = probs[0]
    assert (p.file, p.where, p.field) == ("arm.toml", where, field) and words in p.message, str(p)


def test_a_coupling_to_a_passive_later_or_fixed_joint_is_an_error():
    base = toy_text()
    later = base.replace("mimic = { joint = 2, multiplier = -2, offset = \"pi/6\" }", "").replace(
        'r = "q"\nmimic = { joint = 4, multiplier = 0.5 }', 'r = "q"')
    later = later.replace('theta = "q"\nr = 0\n[[frames]]\nj = 3', 'theta = "q"\nr = 0\nmimic = { joint = 3 }\n[[frames]]\nj = 3', 1)
    with pytest.raises(RobotFileError, match=r"arm.toml, frame 2, field 'mimic.joint': joint 3 comes after frame 2"):
        parse_robot_text(later, file="arm.toml")
    passive = base.replace('theta = 0\nr = "q"\n[[frames]]\nj = 5', 'theta = 0\nr = "q"\nmu = 0\n[[frames]]\nj = 5')
    with pytest.raises(RobotFileError) as info:
        parse_robot_text(passive, file="arm.toml")
    got = {(p.where, p.field) for p in info.value.problems}
    assert ("frame 5", "mimic.joint") in got  # follows the passive joint 4 ...
    assert ("frame 4", "mu") in got           # ... which is on no loop and follows nothing
    fixed = base + '[[frames]]\nj = 6\nant = 5\nsigma = 2\nalpha = 0\nd = 0\ntheta = 0\nr = 0\nmimic = { joint = 1 }\n'
    with pytest.raises(RobotFileError, match=r"frame 6, field 'mimic': a fixed frame"):
        parse_robot_text(fixed, file="arm.toml")


# ---- the generated package and load_model ------------------------------------------------------------------
def test_load_model_of_a_coupled_robot_file_is_the_projected_model(tmp_path):
    f = tmp_path / "coupled_toy.toml"
    f.write_text(toy_text(), encoding="utf-8")
    model = load_model(f)
    assert isinstance(model, ClosedLoopModel) and model.ACTUATED_JOINTS == (1, 2, 4)
    man = json.loads((tmp_path / "generated" / "coupled_toy" / "manifest.json").read_text(encoding="utf-8"))
    assert man["couplings"] == 2 and "closed_loops" not in man
    assert "_closed_loop.py" in man["files"]
    spec = importlib.util.spec_from_file_location("cl", tmp_path / "generated" / "coupled_toy" / "_closed_loop.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    rng = np.random.default_rng(2)
    q, dq, ddq = rng.uniform(-1, 1, (3, 10, 3))
    assert mod.BASE_NAMES == model.BASE_NAMES
    np.testing.assert_allclose(mod.regressor(q, dq, ddq), model.regressor(q, dq, ddq), atol=1e-9)


# ---- exports --------------------------------------------------------------------------------------------------
def test_export_mjcf_writes_couplings_as_joint_equalities_and_export_par_refuses_them(toy):
    """MuJoCo's joint equality ``q1 = polycoef(q2)`` holds the coupling in a simulation of the exported model;
    SYMORO's .par has no coupled joint: an error naming the frame."""
    from symoro_gen.description.mjcf_export import export_mjcf
    from symoro_gen.description.par import export_par

    mujoco = pytest.importorskip("mujoco")
    robot, _ = toy
    rng = np.random.default_rng(1)
    xml = export_mjcf(robot, np.asarray(random_physical_parameters(robot, rng)))
    assert '<joint joint1="joint3" joint2="joint2" polycoef="0.523598775598298' in xml  # pi/6, -2
    m = mujoco.MjModel.from_xml_string(xml)
    assert m.neq == 2 and m.nu == 3  # two equalities, motors on the actuated joints only
    d = mujoco.MjData(m)
    d.qpos[:] = [0.3, 0.2, 0.3 * -2 + np.pi / 6 + 0.05, 0.01, 0.005]  # slightly off the coupling
    for _ in range(2000):
        mujoco.mj_step(m, d)
    assert abs(d.qpos[2] - (-2 * d.qpos[1] + np.pi / 6)) < 1e-2  # pulled back onto it (soft constraint)
    assert abs(d.qpos[4] - 0.5 * d.qpos[3]) < 1e-3
    with pytest.raises(RobotFileError, match=r"coupled_toy.toml, frame 3, field 'mimic'.*no SYMORO .par"):
        export_par(robot)


def test_identify_cli_on_a_coupled_robot_file(tmp_path, cli):
    """`symoro-gen identify coupled_toy.toml rec.csv`: the recordings log the actuated joints 1, 2, 4 only."""
    from symoro_gen.simulate.recording import simulate_recording, write_recording_csv

    from .test_cli_identify import fourier

    f = tmp_path / "coupled_toy.toml"
    f.write_text(toy_text(), encoding="utf-8")
    robot, model = load_robot(f), load_model(f)
    rng = np.random.default_rng(5)
    chi = np.asarray(random_physical_parameters(robot, rng))
    files = []
    for k in range(2):
        t = np.arange(0, 20, 0.002)
        tr = simulate_recording(model, t, *fourier(rng, t, 3, amp=0.25), chi, noise_q=1e-6, noise_tau=0.05, rng=rng)
        write_recording_csv(tmp_path / f"rec{k}.csv", tr)
        files.append(tmp_path / f"rec{k}.csv")
    out = tmp_path / "res.json"
    cli("--quiet", "identify", f, files[0], "--validate", files[1], "--method", "ols", "--json", out)
    d = json.loads(out.read_text())
    assert d["parameters"]["names"] == list(model.BASE_NAMES)
    assert len(d["validation"]["rel_err"]) == 3 and max(d["validation"]["rel_err"]) < 0.05
    v, s = np.array(d["parameters"]["values"]), np.array(d["parameters"]["std"], float)
    assert np.mean(np.abs(v - model.base_parameters(chi)) <= 3 * s) > 0.9
