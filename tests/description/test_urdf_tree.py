"""URDF trees: branches become ``ant``; the imported MDH tree's torques == Pinocchio's RNEA on the URDF.

Pinocchio orders the joints of a URDF tree its own way: the comparison goes by joint name (each
``[[frames]]`` entry of the imported file names its URDF joint).
"""
from __future__ import annotations

import re

import numpy as np
import pinocchio as pin
import pytest

from symoro_gen.description import parse_robot_text
from symoro_gen.description.urdf import import_urdf_text
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.errors import RobotFileError
from symoro_gen.simulate import random_states

from .test_urdf import _axis, _f, _link, _origin

RTOL = 1e-9


def random_tree_urdf(rng: np.random.Generator, n_moving: int, *, style: str = "mixed") -> tuple[str, dict[str, str]]:
    """A random URDF tree of ``n_moving`` moving joints: each hangs off a random earlier link (the base
    included), sometimes through a fixed intermediate link; fixed side links (sensors) here and there.

    Returns the URDF text and the link each moving joint hangs off (before any fixed intermediate link).
    """
    parts = ['<?xml version="1.0"?>\n<robot name="random-tree">\n', _link("base", rng)]
    links = ["base"]
    parent_of: dict[str, str] = {}
    for k in range(1, n_moving + 1):
        aligned = style == "aligned" or (style == "mixed" and rng.random() < 0.5)
        prev = links[int(rng.integers(len(links)))] if k > 1 else "base"
        parent_of[f"joint{k}"] = prev
        if rng.random() < 0.25:
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
        if rng.random() < 0.5:
            body += f'    <dynamics damping="{_f(rng.uniform(0, 2))}" friction="{_f(rng.uniform(0, 1))}"/>\n'
        parts.append(body + "  </joint>\n")
        if rng.random() < 0.2:
            parts.append(_link(f"sensor{k}", rng))
            parts.append(f'  <joint name="sensor_mount{k}" type="fixed">\n' + _origin(rng, False)
                         + f'    <parent link="{child}"/>\n    <child link="sensor{k}"/>\n  </joint>\n')
        links.append(child)
    parts.append("</robot>\n")
    return "".join(parts), parent_of


def frame_joint_names(toml: str) -> list[str]:
    """URDF joint name of each moving frame, in frame order (from the ``[[frames]]`` comments)."""
    return re.findall(r"\[\[frames\]\]  # URDF joint (\S+) \(", toml)


def pinocchio_tree_torque(urdf: str, names: list[str], q, dq, ddq):
    """RNEA of Pinocchio's own URDF model + damping + friction, in the order of ``names``."""
    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    ids = [model.getJointId(nm) for nm in names]
    idx_v = [model.joints[i].idx_v for i in ids]
    q0 = pin.neutral(model)
    out = []
    for qk, vk, ak in zip(q, dq, ddq):
        v, a, dqv = (np.zeros(model.nv) for _ in range(3))
        v[idx_v], a[idx_v], dqv[idx_v] = vk, ak, qk
        tau = pin.rnea(model, data, pin.integrate(model, q0, dqv), v, a)
        tau = tau + model.damping * v + model.friction * np.sign(v)
        out.append(tau[idx_v])
    return np.array(out)


def check_tree(urdf: str, rng, **options):
    toml = import_urdf_text(urdf, **options)
    robot = parse_robot_text(toml)
    names = frame_joint_names(toml)
    assert len(names) == robot.n_joints == pin.buildModelFromXML(urdf).nv
    q, dq, ddq = random_states(rng, 6, robot.n_joints)
    ours = inverse_dynamics(robot, q, dq, ddq, np.array(robot.nominal_vector()))
    ref = pinocchio_tree_torque(urdf, names, q, dq, ddq)
    err = np.abs(ours - ref).max() / np.abs(ref).max()
    assert err < RTOL, f"relative error {err:.2e}\n{toml}"
    return robot, names, toml


