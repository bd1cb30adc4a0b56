"""Closed loops from URDF: ``<loop_joint>`` + ``<transmission>`` -> ``[[loops]]`` and passive joints.

* the palletizer exported to URDF (``export_urdf`` writes the loop joint and the transmissions) and imported
  again gives the same actuated torques as ``robots/palletizer.toml`` (different MDH frames, same robot);
* a four-bar written by hand against an independent computation: Pinocchio RNEA on its open tree (the URDF
  without the loop) at the closed state of the crank-rocker's closed form (sympy derivatives), projected by
  ``G^T`` computed in the test;
* malformed loop elements -> one error naming the file, the element and the field.
"""
from __future__ import annotations

import functools
import math

import numpy as np
import pinocchio as pin
import pytest
import sympy as sp

from symoro_gen import load_model
from symoro_gen.closedloop import ClosedLoopModel
from symoro_gen.description import load_robot, parse_robot_text, robots_dir
from symoro_gen.description.urdf import import_urdf_text
from symoro_gen.description.urdf_export import export_urdf
from symoro_gen.emit.package import build_in_memory
from symoro_gen.errors import RobotFileError
from symoro_gen.simulate.parameters import random_physical_parameters


def closed_model(urdf: str, file: str, **kw) -> ClosedLoopModel:
    robot = parse_robot_text(import_urdf_text(urdf, file=file, **kw), file=file)
    return ClosedLoopModel(robot, build_in_memory(robot))


# ---------------------------------------------------------------------------------------------------
# palletizer: robot file -> URDF (loop_joint) -> robot file
# ---------------------------------------------------------------------------------------------------
def test_palletizer_through_urdf_gives_the_same_actuated_torques():
    pal = load_robot("palletizer")
    ref_model = load_model("palletizer")
    rng = np.random.default_rng(13)
    chi = np.array(random_physical_parameters(pal, rng).values, float)
    names = list(pal.standard_names)
    for k, n in enumerate(names):  # URDF has no rotor inertia nor offset; passive joints have no drive terms
        if n.startswith(("IA", "OFF")) or (n.startswith(("FV", "FS")) and pal.row(int(n[2:])).mu == 0):
            chi[k] = 0.0
    report: list[str] = []
    urdf = export_urdf(pal, chi, report=report)
    assert report == [] and "<loop_joint" in urdf and urdf.count("<transmission") == 4
    model = closed_model(urdf, "palletizer.urdf")
    assert model.ACTUATED_JOINTS == (1, 2, 4, 5)  # same tree order as the robot file
    assert len(model.robot.loops) == 1 and [r.j for r in model.robot.joints if r.mu == 0] == [3, 6]
    q = rng.uniform(-0.6, 0.6, (30, 4))
    dq, ddq = rng.normal(0, 1.5, (30, 4)), rng.normal(0, 4, (30, 4))
    tau_ref = ref_model.torque(q, dq, ddq, chi)
    tau = model.torque(q, dq, ddq, model.nominal_parameters())
    assert np.abs(tau_ref).max() > 10.0
    np.testing.assert_allclose(tau, tau_ref, rtol=0, atol=1e-9 * np.abs(tau_ref).max())
    # the passive joints solved from the imported loop are the parallelogram's (q3 = q5 - q2)
    st = model.closure(q, dq, ddq)
    np.testing.assert_allclose(st.q[:, 2], q[:, 3] - q[:, 1], atol=1e-10)
    assert len(model.BASE_NAMES) == len(ref_model.BASE_NAMES)


# ---------------------------------------------------------------------------------------------------
# four-bar: hand-written URDF against Pinocchio + closed form
# ---------------------------------------------------------------------------------------------------
A, BC, C, D = 0.20, 0.45, 0.40, 0.50  # crank, coupler, rocker, ground (crank-rocker)
GRAV = (0.0, -9.81, 0.0)  # in the plane x-y of the mechanism (axes along z)


