"""MDH robot -> MuJoCo MJCF (``symoro-gen export-mjcf``), with the identified drive terms.

Conventions (MDH frames -> MuJoCo bodies; Khalil & Kleinfinger 1986):

* frame j of the MDH table is MuJoCo body ``link<j>``, nested in body ``link<ant(j)>`` (the world body
  for ``ant = 0``), so trees are kept; its ``pos``/``quat`` are the constant part of ``T(ant, j)``
  (the transform at ``q = 0``, ``quat`` as MuJoCo's ``w x y z``);
* ``T(ant, j)(q) = T(ant, j)(0) Rot(z, s q)`` for a revolute joint (``Trans(z, s q)`` for a prismatic
  one, ``s = -1`` for a ``-q`` row), so joint j is a ``hinge`` (``slide``) at the body origin with
  axis ``0 0 s``: MuJoCo's ``qpos[j]`` is the model's ``q_j`` and its generalised force the model's
  ``tau_j``; a fixed frame (``sigma = 2``, e.g. the payload) is a body without joint;
* each body's ``<inertial>`` is its mass, centre of mass and full inertia at the centre of mass in the
  body frame, from the ten standard parameters at the frame origin (inverse parallel-axis theorem,
  :func:`symoro_gen.description.inertia.com_from_standard`); ``inertiafromgeom="false"``, no geoms;
* drive terms: ``armature`` = rotor inertia ``IA`` (MuJoCo adds it to the diagonal of the joint-space
  inertia matrix, exactly the ``IA ddq`` of the model), ``damping`` = viscous ``FV`` (passive force
  ``-FV dq``), ``frictionloss`` = Coulomb ``FS`` (a soft friction constraint of MuJoCo: equal to
  ``FS sign(dq)`` only away from zero velocity); the torque offset ``OFF`` has no MuJoCo field and is
  written as a comment; one ``<motor>`` per joint (``gear 1``, unlimited) drives ``tau`` directly;
* a joint with a declared friction law (the robot file's ``friction_law``): MuJoCo has no Stribeck, tanh
  or power law of the speed, so the export is an approximation, stated in a comment on the joint
  (:func:`friction_law_terms`): ``frictionloss`` = the Coulomb (sliding) level ``FS`` = ``Fc`` (the
  Stribeck hump ``Fs - Fc`` below ``vs`` and the tanh smoothing below ``v`` are left out: MuJoCo's soft
  friction constraint is its own smoothing), ``damping`` = ``FV`` for the Stribeck and tanh laws; for
  the power law ``FV |dq|^delta sign(dq)`` the linear damping closest to it in least squares over
  ``|dq| <= dq_max`` (``[limits] dq_max``, else 1 rad/s or m/s): ``FV 3 dq_max^(delta - 1) / (delta + 2)``;
* motors on the actuated joints only (``mu = 1``): a passive joint of a closed loop or a coupled joint has none;
* a closed loop (``[[loops]]``, [KK1986]; [KD2002] sec. 7.3) stays cut in the body tree and is closed by
  equality constraints between sites: the cut frame ``k`` (on body ``link<ant(k)>``, pose ``T(ant, k)`` at
  ``q_k = 0``) and the closing frame ``c`` (on ``link<ant(c)>``) must coincide up to a rotation about their
  common z axis, the cut joint being revolute. Two ``<connect site1 site2>`` hold it: sites ``cut<k>`` and
  ``close<c>`` at the two frame origins, sites ``cut<k>_axis`` and ``close<c>_axis`` at ``LOOP_AXIS_POINT``
  along their z axes (two points of the hinge axis held together leave exactly the rotation about it free,
  five independent equations; a planar loop needs fewer and the others hold identically). MuJoCo has no
  equality that leaves a sliding motion free (a ``connect`` holds a point, a ``weld`` a whole frame), so a
  prismatic cut joint is refused (:class:`~symoro_gen.errors.ModelError` naming the loop);
* a coupled joint (``mimic``, ``q_m = multiplier q_s + offset``) has no motor and a joint equality
  ``<joint joint1="joint<m>" joint2="joint<s>" polycoef="offset multiplier 0 0 0"/>`` (MuJoCo enforces it
  as a soft constraint, as it does every equality);
* an elastic joint (the robot file's ``elastic = {K, D}``; Spong's flexible-joint model [Spong1987]) is two
  joints: the link joint ``joint<j>`` as above, without drive terms, and a rotor: a body ``rotor<j>`` at the same
  pose in the same parent, of negligible mass, with a hinge (slide) ``rotor<j>`` on the same axis carrying the
  drive terms (``armature`` = ``IA``, ``damping`` = ``FV``, ``frictionloss`` = ``FS``: the motor side's). A fixed
  tendon ``transmission<j>`` of length ``theta_j - q_j`` (``coef`` 1 on the rotor, -1 on the link), ``stiffness`` =
  ``K``, ``damping`` = ``D``, ``springlength`` 0, passes ``K (theta - q) + D (dtheta - dq)`` to the link and its
  opposite to the rotor; the motor drives the rotor. Without a declared ``IA`` the rotor gets the armature
  :func:`rotor_armature` (the spring's natural frequency ``1 / (20 timestep)``, said in a comment), so that the
  integrator resolves it. At rest under gravity the deflection is ``tau / K`` ([LWR4-TLS] eq. 17);
* a floating base (``base = "floating"``): the link bodies are nested in a body ``base_link`` with a
  ``<freejoint/>`` and the base link's inertial (:func:`floating_base_open`, MuJoCo's free-joint conventions);
* joint ``range`` from the robot file's ``[limits]`` (``q_min``, ``q_max``; a passive joint's
  ``passive_q_min``, ``passive_q_max``) when present, ``gravity`` from the robot file; ``integrator="RK4"``,
  ``timestep`` 1 ms (options).
"""
from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from ..errors import ModelError
from .mdh import joint_sign, row_transform
from .model import FIXED, PRISMATIC, REVOLUTE, RobotDescription
from .urdf_export import (
    constant_transform,
    inertial_of,
    joint_limits,
    link_values,
    xml_comment,
    xml_float,
)

