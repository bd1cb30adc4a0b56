"""URDF import: the imported MDH robot's torques == Pinocchio's RNEA on the URDF itself."""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.description.urdf import import_urdf, import_urdf_text, parse_urdf_text
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.errors import RobotFileError
from symoro_gen.simulate import random_states

LWR_URDF_IN_DATA = Path("kuka_lwr4_flobaroid") / "model" / "kuka_lwr4.urdf"
RTOL = 1e-8
N_SAMPLES = 6


# ---- references ---------------------------------------------------------------------------
def pinocchio_urdf_torque(model: pin.Model, q, dq, ddq):
    """Pinocchio RNEA on the URDF model + damping dq + friction sign(dq) (from <dynamics>).

    ``q`` holds one angle / displacement per joint; continuous joints (nq = 2 in Pinocchio)
    get their (cos, sin) configuration by integrating from the neutral configuration.
    """
    data = model.createData()
    q0 = pin.neutral(model)
    tau = np.array([pin.rnea(model, data, pin.integrate(model, q0, qk), vk, ak) for qk, vk, ak in zip(q, dq, ddq)])
    return tau + model.damping * dq + model.friction * np.sign(dq)


def joint_relative_errors(a, b):
    """Per joint ``||a_j - b_j|| / ||b_j||`` over the samples."""
    a, b = np.asarray(a), np.asarray(b)
    return np.linalg.norm(a - b, axis=0) / np.linalg.norm(b, axis=0)


def _states(rng, n, N=N_SAMPLES):
    return random_states(rng, N, n)


def _check_against_pinocchio(toml_text: str, urdf_text: str, rng, rtol=RTOL):
    robot = parse_robot_text(toml_text)
    model = pin.buildModelFromXML(urdf_text)
    assert model.nv == robot.n_joints
    q, dq, ddq = _states(rng, robot.n_joints)
    chi = np.array(robot.nominal_vector())
    ours = inverse_dynamics(robot, q, dq, ddq, chi)
    ref = pinocchio_urdf_torque(model, q, dq, ddq)
    err = joint_relative_errors(ours, ref)
    assert np.all(err < rtol), f"per-joint relative errors {err}"
    return robot


# ---- random URDF chains -------------------------------------------------------------------
def _f(x) -> str:
    return repr(float(x))


def _vec(v):
    return " ".join(_f(x) for x in v)


def _random_inertial(rng, indent="    "):
    m = rng.uniform(0.2, 3.0)
    B = rng.normal(scale=0.08, size=(3, 3))
    S = B @ B.T + 1e-4 * np.eye(3)  # second moments about the COM
    I = np.trace(S) * np.eye(3) - S  # a physical inertia (triangle inequality holds)
    return (
        f"{indent}<inertial>\n"
        f'{indent}  <origin xyz="{_vec(rng.normal(scale=0.15, size=3))}" rpy="{_vec(rng.uniform(-np.pi, np.pi, 3))}"/>\n'
        f'{indent}  <mass value="{_f(m)}"/>\n'
        f'{indent}  <inertia ixx="{_f(I[0, 0])}" ixy="{_f(I[0, 1])}" ixz="{_f(I[0, 2])}" iyy="{_f(I[1, 1])}" iyz="{_f(I[1, 2])}" izz="{_f(I[2, 2])}"/>\n'
        f"{indent}</inertial>\n"
    )


def _link(name, rng, inertial=True):
    return f'  <link name="{name}">\n' + (_random_inertial(rng) if inertial else "") + "  </link>\n"


def _origin(rng, aligned: bool):
    if aligned:
        xyz = [0.0 if rng.random() < 0.5 else rng.uniform(-0.4, 0.4) for _ in range(3)]
        rpy = rng.integers(-2, 3, size=3) * (math.pi / 2)
    else:
        xyz = rng.uniform(-0.4, 0.4, 3)
        rpy = rng.uniform(-np.pi, np.pi, 3)
    return f'    <origin xyz="{_vec(xyz)}" rpy="{_vec(rpy)}"/>\n'


def _axis(rng, aligned: bool):
    if aligned:
        a = np.zeros(3)
        a[rng.integers(3)] = rng.choice([-1.0, 1.0])
    else:
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
    return f'    <axis xyz="{_vec(a)}"/>\n'