@functools.lru_cache(maxsize=1)
def closed_form_sym():
    """Absolute coupler and rocker angles (upper assembly) as sympy functions of the crank angle."""
    q = sp.Symbol("q", real=True)
    bx, by = A * sp.cos(q), A * sp.sin(q)
    ex, ey = D - bx, -by
    e = sp.sqrt(ex**2 + ey**2)
    a = (BC**2 - C**2 + e**2) / (2 * e)
    h = sp.sqrt(BC**2 - a**2)
    cx, cy = bx + (a * ex - h * ey) / e, by + (a * ey + h * ex) / e
    ph2, ph3 = sp.atan2(cy - by, cx - bx), sp.atan2(cy, cx - D)
    return [sp.lambdify(q, [f, sp.diff(f, q), sp.diff(f, q, 2)], "math") for f in (ph2, ph3)]


def inertial(m, c, I):
    return (f'<inertial><origin xyz="{c[0]} {c[1]} {c[2]}" rpy="0.3 -0.2 0.1"/><mass value="{m}"/>'
            f'<inertia ixx="{I[0]}" ixy="{I[1]}" ixz="{I[2]}" iyy="{I[3]}" iyz="{I[4]}" izz="{I[5]}"/></inertial>')


def fourbar_urdf(loop: str | None = None, transmission: bool = True) -> str:
    """Assembled at q = 0 for crank angle 0: the coupler and rocker joints carry the closed-form angles."""
    ph2, ph3 = (f(0.0)[0] for f in closed_form_sym())
    loop = loop if loop is not None else f"""
  <loop_joint name="pin_C" type="continuous">
    <link1 link="coupler" xyz="{BC} 0 0" rpy="0 0 0"/>
    <link2 link="rocker" xyz="{C} 0 0" rpy="0 0 0.7"/>
    <axis xyz="0 0 1"/>
  </loop_joint>"""
    tr = """
  <transmission name="t1"><type>transmission_interface/SimpleTransmission</type>
    <joint name="crank_joint"><hardwareInterface>EffortJointInterface</hardwareInterface></joint>
    <actuator name="m1"/></transmission>""" if transmission else ""
    return f"""<?xml version="1.0"?>
<robot name="fourbar">
  <link name="ground"/>
  <link name="crank">{inertial(1.2, (0.1, 0.01, 0.02), (0.02, 0.001, 0.002, 0.03, 0.003, 0.04))}</link>
  <link name="coupler">{inertial(0.8, (0.2, -0.02, 0.01), (0.015, -0.002, 0.001, 0.05, 0.002, 0.06))}</link>
  <link name="rocker">{inertial(1.5, (0.18, 0.03, -0.01), (0.03, 0.002, -0.001, 0.04, 0.001, 0.05))}</link>
  <joint name="crank_joint" type="continuous">
    <parent link="ground"/><child link="crank"/><origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
  </joint>
  <joint name="coupler_joint" type="continuous">
    <parent link="crank"/><child link="coupler"/><origin xyz="{A} 0 0" rpy="0 0 {ph2!r}"/><axis xyz="0 0 1"/>
  </joint>
  <joint name="rocker_joint" type="continuous">
    <parent link="ground"/><child link="rocker"/><origin xyz="{D} 0 0" rpy="0 0 {ph3!r}"/><axis xyz="0 0 1"/>
  </joint>{loop}{tr}
</robot>
"""


def pinocchio_projected(urdf: str, q1, dq1, ddq1):
    """tau_a = G^T RNEA_tree(q_t, G dq1, G ddq1 + dG/dq1 dq1^2), G from the closed form (sympy derivatives)."""
    model = pin.buildModelFromXML(urdf)  # the open tree (Pinocchio ignores <loop_joint> and <transmission>)
    data = model.createData()
    model.gravity.linear = np.array(GRAV)
    f2, f3 = closed_form_sym()
    ph2_0, ph3_0 = f2(0.0)[0], f3(0.0)[0]
    order = {name: model.joints[model.getJointId(name)].idx_v for name in ("crank_joint", "coupler_joint", "rocker_joint")}
    out = []
    for a, da, dda in zip(q1, dq1, ddq1):
        (p2, d2, dd2), (p3, d3, dd3) = f2(a), f3(a)
        qt = {"crank_joint": a, "coupler_joint": p2 - a - ph2_0, "rocker_joint": p3 - ph3_0}
        G = {"crank_joint": 1.0, "coupler_joint": d2 - 1.0, "rocker_joint": d3}
        dG = {"crank_joint": 0.0, "coupler_joint": dd2, "rocker_joint": dd3}
        q, v, acc, g = (np.zeros(model.nv) for _ in range(4))
        for n, i in order.items():
            q[i], v[i], acc[i], g[i] = qt[n], G[n] * da, G[n] * dda + dG[n] * da**2, G[n]
        qc = np.array([x for i in range(model.nv) for x in (math.cos(q[i]), math.sin(q[i]))])  # continuous joints
        out.append(g @ pin.rnea(model, data, qc, v, acc))
    return np.array(out)


