"""MDH robot -> URDF (``symoro-gen export-urdf``), loadable by Pinocchio and ROS tools.

Frame j of the MDH table becomes link ``link<j>`` (frame 0 is ``base_link``); the joint from
``link<ant>`` to ``link<j>`` has the constant part of T(ant, j) (q = 0) as origin and z (or -z for a
``-q`` joint) as axis. Standard parameters at the frame origin become URDF inertials at the centre
of mass; FV and FS become ``<dynamics damping friction>``.

An identification (``--from result.json`` of ``symoro-gen identify``) gives every standard parameter
through :func:`symoro_gen.identification.physical.standard_set_from_result`: a physically consistent
set whose regrouping is the identified base parameters (consistent export). The older ``--params`` replaces only
the standard parameters the result names (regrouped ones are ignored, with a warning).

A coupled joint (``mimic`` in the robot file, ``q_j = multiplier q_s + offset``) gets URDF's
``<mimic joint="joint<s>" multiplier offset>`` (the URDF joint value is the model's ``q``), which
:func:`symoro_gen.description.urdf.import_urdf` reads back and Pinocchio (``mimic=True``) builds as a
``JointModelMimic``.

Drive terms: ``FV`` and ``FS`` go to ``<dynamics damping friction>``; URDF has no field for the rotor
inertia ``IA`` nor the torque offset ``OFF``: they are written as ``<!-- armature ... -->`` comments in
the joint and listed by :func:`drive_terms` (the command line writes them to a sidecar JSON). Joint
``<limit>`` from the robot file's ``[limits]`` when it has one (a passive joint's ``lower upper`` from
``passive_q_min, passive_q_max``; else +-pi / +-10 m, effort 1000).

A floating base (``base = "floating"``, docs/floating-base.md#export) gets a ``world`` link and a ``floating``
joint to ``base_link``, which carries the base link's inertial (``XX0 .. M0``): :func:`floating_root`.

Each link is written physically meaningful: mass >= ``min_mass``, inertia at the centre of mass
symmetric positive definite and satisfying the triangle inequalities (eigenvalues raised as needed);
a link whose given values were changed so is reported (``report`` list or a warning), never silently.
"""
from __future__ import annotations

import math
import warnings
from xml.sax.saxutils import quoteattr

import numpy as np

from ..params import INERTIAL_KINDS
from .inertia import check_physical_consistency, com_from_standard
from .mdh import joint_sign, row_transform
from .model import FIXED, PRISMATIC, REVOLUTE, RobotDescription


def constant_transform(robot: RobotDescription, j: int) -> np.ndarray:
    """4x4 T(ant, j) at q = 0."""
    return row_transform(robot.row(j), robot.geometry_subs(), q=0.0)