__all__ = ["LOOP_AXIS_POINT", "LOOP_SOLIMP", "export_mjcf", "floating_base_open", "loop_sites", "quat_from_matrix",
           "rotor_armature"]

#: distance [m] along a loop's cut axis of the second pair of sites held together by a ``connect``
LOOP_AXIS_POINT = 0.1


def quat_from_matrix(R) -> tuple[float, float, float, float]:
    """Unit quaternion ``(w, x, y, z)`` of a rotation matrix (Shepperd's method).

    Examples
    --------
    >>> [round(v, 12) for v in quat_from_matrix(np.eye(3))]
    [1.0, 0.0, 0.0, 0.0]
    """
    R = np.asarray(R, float)
    tr = np.trace(R)
    if tr > 0:
        S = 2.0 * np.sqrt(tr + 1.0)
        q = (0.25 * S, (R[2, 1] - R[1, 2]) / S, (R[0, 2] - R[2, 0]) / S, (R[1, 0] - R[0, 1]) / S)
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        S = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        q = ((R[2, 1] - R[1, 2]) / S, 0.25 * S, (R[0, 1] + R[1, 0]) / S, (R[0, 2] + R[2, 0]) / S)
    elif R[1, 1] > R[2, 2]:
        S = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        q = ((R[0, 2] - R[2, 0]) / S, (R[0, 1] + R[1, 0]) / S, 0.25 * S, (R[1, 2] + R[2, 1]) / S)
    else:
        S = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        q = ((R[1, 0] - R[0, 1]) / S, (R[0, 2] + R[2, 0]) / S, (R[1, 2] + R[2, 1]) / S, 0.25 * S)
    u = np.array(q, float)
    u /= np.linalg.norm(u)
    return float(u[0]), float(u[1]), float(u[2]), float(u[3])


