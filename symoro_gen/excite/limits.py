"""Limits of an excitation design: the robot file's ``[limits]`` (:class:`Limits`, :func:`limits_of`), the passive
joints of a linear closure (:class:`PassiveRange`), a floor below the robot (:class:`Workspace`, :func:`with_floor`)
and the check of a sampled motion against them (:func:`check_limits`); the error every part of ``excite`` raises
(:class:`ExcitationError`) and the CasADi helpers the floor's constraints are built with."""
from __future__ import annotations

import copy
import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import sympy as sp

from ..description.mdh import symbolic_transform
from ..errors import IdentificationError

__all__ = [
    "DEFAULT_LIMITS",
    "DEFAULT_PRISMATIC_LIMITS",
    "WORKSPACE_MARGIN",
    "ExcitationError",
    "Limits",
    "PassiveRange",
    "Workspace",
    "check_limits",
    "floor_linearisation",
    "limits_of",
    "load_casadi",
    "mdh_frames",
    "sympy_to_casadi",
    "with_floor",
]

#: limits used for a robot file without ``[limits]`` (revolute joints [rad], prismatic ones [m]; the
#: output lists the defaulted fields)
DEFAULT_LIMITS = {"q": math.pi, "dq": 2.0, "ddq": 10.0}
DEFAULT_PRISMATIC_LIMITS = {"q": 0.5, "dq": 0.5, "ddq": 2.0}
#: metres the optimiser's floor is raised per unit of its margin (the 1 % margin: 1 cm above ``--z-min``)
WORKSPACE_MARGIN = 1.0


class ExcitationError(IdentificationError):
    """An excitation design cannot be made with the given options (names the option at fault)."""


@dataclass(frozen=True)
class PassiveRange:
    """Position range of a passive joint of a closed-loop robot whose closure is linear (a parallelogram,
    coupled joints): ``lo <= coef . q + offset <= hi`` in the design's (actuated) positions ``q``.

    Attributes: ``joint`` (the robot joint), ``coef`` (n,), ``offset``, ``lo``, ``hi`` (rad or m),
    ``prismatic``."""

    joint: int
    coef: np.ndarray
    offset: float
    lo: float
    hi: float
    prismatic: bool = False


def mdh_frames(robot: Any, n: int, closure: tuple[np.ndarray, np.ndarray] | None = None
               ) -> tuple[tuple, dict[int, Any], dict]:
    """``(qa, T, sub)``: the base-frame transform ``T[j]`` of every frame ``j`` of ``robot`` (the MDH transforms
    ``T(ant, j)`` of Khalil & Kleinfinger 1986 chained, geometry substituted; sympy, in the robot's joint
    symbols) and ``sub``, the substitution that puts them in ``n`` design joint symbols ``qa``: the robot's
    joints, or a closed-loop robot's actuated ones through its linear closure ``q_tree = A qa + b``
    (``closure = (A, b)``)."""
    qt = list(robot.q)  # the tree's joint symbols, joint order
    qa = sp.symbols(f"qa0:{n}", real=True)
    if closure is None:
        sub = dict(zip(qt, qa))
    else:
        A, b = closure
        sub = {qt[i]: sum(float(A[i, k]) * qa[k] for k in range(n)) + float(b[i]) for i in range(len(qt))}
    geo = robot.geometry_subs()
    T: dict[int, Any] = {0: sp.eye(4)}
    for row in robot.rows:
        T[row.j] = T[row.ant] * symbolic_transform(row).subs(geo)
    return qa, {j: M for j, M in T.items() if j != 0}, sub


