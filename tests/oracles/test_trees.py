"""Tree-structured robots end to end: a branching 3-link toy, the SDA10F dual-arm torso
(``robots/sda10f.toml``: a waist carrying two 7-joint arms) and random trees.

References, independent of the symbolic model: the plain numeric Newton-Euler
(:mod:`symoro_gen.dynamics.numeric`), Pinocchio's RNEA on a model built from the MDH table
(:mod:`tests.oracles.pinocchio_model`) and Pinocchio's RNEA on the URDF of the same tree
(``pin.buildModelFromXML`` on :func:`symoro_gen.description.urdf_export.export_urdf`), matched by joint
name. Base parameters: their number equals the numeric rank of the standard regressor, the base
regressor times the closed-form relations gives the standard torques, and a branch's parameters
regroup only onto its own antecedents (Khalil & Kleinfinger 1986 for the tree notation; the grouping
rules of Gautier & Khalil 1990 with ``a(j)`` for ``j - 1``, as SYMORO+ applies them to trees,
Khalil & Bennis 1995).
"""
from __future__ import annotations

import functools

import numpy as np
import pinocchio as pin
import pytest
import sympy as sp
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import symoro_gen
from symoro_gen.baseparams.regroup import numeric_rank
from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.description.urdf_export import export_urdf
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.emit.package import build_in_memory
from symoro_gen.params import split_name
from symoro_gen.simulate import random_payload, random_physical_parameters, random_states
from tests.strategies import mdh_trees

from .pinocchio_model import max_relative_error, pin_torque, random_parameters

RTOL = 1e-9

#: the branching 3-link toy: a vertical waist (frame 1) carrying a revolute arm (frame 2) and, on a
#: second branch (gamma, b: the common normal is not x1), a prismatic arm (frame 3) with a wrist (frame 4)
TOY = """
name = "toy_tree"
gravity = [0, 0, -9.81]
payload = 5

[values]
D2 = 0.3
B3 = 0.12
D3 = 0.2
RL4 = 0.15

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
d = "D2"
theta = "q"
r = 0

[[frames]]
j = 3
ant = 1
sigma = 1
gamma = "2*pi/3"
b = "B3"
alpha = "-pi/2"
d = "D3"
theta = 0
r = "q + 0.1"

[[frames]]
j = 4
ant = 3
sigma = 0
alpha = "pi/2"
d = 0
theta = "q"
r = "RL4"

[[frames]]
j = 5
ant = 2
sigma = 2
alpha = 0
d = 0.1
theta = 0
r = 0
"""


@functools.cache
def toy():
    robot = parse_robot_text(TOY, file="toy_tree.toml")
    return robot, build_in_memory(robot)


@functools.cache
def torso():
    return load_robot("sda10f"), symoro_gen.load_model("sda10f")


def subtree(robot, k: int) -> set[int]:
    """Frame k and every frame it carries."""
    out = {k}
    for r in robot.rows:
        if r.ant in out:
            out.add(r.j)
    return out


def urdf_torque(robot, q, dq, ddq, chi):
    """Pinocchio's RNEA on the URDF export of ``robot`` carrying ``chi`` (IA and OFF, which URDF cannot
    carry, added here; gravity from the robot file), in the robot's joint order (Pinocchio's own order matched by joint name)."""
    model = pin.buildModelFromXML(export_urdf(robot, chi))
    model.gravity = pin.Motion(np.asarray(robot.gravity, float), np.zeros(3))  # URDF has no gravity field
    data = model.createData()
    assert model.nv == robot.n_joints
    idx = [model.joints[model.getJointId(f"joint{r.j}")].idx_v for r in robot.joints]
    vals = dict(zip(robot.standard_names, chi))
    IA = np.array([vals.get(f"IA{r.j}", 0.0) for r in robot.joints])
    OFF = np.array([vals.get(f"OFF{r.j}", 0.0) for r in robot.joints])
    out = []
    for qk, vk, ak in zip(q, dq, ddq):
        Q, V, A = (np.zeros(model.nv) for _ in range(3))
        Q[idx], V[idx], A[idx] = qk, vk, ak
        tau = pin.rnea(model, data, Q, V, A) + model.damping * V + model.friction * np.sign(V)
        out.append(tau[idx])
    return np.array(out) + IA * ddq + OFF