#: impedance of the loop-closure constraints: MuJoCo's equalities are soft, this is the stiffest it allows
LOOP_SOLIMP = "0.9999 0.9999 0.001 0.5 2"


def _v(xs) -> str:
    return " ".join(xml_float(x) for x in xs)


def loop_sites(robot: RobotDescription) -> dict[int, list[tuple[str, np.ndarray]]]:
    """``body (frame number, 0 the world) -> [(site name, position in the body frame)]`` of the closed loops.

    Per loop, the cut frame ``k`` on its antecedent link and the closing frame ``c`` on its link give two sites
    each: ``cut<k>``/``close<c>`` at the frame origin and ``cut<k>_axis``/``close<c>_axis`` at
    :data:`LOOP_AXIS_POINT` along the frame's z axis (the cut joint's axis; its rotation ``q_k`` moves neither
    point). A prismatic cut joint raises :class:`~symoro_gen.errors.ModelError`: MuJoCo has no equality
    constraint that leaves a sliding motion free."""
    subs = robot.geometry_subs()
    out: dict[int, list[tuple[str, np.ndarray]]] = {}
    for lp in robot.loops:
        if lp.cut.sigma == PRISMATIC:
            err = ModelError(
                f"export-mjcf: {robot.name}: the loop cut at joint {lp.cut.j} (closed on frame {lp.close.j}) "
                "has a prismatic cut joint: MuJoCo's equality constraints hold a point (connect) or a whole frame "
                "(weld), none leaves a sliding motion free")
            err.hint = ("export-urdf writes this loop as a <loop_joint> (docs/robot-file.md#closed-loops-from-urdf); "
                        "cutting the loop at one of its revolute joints instead makes it exportable to MuJoCo")
            raise err
        for name, row in ((f"cut{lp.cut.j}", lp.cut), (f"close{lp.close.j}", lp.close)):
            T = row_transform(row, subs, q=0.0)
            out.setdefault(row.ant, []).extend([(name, T[:3, 3]), (f"{name}_axis", T[:3, 3] + LOOP_AXIS_POINT * T[:3, 2])])
    return out


def rotor_armature(K: float, timestep: float) -> float:
    """The rotor inertia written for an elastic joint without a declared ``IA``: the one that puts the natural
    frequency ``sqrt(K / I) / (2 pi)`` of the rotor on its spring at ``1 / (20 timestep)`` (twenty steps per period,
    which the RK4 integrator follows)."""
    return float(K) * (20.0 * timestep / (2.0 * np.pi)) ** 2


def _tendons(robot: RobotDescription) -> list[str]:
    """The ``<tendon>`` element: one fixed tendon ``theta_j - q_j`` per elastic joint, stiffness ``K``, damping ``D``."""
    rows = [f'    <fixed name="transmission{e.joint}" stiffness="{xml_float(e.K)}" damping="{xml_float(e.D)}" '
            f'springlength="0">\n      <joint joint="rotor{e.joint}" coef="1"/>\n'
            f'      <joint joint="joint{e.joint}" coef="-1"/>\n    </fixed>' for e in robot.elastic]
    return ["  <tendon>", *rows, "  </tendon>"] if rows else []


