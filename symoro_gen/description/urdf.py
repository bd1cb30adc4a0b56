"""Import a serial chain or a tree of a URDF as a Khalil-Kleinfinger MDH robot file (TOML text).

Only the standard library's XML parser is used (no urdfdom). The chain from ``base`` to
``tip`` (revolute, continuous, prismatic and fixed joints, any axis and origin) becomes an
MDH table built by the Khalil-Kleinfinger construction at the URDF zero configuration:

* ``z_j`` along the axis of moving joint j (the URDF axis, or its opposite when that axis
  is antiparallel to ``z_{j-1}``: then ``alpha_j = 0`` instead of ``pi`` and the joint
  variable enters as ``-q``);
* ``x_j`` along the common normal of ``z_j`` and ``z_{j+1}``, origin ``O_j`` on ``z_j``. Its
  sign makes the theta offset smallest (``|theta_j(q=0)| <= pi/2`` for j >= 2). For intersecting
  axes ``x_j = +-(z_j x z_{j+1})``; for parallel axes the normal through the point where
  ``x_{j-1}`` meets ``z_j`` (``r_j = 0``); for the last joint (and collinear axes)
  ``x_j = x_{j-1}``;
* frame 0 is either frame 1 at ``q = 0`` (``base_frame="joint"``, the usual MDH choice,
  row 1 reduces to ``theta_1 = q``; gravity is expressed in it) or the URDF base link's
  frame (``base_frame="link"``, row 1 then carries gamma and b as needed);
* fixed joints are folded into the neighbours' constants; when the tip link is reached
  through fixed joints after the last moving one, it gets a fixed frame (sigma = 2), a
  place where a payload can be attached (its inertia stays in the last link).

Trees ([KK1986]): when no ``tip`` is given and several moving chains leave a link below the base,
the whole tree is imported. The moving joints are numbered depth first (children in the file's order),
so that every frame comes after its antecedent, ``ant`` being the frame of the nearest moving joint
above it. Along each chain (a frame and its first moving child) the frames are built as above; every
further child k of frame i (a branch) has its origin on the common normal of ``z_i`` and ``z_k`` (or
on the perpendicular from ``O_i`` when they are parallel), and its row carries the gamma and b that
place that normal on ``z_i``. Fixed tip frames are not added to a tree.

Constant theta / r values at ``q = 0`` are written as offsets (``q - pi/2``, ``q + RL3``).
The URDF inertials of every link rigidly attached to moving link j (through fixed joints,
side branches included) are summed and converted to standard parameters in frame j at its
origin (``XXj .. ZZj`` inertia about the origin, ``MXj MYj MZj = m c``, ``Mj``) and written
under ``[nominal]``, with ``FVj`` / ``FSj`` from the joint's ``<dynamics damping friction>``.
Links fixed to the base are ground and carry nothing. Moving joints off the chain (and
beyond the tip) are left out with a warning.

Closed loops follow the ``<loop_joint>`` extension element read by Drake's former
RigidBodyTree parser, RigidBodyDynamics.jl and Isaac Sim's URDF importer (the most common spelling;
URDF itself has no loops, and Pinocchio, urdfdom and ROS tools ignore the element)::

    <loop_joint name="pin_C" type="continuous">          <!-- revolute | continuous | prismatic -->
      <link1 link="coupler" xyz="0.45 0 0" rpy="0 0 0"/>  <!-- the joint frame on link1 -->
      <link2 link="rocker" xyz="0.40 0 0" rpy="0 0 0"/>   <!-- the joint frame on link2 -->
      <axis xyz="0 0 1"/>                                  <!-- in the joint frame -->
    </loop_joint>

The two joint frames coincide up to a motion along ``axis``. The joint frame on ``link1`` (z along
the axis) becomes the cut frame of a ``[[loops]]`` entry, on the MDH link that carries ``link1``,
with the loop joint's variable (0 at the URDF zero configuration); the joint frame on ``link2``
becomes the closing frame (``sigma = 2``) on the MDH link that carries ``link2`` ([KK1986]; the
``[[loops]]`` table of :mod:`symoro_gen.description.loops`). A ``fixed`` loop joint (a weld) is an
error: a cut joint is revolute or prismatic. The actuated joints are those named by the URDF's
``<transmission>`` elements (ROS ``transmission_interface`` spelling, ``<joint name=...>``), or the
``actuated`` argument; every other moving joint is passive (``mu = 0``). A URDF with loops is imported
whole (no ``tip``); the loop solver starts from the URDF zero configuration, which should be an
assembled one (a loop open there is warned about).

Two decisions, stated to the user:

* a ``<mimic joint multiplier offset>`` joint is a **coupled joint** of the robot file: a
  passive frame (``mu = 0``, no drive terms) with ``mimic = { joint = J, multiplier = k, offset = c }``,
  ``q = k q_J + c`` exactly as URDF's mimic (the robot file's ``q`` is the URDF joint value); the model
  projects the tree on the actuated joints (:mod:`symoro_gen.closedloop`). A mimic of a mimic is composed
  down to the joint that is not one; a cycle, a mimic of a joint outside the imported chain or tree (or
  numbered after it) are errors naming the joint. Mimic joints off the chain are left out like any other
  moving joint there.
* a link carried by a moving joint without ``<inertial>`` gets a warning naming it: its mass
  and inertia are unknown, not zero. When no link rigidly attached to MDH link j has an
  ``<inertial>``, link j gets no inertial ``[nominal]`` entries at all (unknown), rather than
  a zero-mass body.

Public functions: :func:`import_urdf`, :func:`import_urdf_text`, :func:`parse_urdf`.
"""
from __future__ import annotations

import json
import math
import re
import warnings
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ModelError, Problem, RobotFileError
from ..params import INERTIAL_KINDS
from .inertia import matrix_from_six, parallel_axis, six_from_matrix
from .mdh import transform as mdh_transform
from .parse import parse_robot_text

__all__ = ["import_urdf", "import_urdf_text", "parse_urdf", "UrdfModel", "UrdfJoint", "UrdfLink", "UrdfInertial",
           "UrdfLoopJoint"]

#: gravitational acceleration in the URDF root frame (ROS convention: z up)
URDF_GRAVITY = (0.0, 0.0, -9.81)
MOVING_TYPES = ("revolute", "continuous", "prismatic")
KNOWN_TYPES = MOVING_TYPES + ("fixed", "floating", "planar")


# ---------------------------------------------------------------------------------------------
# URDF reading
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class UrdfInertial:
    """``<inertial>`` of a link: mass [kg], pose of the COM frame in the link frame (4x4), inertia about the COM in that frame [kg m^2]."""

    mass: float
    origin: np.ndarray
    inertia: np.ndarray


@dataclass(frozen=True)
class UrdfLink:
    name: str
    inertial: UrdfInertial | None