# ---- the toy and the torso -------------------------------------------------------------------
@pytest.mark.parametrize("which", ["toy", "torso"])
def test_emitted_regressor_equals_numeric_newton_euler_and_pinocchio(which):
    """Emitted NumPy/C regressor (toy: NumPy in memory; torso: the committed package) == numeric
    Newton-Euler == Pinocchio (MDH oracle, and the URDF of the tree) on random states."""
    robot, m = toy() if which == "toy" else torso()
    rng = np.random.default_rng(13)
    q, dq, ddq = random_states(rng, 12, robot.n_joints)
    # rigid bodies (triangle inequalities hold: URDF export writes them unchanged)
    chi = np.asarray(random_physical_parameters(robot, rng))
    pay = np.asarray(random_payload(rng, robot=robot)) if robot.payload is not None else None
    ref = inverse_dynamics(robot, q, dq, ddq, chi, pay)
    tau = m.regressor(q, dq, ddq) @ m.base_parameters(chi)
    if pay is not None:
        tau = tau + m.payload_regressor(q, dq, ddq) @ pay
    assert max_relative_error(tau, ref) < RTOL
    assert max_relative_error(m.standard_regressor(q, dq, ddq) @ chi + (0 if pay is None else
                              m.payload_regressor(q, dq, ddq) @ pay), ref) < RTOL
    assert max_relative_error(pin_torque(robot, q, dq, ddq, chi, pay), ref) < RTOL
    ref0 = inverse_dynamics(robot, q, dq, ddq, chi)  # the URDF export carries no payload
    assert max_relative_error(urdf_torque(robot, q, dq, ddq, chi), ref0) < RTOL


def test_torso_casadi_and_c_backends_equal_numpy():
    robot, m = torso()
    rng = np.random.default_rng(3)
    q, dq, ddq = random_states(rng, 6, robot.n_joints)
    Wn = m._MODEL.numpy_only().regressor(q, dq, ddq)
    f = m.casadi_regressor()
    Wc = np.stack([np.array(f(q[k], dq[k], ddq[k])) for k in range(len(q))])
    assert np.max(np.abs(Wc - Wn)) <= RTOL * np.abs(Wn).max()
    if m.BACKEND != "c":
        pytest.skip("no C compiler here: only the NumPy backend is available")
    assert np.max(np.abs(m.regressor(q, dq, ddq) - Wn)) <= RTOL * np.abs(Wn).max()


@pytest.mark.parametrize("which", ["toy", "torso"])
def test_base_count_is_numeric_rank(which):
    robot, m = toy() if which == "toy" else torso()
    rng = np.random.default_rng(4)
    q, dq, ddq = random_states(rng, 60, robot.n_joints)
    Ws = m.standard_regressor(q, dq, ddq).reshape(-1, len(m.STANDARD_NAMES))
    assert numeric_rank(Ws) == len(m.BASE_NAMES)
    Wb = m.regressor(q, dq, ddq).reshape(-1, len(m.BASE_NAMES))
    assert numeric_rank(Wb) == len(m.BASE_NAMES)


def test_torso_arms_regroup_onto_their_own_branch():
    """Each base parameter of link k combines standard parameters of k's subtree only: the right arm's
    parameters (frames 9..15) reach the waist (frame 1) but never the left arm (2..8), and conversely;
    the two arms, mirror images, get the same number of base parameters."""
    from symoro_gen.baseparams.regroup import group_base_parameters
    from symoro_gen.dynamics.newton_euler import build_regressor

    robot, m = torso()
    bp = group_base_parameters(build_regressor(robot))
    assert bp.base_names == m.BASE_NAMES
    for name in bp.base_names:
        k = split_name(name.rstrip("R"))[1]
        frames = {split_name(s.name)[1] for s in bp.relations[name].free_symbols if s.name in robot.standard_names}
        assert frames <= subtree(robot, k), (name, frames)
    waist = sp.expand(bp.relations["ZZ1R"]).free_symbols
    assert {sp.Symbol(n, real=True) for n in ("YY2", "YY9", "M8", "M15")} <= waist  # both branches onto ant 1
    left = [n for n in bp.base_names if 2 <= split_name(n.rstrip("R"))[1] <= 8]
    right = [n for n in bp.base_names if 9 <= split_name(n.rstrip("R"))[1] <= 15]
    assert len(left) == len(right) == 76
    assert not bp.numeric


def test_toy_branch_rules():
    """The prismatic branch (frame 3 on frame 1): its rotation inertia moves onto frame 1 (its
    antecedent, rotated by 1_R_3); the revolute frames' YY, MZ, M move onto their own antecedents."""
    from symoro_gen.baseparams.regroup import group_base_parameters
    from symoro_gen.dynamics.newton_euler import build_regressor

    robot, m = toy()
    bp = group_base_parameters(build_regressor(robot))
    assert {"XX3", "XY3", "XZ3", "YY3", "YZ3", "ZZ3"} <= set(bp.eliminated)
    S = {n: sp.Symbol(n, real=True) for n in robot.standard_names}
    # 1_R_3 = Rz(2 pi/3) Rx(-pi/2) maps z1 onto -y3: link 3's inertia adds YY3 to ZZ1; link 2 (revolute,
    # d = D2) adds YY2 + D2^2 M2; link 3's mass does not move (its distance to axis 1 varies with q3)
    zz1 = sp.expand(bp.relations["ZZ1R"] - S["ZZ1"] - S["IA1"])
    assert sp.simplify(zz1 - (S["YY3"] + S["YY2"] + sp.Symbol("D2", real=True) ** 2 * S["M2"])) == 0, zz1
    # link 4 (revolute on the prismatic branch) regroups onto link 3, its own antecedent
    assert sp.expand(bp.relations["M3R"] - S["M3"] - S["M4"]) == 0
    for name in bp.base_names:
        k = split_name(name.rstrip("R"))[1]
        frames = {split_name(s.name)[1] for s in bp.relations[name].free_symbols if s.name in robot.standard_names}
        assert frames <= subtree(robot, k), (name, frames)