def _equalities(robot: RobotDescription, timestep: float) -> list[str]:
    """The ``<equality>`` element: two ``connect`` per closed loop (:func:`loop_sites`), one joint equality per
    coupled joint (``q_m = offset + multiplier q_s``).

    A loop's constraints are made as stiff as MuJoCo allows: time constant ``2 timestep`` (its smallest stable
    one) and impedance :data:`LOOP_SOLIMP`; MuJoCo's default (0.02 s, 0.9-0.95) lets the palletizer's
    parallelogram open by 0.7-1.7 mm under its own weight, these settings by 1e-8 to 4e-8 m."""
    rows = []
    solver = f'solref="{xml_float(2 * timestep)} 1" solimp="{LOOP_SOLIMP}"'
    for lp in robot.loops:
        k, c = lp.cut.j, lp.close.j
        rows += [f'    <connect name="loop{k}" site1="cut{k}" site2="close{c}" {solver}/>',
                 f'    <connect name="loop{k}_axis" site1="cut{k}_axis" site2="close{c}_axis" {solver}/>']
    rows += [f'    <joint joint1="joint{c.joint}" joint2="joint{c.source}" '
             f'polycoef="{xml_float(float(c.offset))} {xml_float(float(c.multiplier))} 0 0 0"/>'
             for c in robot.couplings]
    return ["  <equality>", *rows, "  </equality>"] if rows else []


def friction_law_terms(robot: RobotDescription, j: int, vals) -> tuple[dict[str, float], str]:
    """MuJoCo's ``frictionloss`` (``FS``) and ``damping`` (``FV``) for frame ``j`` with a declared friction law,
    and the comment stating the approximation (module docstring); ``({}, "")`` without a law.

    The power law's damping ``b`` minimises ``int_0^V (b v - FV v^delta)^2 dv``: ``b = 3 FV V^(delta-1) /
    (delta + 2)`` with ``V`` the joint's ``dq_max`` (``[limits]``), else 1."""
    law = (robot.friction_laws or {}).get(j)
    if law is None:
        return {}, ""
    fs, fv = float(vals.get(f"FS{j}", 0.0)), float(vals.get(f"FV{j}", 0.0))
    if law.kind == "power":
        vmax = joint_limits(robot, j).get("dq_max", 1.0)
        delta = float(law.scale or 1.0)
        b = 3.0 * fv * vmax ** (delta - 1.0) / (delta + 2.0)
        return {"FV": b}, (f"friction law {law.label()}: MuJoCo has no power law of the speed; damping = "
                           f"{xml_float(b)}, the least-squares linear fit of FV{j} |dq|^delta over |dq| <= "
                           f"{xml_float(vmax)}; frictionloss = FS{j} (Coulomb)")
    if law.dynamic:      # Dahl, LuGre: their sliding part; MuJoCo has no pre-sliding state
        hump = ", the pre-sliding state (sigma0) left out" + (f", the Stribeck hump FSS{j} below vs too"
                                                               if law.coulomb == "stribeck" else "")
        return {"FS": fs, "FV": fv}, (f"friction law {law.label()}: MuJoCo has no {law.kind} law; frictionloss = "
                                      f"FS{j} (the sliding Coulomb level Fc){hump}; damping = FV{j}")
    fss = f" = {xml_float(float(vals[f'FSS{j}']))}" if f"FSS{j}" in vals else ""
    hump = (f", the Stribeck hump FSS{j}{fss} below vs left out"
            if law.coulomb == "stribeck" else ", the smoothing below v left out (MuJoCo's soft constraint smooths)")
    return {"FS": fs, "FV": fv}, (f"friction law {law.label()}: MuJoCo has no {law.kind} law; frictionloss = "
                                  f"FS{j} (the sliding Coulomb level Fc){hump}; damping = FV{j}")