def random_urdf(rng: np.random.Generator, n_moving: int, *, style: str = "mixed", mount: bool = False,
                side_branch: bool = False, tip_link: bool = False, moving_branch: bool = False) -> str:
    """A URDF text of a random serial chain (plus optional fixed side branch / tip / moving branch).

    style: "aligned" (right-angle rpy, axes along +-x/y/z, many zero offsets: parallel,
    antiparallel, intersecting and collinear axes), "general" (arbitrary) or "mixed" (per joint).
    """
    parts = ['<?xml version="1.0"?>\n<robot name="random-chain">\n']
    root = "world" if mount else "base"
    parts.append(_link(root, rng))
    if mount:
        parts.append(_link("base", rng))
        parts.append('  <joint name="mount" type="fixed">\n' + _origin(rng, False)
                     + '    <parent link="world"/>\n    <child link="base"/>\n  </joint>\n')
    prev = "base"
    for k in range(1, n_moving + 1):
        aligned = style == "aligned" or (style == "mixed" and rng.random() < 0.5)
        if rng.random() < 0.3:  # an intermediate link on a fixed joint
            mid = f"mid{k}"
            parts.append(_link(mid, rng, inertial=rng.random() < 0.7))
            parts.append(f'  <joint name="fixed{k}" type="fixed">\n' + _origin(rng, aligned)
                         + f'    <parent link="{prev}"/>\n    <child link="{mid}"/>\n  </joint>\n')
            prev = mid
        typ = rng.choice(["revolute", "revolute", "continuous", "prismatic"])
        child = f"link{k}"
        parts.append(_link(child, rng))
        body = f'  <joint name="joint{k}" type="{typ}">\n' + _origin(rng, aligned) + _axis(rng, aligned)
        body += f'    <parent link="{prev}"/>\n    <child link="{child}"/>\n'
        if typ != "continuous":
            body += '    <limit effort="100" lower="-3.2" upper="3.2" velocity="10"/>\n'
        if rng.random() < 0.6:
            body += f'    <dynamics damping="{_f(rng.uniform(0, 2))}" friction="{_f(rng.uniform(0, 1))}"/>\n'
        parts.append(body + "  </joint>\n")
        if side_branch and k == max(1, n_moving // 2):
            parts.append(_link(f"sensor{k}", rng))
            parts.append(f'  <joint name="sensor_mount{k}" type="fixed">\n' + _origin(rng, False)
                         + f'    <parent link="{child}"/>\n    <child link="sensor{k}"/>\n  </joint>\n')
        if moving_branch and k == 1:
            parts.append(_link("finger", rng))
            parts.append('  <joint name="finger_joint" type="revolute">\n' + _origin(rng, False) + _axis(rng, False)
                         + f'    <parent link="{child}"/>\n    <child link="finger"/>\n'
                         + '    <limit effort="1" lower="-1" upper="1" velocity="1"/>\n  </joint>\n')
        prev = child
    if tip_link:
        parts.append(_link("flange", rng))
        parts.append('  <joint name="flange_joint" type="fixed">\n' + _origin(rng, False)
                     + f'    <parent link="{prev}"/>\n    <child link="flange"/>\n  </joint>\n')
    parts.append("</robot>\n")
    return "".join(parts)


CASES = [(seed, style) for style in ("aligned", "general", "mixed") for seed in range(10)]


@pytest.mark.parametrize("seed,style", CASES)
def test_random_urdf_chain_matches_pinocchio(seed, style):
    rng = np.random.default_rng(1000 * ("aligned", "general", "mixed").index(style) + seed)
    n = int(rng.integers(1, 7))
    urdf = random_urdf(rng, n, style=style, mount=rng.random() < 0.3, side_branch=rng.random() < 0.4,
                       tip_link=rng.random() < 0.5)
    for base_frame in ("joint", "link"):
        toml = import_urdf_text(urdf, base_frame=base_frame, symbols=bool(seed % 2))
        robot = _check_against_pinocchio(toml, urdf, rng)
        assert robot.n_joints == n
        if base_frame == "joint":  # row 1 is theta1 = +-q, all else zero
            r1 = robot.row(1)
            assert (r1.gamma, r1.b, r1.alpha, r1.d) == (0, 0, 0, 0)
            assert r1.r == 0 or robot.row(1).sigma == 1


def test_aligned_chains_give_textbook_tables():
    """Right-angle URDFs: alpha a multiple of pi/2 but never pi (antiparallel axes are flipped: -q),
    |theta offset| <= pi/2, gamma = b = 0 (frame 0 = frame 1 at q = 0)."""
    rng = np.random.default_rng(5)
    seen_minus_q = False
    for _ in range(20):
        urdf = random_urdf(rng, int(rng.integers(2, 7)), style="aligned")
        toml = import_urdf_text(urdf, symbols=False)
        robot = parse_robot_text(toml)
        for row in robot.rows:
            alpha = float(row.alpha)
            assert abs(alpha / (math.pi / 2) - round(alpha / (math.pi / 2))) < 1e-12, toml
            assert abs(alpha) < math.pi - 1e-9, toml
            assert row.gamma == 0 and row.b == 0
            th0 = float(row.theta.subs({s: 0 for s in row.theta.free_symbols}))
            assert abs(th0) <= math.pi / 2 + 1e-12
        seen_minus_q |= '"-q' in toml
        _check_against_pinocchio(toml, urdf, rng)
    assert seen_minus_q  # the sample exercised flipped joint directions


def test_tip_link_gets_a_fixed_frame_and_side_links_are_merged():
    rng = np.random.default_rng(77)
    urdf = random_urdf(rng, 3, style="general", side_branch=True, tip_link=True)
    toml = import_urdf_text(urdf)
    robot = _check_against_pinocchio(toml, urdf, rng)
    assert len(robot.rows) == 4 and robot.rows[-1].sigma == 2 and robot.rows[-1].ant == 3
    # all the moving mass is accounted for: links 1..3 + sensor + flange
    model = pin.buildModelFromXML(urdf)
    total = sum(model.inertias[i].mass for i in range(1, model.njoints))
    assert sum(robot.nominal[f"M{j}"] for j in (1, 2, 3)) == pytest.approx(total, rel=1e-12)


def test_base_below_the_root_rotates_gravity():
    rng = np.random.default_rng(3)
    urdf = random_urdf(rng, 3, style="general", mount=True)
    toml = import_urdf_text(urdf, base="base", base_frame="link")
    robot = _check_against_pinocchio(toml, urdf, rng)
    assert np.linalg.norm(robot.gravity) == pytest.approx(9.81)
    assert abs(robot.gravity[2]) < 9.81 - 1e-3  # the mount is tilted: gravity is not along -z of the base link


def test_moving_side_branch_is_left_out_with_a_warning():
    rng = np.random.default_rng(4)
    urdf = random_urdf(rng, 3, style="general", moving_branch=True)
    tree = parse_robot_text(import_urdf_text(urdf))  # no tip: the whole tree (tests/description/test_urdf_tree.py)
    assert tree.n_joints == 4 and [r.ant for r in tree.rows] == [0, 1, 1, 3]
    with pytest.warns(UserWarning, match="finger_joint"):
        toml = import_urdf_text(urdf, tip="link3")
    assert "finger_joint" in toml.splitlines()[2]
    assert parse_robot_text(toml).n_joints == 3


def test_tip_selects_a_sub_chain():
    rng = np.random.default_rng(8)
    urdf = random_urdf(rng, 4, style="general")
    with pytest.warns(UserWarning, match="left out of the model .*: joint3"):  # what lies beyond the tip
        robot = parse_robot_text(import_urdf_text(urdf, tip="link2"))
    assert robot.n_joints == 2


def test_snap_angles_makes_rounded_right_angles_exact():
    urdf = """<robot name="r">
  <link name="b"/><link name="l1"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <link name="l2"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="j1" type="continuous"><parent link="b"/><child link="l1"/><axis xyz="0 0 1"/></joint>
  <joint name="j2" type="continuous"><origin xyz="0.3 0 0" rpy="1.5708 0 0"/><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/></joint>
</robot>"""
    raw = import_urdf_text(urdf, symbols=False)
    snapped = import_urdf_text(urdf, symbols=False, snap_angles=1e-4)
    assert 'alpha = "0"' in snapped and "d = 0.3" in snapped  # axes parallel again
    assert 'alpha = "0"' not in raw.split("j = 2")[1]  # the file's 1.5708 kept: nearly parallel axes
    _check_against_pinocchio(raw, urdf, np.random.default_rng(0))


# ---- errors -----------------------------------------------------------------------------
_OK_LINKS = '<link name="a"/><link name="b"/>'


@pytest.mark.parametrize(
    "text,pattern",
    [
        ("<robot><link name='a'>", "malformed XML"),
        ("<model/>", "root element must be <robot>"),
        (f"<robot>{_OK_LINKS}<joint name='j' type='hinge'><parent link='a'/><child link='b'/></joint></robot>", "joint j, field 'type'"),
        (f"<robot>{_OK_LINKS}<joint name='j' type='revolute'><parent link='a'/><child link='c'/></joint></robot>", "link 'c' is not defined"),
        (f"<robot>{_OK_LINKS}<joint name='j' type='revolute'><parent link='a'/><child link='b'/><axis xyz='0 0 0'/></joint></robot>", "zero axis"),
        (f"<robot>{_OK_LINKS}<joint name='j' type='revolute'><origin xyz='1 2'/><parent link='a'/><child link='b'/></joint></robot>", "field 'origin'"),
        (f"<robot>{_OK_LINKS}<joint name='j' type='fixed'><parent link='a'/><child link='b'/></joint></robot>", "no moving joint"),
        # a floating joint inside the chain (under the root's only child it is a floating base: tests/floating)
        (f"<robot>{_OK_LINKS}<link name='c'/><joint name='r' type='revolute'><parent link='a'/><child link='c'/></joint>"
         "<joint name='j' type='floating'><parent link='c'/><child link='b'/></joint></robot>", "floating joints cannot"),
        ("<robot><link name='a'><inertial><mass value='-1'/><inertia ixx='1' ixy='0' ixz='0' iyy='1' iyz='0' izz='1'/></inertial></link></robot>", "negative mass"),
    ],
)
def test_bad_urdf_is_rejected_with_location(text, pattern):
    with pytest.raises(RobotFileError, match=re.escape(pattern)) as exc:
        import_urdf_text(text, file="bad.urdf")
    assert "bad.urdf" in str(exc.value)


def test_unknown_base_or_tip_and_tip_not_below_base():
    urdf = random_urdf(np.random.default_rng(1), 3, style="general")
    with pytest.raises(RobotFileError, match="no link named 'nope'"):
        import_urdf_text(urdf, tip="nope")
    with pytest.raises(RobotFileError, match="is not below the base"):
        import_urdf_text(random_urdf(np.random.default_rng(2), 2, mount=True), base="base", tip="world")
    with pytest.raises(RobotFileError, match="carried by moving joint"):
        import_urdf_text(urdf, base="link1")


def test_missing_file():
    with pytest.raises(RobotFileError, match="file not found"):
        import_urdf("/nonexistent/robot.urdf")


# ---- the LWR4 of the recordings -------------------------------------------------------------
@pytest.fixture(scope="module")
def lwr_urdf(shared_data) -> Path:
    p = shared_data / LWR_URDF_IN_DATA
    if not p.is_file():
        pytest.skip(f"LWR4 URDF not available: {p} is absent")
    return p


@pytest.mark.realdata
@pytest.mark.parametrize("base_frame", ["joint", "link"])
def test_lwr4_urdf_matches_pinocchio(base_frame, lwr_urdf):
    toml = import_urdf(lwr_urdf, base_frame=base_frame)
    _check_against_pinocchio(toml, lwr_urdf.read_text(), np.random.default_rng(42))


@pytest.mark.realdata
def test_lwr4_import_is_table_one_of_the_paper(lwr_urdf):
    """alpha 0, pi/2, -pi/2, -pi/2, pi/2, pi/2, -pi/2; r3 = 0.40, r5 = 0.39; theta_j = q_j (no offset, no sign flip)."""
    imported = parse_robot_text(import_urdf(lwr_urdf, name="lwr4"))
    shipped = load_robot("lwr4")
    assert imported.n_joints == 7
    subs_i, subs_s = imported.geometry_subs(), shipped.geometry_subs()
    for a, b in zip(imported.joints, shipped.joints):
        for field in ("gamma", "b", "alpha", "d", "theta", "r"):
            va, vb = getattr(a, field).subs(subs_i), getattr(b, field).subs(subs_s)
            assert float((va - vb).subs({s: 0.37 for s in (va - vb).free_symbols})) == pytest.approx(0, abs=1e-12), (a.j, field)
        assert str(a.theta) == f"q{a.j}"
    assert imported.gravity == shipped.gravity
    assert dict(imported.values) == {"RL3": 0.4, "RL5": 0.39}


@pytest.mark.realdata
def test_lwr4_nominal_values_fit_the_shipped_lwr4_file(lwr_urdf):
    """robots/lwr4.toml (frames of Table I) with the imported nominal values == Pinocchio on the URDF."""
    imported = parse_robot_text(import_urdf(lwr_urdf, name="lwr4"))
    shipped = load_robot("lwr4")
    chi = np.array([imported.nominal.get(n, 0.0) for n in shipped.standard_names])
    model = pin.buildModelFromUrdf(str(lwr_urdf))
    rng = np.random.default_rng(9)
    q, dq, ddq = _states(rng, 7)
    err = joint_relative_errors(inverse_dynamics(shipped, q, dq, ddq, chi), pinocchio_urdf_torque(model, q, dq, ddq))
    assert np.all(err < RTOL), err


def test_name_and_number_options():
    urdf = random_urdf(np.random.default_rng(12), 3, style="general")
    toml = import_urdf_text(urdf, name="arm3", symbols=False)
    robot = parse_robot_text(toml)
    assert robot.name == "arm3" and not robot.values and "[values]" not in toml
    assert parse_robot_text(import_urdf_text(urdf)).name == "random_chain"  # from <robot name="random-chain">
    with pytest.raises(RobotFileError, match="field 'name'"):
        import_urdf_text(urdf, name="not an identifier")


def test_link_with_two_parents_is_not_a_tree():
    text = (
        "<robot><link name='a'/><link name='b'/><link name='c'/>"
        "<joint name='j1' type='revolute'><parent link='a'/><child link='c'/></joint>"
        "<joint name='j2' type='revolute'><parent link='b'/><child link='c'/></joint></robot>"
    )
    with pytest.raises(RobotFileError, match="joint j2, field 'child': link 'c' already has parent joint 'j1'"):
        parse_urdf_text(text, file="two.urdf")


# ---- decisions: <mimic> joints and links without <inertial> ---------------------
def _two_joint_urdf(rng, *, mimic: str | None = None, inertial2: bool = True, tool_inertial: bool = True,
                    finger_mimic: bool = False) -> str:
    """base -> joint1 -> link1 -> joint2 -> link2 -> (fixed) tool, optionally a mimic on joint2 and a
    mimicking finger off the chain on link1."""
    parts = ['<?xml version="1.0"?>\n<robot name="gripper-arm">\n', _link("base", rng), _link("link1", rng),
             _link("link2", rng, inertial=inertial2), _link("tool", rng, inertial=tool_inertial)]
    for k, (parent, child) in enumerate((("base", "link1"), ("link1", "link2")), start=1):
        body = f'  <joint name="joint{k}" type="revolute">\n' + _origin(rng, False) + _axis(rng, False)
        body += f'    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
        body += '    <limit effort="1" lower="-1" upper="1" velocity="1"/>\n'
        if k == 2 and mimic:
            body += f'    <mimic joint="{mimic}" multiplier="-1" offset="0"/>\n'
        parts.append(body + "  </joint>\n")
    parts.append('  <joint name="tool_joint" type="fixed">\n' + _origin(rng, False)
                 + '    <parent link="link2"/>\n    <child link="tool"/>\n  </joint>\n')
    if finger_mimic:
        parts.append(_link("finger", rng))
        parts.append('  <joint name="finger_joint" type="revolute">\n' + _origin(rng, False) + _axis(rng, False)
                     + '    <parent link="link1"/>\n    <child link="finger"/>\n'
                     + '    <limit effort="1" lower="-1" upper="1" velocity="1"/>\n'
                     + '    <mimic joint="joint1"/>\n  </joint>\n')
    return "".join(parts) + "</robot>\n"


def test_mimic_joint_on_the_chain_is_a_coupling_equal_to_pinocchio_mimic():
    """joint2 mimics joint1 (multiplier -1, random axes and origins): imported as a coupled joint, whose
    actuated torque equals Pinocchio's RNEA on the same URDF built with its mimic joints (``mimic=True``:
    Pinocchio's own JointModelMimic, one configuration variable)."""
    from symoro_gen.closedloop import ClosedLoopModel
    from symoro_gen.emit.package import build_in_memory

    urdf = _two_joint_urdf(np.random.default_rng(11), mimic="joint1")
    robot = parse_robot_text(import_urdf_text(urdf, file="arm.urdf", tip="tool"))
    (c,) = robot.couplings
    assert (c.joint, c.source, float(c.multiplier), float(c.offset)) == (2, 1, -1.0, 0.0)
    assert robot.row(2).mu == 0 and [r.j for r in robot.model_joints] == [1]
    model = ClosedLoopModel(robot, build_in_memory(robot))
    pm = pin.buildModelFromXML(urdf, mimic=True)
    assert pm.nq == 1
    rng = np.random.default_rng(1)
    q, dq, ddq = rng.uniform(-1, 1, (3, N_SAMPLES, 1))
    ours = model.torque(q, dq, ddq, robot.nominal_vector())
    ref = pinocchio_urdf_torque(pm, q, dq, ddq)
    np.testing.assert_allclose(ours, ref, atol=1e-9 * np.abs(ref).max())
    # a chain that stops before it leaves the mimic joint out (warned), like any joint off the chain
    with pytest.warns(UserWarning, match="joint2"):
        assert parse_robot_text(import_urdf_text(urdf, tip="link1")).n_joints == 1


def test_mimic_of_a_joint_outside_the_imported_chain_is_an_error_naming_it():
    """joint2 mimics the finger joint, a side branch that the chain base -> tool leaves out."""
    both = _two_joint_urdf(np.random.default_rng(11), mimic="finger_joint", finger_mimic=True)
    urdf = both.replace('    <mimic joint="joint1"/>\n', "")  # the finger itself is an independent joint
    with pytest.raises(RobotFileError) as info:
        import_urdf_text(urdf, file="arm.urdf", tip="tool")
    (p,) = info.value.problems
    assert (p.file, p.where, p.field) == ("arm.urdf", "joint joint2", "mimic")
    assert "'finger_joint'" in p.message and "outside the imported chain" in p.message and "--tip" in p.message
    # the suggestion works: without the tag joint 2 is an independent joint
    no_tag = re.sub(r"\s*<mimic[^>]*/>", "", urdf)
    with pytest.warns(UserWarning, match="finger_joint"):
        assert parse_robot_text(import_urdf_text(no_tag, tip="tool")).n_joints == 2
    # a mimic of a mimic is composed down to the joint that is not one: finger = joint1, joint2 = -1 finger
    with pytest.warns(UserWarning, match="finger_joint"):
        robot = parse_robot_text(import_urdf_text(both, tip="tool"))
    assert [(c.joint, c.source, float(c.multiplier)) for c in robot.couplings] == [(2, 1, -1.0)]


def test_mimic_cycles_and_mimics_of_fixed_or_undefined_joints_are_errors_naming_the_joint():
    urdf = _two_joint_urdf(np.random.default_rng(11), mimic="joint1")
    cases = [
        (urdf.replace('<child link="link1"/>\n', '<child link="link1"/>\n    <mimic joint="joint2"/>\n'),
         "joint joint1", "cycle: joint1 -> joint2 -> joint1"),
        (urdf.replace('mimic joint="joint1"', 'mimic joint="tool_joint"'), "joint joint2", "a fixed joint"),
        (urdf.replace('mimic joint="joint1"', 'mimic joint="nope"'), "joint joint2", "'nope', which is not defined"),
    ]
    for text, where, words in cases:
        with pytest.raises(RobotFileError) as info:
            import_urdf_text(text, file="arm.urdf", tip="tool")
        p = info.value.problems[0]
        assert (p.file, p.where, p.field) == ("arm.urdf", where, "mimic") and words in p.message, p
    for bad, fld in (('multiplier="-1"', "mimic/multiplier"), ('offset="0"', "mimic/offset")):
        text = urdf.replace(bad, bad.split("=")[0] + '="inf"')
        with pytest.raises(RobotFileError) as info:
            parse_urdf_text(text, file="arm.urdf")
        assert [(p.where, p.field) for p in info.value.problems] == [("joint joint2", fld)]
    with pytest.raises(RobotFileError, match=r"joint joint2, field 'mimic/multiplier'.*non-zero"):
        parse_urdf_text(urdf.replace('multiplier="-1"', 'multiplier="0"'), file="arm.urdf")


def test_mimic_tag_without_joint_is_reported():
    urdf = _two_joint_urdf(np.random.default_rng(11), mimic="X")
    with pytest.raises(RobotFileError) as info:
        parse_urdf_text(urdf.replace('joint="X"', ""), file="arm.urdf")
    assert [(p.where, p.field) for p in info.value.problems] == [("joint joint2", "mimic")]


def test_mimic_joint_off_the_chain_is_left_out_with_a_warning():
    urdf = _two_joint_urdf(np.random.default_rng(12), finger_mimic=True)
    with pytest.warns(UserWarning, match="finger_joint"):
        toml = import_urdf_text(urdf, tip="tool")
    assert parse_robot_text(toml).n_joints == 2


def test_link_without_inertial_warns_and_counts_as_massless():
    rng = np.random.default_rng(13)
    urdf = _two_joint_urdf(rng, tool_inertial=False)
    with pytest.warns(UserWarning, match=r"arm\.urdf: link\(s\) tool carried by a moving joint have no <inertial>"):
        toml = import_urdf_text(urdf, file="arm.urdf")
    assert "# Links without <inertial> (mass and inertia unknown): tool." in toml
    robot = _check_against_pinocchio(toml, urdf, rng)  # link 2's own inertial is still there
    assert robot.nominal["M2"] > 0


def test_moving_link_without_any_inertial_gets_no_nominal_values():
    rng = np.random.default_rng(14)
    urdf = _two_joint_urdf(rng, inertial2=False, tool_inertial=False)
    with pytest.warns(UserWarning, match=r"link\(s\) link2, tool .* MDH link\(s\) 2 get no inertial \[nominal\]"):
        toml = import_urdf_text(urdf, file="arm.urdf")
    robot = parse_robot_text(toml)
    assert not any(k.endswith("2") and k.rstrip("0123456789") in ("XX", "M", "MX", "ZZ") for k in robot.nominal)
    assert robot.nominal["M1"] > 0
    # unknown = absent: zero in nominal_vector, as Pinocchio's massless link (joint 2 then carries no torque)
    q, dq, ddq = _states(rng, 2)
    ref = pinocchio_urdf_torque(pin.buildModelFromXML(urdf), q, dq, ddq)
    np.testing.assert_allclose(inverse_dynamics(robot, q, dq, ddq, np.array(robot.nominal_vector())), ref,
                               rtol=1e-9, atol=1e-12)


def test_ground_links_without_inertial_are_silent(recwarn):
    rng = np.random.default_rng(15)
    # a world link without <inertial> carrying the base through a fixed joint: ground, nothing to say
    urdf = _two_joint_urdf(rng).replace('<link name="base">', '<link name="world"/>\n  <link name="base">', 1)
    urdf = urdf.replace("</robot>", '  <joint name="mount" type="fixed">\n    <parent link="world"/>\n'
                        '    <child link="base"/>\n  </joint>\n</robot>')
    import_urdf_text(urdf)
    assert not [w for w in recwarn if "inertial" in str(w.message)]


def test_huge_axis_components_are_normalised():
    # found by tests/fuzz: the norm of (0, 0, 1e308) overflowed to inf, and the axis became NaN
    urdf = random_urdf(np.random.default_rng(3), 2, style="aligned")
    urdf = re.sub(r'<axis xyz="[^"]*"/>', '<axis xyz="0 0 1e308"/>', urdf, count=1)
    robot = parse_robot_text(import_urdf_text(urdf))
    ref = parse_robot_text(import_urdf_text(urdf.replace('"0 0 1e308"', '"0 0 1"')))
    assert robot.rows == ref.rows