# ---- random trees ------------------------------------------------------------------------------
@settings(max_examples=25, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(text=mdh_trees(2, 14, random_gravity=True), seed=st.integers(0, 2**32 - 1))
def test_numeric_newton_euler_matches_pinocchio_on_random_trees(text, seed):
    robot = parse_robot_text(text)
    rng = np.random.default_rng(seed)
    chi, pay = random_parameters(robot, rng)
    q, dq, ddq = random_states(rng, 6, robot.n_joints)
    ref = pin_torque(robot, q, dq, ddq, chi, pay)
    assert max_relative_error(inverse_dynamics(robot, q, dq, ddq, chi, pay), ref) < RTOL
    chi = np.asarray(random_physical_parameters(robot, rng))  # rigid bodies: exported to URDF unchanged
    ref = inverse_dynamics(robot, q, dq, ddq, chi)
    assert max_relative_error(urdf_torque(robot, q, dq, ddq, chi), ref) < RTOL


@settings(max_examples=6, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(text=mdh_trees(2, 14))
def test_pipeline_identities_on_random_trees(text):
    """Generated model (emitted NumPy kernels) == numeric Newton-Euler; base identity; base count == rank."""
    robot = parse_robot_text(text, file="random_tree.toml")
    m = build_in_memory(robot)
    rng = np.random.default_rng(0)
    n = robot.n_joints
    q, dq, ddq = random_states(rng, 20, n)
    chi = rng.normal(size=len(m.STANDARD_NAMES))
    pay = rng.normal(size=len(m.PAYLOAD_NAMES)) if m.PAYLOAD_NAMES else None
    ref = inverse_dynamics(robot, q, dq, ddq, chi, pay)
    assert np.max(np.abs(m.torque(q, dq, ddq, chi, pay) - ref)) <= RTOL * max(1.0, np.abs(ref).max())
    Ws, Wb = m.standard_regressor(q, dq, ddq), m.regressor(q, dq, ddq)
    assert np.max(np.abs(Wb @ m.base_parameters(chi) - Ws @ chi)) <= RTOL * max(1.0, np.abs(Ws @ chi).max())
    q, dq, ddq = random_states(rng, max(40, 8 * n), n)
    assert numeric_rank(m.standard_regressor(q, dq, ddq).reshape(-1, len(m.STANDARD_NAMES))) == len(m.BASE_NAMES), text


def test_tree_strategy_branches_anywhere():
    """The strategy draws branches on the base, on inner frames, several children per frame, and
    gamma/b on branch rows (checked on a derandomized sample)."""
    from hypothesis import Phase, find

    def draws(pred):
        text = find(mdh_trees(2, 14), lambda t: pred(parse_robot_text(t)),
                    settings=settings(max_examples=2000, database=None, deadline=None, phases=[Phase.generate],
                                      suppress_health_check=list(HealthCheck)))
        return parse_robot_text(text)

    assert sum(x.ant == 0 for x in draws(lambda r: sum(x.ant == 0 for x in r.joints) >= 2).joints) >= 2
    draws(lambda r: any(len([x for x in r.joints if x.ant == k]) >= 3 for k in range(1, r.n_joints)))
    assert draws(lambda r: r.n_joints == 14 and any(x.ant not in (0, x.j - 1) for x in r.joints)).n_joints == 14
    draws(lambda r: any(x.ant != x.j - 1 and x.gamma != 0 and x.b != 0 for x in r.joints))
    draws(lambda r: any(x.ant != x.j - 1 and x.sigma == 1 for x in r.joints))  # a prismatic branch


@pytest.mark.parametrize("which", ["toy", "torso"])
def test_symoro_par_round_trip_keeps_the_tree(which):
    """SYMORO ``.par`` export of a tree (``Type = 1``, the ``Ant`` list) and import back: the same frames
    and the same torques."""
    from symoro_gen.description.par import export_par, import_par_text

    robot = toy()[0] if which == "toy" else torso()[0]
    par = export_par(robot)
    assert "Type = 1 (* Tree *)" in par.splitlines()
    back = parse_robot_text(import_par_text(par, file=f"{robot.name}.par"), file="back.toml")
    assert [(r.j, r.ant, r.sigma) for r in back.rows] == [(r.j, r.ant, r.sigma) for r in robot.rows]
    rng = np.random.default_rng(2)
    q, dq, ddq = random_states(rng, 5, robot.n_joints)
    chi = rng.normal(size=len(robot.standard_names))
    pay = rng.normal(size=10) if robot.payload is not None else None
    np.testing.assert_allclose(inverse_dynamics(back, q, dq, ddq, chi, pay), inverse_dynamics(robot, q, dq, ddq, chi, pay),
                               rtol=1e-12, atol=1e-12)