def floating_base_open(vals, report: list | None) -> list[str]:
    """The opening of a floating base's body (``base = "floating"``, docs/floating-base.md): ``base_link`` at the
    world origin with a ``<freejoint name="base"/>`` and the base link's inertial from ``XX0 .. M0`` (a negligible
    mass, said in the file, when they are all zero: MuJoCo needs one on a moving body).

    MuJoCo's free joint: ``qpos`` = the position of the body origin and its quaternion ``w x y z`` (body axes to
    world axes), ``qvel`` = the linear velocity of the origin in world axes, then the angular velocity in body
    axes; its generalised force is the force in world axes and the moment in body axes (MuJoCo's documentation,
    "Floating objects"). The model's free-flyer conventions (Pinocchio's) differ in the quaternion's order and in
    the linear velocity's axes (docs/floating-base.md#export)."""
    out = ['    <body name="base_link" pos="0 0 0">', '      <freejoint name="base"/>']
    inert = inertial_of(vals, 0, report, "export-mjcf")
    if inert is None:
        inert = (1e-9, np.zeros(3), 1e-12 * np.eye(3))
        out.append("      <!-- the base link has no inertial parameters: negligible mass written -->")
    m, c, Ic = inert
    full = (Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2])
    out.append(f'      <inertial pos="{_v(c)}" mass="{xml_float(m)}" fullinertia="{_v(full)}"/>')
    return out