def rpy_from_matrix(R: np.ndarray) -> tuple[float, float, float]:
    """URDF roll-pitch-yaw (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    pitch = math.atan2(-R[2, 0], math.hypot(R[0, 0], R[1, 0]))
    if abs(math.cos(pitch)) < 1e-12:
        roll = math.atan2(-R[1, 2], R[1, 1])
        yaw = 0.0
    else:
        roll = math.atan2(R[2, 1], R[2, 2])
        yaw = math.atan2(R[1, 0], R[0, 0])
    return roll, pitch, yaw


def physical_inertial(p10, *, min_mass: float = 1e-6, min_inertia: float = 1e-9):
    """(mass, com, inertia at com) from standard parameters at the frame origin, made physical."""
    p = [float(x) for x in p10]
    m, c, Ic = com_from_standard(p[:9] + [max(p[9], min_mass)])
    w, V = np.linalg.eigh((Ic + Ic.T) / 2)
    w = np.maximum(w, min_inertia)
    # triangle inequalities on principal moments
    for _ in range(3):
        for k in range(3):
            others = w[(k + 1) % 3] + w[(k + 2) % 3]
            if w[k] > others:
                w[(k + 1) % 3] += (w[k] - others) / 2 + min_inertia
                w[(k + 2) % 3] += (w[k] - others) / 2 + min_inertia
    return m, c, V @ np.diag(w) @ V.T


def xml_float(x: float) -> str:
    """A number as written in the exported URDF and MJCF files (the shortest text that reads back exactly)."""
    return repr(float(x))


def drive_terms(robot: RobotDescription, vals: dict) -> dict[str, dict[str, float]]:
    """``joint<j> -> {IA, FV, FS, OFF}`` (the values present) for every moving joint."""
    out = {}
    for row in robot.joints:
        d = {k: float(vals[f"{k}{row.j}"]) for k in ("IA", "FV", "FS", "OFF") if f"{k}{row.j}" in vals}
        if d:
            out[f"joint{row.j}"] = d
    return out


def joint_limits(robot: RobotDescription, j: int) -> dict[str, float]:
    """``q_min, q_max, dq_max, tau_max`` of moving joint ``j`` from the robot file's ``[limits]`` (present ones;
    a passive joint's ``q_min, q_max`` from ``passive_q_min, passive_q_max``)."""
    lim = getattr(robot, "limits", None)
    if lim is None:
        return {}
    logged = [r.j for r in robot.model_joints]
    if j not in logged:  # a passive joint of a closed-loop robot: [limits] lists the actuated ones
        if j not in lim.passive_joints or lim.passive_q_min is None or lim.passive_q_max is None:
            return {}
        k = lim.passive_joints.index(j)
        return {"q_min": float(lim.passive_q_min[k]), "q_max": float(lim.passive_q_max[k])}
    k = logged.index(j)
    out = {}
    for f in ("q_min", "q_max", "dq_max", "tau_max"):
        v = getattr(lim, f, None)
        if v is not None and v[k] is not None and math.isfinite(float(v[k])):
            out[f] = float(v[k])
    return out


def link_values(robot: RobotDescription, chi_std=None, chi_payload=None, *, params: dict | None = None) -> dict:
    """``name -> value`` of every standard (and payload) parameter written (defaults: nominal, else 0)."""
    names = list(robot.standard_names)
    chi = np.zeros(len(names)) if chi_std is None and robot.nominal_vector() is None else np.array(
        chi_std if chi_std is not None else robot.nominal_vector(), float)
    vals = dict(zip(names, chi))
    pay = chi_payload if chi_payload is not None else robot.nominal_payload()
    if robot.payload is not None and pay is not None:
        vals.update(zip(robot.payload_names, np.asarray(pay, float)))
    ignored = []
    for k, v in (params or {}).items():
        if k in vals or k in robot.payload_names:
            vals[k] = float(v)
        else:
            ignored.append(k)
    if ignored:
        warnings.warn(f"export: parameters not applied (regrouped or unknown): {', '.join(ignored)}", stacklevel=3)
    return vals


def inertial_of(vals: dict, j: int, report: list | None, what: str = "export"):
    """(mass, com, I_c) of link ``j`` made physical; a change is reported (never silent)."""
    p10 = [vals.get(f"{k}{j}", 0.0) for k in INERTIAL_KINDS]
    if not any(p10):
        return None
    reasons = check_physical_consistency(p10)
    m, c, Ic = physical_inertial(p10)
    if reasons:
        msg = (f"{what}: link {j}: inertial parameters not physically consistent ({'; '.join(reasons)}); "
               f"written as mass {m:.6g}, inertia at the centre of mass with principal moments "
               f"{', '.join(f'{x:.3g}' for x in np.linalg.eigvalsh(Ic))}")
        if report is not None:
            report.append(msg)
        else:
            warnings.warn(msg, stacklevel=3)
    return m, c, Ic