@pytest.mark.filterwarnings("ignore:.*have no <inertial>")
@pytest.mark.parametrize("seed", range(12))
@pytest.mark.parametrize("base_frame", ["joint", "link"])
def test_random_urdf_tree_matches_pinocchio(seed, base_frame):
    rng = np.random.default_rng(500 + seed)
    n = int(rng.integers(3, 9))
    urdf, parent_of = random_tree_urdf(rng, n, style=("aligned", "general", "mixed")[seed % 3])
    robot, names, _ = check_tree(urdf, rng, base_frame=base_frame, symbols=bool(seed % 2))
    # the antecedent of each frame is the frame of the moving joint carrying its URDF joint
    frame_of = {nm: j for j, nm in enumerate(names, start=1)}
    carrier = {f"link{k}": f"joint{k}" for k in range(1, n + 1)}
    for nm, row in zip(names, robot.joints):
        lk = parent_of[nm]
        assert row.ant == (frame_of[carrier[lk]] if lk in carrier else 0), (nm, row)


def test_branching_urdf_without_tip_is_a_tree_and_with_tip_a_chain():
    rng = np.random.default_rng(21)
    urdf, _ = random_tree_urdf(rng, 6, style="general")
    robot, names, toml = check_tree(urdf, rng)
    assert any(r.ant != r.j - 1 for r in robot.rows)  # it does branch
    assert "tree below base" in robot.source and "# Tree below base" in toml
    tip = f"link{names[-1][5:]}"
    with pytest.warns(UserWarning, match="left out of the model"):
        chain = parse_robot_text(import_urdf_text(urdf, tip=tip))
    assert all(r.ant == r.j - 1 for r in chain.rows) and chain.n_joints < robot.n_joints


def test_aligned_tree_rows_are_textbook():
    """Right-angle trees: every alpha a multiple of pi/2 but never pi (an axis antiparallel to its
    antecedent's is flipped, ``-q``), on branches too; the branches carry gamma / b."""
    rng = np.random.default_rng(3)
    seen_branch_gamma = False
    for _ in range(6):
        urdf, _ = random_tree_urdf(rng, int(rng.integers(3, 8)), style="aligned")
        robot, _, toml = check_tree(urdf, rng, symbols=False)
        for row in robot.rows:
            a = float(row.alpha) / (np.pi / 2)
            assert abs(a - round(a)) < 1e-12 and abs(round(a)) < 2, toml
            seen_branch_gamma |= row.ant != row.j - 1 and (row.gamma != 0 or row.b != 0)
    assert seen_branch_gamma


def test_mimic_joint_in_a_tree_is_a_coupling_and_a_later_one_an_error_naming_it():
    link = '<link name="{}"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" iyz="0" izz="1"/></inertial></link>'
    joint = '<joint name="{}" type="revolute"><parent link="{}"/><child link="{}"/><axis xyz="0 0 1"/>{}</joint>'
    urdf = ("<robot name='t'>" + "".join(link.format(n) for n in ("b", "l1", "l2", "l3"))
            + joint.format("j1", "b", "l1", "") + joint.format("j2", "l1", "l2", "")
            + joint.format("j3", "l1", "l3", '<mimic joint="j2" multiplier="0.5" offset="0.1"/>') + "</robot>")
    robot = parse_robot_text(import_urdf_text(urdf, file="t.urdf"))
    assert [(c.joint, c.source, float(c.multiplier), float(c.offset)) for c in robot.couplings] == [(3, 2, 0.5, 0.1)]
    assert [r.ant for r in robot.rows] == [0, 1, 1] and [r.j for r in robot.model_joints] == [1, 2]
    # j2 mimicking j3, which is numbered after it (depth first, file order): an error naming it
    later = urdf.replace('<mimic joint="j2" multiplier="0.5" offset="0.1"/>', "").replace(
        '<child link="l2"/><axis xyz="0 0 1"/>', '<child link="l2"/><axis xyz="0 0 1"/><mimic joint="j3"/>')
    with pytest.raises(RobotFileError, match=r"t.urdf, joint j2, field 'mimic'.*'j3', which comes after it"):
        import_urdf_text(later, file="t.urdf")
    assert parse_robot_text(import_urdf_text(urdf.replace('<mimic joint="j2" multiplier="0.5" offset="0.1"/>', ""))).n_joints == 3


