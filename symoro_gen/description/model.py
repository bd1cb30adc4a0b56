"""Value types describing a robot: MDH rows, drive chain, the whole robot."""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING

import sympy as sp

from ..params import DRIVE_KINDS, INERTIAL_KINDS, param_name
from .friction_law import FrictionLaw

if TYPE_CHECKING:
    from .elastic import ElasticJoint

REVOLUTE, PRISMATIC, FIXED = 0, 1, 2


def q_symbol(j: int) -> sp.Symbol:
    """Joint position symbol of joint j (frame j)."""
    return sp.Symbol(f"q{j}", real=True)


def dq_symbol(j: int) -> sp.Symbol:
    return sp.Symbol(f"dq{j}", real=True)


def ddq_symbol(j: int) -> sp.Symbol:
    return sp.Symbol(f"ddq{j}", real=True)


@dataclass(frozen=True)
class MdhRow:
    """One frame of a Khalil-Kleinfinger MDH table.

    T(ant, j) = Rot(z, gamma) Trans(z, b) Rot(x, alpha) Trans(x, d) Rot(z, theta) Trans(z, r).
    Geometric fields are sympy expressions; ``theta`` (revolute) or ``r`` (prismatic) contains
    the joint symbol ``q<j>``. The transform itself, numeric and symbolic, and the joint sign are in
    :mod:`symoro_gen.description.mdh`.

    Examples
    --------
    A revolute joint 2 on frame 1, turned by ``pi/2`` about x, offset ``D2`` along x:

    >>> row = MdhRow(j=2, ant=1, sigma=REVOLUTE, mu=1, gamma=sp.S(0), b=sp.S(0), alpha=sp.pi / 2,
    ...              d=sp.Symbol("D2"), theta=q_symbol(2), r=sp.S(0))
    >>> row.is_moving, row.drive
    (True, ('IA', 'FV', 'FS', 'OFF'))
    >>> MdhRow(3, 2, FIXED, 0, *[sp.S(0)] * 6).is_moving
    False
    """

    j: int
    ant: int
    sigma: int
    mu: int
    gamma: sp.Expr
    b: sp.Expr
    alpha: sp.Expr
    d: sp.Expr
    theta: sp.Expr
    r: sp.Expr
    drive: tuple[str, ...] = DRIVE_KINDS
    #: the joint's name in the robot's logs and URDF (``name`` of the ``[[frames]]`` entry), or None
    name: str | None = None

    @property
    def is_moving(self) -> bool:
        return self.sigma in (REVOLUTE, PRISMATIC)


@dataclass(frozen=True)
class DriveChain:
    """Motor-side to joint-side mapping (for recordings made on the motor side).

    With ``R = diag(ratios) @ coupling`` and ``D = diag(directions)`` (entries +-1)::

        q_motor   = R @ D @ (q_joint - offsets)       (motor k turns by ratios[k] * sum_j coupling[k][j] * q~_j)
        q_joint   = D @ inv(R) @ q_motor + offsets    (velocities, accelerations: without offsets)
        tau_joint = D @ R.T @ tau_motor               (power balance tau_joint . dq_joint = tau_motor . dq_motor)

    ``offsets`` is the joint position (MDH convention) when the motor reads zero, e.g. the TX40's
    ``q2 -= pi/2, q3 += pi/2`` is ``offsets = [0, -pi/2, pi/2, 0, 0, 0]``; its wrist (motor 6 turns
    as ``32 (q5 + q6)``) is ``ratios[5] = 32, coupling[5] = [0, 0, 0, 0, 1, 1]``, which gives the
    joint-5 torque ``45 tau_m5 + 32 tau_m6``. Applied by
    :func:`symoro_gen.preprocessing.drive_chain.motor_to_joint`.
    """

    ratios: tuple[float, ...]
    coupling: tuple[tuple[float, ...], ...]
    offsets: tuple[float, ...]
    directions: tuple[float, ...]