def export_urdf(robot: RobotDescription, chi_std=None, chi_payload=None, *, params: dict | None = None,
                notes=(), report: list | None = None) -> str:
    """URDF text of ``robot``.

    Parameters
    ----------
    robot : RobotDescription
    chi_std, chi_payload : array_like, optional
        Standard / payload parameters (default: the robot file's nominal values, zeros when absent).
    params : dict, optional
        ``name -> value`` overriding standard parameters (e.g. identified ones); regrouped
        names (``...R``) are ignored with a warning.
    notes : sequence of str
        Lines written as a comment at the top (e.g. where the parameters come from).
    report : list, optional
        Receives the messages about links whose values had to be changed (else: warnings).
    """
    vals = link_values(robot, chi_std, chi_payload, params=params)
    out = ['<?xml version="1.0"?>', f"<robot name={quoteattr(robot.name)}>",
           f"  <!-- exported by symoro_gen from {robot.file.split('/')[-1]} ({xml_comment(robot.source[:120])}) -->"]
    out += [f"  <!-- {xml_comment(n)} -->" for n in notes]
    out += floating_root(robot, vals, report) if robot.floating else ['  <link name="base_link"/>']
    for row in robot.rows:
        j = row.j
        out.append(f'  <link name="link{j}">')
        out += inertial_lines(inertial_of(vals, j, report, "export-urdf"))
        out.append("  </link>")
        T = constant_transform(robot, j)
        rpy = rpy_from_matrix(T[:3, :3])
        parent = "base_link" if row.ant == 0 else f"link{row.ant}"
        kind = {REVOLUTE: "revolute", PRISMATIC: "prismatic", FIXED: "fixed"}[row.sigma]
        out.append(f'  <joint name="joint{j}" type="{kind}">')
        out.append(f'    <parent link="{parent}"/>')
        out.append(f'    <child link="link{j}"/>')
        out.append(f'    <origin xyz="{xml_float(T[0, 3])} {xml_float(T[1, 3])} {xml_float(T[2, 3])}" '
                   f'rpy="{xml_float(rpy[0])} {xml_float(rpy[1])} {xml_float(rpy[2])}"/>')
        if row.sigma != FIXED:
            s = joint_sign(row)
            out.append(f'    <axis xyz="0 0 {s}"/>')
            lim = joint_limits(robot, j)
            dflt = math.pi if row.sigma == REVOLUTE else 10.0
            out.append(f'    <limit lower="{xml_float(lim.get("q_min", -dflt))}" '
                       f'upper="{xml_float(lim.get("q_max", dflt))}" '
                       f'effort="{xml_float(lim.get("tau_max", 1000.0))}" '
                       f'velocity="{xml_float(lim.get("dq_max", 100.0))}"/>')
            cp = robot.coupling(j)
            if cp is not None:  # a coupled joint: URDF's mimic, q_j = multiplier q_source + offset
                out.append(f'    <mimic joint="joint{cp.source}" multiplier="{xml_float(float(cp.multiplier))}" '
                           f'offset="{xml_float(float(cp.offset))}"/>')
            fv, fs = vals.get(f"FV{j}", 0.0), vals.get(f"FS{j}", 0.0)
            if fv or fs:
                out.append(f'    <dynamics damping="{xml_float(max(fv, 0.0))}" friction="{xml_float(max(fs, 0.0))}"/>')
            ia, off = vals.get(f"IA{j}", 0.0), vals.get(f"OFF{j}", 0.0)
            if ia or off:
                out.append(f"    <!-- armature (rotor inertia IA{j}, no URDF field): {xml_float(ia)} "
                           f"{'kg m^2' if row.sigma == REVOLUTE else 'kg'}; torque offset OFF{j}: {xml_float(off)} -->")
        out.append("  </joint>")
    out += _loop_elements(robot)
    out.append("</robot>")
    return "\n".join(out) + "\n"