@pytest.fixture(scope="module")
def fourbar():
    return closed_model(fourbar_urdf(), "fourbar.urdf", gravity=GRAV)


def test_fourbar_urdf_torque_equals_pinocchio_projected_on_the_crank(fourbar):
    rng = np.random.default_rng(3)
    q = rng.uniform(-math.pi, math.pi, (25, 1))  # the crank turns all the way round
    dq, ddq = rng.normal(0, 2, (25, 1)), rng.normal(0, 5, (25, 1))
    ref = pinocchio_projected(fourbar_urdf(), q[:, 0], dq[:, 0], ddq[:, 0])
    tau = fourbar.torque(q, dq, ddq, fourbar.nominal_parameters())[:, 0]
    assert np.abs(ref).max() > 0.5
    np.testing.assert_allclose(tau, ref, rtol=0, atol=1e-9 * np.abs(ref).max())


def test_fourbar_actuated_joint_by_option_and_passive_ones():
    text = import_urdf_text(fourbar_urdf(transmission=False), file="fourbar.urdf", actuated=["crank_joint"])
    robot = parse_robot_text(text, file="fourbar.toml")
    assert [r.mu for r in robot.joints] == [1, 0, 0] and len(robot.loops) == 1
    assert robot.loops[0].cut.ant == 2 and robot.loops[0].close.ant == 3  # coupler -> rocker


def with_limit(urdf: str, joint: str, lower: float, upper: float) -> str:
    """``urdf`` with the continuous joint ``joint`` made revolute with ``<limit lower upper>``."""
    i = urdf.index(f'<joint name="{joint}" type="continuous">')
    k = urdf.index("</joint>", i)
    return (urdf[:i] + urdf[i:k].replace('type="continuous"', 'type="revolute"')
            + f'<limit lower="{lower}" upper="{upper}" velocity="2" effort="5"/>' + urdf[k:])


def test_passive_joint_limits_are_imported_as_passive_q_min_and_q_max():
    urdf = with_limit(with_limit(with_limit(fourbar_urdf(), "crank_joint", -3.0, 3.0), "coupler_joint", -0.4, 2.5),
                      "rocker_joint", -1.25, 0.75)
    text = import_urdf_text(urdf, file="fourbar.urdf")
    assert "passive_q_min = [-0.4, -1.25]" in text and "passive_q_max = [2.5, 0.75]" in text
    lim = parse_robot_text(text, file="fourbar.toml").limits
    assert lim.q_min == (-3.0,) and lim.q_max == (3.0,) and lim.dq_max == (2.0,) and lim.tau_max == (5.0,)
    assert lim.passive_joints == (2, 3) and lim.passive_q_min == (-0.4, -1.25) and lim.passive_q_max == (2.5, 0.75)
    # written only when every passive joint gives lower < upper (the URDF's lower = upper = 0: no range)
    for partial in (with_limit(fourbar_urdf(), "coupler_joint", -0.4, 2.5),
                    with_limit(with_limit(fourbar_urdf(), "coupler_joint", -0.4, 2.5), "rocker_joint", 0, 0)):
        assert "passive_q_" not in import_urdf_text(partial, file="fourbar.urdf")


def test_passive_limits_go_through_urdf_export_and_import():
    pal = parse_robot_text((robots_dir() / "palletizer.toml").read_text().split("\n[limits]", 1)[0]
                           + '\n[limits]\nangles = "deg"\npassive_q_min = [-150, -30]\npassive_q_max = [-30, 30]\n')
    urdf = export_urdf(pal, report=[])
    robot = parse_robot_text(import_urdf_text(urdf, file="palletizer.urdf"), file="palletizer.toml")
    assert robot.limits.passive_joints == (3, 6)
    np.testing.assert_allclose(robot.limits.passive_q_min, np.radians([-150, -30]), rtol=1e-12)
    np.testing.assert_allclose(robot.limits.passive_q_max, np.radians([-30, 30]), rtol=1e-12)