@dataclass(frozen=True)
class UrdfJoint:
    """A URDF joint; ``origin`` is the child frame in the parent frame at q = 0 (4x4), ``axis`` a unit vector in the child frame."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    damping: float | None = None
    friction: float | None = None
    mimic: str | None = None  # the joint this one mimics (<mimic joint=...>)
    #: ``<mimic multiplier offset>`` (URDF defaults 1 and 0): this joint's value is ``multiplier * q + offset``
    mimic_multiplier: float = 1.0
    mimic_offset: float = 0.0
    #: ``<limit lower upper velocity effort>`` (each None when absent)
    limit: tuple[float | None, float | None, float | None, float | None] | None = None

    @property
    def is_moving(self) -> bool:
        return self.type in MOVING_TYPES


@dataclass(frozen=True)
class UrdfLoopJoint:
    """A ``<loop_joint>`` (the closing joint of a kinematic loop; Drake / RigidBodyDynamics.jl / Isaac Sim
    spelling): the joint frame is ``origin1`` in ``link1`` and ``origin2`` in ``link2`` (4x4); the two
    frames coincide up to a motion of ``type`` along ``axis`` (a unit vector in the joint frame)."""

    name: str
    type: str
    link1: str
    origin1: np.ndarray
    link2: str
    origin2: np.ndarray
    axis: np.ndarray


@dataclass(frozen=True)
class UrdfModel:
    """The kinematic tree of a URDF file (links and joints by name), its loop joints and the joints
    named by its ``<transmission>`` elements (``None``: the file has no transmission)."""

    name: str
    links: dict
    joints: dict
    file: str = "<string>"
    loops: tuple = ()
    transmitted: frozenset | None = None

    def parent_joint(self, link: str) -> UrdfJoint | None:
        for jt in self.joints.values():
            if jt.child == link:
                return jt
        return None

    def child_joints(self, link: str) -> list[UrdfJoint]:
        return [jt for jt in self.joints.values() if jt.parent == link]

    @property
    def roots(self) -> list[str]:
        children = {jt.child for jt in self.joints.values()}
        return [name for name in self.links if name not in children]


def _rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF rpy: ``R = Rz(yaw) Ry(pitch) Rx(roll)`` (fixed axes x, y, z)."""
    cr, sr, cp, sp_, cy, sy = math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch), math.cos(yaw), math.sin(yaw)
    Rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp_], [0, 1.0, 0], [-sp_, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    return Rz @ Ry @ Rx


def _hom(R: np.ndarray, p) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = p
    return T


def _inv(T: np.ndarray) -> np.ndarray:
    R, p = T[:3, :3], T[:3, 3]
    return _hom(R.T, -R.T @ p)


class _Reader:
    """Collects problems while reading attributes; optionally snaps near-right angles."""

    def __init__(self, file: str, snap_angles: float = 0.0):
        self.file = file
        self.snap_angles = snap_angles
        self.problems: list[Problem] = []

    def snapped(self, values, period: float):
        """Values within ``snap_angles`` of a multiple of ``period`` are set to that multiple."""
        if self.snap_angles <= 0:
            return values
        out = []
        for v in values:
            k = round(v / period)
            out.append(k * period if abs(v - k * period) < self.snap_angles else v)
        return out

    def bad(self, where: str, fld: str, msg: str) -> None:
        self.problems.append(Problem(self.file, where, fld, msg))

    def floats(self, elem, attr: str, n: int, where: str, fld: str, default=None):
        raw = elem.get(attr) if elem is not None else None
        if raw is None:
            if default is None:
                self.bad(where, fld, f"missing attribute '{attr}'")
                return [0.0] * n
            return list(default)
        try:
            vals = [float(x) for x in raw.split()]
        except ValueError:
            self.bad(where, fld, f"'{attr}' must be {n} number(s), got {raw!r}")
            return [0.0] * n if default is None else list(default)
        if len(vals) != n or not all(math.isfinite(v) for v in vals):
            self.bad(where, fld, f"'{attr}' must be {n} finite number(s), got {raw!r}")
            return [0.0] * n if default is None else list(default)
        return vals

    def axis(self, elem, where: str) -> np.ndarray:
        """The unit ``<axis xyz>`` (default x) of a moving joint; a zero axis is reported."""
        axis = np.array(self.snapped(self.floats(elem.find("axis"), "xyz", 3, where, "axis", default=(1.0, 0.0, 0.0)), 1.0))
        big = float(np.abs(axis).max())  # scaled first: the norm of (0, 0, 1e308) overflows
        nrm = big * float(np.linalg.norm(axis / big)) if big > 0 else 0.0
        if nrm < 1e-12:
            self.bad(where, "axis", "zero axis")
            return np.array([1.0, 0.0, 0.0])
        return (axis / big) / np.linalg.norm(axis / big)

    def origin(self, elem, where: str, tag: str = "origin") -> np.ndarray:
        o = elem.find("origin") if tag == "origin" else elem
        if o is None:
            return np.eye(4)
        xyz = self.floats(o, "xyz", 3, where, tag, default=(0.0, 0.0, 0.0))
        rpy = self.snapped(self.floats(o, "rpy", 3, where, tag, default=(0.0, 0.0, 0.0)), math.pi / 2)
        return _hom(_rpy_matrix(*rpy), xyz)


def parse_urdf_text(text: str, file: str = "<string>", *, snap_angles: float = 0.0) -> UrdfModel:
    """Read URDF text into a :class:`UrdfModel` (every problem reported at once).

    ``snap_angles`` > 0 [rad]: joint and inertial ``rpy`` values within it of a multiple of
    pi/2, and joint-axis components within it of 0 or +-1, are made exact (URDFs often write
    ``1.5708`` for pi/2, which would turn parallel axes into nearly parallel ones with a far
    away common normal). Default 0: the file's numbers are used as they are.

    Raises
    ------
    RobotFileError
        Malformed XML, missing or bad attributes, unknown joint types, joints naming missing
        links, a link with two parents.
    """
    rd = _Reader(file, snap_angles)
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise RobotFileError([Problem(file, f"line {exc.position[0]}", "", f"malformed XML: {exc}")]) from None
    if root.tag != "robot":
        raise RobotFileError([Problem(file, "", "", f"root element must be <robot>, got <{root.tag}>")])
    links: dict[str, UrdfLink] = {}
    for el in root.findall("link"):
        name = el.get("name")
        if not name:
            rd.bad("<link>", "name", "link without a name")
            continue
        if name in links:
            rd.bad(f"link {name}", "name", "defined twice")
        where = f"link {name}"
        inertial = None
        ie = el.find("inertial")
        if ie is not None:
            me = ie.find("mass")
            mass = rd.floats(me, "value", 1, where, "inertial/mass")[0] if me is not None else None
            if mass is None:
                rd.bad(where, "inertial/mass", "missing <mass value=...>")
                mass = 0.0
            elif mass < 0:
                rd.bad(where, "inertial/mass", f"negative mass {mass}")
            ine = ie.find("inertia")
            if ine is None:
                rd.bad(where, "inertial/inertia", "missing <inertia ixx=... izz=...>")
                I = np.zeros((3, 3))
            else:
                v = {k: rd.floats(ine, k, 1, where, f"inertial/inertia/{k}")[0] for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
                I = matrix_from_six([v[k] for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")])
            inertial = UrdfInertial(mass, rd.origin(ie, where), I)
        links[name] = UrdfLink(name, inertial)
    joints: dict[str, UrdfJoint] = {}
    parent_of: dict[str, str] = {}
    for el in root.findall("joint"):
        name = el.get("name")
        if not name:
            rd.bad("<joint>", "name", "joint without a name")
            continue
        where = f"joint {name}"
        if name in joints:
            rd.bad(where, "name", "defined twice")
        typ = el.get("type", "")
        if typ not in KNOWN_TYPES:
            rd.bad(where, "type", f"unknown joint type {typ!r} (expected one of {', '.join(KNOWN_TYPES)})")
        pe, ce = el.find("parent"), el.find("child")
        parent = pe.get("link") if pe is not None else None
        child = ce.get("link") if ce is not None else None
        for fld, lk in (("parent", parent), ("child", child)):
            if not lk:
                rd.bad(where, fld, f"missing <{fld} link=...>")
            elif lk not in links:
                rd.bad(where, fld, f"link {lk!r} is not defined")
        if child:
            if child in parent_of:
                rd.bad(where, "child", f"link {child!r} already has parent joint {parent_of[child]!r} (not a tree)")
            parent_of[child] = name
        if typ in MOVING_TYPES:
            axis = rd.axis(el, where)
        else:
            axis = np.array(rd.snapped(rd.floats(el.find("axis"), "xyz", 3, where, "axis", default=(1.0, 0.0, 0.0)), 1.0))
        damping = friction = None
        de = el.find("dynamics")
        if de is not None:
            if de.get("damping") is not None:
                damping = rd.floats(de, "damping", 1, where, "dynamics/damping")[0]
            if de.get("friction") is not None:
                friction = rd.floats(de, "friction", 1, where, "dynamics/friction")[0]
        mimic, mult, moff = None, 1.0, 0.0
        mi = el.find("mimic")
        if mi is not None:
            mimic = mi.get("joint") or ""
            if not mimic:
                rd.bad(where, "mimic", "missing <mimic joint=...>")
            mult = rd.floats(mi, "multiplier", 1, where, "mimic/multiplier", default=(1.0,))[0]
            moff = rd.floats(mi, "offset", 1, where, "mimic/offset", default=(0.0,))[0]
            if mult is not None and mult == 0.0 and typ in MOVING_TYPES:
                rd.bad(where, "mimic/multiplier", "must be non-zero (a joint that does not move is a fixed joint)")
        limit = None
        le = el.find("limit")
        if le is not None:
            lower, upper, velocity, effort = (rd.floats(le, k, 1, where, f"limit/{k}")[0] if le.get(k) is not None
                                              else None for k in ("lower", "upper", "velocity", "effort"))
            limit = (lower, upper, velocity, effort)
        joints[name] = UrdfJoint(name, typ, parent or "", child or "", rd.origin(el, where), axis, damping, friction,
                                 mimic=mimic, limit=limit, mimic_multiplier=float(mult if mult is not None else 1.0),
                                 mimic_offset=float(moff if moff is not None else 0.0))
    loops = _parse_loop_joints(root, rd, links, joints)
    transmitted = _parse_transmissions(root, rd, joints)
    if not links:
        rd.bad("<robot>", "link", "no link defined")
    if rd.problems:
        raise RobotFileError(rd.problems)
    return UrdfModel(root.get("name", ""), links, joints, file, loops=tuple(loops), transmitted=transmitted)


#: ``<loop_joint type>`` values and their MDH joint type (continuous = revolute without limits)
LOOP_TYPES = {"revolute": 0, "continuous": 0, "prismatic": 1}


def _parse_loop_joints(root, rd: _Reader, links: dict, joints: dict) -> list[UrdfLoopJoint]:
    """The ``<loop_joint>`` elements (see the module docstring), every problem reported."""
    out: list[UrdfLoopJoint] = []
    names: set[str] = set()
    for el in root.findall("loop_joint"):
        name = el.get("name")
        if not name:
            rd.bad("<loop_joint>", "name", "loop joint without a name")
            continue
        where = f"loop_joint {name}"
        if name in names or name in joints:
            rd.bad(where, "name", "defined twice (joint and loop joint names share one namespace)")
        names.add(name)
        typ = el.get("type", "")
        if typ == "fixed":
            rd.bad(where, "type", "a fixed loop joint (a weld, 6 constraints) is not supported: the cut joint of a "
                                  "[[loops]] entry is revolute or prismatic; merge the two links instead")
        elif typ not in LOOP_TYPES:
            rd.bad(where, "type", f"unknown loop joint type {typ!r} (expected one of {', '.join(LOOP_TYPES)})")
        ends = []
        for tag in ("link1", "link2"):
            le = el.find(tag)
            lk = le.get("link") if le is not None else None
            if le is None:
                rd.bad(where, tag, f"missing <{tag} link=... xyz=... rpy=...>")
            elif not lk:
                rd.bad(where, tag, f"missing attribute 'link' in <{tag}>")
            elif lk not in links:
                rd.bad(where, tag, f"link {lk!r} is not defined")
            ends.append((lk or "", rd.origin(le, where, tag) if le is not None else np.eye(4)))
        if ends[0][0] and ends[0][0] == ends[1][0]:
            rd.bad(where, "link2", f"link1 and link2 are the same link {ends[0][0]!r}: no loop")
        out.append(UrdfLoopJoint(name, typ, ends[0][0], ends[0][1], ends[1][0], ends[1][1], rd.axis(el, where)))
    return out


def _parse_transmissions(root, rd: _Reader, joints: dict) -> frozenset | None:
    """Names of the joints driven by a ``<transmission>`` (ROS ``transmission_interface`` spelling:
    ``<transmission><joint name=.../>...</transmission>``); None when the file has none."""
    els = root.findall("transmission")
    if not els:
        return None
    out = set()
    for k, el in enumerate(els, start=1):
        where = f"transmission {el.get('name') or k}"
        for je in el.findall("joint"):
            jn = je.get("name")
            if not jn:
                rd.bad(where, "joint", "missing attribute 'name' in <joint>")
            elif jn not in joints:
                rd.bad(where, "joint", f"joint {jn!r} is not defined")
            else:
                out.add(jn)
    return frozenset(out)


def parse_urdf(path, *, snap_angles: float = 0.0) -> UrdfModel:
    """Read the URDF file at ``path`` (see :func:`parse_urdf_text`)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RobotFileError([Problem(str(p), "", "", "file not found")]) from None
    except UnicodeDecodeError as exc:
        raise RobotFileError([Problem(str(p), "", "", f"not UTF-8 text ({exc.reason})")]) from None
    return parse_urdf_text(text, file=str(p), snap_angles=snap_angles)


# ---------------------------------------------------------------------------------------------
# chain selection
# ---------------------------------------------------------------------------------------------
def _subtree_has_moving(model: UrdfModel, link: str) -> bool:
    return any(jt.is_moving or _subtree_has_moving(model, jt.child) for jt in model.child_joints(link))


def _select_chain(model: UrdfModel, base: str | None, tip: str | None, *,
                  allow_tree: bool = False) -> tuple[str, list[UrdfJoint] | None]:
    """Base link and the joints from base to tip (in order); ``None`` instead of the joints when no tip
    is given, the subtree branches into several moving chains and ``allow_tree`` (a tree to import whole)."""
    f = model.file
    roots = model.roots
    if len(roots) != 1:
        raise RobotFileError([Problem(f, "<robot>", "link", f"expected one root link, found {len(roots)}: {', '.join(roots) or 'none'} (cycle or forest)")])
    root = roots[0]
    if base is None:
        base = root
    for lk, what in ((base, "base"), (tip, "tip")):
        if lk is not None and lk not in model.links:
            raise RobotFileError([Problem(f, f"{what} link", lk, f"no link named {lk!r} (links: {', '.join(model.links)})")])
    # the base must be fixed to the root (gravity constant in its frame)
    lk = base
    while lk != root:
        jt = model.parent_joint(lk)
        assert jt is not None  # one root: every other link has a parent joint
        if jt.is_moving:
            raise RobotFileError([Problem(f, f"base link {base}", "base", f"the base is carried by moving joint {jt.name!r}; choose a base fixed to the root link {root!r}")])
        lk = jt.parent
    if tip is None:
        lk = base
        while True:
            kids = model.child_joints(lk)
            moving = [jt for jt in kids if jt.is_moving or _subtree_has_moving(model, jt.child)]
            if len(moving) > 1 and allow_tree:
                return base, None
            if len(moving) > 1:
                raise RobotFileError([Problem(f, f"link {lk}", "tip", "the tree branches here into several moving chains ("
                                              + ", ".join(jt.name for jt in moving) + "); choose the chain with tip=LINK")])
            if moving:
                lk = moving[0].child
            elif len(kids) == 1:
                lk = kids[0].child  # a single fixed link (flange, tool) ends the chain
            else:
                break
        tip = lk
    chain: list[UrdfJoint] = []
    lk = tip
    while lk != base:
        jt = model.parent_joint(lk)
        if jt is None:
            raise RobotFileError([Problem(f, f"tip link {tip}", "tip", f"link {tip!r} is not below the base link {base!r}")])
        chain.append(jt)
        lk = jt.parent
    chain.reverse()
    _refuse_joints(f, chain, "an MDH chain", "an open-chain model", "end the chain before it with --tip")
    if not any(jt.is_moving for jt in chain):
        raise RobotFileError([Problem(f, f"chain {base} -> {tip}", "", "no moving joint between base and tip")])
    return base, chain


def _select_tree(model: UrdfModel, base: str) -> list[UrdfJoint]:
    """Every joint below ``base``, depth first (children in file order): the order of the MDH frames
    of a tree, each joint after its antecedent and a joint's first moving child right after it."""
    f = model.file
    out: list[UrdfJoint] = []

    def visit(lk: str) -> None:
        for jt in model.child_joints(lk):
            out.append(jt)
            visit(jt.child)

    visit(base)
    _refuse_joints(f, out, "an MDH tree", "a tree model", "import one chain that avoids it with --tip")
    return out


def _refuse_joints(f: str, joints: list[UrdfJoint], structure: str, model_kind: str, hint: str) -> None:
    """One error naming every floating/planar joint of ``joints`` (``<mimic>`` joints are couplings,
    :func:`_couplings`)."""
    bad = [jt for jt in joints if jt.type in ("floating", "planar")]
    if bad:
        raise RobotFileError([Problem(f, f"joint {jt.name}", "type", f"{jt.type} joints cannot be part of {structure}") for jt in bad])


def _couplings(model: UrdfModel, moving: list[UrdfJoint]) -> dict[str, tuple[str, float, float]]:
    """``{mimic joint: (followed joint, multiplier, offset)}`` of the imported moving joints (URDF
    ``<mimic>``: ``q = multiplier * q_followed + offset``). A mimic of a mimic is composed down to the
    joint that is not one (``k1 (k2 q + c2) + c1``); a cycle, a mimic of an undefined or fixed joint, of a
    joint outside the imported chain or tree, or of a joint numbered after it are errors naming the joint."""
    f = model.file
    index = {jt.name: i for i, jt in enumerate(moving)}
    out: dict[str, tuple[str, float, float]] = {}
    problems = []
    for jt in moving:
        if jt.mimic is None:
            continue
        where = f"joint {jt.name}"
        k, c, seen, cur = 1.0, 0.0, [jt.name], jt
        err = None
        while cur.mimic is not None:
            tgt = model.joints.get(cur.mimic)
            k, c = k * cur.mimic_multiplier, c + k * cur.mimic_offset
            if tgt is None:
                err = f"mimics joint {cur.mimic!r}, which is not defined"
                break
            if tgt.name in seen:
                err = "mimic joints form a cycle: " + " -> ".join(seen + [tgt.name])
            elif not tgt.is_moving:
                err = f"mimics joint {tgt.name!r}, a {tgt.type} joint (no joint variable)"
            if err:
                break
            seen.append(tgt.name)
            cur = tgt
        if err is None and cur.name not in index:
            err = (f"mimics joint {cur.name!r}, which is outside the imported chain/tree: import a chain or tree "
                   "that contains it (--tip), or delete the <mimic> tag to identify the joint as an independent one")
        elif err is None and index[cur.name] > index[jt.name]:
            err = (f"mimics joint {cur.name!r}, which comes after it in the frame numbering (depth first, children "
                   "in the file's order): a coupled joint follows an earlier one; list the followed joint first")
        if err:
            problems.append(Problem(f, where, "mimic", err))
            continue
        out[jt.name] = (cur.name, k, c)
    if problems:
        raise RobotFileError(problems)
    return out


# ---------------------------------------------------------------------------------------------
# geometry: Khalil-Kleinfinger frames
# ---------------------------------------------------------------------------------------------
def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _frame(O, x, z) -> np.ndarray:
    x, z = _unit(np.asarray(x, float)), _unit(np.asarray(z, float))
    return _hom(np.column_stack([x, np.cross(z, x), z]), O)


def _perp(v, z):
    """Component of v orthogonal to the unit vector z."""
    return v - (v @ z) * z


def _closest(p1, u1, p2, u2):
    """Feet of the common normal of two non-parallel lines (unit directions)."""
    w0 = p1 - p2
    b, d, e = u1 @ u2, u1 @ w0, u2 @ w0
    den = 1.0 - b * b
    s, t = (b * e - d) / den, (e - b * d) / den
    return p1 + s * u1, p2 + t * u2


def _pick_sign(x, ref, z):
    """``x`` or ``-x``, whichever makes the rotation from ``ref`` about ``z`` smallest (ties: +pi/2)."""
    c = x @ ref
    if abs(c) > 1e-12:
        return x if c > 0 else -x
    return x if np.cross(ref, x) @ z > 0 else -x


def _kk_frames(points, axes, base_frame: str, tol: float, parents=None):
    """Frames 0..n (4x4 poses in the base-link frame at q = 0) and the joint signs.

    ``parents[i]`` is the index of the moving joint that carries joint i (-1: the base), in an order
    where a joint comes after its parent and a joint's first child comes right after it (depth-first
    preorder); ``None`` is the serial chain ``[-1, 0, 1, ...]``. Along a chain (a joint and its first
    child) the frames are those of the Khalil-Kleinfinger construction described in the module
    docstring. A further child k of joint i (a branch, [KK1986]) starts on the common normal of
    ``z_i`` and ``z_k`` (its foot on ``z_k``, or the foot of the perpendicular from ``O_i`` when the
    axes are parallel), which the row of k then describes with gamma and b.
    """
    n = len(points)
    parents = list(range(-1, n - 1)) if parents is None else list(parents)
    X, Z = np.array([1.0, 0, 0]), np.array([0, 0, 1.0])
    zs: list[np.ndarray] = []
    signs: list[int] = []
    first_root = parents.index(-1)
    for i, a in enumerate(axes):
        p = parents[i]
        if p >= 0:
            prev_z = zs[p]
        elif base_frame == "link":
            prev_z = Z
        else:
            prev_z = zs[first_root] if i != first_root else None
        s = -1 if (prev_z is not None and a @ prev_z < -1 + tol) else 1
        zs.append(s * a)
        signs.append(s)
    frames: list = [None] * n
    start: dict = {}  # joint -> (anchor on its axis, reference direction for its x axis)

    def branch_start(k, O, z, x):
        """Anchor on axis k and reference x for a joint hung off the frame (O, z, x)."""
        pk, zk = points[k], zs[k]
        if np.linalg.norm(np.cross(z, zk)) > tol:
            _, anchor = _closest(O, z, pk, zk)
        else:
            anchor = pk + ((O - pk) @ zk) * zk
        ref = _perp(x, zk)
        if np.linalg.norm(ref) <= tol:
            # x of the parent frame along z_k (z_k meets z at a right angle, on x): the common normal
            # z x z_k, orthogonal to z_k and non-zero since x is orthogonal to z (``cross(z_k, x)`` is 0)
            ref = np.cross(z, zk)
        return anchor, _unit(ref)

    # anchor A_1 and reference direction for x_1
    p1, z1 = points[first_root], zs[first_root]
    if base_frame == "link" and np.linalg.norm(np.cross(Z, z1)) > tol:
        _, anchor = _closest(np.zeros(3), Z, p1, z1)
    else:
        anchor = p1 + ((-p1) @ z1) * z1  # closest point of axis 1 to the base origin
    ref = _perp(X, z1)
    ref = _unit(ref) if np.linalg.norm(ref) > tol else _unit(_perp(np.array([0, 1.0, 0]), z1))
    start[first_root] = (anchor, ref)
    for i in range(n):
        if i not in start:  # a branch: on its parent frame (frame 0 for a further root)
            p = parents[i]
            F = frames[p] if p >= 0 else (np.eye(4) if base_frame == "link" else frames[first_root])
            start[i] = branch_start(i, F[:3, 3], F[:3, 2], F[:3, 0])
        anchor, ref = start.pop(i)
        zi = zs[i]
        main = i + 1 if i + 1 < n and parents[i + 1] == i else None
        if main is None:
            O, x, next_anchor = anchor, _unit(_perp(ref, zi)), None
        else:
            pn, zn = points[main], zs[main]
            if np.linalg.norm(np.cross(zi, zn)) > tol:
                F, G = _closest(anchor, zi, pn, zn)
                x = _unit(G - F) if np.linalg.norm(G - F) > tol else _unit(np.cross(zi, zn))
                O, next_anchor = F, G
            else:
                w = _perp(pn - anchor, zi)
                if np.linalg.norm(w) > tol:
                    x, next_anchor = _unit(w), anchor + w
                else:
                    x, next_anchor = _unit(_perp(ref, zi)), anchor
                O = anchor
            x = _pick_sign(x, ref, zi)
        frames[i] = _frame(O, x, zi)
        if main is not None:
            start[main] = (next_anchor, x)
    frame0 = np.eye(4) if base_frame == "link" else frames[first_root].copy()
    return [frame0] + frames, signs


def _mdh_from_transform(T: np.ndarray, tol: float) -> tuple[float, float, float, float, float, float]:
    """``(gamma, b, alpha, d, theta, r)`` with ``T = Rz(gamma) Tz(b) Rx(alpha) Tx(d) Rz(theta) Tz(r)``.

    gamma is chosen in (-pi/2, pi/2] where possible (0 when the x axis of the antecedent
    frame already is the common normal), b = 0 for parallel z axes.
    """
    x0, y0, z0 = np.eye(3)
    o, xp, zp = T[:3, 3], T[:3, 0], T[:3, 2]
    nz = np.cross(z0, zp)
    if np.linalg.norm(nz) > tol:
        F0, F1 = _closest(np.zeros(3), z0, o, zp)
        u = _unit(F1 - F0) if np.linalg.norm(F1 - F0) > tol else _unit(nz)
    else:
        F0 = np.zeros(3)
        F1 = _perp(o, z0)
        u = _unit(F1) if np.linalg.norm(F1) > tol else x0
    u = _pick_sign(u, x0, z0)
    gamma = math.atan2(u @ y0, u @ x0)
    b = float(F0 @ z0)
    d = float((F1 - F0) @ u)
    alpha = math.atan2(np.cross(z0, zp) @ u, z0 @ zp)
    theta = math.atan2(np.cross(u, xp) @ zp, u @ xp)
    r = float((o - F1) @ zp)
    return gamma, b, alpha, d, theta, r


# ---------------------------------------------------------------------------------------------
# formatting
# ---------------------------------------------------------------------------------------------
_ANGLES = {0: "0", 1: "pi/2", -1: "-pi/2", 2: "pi", -2: "pi"}


def _snap(x: float, tol: float) -> float:
    x = 0.0 if abs(x) < tol else float(x)
    return float(f"{x:.12g}")


def _angle_str(a: float, tol: float) -> str:
    k = round(a / (math.pi / 2))
    if abs(a - k * math.pi / 2) < tol and k in _ANGLES:
        return _ANGLES[k]
    return repr(_snap(a, tol))


def _num(x: float) -> str:
    return repr(float(x))


def _offset_expr(var: str, off: str) -> str:
    if off in ("0", "0.0"):
        return var
    return f"{var} - {off[1:]}" if off.startswith("-") else f"{var} + {off}"


def _identifier(name: str) -> str:
    s = re.sub(r"\W", "_", name)
    if not s or s[0].isdigit():
        s = "r_" + s
    return s


# ---------------------------------------------------------------------------------------------
# import
# ---------------------------------------------------------------------------------------------
def import_urdf(path, base: str | None = None, tip: str | None = None, name: str | None = None, **options) -> str:
    """A URDF serial chain or tree as robot-file text (TOML) in Khalil-Kleinfinger MDH notation.

    Parameters
    ----------
    path : str or PathLike
        The URDF file.
    base, tip : str, optional
        Link names bounding the chain. Default: the root link, and the end of the single
        moving chain below it (followed by a single fixed link if there is one); when the URDF
        branches into several moving chains below the base and no tip is given, the whole tree.
    name : str, optional
        Robot name (default: the URDF robot name made an identifier).
    **options
        See :func:`import_urdf_text` (``base_frame``, ``symbols``, ``gravity``, ``tol``,
        ``snap_angles``, ``actuated``, ``floating``).

    Returns
    -------
    str
        TOML text, loadable with :func:`symoro_gen.description.parse_robot_text`.

    Raises
    ------
    RobotFileError
        Unreadable or malformed URDF, unknown base/tip link, no moving joint in the chain,
        floating/planar joint in the chain or tree, a mimic joint whose followed joint is not in it.
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise RobotFileError([Problem(str(p), "", "", "file not found")]) from None
    except UnicodeDecodeError as exc:
        raise RobotFileError([Problem(str(p), "", "", f"not UTF-8 text ({exc.reason})")]) from None
    return import_urdf_text(text, base=base, tip=tip, name=name, file=str(p), **options)


def import_urdf_text(
    text: str,
    base: str | None = None,
    tip: str | None = None,
    name: str | None = None,
    *,
    file: str = "<string>",
    base_frame: str = "joint",
    symbols: bool = True,
    gravity=URDF_GRAVITY,
    tol: float = 1e-9,
    snap_angles: float = 0.0,
    actuated=None,
    floating: bool | None = None,
) -> str:
    """URDF text -> robot-file text (see :func:`import_urdf`).

    Parameters
    ----------
    text : str
        URDF XML.
    base, tip, name : see :func:`import_urdf`.
    file : str
        Name used in messages and in the ``source`` line.
    base_frame : {"joint", "link"}
        ``"joint"``: frame 0 is frame 1 at ``q = 0`` (MDH habit; row 1 is ``theta1 = q``);
        ``"link"``: frame 0 is the base link's frame (row 1 carries gamma/b/alpha/d/r).
    symbols : bool
        Non-zero lengths as symbols with ``[values]`` (``d3 = "D3"``, ``r3 = "RL3"``,
        ``b1 = "B1"``) rather than numbers.
    gravity : sequence of 3 float
        Gravitational acceleration in the URDF root link's frame [m/s^2].
    tol : float
        Geometric tolerance [m, rad] for parallel / intersecting axes and for writing
        near-zero values and multiples of pi/2 exactly.
    snap_angles : float
        Make URDF rpy angles and axis components that are within this [rad] of a right
        angle (of 0, +-1) exact before building the frames (see :func:`parse_urdf_text`);
        0 (default) keeps the file's numbers, so the model is exactly the URDF's.
    actuated : sequence of str, optional
        A URDF with ``<loop_joint>`` elements: names of the actuated joints (default: the joints named
        by its ``<transmission>`` elements); every other moving joint is passive (``mu = 0``).
        Ignored without loop joints.
    floating : bool, optional
        A floating base (:func:`_floating_base`; default: when a ``floating`` joint carries the root's only child).

    Returns
    -------
    str
        TOML robot-file text.
    """
    model = parse_urdf_text(text, file=file, snap_angles=snap_angles)
    f = model.file
    base, floating, base_frame = _floating_base(model, base, floating, base_frame)
    base, chain, tree, tip = _imported_part(model, base, tip)
    pose = _link_poses(model, base)
    g_base = np.asarray(gravity, float) if floating else _gravity_in_base(model, base, gravity)
    moving = [jt for jt in chain if jt.is_moving]
    n = len(moving)
    index = {jt.name: i for i, jt in enumerate(moving)}
    coupled = _couplings(model, moving)
    passive = _passive_joints(model, moving, actuated, coupled)
    parents = _moving_parents(model, base, moving, index)
    points = [pose[jt.child][:3, 3] for jt in moving]
    axes = [_unit(pose[jt.child][:3, :3] @ jt.axis) for jt in moving]
    frames, signs = _kk_frames(points, axes, base_frame, tol, parents)

    owner, ignored = _link_owners(model, base, chain, index)
    no_inertial = sorted(lk for lk, i in owner.items() if i is not None and model.links[lk].inertial is None)
    known = {i for lk, i in owner.items() if i is not None and model.links[lk].inertial is not None}
    unknown_links = [i for i in range(1, n + 1) if i not in known]
    _warn_left_out(f, f"{base} -> {tip}", ignored, no_inertial, unknown_links)
    inertial = _standard_parameters(model, owner, pose, frames, n)
    loop_frames = _loop_frames(model, owner, pose, frames, tol)

    rows = _mdh_rows(f, frames, parents, moving, tol)
    tip_fixed = not tree and chain[-1].type == "fixed"
    if tip_fixed:
        T = _inv(frames[n]) @ pose[tip]
        rows.append((n + 1, n, 2, _mdh_from_transform(T, tol), None))

    out = _UrdfText(tol, symbols, index, coupled, passive)
    out.nominal += _base_link_parameters(model, owner, pose) if floating else []
    for j, ant, sigma, params, jt in rows:
        out.frame(j, ant, sigma, params, jt, signs[j - 1] if jt is not None else 1, tip)
        if jt is not None:
            out.nominal_values(j, jt, inertial[j] if j not in unknown_links else None)
    for ell, (lj, cut, close) in enumerate(loop_frames, start=1):
        out.loop(len(rows) + ell, len(loop_frames), lj, cut, close)

    chain_text = ", ".join(f"{jt.name} ({jt.type})" for jt in chain)
    head = [f"# Imported from {file} by symoro_gen.description.urdf.import_urdf.",
            f"# Chain {base} -> {tip}: {chain_text}." if not tree else
            f"# Tree below {base} (frames depth first, branches by ant): {chain_text}."]
    if ignored:
        head.append("# Left out (moving joints off the chain, and what they carry): " + ", ".join(sorted(ignored)) + ".")
    if no_inertial:
        head.append("# Links without <inertial> (mass and inertia unknown): " + ", ".join(no_inertial) + "."
                    + (f" No nominal inertial values for MDH link(s) {', '.join(map(str, unknown_links))}."
                       if unknown_links else ""))
    if loop_frames:
        head.append(f"# Closed loops ([[loops]]) from the <loop_joint> elements; passive joints (mu = 0): "
                    f"{', '.join(jt.name for jt in moving if jt.name in passive)}; the loop solver starts from the "
                    "URDF zero configuration (no [loop_reference]: all zero).")
    if coupled:
        head.append("# Coupled joints (URDF <mimic>, q = multiplier * q_followed + offset; passive, no drive terms): "
                    + ", ".join(f"{jn} follows {src}" for jn, (src, _, _) in coupled.items()) + ".")
    if tip_fixed:
        head.append(f"# Frame {n + 1} is the tip link {tip} (fixed); its inertia is included in link {n}. "
                    f"Set payload = {n + 1} to identify a payload there.")
    robot_name = name if name is not None else _identifier(model.name or Path(file).stem or "robot")
    source = _source_text(model, file, f"tree below {base}" if tree else f"chain {base} -> {tip}",
                          "frame 0 = frame 1 at q = 0" if base_frame == "joint" else f"frame 0 = link {base}", floating)
    g0 = frames[0][:3, :3].T @ g_base
    head += [f"name = {json.dumps(robot_name)}", f"source = {json.dumps(source)}", *(['base = "floating"'] * floating),
             "gravity = [" + ", ".join(_num(_snap(x, tol)) for x in g0) + "]"]
    text_out = out.text(head, _limits_table([jt for jt in moving if jt.name not in passive],
                                            tuple(jt for jt in moving if jt.name in passive)))
    parse_robot_text(text_out, file=f"{file} (imported)")  # the output is a valid robot file, or say why
    return text_out


def _source_text(model: UrdfModel, file: str, what: str, frame_note: str, floating: bool) -> str:
    """The ``source`` line of an imported robot file."""
    return (f"URDF {Path(file).name} (robot '{model.name}'), {what}, {frame_note}"
            + (" (a floating base: the free body of Pinocchio's free-flyer root)" if floating else "")
            + "; imported by symoro_gen.description.urdf.import_urdf; nominal values from the URDF inertials "
            "(FV, FS from <dynamics damping friction>)")


def _floating_base(model: UrdfModel, base: str | None, floating: bool | None, base_frame: str
                   ) -> tuple[str | None, bool, str]:
    """``(base link, floating, base_frame)`` of a URDF import.

    A floating base (robot file ``base = "floating"``, docs/floating-base.md) is the free body of Pinocchio's
    free-flyer root (``pinocchio.buildModelFromUrdf(file, JointModelFreeFlyer())``): frame 0 is the base
    link's frame (``base_frame = "link"``) and gravity stays in the world (root) frame. ``floating=None``
    (default) takes the child of a ``floating`` joint that is the root link's only joint (a ``world`` link, the
    URDF habit) as the floating base; ``floating=True`` makes the base link (default: the root) a free body;
    ``floating=False`` keeps a fixed base (a ``floating`` joint is then refused as before).
    """
    if base_frame not in ("joint", "link"):
        raise ValueError(f"base_frame must be 'joint' or 'link', got {base_frame!r}")
    if floating is False:
        return base, False, base_frame
    kids = model.child_joints(model.roots[0]) if len(model.roots) == 1 else []
    if base is None and len(kids) == 1 and kids[0].type == "floating":
        return kids[0].child, True, "link"
    return base, bool(floating), "link" if floating else base_frame


def _base_link_parameters(model: UrdfModel, owner: dict[str, int | None], pose: dict[str, np.ndarray]
                          ) -> list[tuple[str, float]]:
    """The floating base link's standard parameters ``XX0 .. M0`` (frame 0 = the base link's frame, at its
    origin): the inertials of every URDF link fixed to it summed (none: no values, unknown)."""
    J, ms, m, known = np.zeros((3, 3)), np.zeros(3), 0.0, False
    for lk, i in owner.items():
        ine = model.links[lk].inertial
        if i is not None or ine is None:
            continue
        T = pose[lk] @ ine.origin
        R, c = T[:3, :3], T[:3, 3]
        J, ms, m, known = J + parallel_axis(R @ ine.inertia @ R.T, ine.mass, c), ms + ine.mass * c, m + ine.mass, True
    if not known:
        return []
    return list(zip((f"{k}0" for k in INERTIAL_KINDS), [*six_from_matrix(J), *ms, m]))


def _imported_part(model: UrdfModel, base: str | None, tip: str | None
                   ) -> tuple[str, list[UrdfJoint], bool, str]:
    """``(base, joints, tree, tip)``: the chain from base to tip, or the whole tree below the base (``tree``,
    and then ``tip`` is the base) when it branches into several moving chains or has loops."""
    if model.loops and tip is not None:
        raise RobotFileError([Problem(model.file, "tip link", tip, "a URDF with <loop_joint> elements is imported "
                                      "whole (the tree below the base and its loops): give no tip")])
    base, selected = _select_chain(model, base, tip, allow_tree=True)
    if selected is None or model.loops:  # several moving chains below the base, or loops: the whole tree
        return base, _select_tree(model, base), True, base
    return base, selected, False, selected[-1].child


def _warn_left_out(f: str, chain: str, ignored: list[str], no_inertial: list[str], unknown_links: list[int]) -> None:
    """Warn (at the caller of :func:`import_urdf_text`) about the moving side joints left out of the chain
    and the carried links without ``<inertial>``."""
    if ignored:
        warnings.warn(
            f"{f}: moving joints outside the chain {chain} are left out of the model "
            f"(with what they carry): {', '.join(sorted(ignored))}",
            UserWarning,
            stacklevel=3,
        )
    if no_inertial:
        what = (f"MDH link(s) {', '.join(map(str, unknown_links))} get no inertial [nominal] values (unknown)"
                if unknown_links else "they count as massless in the [nominal] values of their MDH link")
        warnings.warn(f"{f}: link(s) {', '.join(no_inertial)} carried by a moving joint have no <inertial>: "
                      f"their mass and inertia are unknown; {what}", UserWarning, stacklevel=3)


def _link_poses(model: UrdfModel, base: str) -> dict[str, np.ndarray]:
    """Link poses (base-link frame, q = 0) of the whole subtree below the base."""
    pose = {base: np.eye(4)}
    stack = [base]
    while stack:
        lk = stack.pop()
        for jt in model.child_joints(lk):
            pose[jt.child] = pose[lk] @ jt.origin
            stack.append(jt.child)
    return pose


def _gravity_in_base(model: UrdfModel, base: str, gravity) -> np.ndarray:
    """The gravity vector (given in the root link's frame) in the base link's frame."""
    R_root_base = np.eye(3)
    lk = base
    jt = model.parent_joint(lk)
    while jt is not None:
        R_root_base = jt.origin[:3, :3] @ R_root_base
        lk = jt.parent
        jt = model.parent_joint(lk)
    return R_root_base.T @ np.asarray(gravity, float)


def _moving_parents(model: UrdfModel, base: str, moving: list[UrdfJoint], index: dict[str, int]) -> list[int]:
    """Index of the moving joint carrying each moving joint (-1: the base); ``ant = parent + 1``."""
    parents = []
    for jt in moving:
        up = model.parent_joint(jt.parent) if jt.parent != base else None
        while up is not None and up.name not in index:
            up = model.parent_joint(up.parent) if up.parent != base else None
        parents.append(-1 if up is None else index[up.name])
    return parents


def _link_owners(model: UrdfModel, base: str, chain: list[UrdfJoint], index: dict[str, int]
                 ) -> tuple[dict[str, int | None], list[str]]:
    """Which MDH link carries each URDF link (None: the ground), and the moving side joints left out
    (with what they carry)."""
    owner: dict[str, int | None] = {base: None}
    ignored: list[str] = []
    on_chain = {jt.name for jt in chain}
    for jt in chain:  # parents before children (a chain, or a tree depth first)
        owner[jt.child] = index[jt.name] + 1 if jt.is_moving else owner[jt.parent]
    for lk in [base] + [jt.child for jt in chain]:
        stack = [jt for jt in model.child_joints(lk) if jt.name not in on_chain]
        while stack:
            jt = stack.pop()
            if jt.type != "fixed":
                ignored.append(jt.name)
                continue
            owner[jt.child] = owner[jt.parent]
            stack.extend(model.child_joints(jt.child))
    return owner, ignored


def _standard_parameters(model: UrdfModel, owner: dict[str, int | None], pose: dict[str, np.ndarray],
                         frames: list, n: int) -> dict[int, np.ndarray]:
    """The standard parameters of each moving link, in its MDH frame at the origin (the inertials of every
    URDF link it carries summed)."""
    inertial = {i: np.zeros(10) for i in range(1, n + 1)}
    J = {i: np.zeros((3, 3)) for i in range(1, n + 1)}
    for lk, i in owner.items():
        ine = model.links[lk].inertial
        if i is None or ine is None:
            continue
        T = _inv(frames[i]) @ pose[lk] @ ine.origin
        R, c, m = T[:3, :3], T[:3, 3], ine.mass
        J[i] += parallel_axis(R @ ine.inertia @ R.T, m, c)
        inertial[i][6:9] += m * c
        inertial[i][9] += m
    for i in range(1, n + 1):
        inertial[i][:6] = six_from_matrix(J[i])
    return inertial


def _mdh_rows(f: str, frames: list, parents: list[int], moving: list[UrdfJoint], tol: float) -> list[tuple]:
    """``(j, ant, sigma, MDH parameters, URDF joint)`` of every moving joint."""
    rows: list[tuple] = []
    for i in range(1, len(moving) + 1):
        ant = parents[i - 1] + 1
        T = _inv(frames[ant]) @ frames[i]
        params = _mdh_from_transform(T, tol)
        err = np.abs(mdh_transform(*params) - T).max()
        if err > 1e3 * tol:  # pragma: no cover - internal consistency check
            raise ModelError(f"{f}: MDH decomposition of joint {moving[i - 1].name} is off by {err:.2e}")
        rows.append((i, ant, 0 if moving[i - 1].type != "prismatic" else 1, params, moving[i - 1]))
    return rows


class _UrdfText:
    """The robot-file text of a URDF import, written part by part: ``[[frames]]``, ``[[loops]]``, the
    ``[nominal]`` values, and the lengths written as symbols (``[values]``, in order of appearance)."""

    def __init__(self, tol: float, symbols: bool, index: dict[str, int],
                 coupled: dict[str, tuple[str, float, float]], passive: set[str]) -> None:
        self.tol, self.symbols, self.index, self.coupled, self.passive = tol, symbols, index, coupled, passive
        self.values: dict[str, float] = {}
        self.frames: list[str] = []
        self.loops: list[str] = []
        self.nominal: list[tuple[str, float]] = []

    def length(self, x: float, sym: str) -> str:
        x = _snap(x, self.tol)
        if x == 0.0:
            return "0"
        if self.symbols:
            self.values[sym] = x
            return f'"{sym}"'
        return _num(x)

    def geometry(self, k: int, params: tuple[float, ...], var: int | None, sign: int = 1) -> list[str]:
        """``gamma b alpha d theta r`` of frame ``k`` (gamma and b only when not zero); ``var``: 0 revolute
        (``theta = ±q + ...``), 1 prismatic (``r = ±q + ...``), None fixed; ``sign``: that of q."""
        tol = self.tol
        gamma, b, alpha, d, theta, r = params
        out = []
        g_s, b_s = _angle_str(gamma, tol), self.length(b, f"B{k}")
        if g_s != "0" or b_s != "0":
            out += [f'gamma = "{g_s}"', f"b = {b_s}"]
        out += [f'alpha = "{_angle_str(alpha, tol)}"', f"d = {self.length(d, f'D{k}')}"]
        q = "q" if sign > 0 else "-q"
        if var == 0:
            out += [f'theta = "{_offset_expr(q, _angle_str(theta, tol))}"', f"r = {self.length(r, f'RL{k}')}"]
        elif var == 1:
            r_s = self.length(r, f"RL{k}")
            r_s = r_s.strip('"') if r_s != "0" else "0"
            out += [f'theta = "{_angle_str(theta, tol)}"', f'r = "{_offset_expr(q, r_s)}"']
        else:
            out += [f'theta = "{_angle_str(theta, tol)}"', f"r = {self.length(r, f'RL{k}')}"]
        return out

    def frame(self, j: int, ant: int, sigma: int, params: tuple[float, ...], jt: UrdfJoint | None, sign: int,
              tip: str) -> None:
        """The ``[[frames]]`` entry of frame ``j`` (``jt``: its URDF joint, None for the tip link's frame)."""
        tol = self.tol
        lines = ["[[frames]]  # " + (f"URDF joint {jt.name} ({jt.type}), link {jt.child}" if jt
                                     else f"fixed frame of the tip link {tip}"),
                 f"j = {j}", f"ant = {ant}", f"sigma = {sigma}"]
        if jt is not None and jt.name and not any(ch.isspace() for ch in jt.name):
            lines.append(f"name = {json.dumps(jt.name)}")   # ROS bags' joints are matched by it
        if jt is not None and jt.name in self.coupled:
            src, k_, c_ = self.coupled[jt.name]
            off = _angle_str(c_, tol) if sigma == 0 else repr(_snap(c_, tol))
            off = off if re.fullmatch(r"-?[0-9.eE+-]+", off) else f'"{off}"'  # a number, or "pi/2"
            lines.append(f"mimic = {{ joint = {self.index[src] + 1}, multiplier = {_num(_snap(k_, tol))}, "
                         f'offset = {off} }}  # URDF <mimic joint="{jt.mimic}">')
        elif jt is not None and jt.name in self.passive:
            lines.append("mu = 0")
        lines += self.geometry(j, params, sigma if sigma in (0, 1) else None, sign)
        self.frames.append("\n".join(lines))

    def nominal_values(self, j: int, jt: UrdfJoint, inertial: np.ndarray | None) -> None:
        """The standard parameters of link ``j`` (None: unknown) and its drive terms (none when passive)."""
        if inertial is not None:
            self.nominal += [(f"{kind}{j}", v) for kind, v in zip(INERTIAL_KINDS, inertial)]
        if jt.name not in self.passive:  # passive joints carry no drive terms
            if jt.damping is not None:
                self.nominal.append((f"FV{j}", jt.damping))
            if jt.friction is not None:
                self.nominal.append((f"FS{j}", jt.friction))

    def loop(self, k: int, n_loops: int, lj: UrdfLoopJoint, cut_frame: tuple, close_frame: tuple) -> None:
        """The ``[[loops]]`` entry of a ``<loop_joint>``: cut frame ``k``, closing frame ``k + n_loops``."""
        (ant1, sig, p1), (ant2, p2) = cut_frame, close_frame
        cut = [f"ant = {ant1}", f"sigma = {sig}"] + self.geometry(k, p1, sig)
        close = [f"ant = {ant2}", "sigma = 2"] + self.geometry(k + n_loops, p2, None)
        self.loops.append(f"[[loops]]  # URDF loop_joint {lj.name} ({lj.type}): cut frame {k} on link {lj.link1}, "
                          f"closing frame {k + n_loops} on link {lj.link2}\ncut = {{ " + ", ".join(cut)
                          + " }\nclose = { " + ", ".join(close) + " }")

    def text(self, head: list[str], limits_text: str) -> str:
        parts = ["\n".join(head)]
        if self.values:
            parts.append("[values]\n" + "\n".join(f"{k} = {_num(v)}" for k, v in self.values.items()))
        parts += self.frames
        parts += self.loops
        nominal_lines = ["[nominal]", "# standard parameters in frame j at its origin [kg, kg m, kg m^2]; "
                                      "FV [N m s/rad], FS [N m]"]
        nominal_lines += [f"{k} = {_num(_snap(v, 1e-15))}" for k, v in self.nominal]
        parts.append("\n".join(nominal_lines))
        if limits_text:
            parts.append(limits_text)
        return "\n\n".join(parts) + "\n"


def _passive_joints(model: UrdfModel, moving: list[UrdfJoint], actuated, coupled=None) -> set[str]:
    """Names of the passive moving joints: the mimic joints (``coupled``), and for a URDF with loop joints
    those not in ``actuated`` (default: the joints named by the ``<transmission>`` elements). A followed
    joint must be actuated."""
    coupled = coupled or {}
    f = model.file
    if actuated is not None and model.loops:
        named = sorted(set(map(str, actuated)) & set(coupled))
        if named:
            raise RobotFileError([Problem(f, "actuated", "joint", f"{', '.join(named)}: a mimic joint is passive (it "
                                          "follows another joint); do not name it as actuated")])
    if not model.loops:
        return set(coupled)
    passive = _loop_passive(model, moving, actuated) | set(coupled)
    for jn, (src, _, _) in coupled.items():
        if src in passive:
            raise RobotFileError([Problem(f, f"joint {jn}", "mimic", f"follows joint {src!r}, which is passive (not "
                                          "actuated): a coupled joint follows an actuated one")])
    return passive


def _loop_passive(model: UrdfModel, moving: list[UrdfJoint], actuated) -> set[str]:
    """The passive joints of a URDF with loop joints: the moving joints not in ``actuated`` (default: those
    named by the ``<transmission>`` elements)."""
    f = model.file
    names = {jt.name for jt in moving}
    if actuated is None:
        if model.transmitted is None:
            raise RobotFileError([Problem(f, "<loop_joint>", "transmission", (
                "a URDF with loop joints must say which joints are actuated: name them in <transmission> "
                "elements (<transmission><joint name=.../></transmission>) or pass --actuated J1,J2,..."))])
        act = set(model.transmitted)
        where = "<transmission>"
    else:
        act = {str(a) for a in actuated}
        where = "actuated"
    unknown = sorted(act - names)
    if unknown:
        raise RobotFileError([Problem(f, where, "joint", f"not a moving joint of the imported tree: {', '.join(unknown)} "
                                      f"(moving joints: {', '.join(jt.name for jt in moving)})")])
    if not act:
        raise RobotFileError([Problem(f, where, "joint", "no actuated joint")])
    return names - act


def _align_z(axis: np.ndarray) -> np.ndarray:
    """A rotation whose z column is the unit vector ``axis`` (x: the part of a base vector orthogonal to it)."""
    ref = np.array([1.0, 0, 0]) if abs(axis[0]) < 0.9 else np.array([0, 1.0, 0])
    return _frame(np.zeros(3), _perp(ref, axis), axis)[:3, :3]


def _loop_frames(model: UrdfModel, owner: dict, pose: dict, frames: list, tol: float) -> list:
    """The cut and closing frames of every ``<loop_joint>`` as MDH parameters on their links.

    The joint frame on ``link1`` (``origin1``, z along the axis) becomes the cut frame, on the MDH link
    carrying ``link1``, with the loop joint's variable (its value at the URDF zero configuration is 0);
    the joint frame on ``link2`` becomes the closing frame (fixed, ``sigma = 2``) on the MDH link carrying
    ``link2``. The loop is closed when they coincide ([KK1986], [[loops]] of the robot file). A loop that
    is not closed at the URDF zero configuration is warned about (the solver starts from there)."""
    f = model.file
    out = []
    problems = []
    for lj in model.loops:
        where = f"loop_joint {lj.name}"
        ants = []
        for tag, lk in (("link1", lj.link1), ("link2", lj.link2)):
            if lk not in owner:
                problems.append(Problem(f, where, tag, f"link {lk!r} is not in the tree imported below the base"))
            ants.append(owner.get(lk) or 0)
        if problems:
            continue
        if ants[0] == ants[1]:
            problems.append(Problem(f, where, "link2", f"links {lj.link1!r} and {lj.link2!r} are rigidly attached "
                                    "to the same body: no loop"))
            continue
        R = _hom(_align_z(lj.axis), np.zeros(3))
        J1 = pose[lj.link1] @ lj.origin1 @ R
        J2 = pose[lj.link2] @ lj.origin2 @ R
        gap = float(np.linalg.norm(J1[:3, 3] - J2[:3, 3]))
        tilt = float(np.linalg.norm(np.cross(J1[:3, 2], J2[:3, 2])))
        if lj.type == "prismatic":
            gap = float(np.linalg.norm(_perp(J1[:3, 3] - J2[:3, 3], J1[:3, 2])))
        if gap > 1e3 * tol or tilt > 1e3 * tol:
            warnings.warn(f"{f}: loop_joint {lj.name} is not closed at the URDF zero configuration (gap {gap:.3g} m, "
                          f"axes {math.degrees(math.asin(min(tilt, 1.0))):.3g} deg apart): the loop solver starts "
                          "from there; add a [loop_reference] of an assembled configuration to the robot file",
                          UserWarning, stacklevel=3)
        p1 = _mdh_from_transform(_inv(frames[ants[0]]) @ J1, tol)
        p2 = _mdh_from_transform(_inv(frames[ants[1]]) @ J2, tol)
        out.append((lj, (ants[0], LOOP_TYPES[lj.type], p1), (ants[1], p2)))
    if problems:
        raise RobotFileError(problems)
    return out

def _limits_table(moving: list[UrdfJoint], passive: tuple[UrdfJoint, ...] = ()) -> str:
    """``[limits]`` from the moving joints' ``<limit lower upper velocity effort>`` (a field is written
    when every joint gives it; the robot file's q is the URDF joint value, so no sign change), and
    ``passive_q_min, passive_q_max`` from the ``passive`` joints' ``lower, upper`` (when every one gives
    both, ``lower < upper``)."""
    cols: dict[str, list[float]] = {}
    for i, key in enumerate(("q_min", "q_max", "dq_max", "tau_max")):
        given = [jt.limit[i] if jt.limit is not None else None for jt in moving]
        vals = [v for v in given if v is not None]
        if given and len(vals) == len(given):
            if key in ("dq_max", "tau_max") and not all(v > 0 for v in vals):
                continue  # URDF writes 0 for "unknown"
            cols[key] = vals
    if ("q_min" in cols) != ("q_max" in cols) or ("q_min" in cols and not all(
            lo < hi for lo, hi in zip(cols["q_min"], cols["q_max"]))):
        cols.pop("q_min", None)
        cols.pop("q_max", None)
    bounds = [jt.limit[:2] if jt.limit is not None else (None, None) for jt in passive]
    ranges = [(lo, hi) for lo, hi in bounds if lo is not None and hi is not None and lo < hi]
    if bounds and len(ranges) == len(bounds):
        cols["passive_q_min"], cols["passive_q_max"] = [lo for lo, _ in ranges], [hi for _, hi in ranges]
    if not cols:
        return ""
    lines = ["[limits]", "# from the URDF <limit lower upper velocity effort> of each joint [rad or m, /s, N m or N]"]
    lines += [f"{k} = [" + ", ".join(_num(float(v)) for v in vals) + "]" for k, vals in cols.items()]
    return "\n".join(lines)