def inertial_lines(inert) -> list[str]:
    """The ``<inertial>`` element of a link (mass, centre of mass, inertia at the centre of mass in link axes);
    none for ``None``."""
    if inert is None:
        return []
    m, c, Ic = inert
    return [
        "    <inertial>",
        f'      <origin xyz="{xml_float(c[0])} {xml_float(c[1])} {xml_float(c[2])}" rpy="0 0 0"/>',
        f'      <mass value="{xml_float(m)}"/>',
        f'      <inertia ixx="{xml_float(Ic[0, 0])}" ixy="{xml_float(Ic[0, 1])}" ixz="{xml_float(Ic[0, 2])}" '
        f'iyy="{xml_float(Ic[1, 1])}" iyz="{xml_float(Ic[1, 2])}" izz="{xml_float(Ic[2, 2])}"/>',
        "    </inertial>",
    ]


def floating_root(robot: RobotDescription, vals: dict, report: list | None) -> list[str]:
    """The root of a floating-base robot (``base = "floating"``, docs/floating-base.md): a ``world`` link and a
    ``floating`` joint ``base_joint`` (identity origin) to ``base_link``, frame 0, which carries the base link's
    inertial from ``XX0 .. M0`` (made physical as every link's, :func:`inertial_of`).

    This is the URDF habit that :func:`symoro_gen.description.urdf.import_urdf` reads back as a floating base
    (the child of a ``floating`` joint that is the root link's only joint) and that Pinocchio's URDF parser
    builds as a ``JointModelFreeFlyer`` (its ``q``: position, quaternion ``x y z w``, the model's conventions)."""
    return ['  <link name="world"/>',
            '  <joint name="base_joint" type="floating">',
            '    <parent link="world"/>',
            '    <child link="base_link"/>',
            '    <origin xyz="0 0 0" rpy="0 0 0"/>',
            "  </joint>",
            '  <link name="base_link">',
            *inertial_lines(inertial_of(vals, 0, report, "export-urdf")),
            "  </link>"]


def _loop_elements(robot: RobotDescription) -> list[str]:
    """``<loop_joint>`` per ``[[loops]]`` entry and a ``<transmission>`` per actuated joint (closed-loop robots).

    The cut frame's constant pose on its antecedent link is ``<link1>``, the closing frame's pose on its link
    is ``<link2>``; the loop joint turns (or slides) along z of the cut frame (``-z`` for a ``-q`` joint), so
    the two frames coincide at the loop joint's value ``q<cut>`` (the convention read by
    :func:`symoro_gen.description.urdf.import_urdf`)."""
    if not robot.loops:
        return []
    subs = robot.geometry_subs()
    out = []
    for lp in robot.loops:
        kind = "prismatic" if lp.cut.sigma == PRISMATIC else "revolute"
        out.append(f'  <loop_joint name="loop{lp.cut.j}" type="{kind}">')
        for tag, row in (("link1", lp.cut), ("link2", lp.close)):
            T = row_transform(row, subs, q=0.0)
            rpy = rpy_from_matrix(T[:3, :3])
            link = "base_link" if row.ant == 0 else f"link{row.ant}"
            out.append(f'    <{tag} link="{link}" xyz="{xml_float(T[0, 3])} {xml_float(T[1, 3])} {xml_float(T[2, 3])}" '
                       f'rpy="{xml_float(rpy[0])} {xml_float(rpy[1])} {xml_float(rpy[2])}"/>')
        out.append(f'    <axis xyz="0 0 {joint_sign(lp.cut)}"/>')
        out.append("  </loop_joint>")
    for row in robot.actuated:
        out += [f'  <transmission name="transmission{row.j}">',
                "    <type>transmission_interface/SimpleTransmission</type>",
                f'    <joint name="joint{row.j}"><hardwareInterface>hardware_interface/EffortJointInterface'
                "</hardwareInterface></joint>",
                f'    <actuator name="motor{row.j}"><mechanicalReduction>1</mechanicalReduction></actuator>',
                "  </transmission>"]
    return out


def xml_comment(text: str) -> str:
    """Text safe inside an XML comment (no ``--``), for the URDF and MJCF exports."""
    return str(text).replace("--", "- -")