def problem(urdf: str, **kw) -> str:
    """The single problem reported, as one line ``file, where, field: message``."""
    with pytest.raises(RobotFileError) as ei:
        import_urdf_text(urdf, file="bad.urdf", **kw)
    (p,) = ei.value.problems
    assert p.file == "bad.urdf"
    return f"{p.file}, {p.where}, {p.field}: {p.message}"


@pytest.mark.parametrize("loop, words", [
    ('<loop_joint name="L" type="fixed"><link1 link="coupler"/><link2 link="rocker"/></loop_joint>',
     ["loop_joint L", "type", "weld"]),
    ('<loop_joint name="L" type="ball"><link1 link="coupler"/><link2 link="rocker"/></loop_joint>',
     ["loop_joint L", "type", "'ball'"]),
    ('<loop_joint name="L" type="revolute"><link1 link="coupler"/></loop_joint>',
     ["loop_joint L", "link2", "missing"]),
    ('<loop_joint name="L" type="revolute"><link1 link="nowhere"/><link2 link="rocker"/></loop_joint>',
     ["loop_joint L", "link1", "'nowhere'"]),
    ('<loop_joint name="L" type="revolute"><link1 link="coupler" xyz="1 two 3"/><link2 link="rocker"/></loop_joint>',
     ["loop_joint L", "link1", "'xyz'"]),
    ('<loop_joint name="L" type="revolute"><link1 link="coupler"/><link2 link="rocker"/><axis xyz="0 0 0"/></loop_joint>',
     ["loop_joint L", "axis", "zero axis"]),
    ('<loop_joint name="L" type="revolute"><link1 link="rocker"/><link2 link="rocker"/></loop_joint>',
     ["loop_joint L", "link2", "no loop"]),
    ('<loop_joint type="revolute"><link1 link="coupler"/><link2 link="rocker"/></loop_joint>',
     ["<loop_joint>", "name"]),
])
def test_malformed_loop_elements_are_one_error_naming_file_element_and_field(loop, words):
    msg = problem(fourbar_urdf(loop=loop))
    assert "\n" not in msg, msg
    for w in words:
        assert w in msg, (w, msg)


def test_loops_without_actuated_joints_or_with_a_tip_are_errors():
    assert "transmission" in problem(fourbar_urdf(transmission=False))
    assert "not a moving joint" in problem(fourbar_urdf(), actuated=["pin_C"])
    assert "give no tip" in problem(fourbar_urdf(), tip="rocker")
    bad_tr = fourbar_urdf().replace('<joint name="crank_joint"><hard', '<joint name="crank"><hard')
    msg = problem(bad_tr)
    assert "transmission t1" in msg and "'crank'" in msg


def test_an_open_loop_at_zero_is_warned_about():
    with pytest.warns(UserWarning, match="loop_joint pin_C is not closed at the URDF zero configuration"):
        import_urdf_text(fourbar_urdf().replace(f'<link2 link="rocker" xyz="{C} 0 0"', '<link2 link="rocker" xyz="0.3 0 0"'),
                         file="open.urdf")


def test_cli_import_urdf_with_actuated_option_and_a_one_line_error(tmp_path, cli):
    src = tmp_path / "fourbar.urdf"
    src.write_text(fourbar_urdf(transmission=False))
    out = tmp_path / "fourbar.toml"
    cli("--quiet", "import-urdf", src, "--actuated", "crank_joint", "-o", out)
    robot = load_robot(out)
    assert [r.mu for r in robot.joints] == [1, 0, 0] and len(robot.loops) == 1
    bad = tmp_path / "bad.urdf"
    bad.write_text(fourbar_urdf(transmission=False))
    res = cli("import-urdf", bad, "-o", tmp_path / "bad.toml", rc=2)
    assert f"{bad}, <loop_joint>, field 'transmission'" in res.err and "Traceback" not in res.err
    assert not (tmp_path / "bad.toml").exists()


# ---------------------------------------------------------------------------------------------------
# slider-crank closed by a prismatic loop joint on the ground
# ---------------------------------------------------------------------------------------------------
SA, SL, SE = 0.15, 0.5, 0.05  # crank, rod, height of the slider's line