@dataclass(frozen=True)
class JointLimits:
    """Per-joint motion and torque limits of the robot file's ``[limits]`` table (SI units).

    Each field is a tuple with one entry per moving joint (joint order), or None when the file
    does not give it. Positions in rad (revolute) or m (prismatic), velocities rad/s or m/s,
    accelerations rad/s^2 or m/s^2, torques N m or N. See ``docs/robot-file.md``.

    For a closed-loop or coupled robot, the fields of ``FIELDS`` have one entry per actuated joint, and
    ``passive_q_min``, ``passive_q_max`` the position range of each passive joint (``mu = 0``), whose joint
    numbers are ``passive_joints`` (joint order; ``()`` when the file gives no passive range).
    """

    q_min: tuple[float, ...] | None = None
    q_max: tuple[float, ...] | None = None
    dq_max: tuple[float, ...] | None = None
    ddq_max: tuple[float, ...] | None = None
    tau_max: tuple[float, ...] | None = None
    passive_q_min: tuple[float, ...] | None = None
    passive_q_max: tuple[float, ...] | None = None
    passive_joints: tuple[int, ...] = ()

    FIELDS = ("q_min", "q_max", "dq_max", "ddq_max", "tau_max")


@dataclass(frozen=True)
class LoopClosure:
    """One closed loop in Khalil & Kleinfinger's notation ([KK1986]; [KD2002] sec. 7.3; SYMORO+ ``.par``
    frames ``NL+1..NJ`` and ``NJ+1..NF``).

    The loop is cut at a passive joint: ``cut`` is the frame of the cut joint, placed on its
    antecedent link ``cut.ant`` with its joint variable ``q<cut.j>``; ``close`` is a fixed frame
    (``sigma = 2``) on the link ``close.ant`` on the other side of the cut. The loop is closed when
    both frames coincide, ``T(0, cut) = T(0, close)``. Neither frame carries a body.
    """

    cut: MdhRow
    close: MdhRow


@dataclass(frozen=True)
class Coupling:
    """A coupled (mimic) joint: ``q<joint> = multiplier * q<source> + offset``.

    The semantics of URDF's ``<mimic joint multiplier offset>``: frame ``joint`` is a passive joint
    (``mu = 0``) whose variable is a linear function of the actuated joint ``source`` (a gear pair, the
    two fingers of a gripper). It is a holonomic constraint with a constant Jacobian: the model is the
    tree's projected by ``G = d q_tree / d q_a`` (:mod:`symoro_gen.closedloop`, as for closed loops), so
    ``tau_source = tau_tree,source + multiplier * tau_tree,joint``. ``multiplier`` and ``offset`` are
    exact sympy numbers (``offset`` in rad or m, the unit of ``joint``).
    """

    joint: int
    source: int
    multiplier: sp.Expr
    offset: sp.Expr