class Workspace:
    """A floor (or table) plane below the robot: the origin of every moving or tool frame stays at
    ``z >= z_min`` in the base frame 0 (``excite --z-min``), the robot's forward kinematics (the MDH
    transforms ``T(ant, j)`` of Khalil & Kleinfinger 1986, geometry substituted) in the design's joint
    positions (a closed-loop robot's actuated ones, through its linear closure ``q_tree = A q + b``).

    Only frame origins are checked: a link's extent (its radius, a tool's length past its frame) is the
    user's clearance, added to ``z_min``. ``frames`` are the frames whose origin moves; ``heights(q)``
    (NumPy) and ``casadi()`` (a CasADi function ``q -> z``) give their heights.
    """

    def __init__(self, robot: Any, z_min: float, n: int, closure: tuple[np.ndarray, np.ndarray] | None = None):
        self.z_min, self.n = float(z_min), int(n)
        qa, frames, sub = mdh_frames(robot, self.n, closure)
        z = {j: T[2, 3].subs(sub) for j, T in frames.items()}
        fixed = {j: float(e) for j, e in z.items() if not e.free_symbols}
        low = {j: v for j, v in fixed.items() if v < self.z_min}
        if low:
            j, v = next(iter(low.items()))
            raise ExcitationError(f"--z-min {self.z_min:g}: the origin of frame {j} is fixed at z = {v:.4g} m in the base "
                                  f"frame, below it (z is the base frame's: give the floor's height there)")
        self.frames = tuple(j for j in z if j not in fixed)
        exprs = [z[j] for j in self.frames]
        self._np = sp.lambdify([qa], exprs, modules="numpy")
        self._sym = (qa, exprs)
        self._ca: Any = None  # the CasADi function, built on first use (every IPOPT start and SDP refinement uses it)

    def raised(self, dz: float) -> Workspace:
        """The same floor ``dz`` higher (the margin of the optimiser's constraints)."""
        out = copy.copy(self)
        out.z_min = self.z_min + dz
        return out

    def heights(self, q) -> np.ndarray:
        """Heights ``(N, len(frames))`` of the moving frame origins for positions ``q`` (N, n)."""
        q = np.atleast_2d(np.asarray(q, float))
        out = self._np(q.T)
        return np.column_stack([np.broadcast_to(np.asarray(v, float), (q.shape[0],)) for v in out])

    def casadi(self):
        """CasADi function ``q (n) -> z (len(frames))`` (built once)."""
        if self._ca is None:
            ca = load_casadi()
            qs = ca.SX.sym("q", self.n)
            self._ca = ca.Function("heights", [qs], [sympy_to_casadi(*self._sym, qs)])
        return self._ca


