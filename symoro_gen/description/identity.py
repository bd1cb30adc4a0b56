"""The identity of a robot: a hash of its canonical description, carried by identification results.

``robot_id(robot)`` is what the JSON of ``symoro-gen identify`` and ``diagnose`` write as ``robot_id`` and what
the commands that read a result back (``export-urdf --params``/``--from``, ``export-mjcf --from``) compare with
the robot they export, so that one robot's parameters are never written into another's file.

It hashes what gives the identified parameters their meaning, as numbers, not text: every frame of the MDH
table ([KK1986]; ``j``, ``ant``, joint type ``sigma``, actuation ``mu``, the numeric ``gamma, b, alpha, d, theta,
r`` at ``q = 0`` with the geometric constants of ``[values]`` substituted, the joint's sign, its drive terms),
the closed loops' cut and closing frames, the coupled joints, the payload frame, the drive chain (ratios,
coupling, offsets, directions) and gravity. Not hashed: the file's bytes, comments, key order and spelling
of expressions (``pi/2`` and ``1.5707963267948966`` are the same number), the robot's name and source, the
nominal parameters, ``[limits]`` and ``[loop_reference]``. Numbers are written with 12 significant digits,
so that the same value computed two ways hashes alike.
"""
from __future__ import annotations

import hashlib
import json
import warnings
from collections.abc import Mapping
from typing import Any

from ..errors import ModelError
from .mdh import joint_sign, row_values
from .model import FIXED, MdhRow, RobotDescription

__all__ = ["ID_LENGTH", "canonical_description", "check_result_robot", "robot_id"]

#: hexadecimal digits of SHA-256 kept in a robot id
ID_LENGTH = 16


def _num(x: Any) -> str:
    return format(float(x) or 0.0, ".12g")  # -0.0 written as 0


def _frame(row: MdhRow, subs: dict) -> list[Any]:
    values = [_num(v) for v in row_values(row, subs, 0.0)]
    sign = 0 if row.sigma == FIXED else joint_sign(row)
    return [row.j, row.ant, row.sigma, row.mu, *values, sign, list(row.drive)]


def canonical_description(robot: RobotDescription) -> dict[str, Any]:
    """The numbers :func:`robot_id` hashes (module docstring), as a JSON-ready mapping."""
    subs = robot.geometry_subs()
    dc = robot.drive_chain
    return {
        "frames": [_frame(r, subs) for r in robot.rows],
        "loops": [[_frame(lp.cut, subs), _frame(lp.close, subs)] for lp in robot.loops],
        "couplings": [[c.joint, c.source, _num(c.multiplier), _num(c.offset)] for c in robot.couplings],
        "payload": robot.payload,
        "drive_chain": None if dc is None else {
            "ratios": [_num(x) for x in dc.ratios], "coupling": [[_num(x) for x in row] for row in dc.coupling],
            "offsets": [_num(x) for x in dc.offsets], "directions": [_num(x) for x in dc.directions]},
        "gravity": [_num(g) for g in robot.gravity],
        **({"base": robot.base} if robot.floating else {}),  # fixed-base ids unchanged
    }


def robot_id(robot: RobotDescription) -> str:
    """The robot's identity: the first :data:`ID_LENGTH` hexadecimal digits of the SHA-256 of
    :func:`canonical_description` (sorted-key JSON)."""
    text = json.dumps(canonical_description(robot), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()[:ID_LENGTH]


def check_result_robot(doc: Mapping[str, Any], robot: RobotDescription, *, option: str, source: str,
                       command: str) -> None:
    """Refuse an identification result (``doc``, the JSON of ``identify``/``diagnose``) of another robot.

    A ``robot_id`` that differs from ``robot_id(robot)`` raises :class:`~symoro_gen.errors.ModelError` naming
    both robots and ``option``; a result without ``robot_id`` (written before results carried it) is accepted
    with a warning."""
    target = robot_id(robot)
    theirs = doc.get("robot_id")
    name = doc.get("robot")
    if theirs is None:
        names = f"it names robot {name!r}" if name is not None else "it names no robot"
        warnings.warn(f"{command} {option} {source}: the result has no robot_id (written by an older symoro-gen): "
                      f"not checked that it is a result of {robot.name} ({names})", stacklevel=3)
    elif theirs != target:
        err = ModelError(f"{command} {option} {source}: a result of robot {name!r} (robot_id {theirs}), not of "
                         f"{robot.name!r} (robot_id {target}): its parameters belong to another robot")
        err.hint = (f"give a result of `symoro-gen identify {robot.name} ... --json` (robot_id is a hash of the "
                    "robot's geometry, joints, drive chain, payload frame and gravity; see docs/json-output.md)")
        raise err