@functools.lru_cache(maxsize=1)
def slider_crank_sym():
    """Tree joint values (crank, rod, slider; revolute) and their first and second derivatives in the crank angle."""
    q = sp.Symbol("q", real=True)
    phi = sp.asin((SE - SA * sp.sin(q)) / SL)  # absolute angle of the rod
    phi0 = phi.subs(q, 0)
    exprs = [q, phi - phi0 - q, phi0 - phi]
    return sp.lambdify(q, [[e, sp.diff(e, q), sp.diff(e, q, 2)] for e in exprs], "math"), float(phi0)


def slider_crank_urdf() -> str:
    _, phi0 = slider_crank_sym()
    x0 = SA + SL * math.cos(phi0)
    return f"""<robot name="slider_crank">
  <link name="ground"/>
  <link name="crank">{inertial(1.0, (0.07, 0.01, 0.0), (0.01, 0.0, 0.0, 0.02, 0.0, 0.025))}</link>
  <link name="rod">{inertial(0.7, (0.25, -0.01, 0.01), (0.005, 0.001, 0.0, 0.03, 0.0, 0.032))}</link>
  <link name="slider">{inertial(2.0, (0.01, 0.02, 0.0), (0.004, 0.0, 0.0, 0.005, 0.0, 0.006))}</link>
  <joint name="crank_joint" type="revolute"><parent link="ground"/><child link="crank"/>
    <axis xyz="0 0 1"/><limit lower="-4" upper="4" effort="10" velocity="10"/></joint>
  <joint name="rod_joint" type="revolute"><parent link="crank"/><child link="rod"/>
    <origin xyz="{SA} 0 0" rpy="0 0 {phi0!r}"/><axis xyz="0 0 1"/><limit lower="-4" upper="4" effort="10" velocity="10"/></joint>
  <joint name="slider_joint" type="revolute"><parent link="rod"/><child link="slider"/>
    <origin xyz="{SL} 0 0" rpy="0 0 {-phi0!r}"/><axis xyz="0 0 1"/><limit lower="-4" upper="4" effort="10" velocity="10"/></joint>
  <loop_joint name="track" type="prismatic">
    <link1 link="slider" xyz="0 0 0" rpy="0 0 0"/>
    <link2 link="ground" xyz="{x0!r} {SE} 0" rpy="0 0 0"/>
    <axis xyz="1 0 0"/>
  </loop_joint>
  <transmission name="t"><joint name="crank_joint"/></transmission>
</robot>
"""


def test_slider_crank_with_a_prismatic_loop_joint_equals_pinocchio_projected():
    urdf = slider_crank_urdf()
    text = import_urdf_text(urdf, file="slider_crank.urdf", gravity=GRAV)
    robot = parse_robot_text(text, file="slider_crank.toml")
    assert robot.loops[0].cut.sigma == 1 and robot.loops[0].close.ant == 0  # prismatic cut, closing on the ground
    model = ClosedLoopModel(robot, build_in_memory(robot))
    rng = np.random.default_rng(11)
    q = rng.uniform(-math.pi, math.pi, (20, 1))
    dq, ddq = rng.normal(0, 2, (20, 1)), rng.normal(0, 5, (20, 1))
    pm = pin.buildModelFromXML(urdf)
    data = pm.createData()
    pm.gravity.linear = np.array(GRAV)
    f, _ = slider_crank_sym()
    idx = [pm.joints[pm.getJointId(n)].idx_v for n in ("crank_joint", "rod_joint", "slider_joint")]
    ref = []
    for a, da, dda in zip(q[:, 0], dq[:, 0], ddq[:, 0]):
        vals = np.array(f(a))  # (3 joints, [value, d/dq, d2/dq2])
        qt, v, acc, g = (np.zeros(pm.nv) for _ in range(4))
        qt[idx], g[idx] = vals[:, 0], vals[:, 1]
        v[idx], acc[idx] = vals[:, 1] * da, vals[:, 1] * dda + vals[:, 2] * da**2
        ref.append(g @ pin.rnea(pm, data, qt, v, acc))
    ref_a = np.array(ref)
    tau = model.torque(q, dq, ddq, model.nominal_parameters())[:, 0]
    assert np.abs(ref_a).max() > 0.5
    np.testing.assert_allclose(tau, ref_a, rtol=0, atol=1e-9 * np.abs(ref_a).max())