def floor_linearisation(ws: Workspace):
    """``q (N, n) -> (h (N, k), J (N, k, n))``: the frame heights of ``ws`` and their Jacobians (CasADi)."""
    ca = load_casadi()
    qs = ca.SX.sym("q", ws.n)
    h = ws.casadi()(qs)
    f = ca.Function("hJ", [qs], [h, ca.jacobian(h, qs)])

    def run(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        H, J = f.map(len(Q))(Q.T)
        k = len(ws.frames)
        return np.asarray(H).T, np.asarray(J).reshape(k, len(Q), ws.n).transpose(1, 0, 2)
    return run


@dataclass(frozen=True)
class Limits:
    """Per-joint limits used by the design (SI units, arrays of length n).

    Attributes
    ----------
    q_min, q_max, dq_max, ddq_max : ndarray (n,)
    tau_max : ndarray (n,) or None
    defaulted : tuple of str
        The fields that were not in the robot file (taken from :data:`DEFAULT_LIMITS`).
    passive : tuple of PassiveRange
        A closed-loop robot's passive joint ranges, linear in the actuated positions (``[limits]``
        ``passive_q_min/passive_q_max`` through the linear closure).
    workspace : Workspace or None
        A floor plane the frame origins stay above (``excite --z-min``); :meth:`shrunk` raises it by
        ``margin * WORKSPACE_MARGIN``.
    """

    q_min: np.ndarray
    q_max: np.ndarray
    dq_max: np.ndarray
    ddq_max: np.ndarray
    tau_max: np.ndarray | None = None
    defaulted: tuple[str, ...] = ()
    prismatic: tuple[bool, ...] = ()
    passive: tuple[PassiveRange, ...] = ()
    workspace: Workspace | None = None

    def is_prismatic(self, j: int) -> bool:
        """Joint ``j`` (0-based) is prismatic (its limits are in m, m/s, m/s^2)."""
        return bool(self.prismatic[j]) if j < len(self.prismatic) else False

    @property
    def n(self) -> int:
        return len(self.q_min)

    def shrunk(self, margin: float) -> Limits:
        """The limits tightened by the fraction ``margin`` (positions about the range centre)."""
        c, h = (self.q_max + self.q_min) / 2, (self.q_max - self.q_min) / 2 * (1 - margin)
        tau = None if self.tau_max is None else self.tau_max * (1 - margin)
        passive = tuple(PassiveRange(p.joint, p.coef, p.offset, (p.lo + p.hi) / 2 - (p.hi - p.lo) / 2 * (1 - margin),
                                     (p.lo + p.hi) / 2 + (p.hi - p.lo) / 2 * (1 - margin), p.prismatic)
                        for p in self.passive)
        ws = None if self.workspace is None else self.workspace.raised(margin * WORKSPACE_MARGIN)
        return Limits(c - h, c + h, self.dq_max * (1 - margin), self.ddq_max * (1 - margin), tau, self.defaulted,
                      self.prismatic, passive, ws)

    def passive_rows(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(C, offset, lo, hi)`` of the passive ranges, ``lo <= C q + offset <= hi`` (``C``: (k, n))."""
        ps = self.passive
        return (np.array([p.coef for p in ps]).reshape(len(ps), self.n), np.array([p.offset for p in ps]),
                np.array([p.lo for p in ps]), np.array([p.hi for p in ps]))

    def passive_positions(self, q) -> np.ndarray:
        """The passive joints' positions ``(N, len(passive))`` for the design's positions ``q`` (N, n)."""
        C, off, _, _ = self.passive_rows()
        return np.asarray(q, float) @ C.T + off

    @functools.cached_property
    def centre(self) -> np.ndarray:
        """The rest position about which designs are built and scaled: the centre of the position ranges or,
        with passive ranges, the point that maximises the smallest relative margin ``s*`` to every actuated and
        passive bound and, among those, is nearest to the centre of the ranges (L1 in half-ranges): two
        linear programmes (scipy's HiGHS)."""
        c = (self.q_max + self.q_min) / 2
        if not self.passive:
            return c
        from scipy.optimize import linprog

        n = self.n
        Cp, op, lp, hp = self.passive_rows()
        C, off = np.vstack([np.eye(n), Cp]), np.concatenate([np.zeros(n), op])
        lo, hi = np.concatenate([self.q_min, lp]), np.concatenate([self.q_max, hp])
        half = (hi - lo) / 2
        # 1: variables (q, s): max s  s.t.  C q + off <= hi - s half,  lo + s half <= C q + off,  s <= 1
        A = np.vstack([np.hstack([C, half[:, None]]), np.hstack([-C, half[:, None]])])
        b = np.concatenate([hi - off, off - lo])
        res = linprog(np.r_[np.zeros(n), -1.0], A_ub=A, b_ub=b, bounds=[(None, None)] * n + [(None, 1.0)],
                      method="highs")
        if res.status != 0 or -res.fun <= 1e-9:
            rng = ", ".join(f"joint {p.joint} [{p.lo:.4g}, {p.hi:.4g}]" for p in self.passive)
            raise ExcitationError(f"no position of the actuated joints within [limits] q_min/q_max keeps the passive "
                                  f"joints within passive_q_min/passive_q_max ({rng}, through the loop closure): "
                                  f"check [limits]")
        s_star = (1 - 1e-6) * -res.fun
        # 2: variables (q, u): min sum u / half_q  s.t.  the margin s* and |q - c| <= u
        I, hq = np.eye(n), half[:n]
        A2 = np.vstack([np.hstack([C, np.zeros((len(C), n))]), np.hstack([-C, np.zeros((len(C), n))]),
                        np.hstack([I, -I]), np.hstack([-I, -I])])
        b2 = np.concatenate([hi - off - s_star * half, off - lo - s_star * half, c, -c])
        res2 = linprog(np.r_[np.zeros(n), 1.0 / hq], A_ub=A2, b_ub=b2, bounds=[(None, None)] * (2 * n), method="highs")
        return np.asarray((res2.x if res2.status == 0 else res.x)[:n], float)

    def room(self) -> tuple[np.ndarray, np.ndarray]:
        """``(up, down)``: the room of each joint's position above and below :attr:`centre`."""
        if not self.passive:
            h = (self.q_max - self.q_min) / 2
            return h, h
        return self.q_max - self.centre, self.centre - self.q_min

    def defaulted_text(self) -> str:
        """The fields the robot file does not give and the values used for them, e.g. ``"ddq_max (10 rad/s^2
        for the revolute joints)"``; empty when every field is given."""
        units = {"q_min": ("rad", "m"), "q_max": ("rad", "m"), "dq_max": ("rad/s", "m/s"), "ddq_max": ("rad/s^2", "m/s^2")}
        parts = []
        for k in self.defaulted:
            vals = np.abs(getattr(self, k))
            kinds = []
            for prismatic, name in ((False, "revolute"), (True, "prismatic")):
                sel = [j for j in range(self.n) if self.is_prismatic(j) == prismatic]
                if sel:
                    kinds.append(f"{vals[sel[0]]:g} {units[k][int(prismatic)]} for the {name} joints")
            parts.append(f"{k} ({'; '.join(kinds)})")
        return ", ".join(parts)

    def as_dict(self) -> dict:
        d = {k: getattr(self, k).tolist() for k in ("q_min", "q_max", "dq_max", "ddq_max")}
        d["tau_max"] = None if self.tau_max is None else self.tau_max.tolist()
        d["defaulted"] = list(self.defaulted)
        if self.passive:
            d["passive"] = [{"joint": p.joint, "coef": p.coef.tolist(), "offset": p.offset, "q_min": p.lo,
                             "q_max": p.hi} for p in self.passive]
        return d


def limits_of(robot: Any, n: int | None = None, model: Any = None) -> Limits:
    """:class:`Limits` from a :class:`~symoro_gen.description.model.RobotDescription`'s ``[limits]``.

    Fields the file does not give are taken from :data:`DEFAULT_LIMITS` (revolute joints: positions
    ``+-pi``, velocities 2 rad/s, accelerations 10 rad/s^2) or :data:`DEFAULT_PRISMATIC_LIMITS`
    (0.5 m, 0.5 m/s, 2 m/s^2) and listed in ``defaulted``; torque limits stay None. With the ``model`` of a
    closed-loop robot whose closure is linear (``model.linear_closure()``), ``passive_q_min/passive_q_max``
    become :class:`PassiveRange` rows through ``q_tree = A q_a + b``.
    """
    n = robot.n_joints if n is None else n
    rows = list(getattr(robot, "actuated", None) or robot.joints)  # a closed-loop robot's design is in its actuated joints
    if len(rows) != n:
        rows = list(robot.joints)
    prismatic = np.array([getattr(r, "sigma", 0) == 1 for r in rows][:n] + [False] * max(0, n - len(rows)))
    lim = getattr(robot, "limits", None)
    got = {k: (None if lim is None else getattr(lim, k)) for k in ("q_min", "q_max", "dq_max", "ddq_max", "tau_max")}
    defaulted = []
    out = {}
    for k, key, sign in (("q_min", "q", -1.0), ("q_max", "q", 1.0), ("dq_max", "dq", 1.0), ("ddq_max", "ddq", 1.0)):
        if got[k] is None:
            defaulted.append(k)
            out[k] = sign * np.where(prismatic, DEFAULT_PRISMATIC_LIMITS[key], DEFAULT_LIMITS[key])
        else:
            out[k] = np.asarray(got[k], float)
    tau = None if got["tau_max"] is None else np.asarray(got["tau_max"], float)
    limits = Limits(out["q_min"], out["q_max"], out["dq_max"], out["ddq_max"], tau, tuple(defaulted),
                    tuple(bool(p) for p in prismatic), _passive_ranges_of(robot, lim, model))
    limits.centre  # noqa: B018 - passive ranges that no actuated position meets are said now, not mid-design
    return limits


def with_floor(limits: Limits, robot: Any, model: Any, z_min: float) -> Limits:
    """``limits`` with a :class:`Workspace` floor at ``z_min`` (a closed-loop robot's through its linear closure);
    an :class:`ExcitationError` when the rest position at :attr:`Limits.centre` already puts a frame origin below
    it (designs are built about that position)."""
    closure = None
    lc = model.linear_closure() if hasattr(model, "linear_closure") else None
    if lc is not None:
        closure = lc.numeric()
    ws = Workspace(robot, z_min, limits.n, closure)
    out = dataclasses.replace(limits, workspace=ws)
    h = ws.heights(out.centre[None])[0]
    if np.any(h <= ws.z_min):
        i = int(np.argmin(h))
        raise ExcitationError(f"--z-min {z_min:g}: at the centre of the joint ranges (q = "
                              f"{np.array2string(out.centre, precision=3)}), the rest position designs are built "
                              f"about, the origin of frame {ws.frames[i]} is at z = {h[i]:.4g} m, already below the "
                              "floor: lower --z-min or centre [limits] q_min/q_max on an upright posture")
    return out


def _passive_ranges_of(robot: Any, lim: Any, model: Any) -> tuple[PassiveRange, ...]:
    """The ``[limits]`` passive ranges as rows linear in the actuated positions (see :func:`limits_of`)."""
    joints = tuple(getattr(lim, "passive_joints", ()) or ())
    lc = model.linear_closure() if joints and hasattr(model, "linear_closure") else None
    if lc is None:
        return ()
    A, b = lc.numeric()
    row = {j: i for i, j in enumerate(lc.joints)}
    return tuple(PassiveRange(j, A[row[j]], float(b[row[j]]), float(lo), float(hi), robot.row(j).sigma == 1)
                 for j, lo, hi in zip(joints, lim.passive_q_min, lim.passive_q_max))


def check_limits(limits: Limits, q, dq, ddq, tau=None, *, rtol: float = 1e-9) -> dict:
    """Per-joint peak usage of each limit (1 = at the limit) and whether every sample is inside (``passive``:
    the passive joints' position ranges, :attr:`Limits.passive`)."""
    q, dq, ddq = (np.asarray(x, float) for x in (q, dq, ddq))
    c, h = (limits.q_max + limits.q_min) / 2, (limits.q_max - limits.q_min) / 2
    use = {"q": (np.abs(q - c) / h).max(0), "dq": (np.abs(dq) / limits.dq_max).max(0),
           "ddq": (np.abs(ddq) / limits.ddq_max).max(0)}
    if tau is not None and limits.tau_max is not None:
        use["tau"] = (np.abs(tau) / limits.tau_max).max(0)
    if limits.workspace is not None:  # 1 = a frame origin on the floor, from its height at the centre
        ws = limits.workspace
        ref = ws.heights(limits.centre[None])[0]
        use["workspace"] = (ref - ws.heights(q).min(0)) / (ref - ws.z_min)
    if limits.passive:
        _, _, lo, hi = limits.passive_rows()
        use["passive"] = (np.abs(limits.passive_positions(q) - (lo + hi) / 2) / ((hi - lo) / 2)).max(0)
    ok = all(bool(np.all(u <= 1 + rtol)) for u in use.values())
    return {"ok": ok, "usage": {k: v.tolist() for k, v in use.items()}}


def load_casadi():
    """The ``casadi`` module (imported on first use: heavy, and needed only to optimise)."""
    import casadi as ca  # heavy; only for the optimisation

    return ca


def sympy_to_casadi(qa: tuple, exprs: list, q) -> Any:
    """The sympy expressions ``exprs`` in the symbols ``qa`` as one CasADi column in ``q`` (SX)."""
    ca = load_casadi()
    vals = sp.lambdify([qa], exprs, modules=[{"sin": ca.sin, "cos": ca.cos}])([q[k] for k in range(len(qa))])
    return ca.vertcat(*[v if isinstance(v, ca.SX) else ca.SX(float(v)) for v in vals])
