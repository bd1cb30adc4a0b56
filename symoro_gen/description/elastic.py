"""Declared elastic joints: the robot file's ``elastic = {K = ..., D = ...}`` (per frame or top level).

The model is Spong's flexible-joint model (M. W. Spong, "Modeling and control of elastic joint robots",
ASME J. Dyn. Syst. Meas. Control 109(4), 1987): each elastic joint ``j`` is a rotor (motor side, position
``theta_j = q_mj / N_j`` seen through the gear ratio ``N_j``) coupled to the link (position ``q_j``) by a
torsional spring of stiffness ``K_j`` and a damper ``D_j``; the torque the transmission passes to the link is

    tau_j = K_j (theta_j - q_j) + D_j (dtheta_j - dq_j).

Read statically (``D`` term zero), the link position from the motor encoder is ``q_j = q_mj / N_j - tau_j / K_j``:
eq. 17 of the KUKA LWR4 torque-sensor paper (Gautier, Briot et al.; ``K = 10 000 N m/rad`` for joints 1-5,
``7 500`` for 6-7). Units: ``K`` in N m/rad (N/m for a prismatic joint), ``D`` in N m s/rad (N s/m), both on the
joint (link) side of the gear.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

from .model import MdhRow

__all__ = ["ELASTIC_KEYS", "ElasticJoint", "parse_elastic"]

#: the fields of an ``elastic`` table
ELASTIC_KEYS = ("K", "D")
#: the largest magnitude accepted (the robot file's bound on every number)
_MAX = 1e12


@dataclass(frozen=True)
class ElasticJoint:
    """A declared elastic joint: frame ``joint``, stiffness ``K > 0`` and damping ``D >= 0`` of its transmission
    (joint side of the gear; Spong 1987)."""

    joint: int
    K: float
    D: float = 0.0

    def deflection(self, tau):
        """The static deflection ``theta - q = tau / K`` (LWR4 paper, eq. 17) of a torque ``tau`` (array or
        number)."""
        return tau / self.K


def _number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and abs(v) <= _MAX


def _read_table(raw, where: str, bad: Callable[[str, str, str], None]) -> tuple[float, float] | None:
    """``(K, D)`` of one ``elastic`` table, None after a reported problem."""
    if not isinstance(raw, Mapping):
        bad(where, "elastic", f"must be a table {{K = stiffness, D = damping}}, got {raw!r}")
        return None
    ok = True
    for k in sorted(set(raw) - set(ELASTIC_KEYS)):
        bad(where, f"elastic.{k}", "unknown field (allowed: K, D)")
        ok = False
    if "K" not in raw:
        bad(where, "elastic.K", "missing: the joint stiffness K [N m/rad] of an elastic joint")
        return None
    K, D = raw["K"], raw.get("D", 0.0)
    if not _number(K) or K <= 0:
        bad(where, "elastic.K", f"must be a positive finite number (stiffness, N m/rad), got {K!r}")
        ok = False
    if not _number(D) or D < 0:
        bad(where, "elastic.D", f"must be a finite number >= 0 (damping, N m s/rad), got {D!r}")
        ok = False
    return (float(K), float(D)) if ok else None


def parse_elastic(top, entries: Sequence, rows: Sequence[MdhRow],
                  bad: Callable[[str, str, str], None]) -> tuple[ElasticJoint, ...]:
    """The elastic joints of a robot file, in joint order.

    ``top`` is the top-level ``elastic`` table (None when absent): it declares every actuated moving joint
    elastic; a frame's own ``elastic`` table (``entries``: the raw ``[[frames]]`` entries, ``rows`` the parsed
    frames) replaces it for that joint. Only an actuated moving joint (``mu = 1``) can be elastic: a fixed frame
    or a passive joint is reported. Problems go to ``bad(where, field, message)``.
    """
    default = _read_table(top, "top level", bad) if top is not None else None
    out = []
    for fr, r in zip(entries, rows):
        own = fr.get("elastic") if isinstance(fr, Mapping) else None
        where = f"frame {r.j}"
        if own is not None:
            if not r.is_moving or r.mu != 1:
                what = "a fixed frame" if not r.is_moving else "a passive joint (mu = 0)"
                bad(where, "elastic", f"{what} has no transmission: only an actuated joint can be elastic")
                continue
            kd = _read_table(own, where, bad)
            if kd is not None:
                out.append(ElasticJoint(r.j, *kd))
        elif default is not None and r.is_moving and r.mu == 1:
            out.append(ElasticJoint(r.j, *default))
    return tuple(out)