def export_mjcf(robot: RobotDescription, chi_std=None, chi_payload=None, *, notes=(), report: list | None = None,
                timestep: float = 0.001, integrator: str = "RK4", motors: bool = True) -> str:
    """MJCF text of ``robot`` (conventions in the module docstring).

    Parameters
    ----------
    robot : RobotDescription
    chi_std, chi_payload : array_like, optional
        Standard / payload parameters (default: the robot file's nominal values).
    notes : sequence of str
        Lines written as a comment at the top.
    report : list, optional
        Receives the messages about links whose inertial values had to be made physical.
    timestep, integrator : MuJoCo ``<option>`` values.
    motors : bool
        One ``<motor>`` actuator per joint.

    Returns
    -------
    str
    """
    vals = link_values(robot, chi_std, chi_payload)
    g = robot.gravity
    out = ["<?xml version=\"1.0\"?>", f"<mujoco model={quoteattr(robot.name)}>",
           f"  <!-- exported by symoro_gen from {robot.file.split('/')[-1]} ({xml_comment(robot.source[:120])}) -->",
           ("  <!-- MDH frame j = body link<j> (pos/quat: T(ant, j) at q = 0), joint j about/along its z axis; "
            "armature = IA, damping = FV, frictionloss = FS -->")]
    out += [f"  <!-- {xml_comment(n)} -->" for n in notes]
    out += ['  <compiler angle="radian" inertiafromgeom="false" autolimits="true"/>',
            f'  <option gravity="{_v(g)}" timestep="{xml_float(timestep)}" integrator="{integrator}"/>',
            "  <worldbody>"]
    children: dict[int, list] = {}
    for row in robot.rows:
        children.setdefault(row.ant, []).append(row)
    joints = []
    sites = loop_sites(robot)

    def site_lines(j, ind):
        return [f'{ind}<site name="{name}" pos="{_v(p)}"/>' for name, p in sites.get(j, ())]

    def rotor(row, depth, T):
        """The rotor body of an elastic joint (before its link's body, same parent and pose); the drive terms."""
        j, ind = row.j, "  " * depth
        e = robot.elastic_joint(j)
        assert e is not None
        out.append(f'{ind}<body name="rotor{j}" pos="{_v(T[:3, 3])}" quat="{_v(quat_from_matrix(T[:3, :3]))}">')
        out.append(f'{ind}  <inertial pos="0 0 0" mass="1e-09" diaginertia="1e-12 1e-12 1e-12"/>')
        attrs = [f'name="rotor{j}"', f'type="{"hinge" if row.sigma == REVOLUTE else "slide"}"', 'pos="0 0 0"',
                 f'axis="0 0 {joint_sign(row)}"']
        ia = vals.get(f"IA{j}", 0.0)
        if ia <= 0:
            ia = rotor_armature(e.K, timestep)
            out.append(f"{ind}  <!-- rotor {j}: no IA{j} declared: armature {xml_float(ia)} (spring period = 20 "
                       "time steps) -->")
        attrs.append(f'armature="{xml_float(ia)}"')
        for key, attr in (("FV", "damping"), ("FS", "frictionloss")):
            v = vals.get(f"{key}{j}", 0.0)
            if v:
                attrs.append(f'{attr}="{xml_float(max(v, 0.0))}"')
        out.append(f"{ind}  <joint {' '.join(attrs)}/>")
        out.append(f"{ind}</body>")

    def body(row, depth):
        j = row.j
        ind = "  " * depth
        T = constant_transform(robot, j)
        elastic = row.sigma != FIXED and robot.elastic_joint(j) is not None
        if elastic:
            rotor(row, depth, T)
        out.append(f'{ind}<body name="link{j}" pos="{_v(T[:3, 3])}" quat="{_v(quat_from_matrix(T[:3, :3]))}">')
        inert = inertial_of(vals, j, report, "export-mjcf")
        if inert is None and row.sigma != FIXED:
            # MuJoCo needs mass and inertia on a moving body: a negligible one, said in the file
            inert = (1e-9, np.zeros(3), 1e-12 * np.eye(3))
            out.append(f"{ind}  <!-- link {j} has no inertial parameters: negligible mass written -->")
        if inert is not None:
            m, c, Ic = inert
            full = (Ic[0, 0], Ic[1, 1], Ic[2, 2], Ic[0, 1], Ic[0, 2], Ic[1, 2])
            out.append(f'{ind}  <inertial pos="{_v(c)}" mass="{xml_float(m)}" fullinertia="{_v(full)}"/>')
        if row.sigma != FIXED:
            s = joint_sign(row)
            attrs = [f'name="joint{j}"', f'type="{"hinge" if row.sigma == REVOLUTE else "slide"}"', 'pos="0 0 0"',
                     f'axis="0 0 {s}"']
            law_vals, law_note = friction_law_terms(robot, j, vals)
            for key, attr in (("IA", "armature"), ("FV", "damping"), ("FS", "frictionloss")):
                v = law_vals.get(key, vals.get(f"{key}{j}", 0.0))
                if v and not elastic:  # an elastic joint's drive terms are on its rotor
                    attrs.append(f'{attr}="{xml_float(max(v, 0.0))}"')
            lim = joint_limits(robot, j)
            if "q_min" in lim and "q_max" in lim:
                attrs.append(f'range="{xml_float(lim["q_min"])} {xml_float(lim["q_max"])}"')
            if law_note:
                out.append(f"{ind}  <!-- {xml_comment(law_note)} -->")
            out.append(f"{ind}  <joint {' '.join(attrs)}/>")
            off = vals.get(f"OFF{j}", 0.0)
            if off:
                out.append(f"{ind}  <!-- torque offset OFF{j} = {xml_float(off)} (no MuJoCo field) -->")
            if row.mu == 1:  # a passive joint (of a closed loop, or coupled) has no motor
                joints.append((j, lim))
        out.extend(site_lines(j, ind + "  "))
        for ch in children.get(j, ()):
            body(ch, depth + 1)
        out.append(f"{ind}</body>")

    out += site_lines(0, "    ") + (floating_base_open(vals, report) if robot.floating else [])
    for row in children.get(0, ()):
        body(row, 3 if robot.floating else 2)
    out += ["    </body>"] if robot.floating else []  # a floating base's body
    out.append("  </worldbody>")
    out += _tendons(robot)
    out += _equalities(robot, timestep)
    if motors and joints:
        out.append("  <actuator>")
        for j, lim in joints:
            rng = f' ctrlrange="{xml_float(-lim["tau_max"])} {xml_float(lim["tau_max"])}"' if "tau_max" in lim else ""
            driven = "rotor" if robot.elastic_joint(j) is not None else "joint"  # an elastic joint: its rotor
            out.append(f'    <motor name="motor{j}" joint="{driven}{j}" gear="1"{rng}/>')
        out.append("  </actuator>")
    out.append("</mujoco>")
    return "\n".join(out) + "\n"