@dataclass(frozen=True)
class RobotDescription:
    """A parsed, validated robot file."""

    name: str
    rows: tuple[MdhRow, ...]
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    values: Mapping[str, float] = field(default_factory=dict)
    payload: int | None = None
    nominal: Mapping[str, float] | None = None
    source: str = ""
    file: str = "<string>"
    file_hash: str = ""
    drive_chain: DriveChain | None = None
    limits: JointLimits | None = None
    loops: tuple[LoopClosure, ...] = ()
    loop_reference: Mapping[str, float] = field(default_factory=dict)
    couplings: tuple[Coupling, ...] = ()
    #: declared friction laws by frame number (``friction_law`` field, :mod:`.friction_law`)
    friction_laws: Mapping[int, FrictionLaw] = field(default_factory=dict)
    #: the declared elastic joints (``elastic`` tables; :mod:`symoro_gen.description.elastic`), joint order
    elastic: tuple[ElasticJoint, ...] = ()
    #: ``"fixed"`` (frame 0 is the ground) or ``"floating"`` (frame 0 is a free body with 6 degrees of
    #: freedom whose 10 inertial parameters are unknowns; :mod:`symoro_gen.dynamics.floating`)
    base: str = "fixed"
    #: the contact frames of a floating base (top-level ``contacts``: frame numbers, in the file's order),
    #: whose pose and Jacobian its generated package emits (:mod:`symoro_gen.emit.floating`)
    contacts: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "values", MappingProxyType(dict(self.values)))
        object.__setattr__(self, "loop_reference", MappingProxyType(dict(self.loop_reference)))
        if self.nominal is not None:
            object.__setattr__(self, "nominal", MappingProxyType(dict(self.nominal)))

    # ---- derived views -------------------------------------------------
    @property
    def joints(self) -> tuple[MdhRow, ...]:
        """The moving frames (revolute or prismatic), in joint order."""
        return tuple(r for r in self.rows if r.is_moving)

    @property
    def floating(self) -> bool:
        """True for a floating base (``base = "floating"``): frame 0 is a free body."""
        return self.base == "floating"

    @property
    def n_joints(self) -> int:
        return len(self.joints)

    @property
    def model_joints(self) -> tuple[MdhRow, ...]:
        """The joints of the identification model and of the recordings: every moving joint, or the
        actuated ones of a closed-loop robot (``[[loops]]``) or of one with coupled joints (``mimic``):
        its passive joints are solved, not logged."""
        return self.actuated if self.constrained else self.joints

    @property
    def joint_names(self) -> tuple[str, ...] | None:
        """The names of the model joints (``name`` of their ``[[frames]]`` entries), or None unless
        every model joint has one."""
        names = [r.name for r in self.model_joints]
        return None if not names or any(n is None for n in names) else tuple(str(n) for n in names)

    @property
    def constrained(self) -> bool:
        """True for a robot whose model is its tree's projected on the actuated joints: closed loops
        (``[[loops]]``) or coupled joints (``mimic``), see :mod:`symoro_gen.closedloop`."""
        return bool(self.loops or self.couplings)

    def elastic_joint(self, j: int) -> ElasticJoint | None:
        """The declared elasticity of joint ``j`` (an ``elastic`` table), or None for a rigid joint."""
        return next((e for e in self.elastic if e.joint == j), None)

    def coupling(self, j: int) -> Coupling | None:
        """The coupling of frame ``j`` (a mimic joint), or None."""
        return next((c for c in self.couplings if c.joint == j), None)

    @property
    def actuated(self) -> tuple[MdhRow, ...]:
        """The actuated moving frames (``mu = 1``), in joint order (all joints of an open structure)."""
        return tuple(r for r in self.joints if r.mu == 1)

    def row(self, j: int) -> MdhRow:
        return self.rows[j - 1]

    @property
    def q(self) -> tuple[sp.Symbol, ...]:
        return tuple(q_symbol(r.j) for r in self.joints)

    @property
    def dq(self) -> tuple[sp.Symbol, ...]:
        return tuple(dq_symbol(r.j) for r in self.joints)

    @property
    def ddq(self) -> tuple[sp.Symbol, ...]:
        return tuple(ddq_symbol(r.j) for r in self.joints)

    @property
    def standard_names(self) -> tuple[str, ...]:
        """Names of the robot's standard parameters (payload excluded), column order; a floating base's
        link (frame 0) first, with its 10 inertial parameters (no drive terms)."""
        names: list[str] = [param_name(k, 0) for k in INERTIAL_KINDS] if self.floating else []
        for r in self.joints:
            names += [param_name(k, r.j) for k in INERTIAL_KINDS]
            names += [param_name(k, r.j) for k in DRIVE_KINDS if k in r.drive]
        return tuple(names)

    @property
    def payload_names(self) -> tuple[str, ...]:
        if self.payload is None:
            return ()
        return tuple(param_name(k, self.payload) for k in INERTIAL_KINDS)

    @property
    def geometry_symbols(self) -> tuple[sp.Symbol, ...]:
        return tuple(sp.Symbol(k, real=True) for k in sorted(self.values))

    def geometry_subs(self) -> dict[sp.Symbol, float]:
        return {sp.Symbol(k, real=True): float(v) for k, v in self.values.items()}

    def children(self, j: int) -> tuple[int, ...]:
        return tuple(r.j for r in self.rows if r.ant == j)

    def ancestors(self, j: int) -> tuple[int, ...]:
        """Frames from j's antecedent down to the base (0 excluded)."""
        out = []
        a = self.row(j).ant
        while a != 0:
            out.append(a)
            a = self.row(a).ant
        return tuple(out)

    def nominal_vector(self) -> tuple[float, ...] | None:
        """Nominal standard parameters in ``standard_names`` order (missing ones 0), or None."""
        if self.nominal is None:
            return None
        return tuple(float(self.nominal.get(n, 0.0)) for n in self.standard_names)

    def nominal_payload(self) -> tuple[float, ...] | None:
        if self.nominal is None or self.payload is None:
            return None
        if not any(n in self.nominal for n in self.payload_names):
            return None
        return tuple(float(self.nominal.get(n, 0.0)) for n in self.payload_names)