def test_dual_arm_torso_urdf_imports_as_the_shipped_tree():
    """The shipped torso exported to URDF and imported back: the same tree (ant of every frame) and the same
    torques (Pinocchio on the URDF == numeric Newton-Euler on both robot files)."""
    from symoro_gen.description import load_robot
    from symoro_gen.description.urdf_export import export_urdf
    from symoro_gen.simulate import random_physical_parameters

    torso = load_robot("sda10f")
    rng = np.random.default_rng(9)
    chi = np.asarray(random_physical_parameters(torso, rng))  # rigid bodies: exported unchanged
    urdf = export_urdf(torso, chi)
    robot, names, _ = check_tree(urdf, rng)
    assert [r.ant for r in robot.rows] == [r.ant for r in torso.joints]
    q, dq, ddq = random_states(rng, 5, torso.n_joints)
    a = inverse_dynamics(robot, q, dq, ddq, np.array(robot.nominal_vector()))
    # URDF carries the rigid bodies, FV (damping) and FS (friction); not IA and OFF
    urdf_part = np.array([0.0 if n.startswith(("IA", "OFF")) else x for n, x in zip(torso.standard_names, chi)])
    b = inverse_dynamics(torso, q, dq, ddq, urdf_part)
    np.testing.assert_allclose(a, b, rtol=1e-8, atol=1e-8 * np.abs(b).max())


def test_import_urdf_command_writes_the_tree(tmp_path):
    """``symoro-gen import-urdf tree.urdf -o tree.toml`` (no --tip): the robot file of the whole tree,
    which ``generate`` accepts."""
    import warnings

    from symoro_gen.cli import main

    urdf, _ = random_tree_urdf(np.random.default_rng(21), 5, style="aligned")
    (tmp_path / "tree.urdf").write_text(urdf)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert main(["--quiet", "import-urdf", str(tmp_path / "tree.urdf"), "-o", str(tmp_path / "tree.toml")]) == 0
        robot = parse_robot_text((tmp_path / "tree.toml").read_text())
        assert robot.n_joints == 5 and any(r.ant != r.j - 1 for r in robot.rows)
        assert main(["--quiet", "generate", str(tmp_path / "tree.toml"), "--out", str(tmp_path / "gen")]) == 0
    assert (tmp_path / "gen" / robot.name / "base_parameters.md").is_file()


def _two_branch_urdf(main_origin: str, main_axis: str, branch_origin: str, branch_axis: str) -> str:
    """A vertical waist carrying two one-joint branches (the first child is the main chain)."""
    inertial = ('<inertial><mass value="1.3"/><origin xyz="0.01 0.02 0.03"/><inertia ixx="0.1" iyy="0.12" '
                'izz="0.13" ixy="0.001" ixz="0" iyz="0"/></inertial>')
    links = "".join(f'<link name="{n}">{inertial}</link>' for n in ("base", "waist", "main", "side"))

    def joint(name, origin, axis, parent, child):
        return (f'<joint name="{name}" type="revolute"><origin xyz="{origin}"/><axis xyz="{axis}"/>'
                f'<parent link="{parent}"/><child link="{child}"/>'
                '<limit effort="10" lower="-3" upper="3" velocity="2"/></joint>')

    return ('<robot name="meeting-branch">' + links + joint("waist_j", "0 0 0.3", "0 0 1", "base", "waist")
            + joint("main_j", main_origin, main_axis, "waist", "main")
            + joint("side_j", branch_origin, branch_axis, "waist", "side") + "</robot>")


@pytest.mark.parametrize("base_frame", ["joint", "link"])
@pytest.mark.parametrize("main, branch", [
    # main axis on the waist's axis (its x arbitrary), branch axis along that x: used to give a NaN
    (("0 0 0", "0 0 1"), ("0 0 0", "1 0 0")),
    (("0 0 0.1", "0 0 1"), ("0 0.2 0.1", "1 0 0")),
    (("0 0 0", "1 0 0"), ("0 0 0.1", "0 1 0")),
    # branch axis parallel to (and on) its parent's axis, and crossing it
    (("0 0.2 0.1", "0 1 0"), ("0 0 0.1", "0 0 1")),
    (("0.1 0 0", "0 1 0"), ("0 0 0", "0 1 0")),
])
def test_branch_axis_meeting_its_parents_axis_imports_equal_to_pinocchio(main, branch, base_frame):
    """A branch whose axis intersects, or is parallel to, its parent's axis (its parent's x axis then
    possibly along the branch axis): the import's torques equal Pinocchio's RNEA on the URDF (1e-9)."""
    robot, names, _ = check_tree(_two_branch_urdf(*main, *branch), np.random.default_rng(8), base_frame=base_frame)
    assert [r.ant for r in robot.joints] == [0, 1, 1] and names == ["waist_j", "main_j", "side_j"]
