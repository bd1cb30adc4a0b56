"""Optimal excitation trajectories (issue 11, section 1).

The trajectory of an identification experiment is chosen so that the base regressor ``W`` stacked
over it is well conditioned: the least-squares estimate of the base parameters is then insensitive
to torque noise and modelling errors (Gautier & Khalil 1992, "Exciting trajectories for the
identification of base inertial parameters of robots", IJRR 11(4); Swevers, Ganseman, Tukel,
De Schutter & Van Brussel 1997, "Optimal robot excitation and identification", IEEE T-RA 13(5)).

Two kinds of motion, both *linear in their design variables* ``X`` (one column per joint)::

    q(t) = Phi(t) X,   dq(t) = Phi'(t) X,   ddq(t) = Phi''(t) X

* :class:`FourierBasis` - Swevers' finite Fourier series
  ``q_j(t) = q0_j + sum_k a_jk/(w k) sin(w k t) - b_jk/(w k) cos(w k t)``; the last harmonic's
  coefficients are eliminated so that every joint starts and ends at rest
  (``dq(0) = sum_k a_jk = 0``, ``ddq(0) = w sum_k k b_jk = 0``; the motion is periodic).
* :class:`PointToPointBasis` - via-points joined by synchronised trapezoidal-acceleration
  (double-S) profiles of one fixed shape, as industrial controllers run them (the RX-90 paper's kind
  of motion): the robot stops at every via-point.
* :class:`SplineBasis` - a clamped cubic B-spline per joint at rest at both ends (Rackl, Lampariello &
  Hirzinger 2012, ICRA); with :func:`friction_trajectory` starts (bursts at the velocity limit between
  slow motion, the friction columns' optimum) it reaches a lower cond than the Fourier series on the
  LWR4 (docs/excitation.md).

Position, velocity and acceleration limits are then *linear* constraints on ``X`` (imposed on a
grid denser than the output one, with a small margin, and verified again on the output samples);
torque limits, when nominal parameters are known, are nonlinear constraints ``|W(q, dq, ddq) chi_b|
<= tau_max`` at the optimisation samples.

The criterion is evaluated with the generated CasADi model of the robot (``casadi_regressor()``)
and minimised by IPOPT through ``casadi.nlpsol`` from several seeded random feasible starts. The
condition number is not smooth (largest over smallest singular value); the default criterion is
the power-mean bound ``(log tr(Mn^p) + log tr(Mn^-p)) / p`` of ``Mn = M / tr M``, ``M = W^T W``, which
satisfies ``cond(W)^2 <= exp(criterion) <= nb^(2/p) cond(W)^2``; ``p`` is raised by continuation
(:data:`COND_POWERS`: 8, then 64 warm-started from the first optimum); ``"logdet"`` minimises
``-log det M`` (D-optimality).

:func:`cond_lower_bound` bounds from below the cond of ANY trajectory within the velocity limits
(whatever its duration and samples): the friction columns ``dq_j, sign dq_j, 1`` cap ``sigma_min``
(:func:`friction_ceiling`), a set of columns with a constant squared norm per sample (the first
moments of a link turning about a fixed horizontal axis: ``g^2``) floors ``sigma_max``.
How low cond can go over distributions of states (a relaxation of every trajectory) is
:mod:`symoro_gen.excite_relaxation`'s. The value reported, ``cond``, is always the true, unscaled 2-norm
condition number of the base regressor stacked over the output samples, as the field reports it.
"""
from __future__ import annotations

import copy
import dataclasses
import functools
import math
import time
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import sympy as sp

from . import __version__
from .atomic import FORCE_HELP, json_output, write_output_bytes, write_output_text
from .description.mdh import symbolic_transform
from .errors import IdentificationError, ModelError
from .loader import model_for
from .model import IdentificationModel
from .progress import ProgressCounter
from .report import Figure, Heading, Paragraph, Report, Table, check_report_path
from .report.document import write_report_files
from .report.plots import WIDTH_IN, _png, require_matplotlib
from .simulate.trajectories import _piecewise_jerk

__all__ = [
    "CondBound",
    "DEFAULT_LIMITS",
    "ExcitationResult",
    "FourierBasis",
    "Limits",
    "PointToPointBasis",
    "SplineBasis",
    "basis_eval",
    "check_limits",
    "cond_lower_bound",
    "design_information",
    "friction_ceiling",
    "friction_trajectory",
    "limits_of",
    "optimise_excitation",
    "output_times",
    "predicted_sigma",
    "random_trajectory",
    "refine_excitation",
    "stacked_cond",
    "write_trajectory_csv",
]

#: limits used for a robot file without ``[limits]`` (revolute joints [rad], prismatic ones [m]; the
#: output lists the defaulted fields)
DEFAULT_LIMITS = {"q": math.pi, "dq": 2.0, "ddq": 10.0}
DEFAULT_PRISMATIC_LIMITS = {"q": 0.5, "dq": 0.5, "ddq": 2.0}


#: power p of the smooth cond criterion (a power of 2): exp(criterion) is within nb^(2/p) of cond^2
COND_POWER = 8
#: continuation of the cond criterion: IPOPT runs with each power in turn, each stage warm-started
#: from the previous one (a small p is smooth and well scaled far from the optimum, a large p is
#: within nb^(2/p) of cond^2 near it: 64^(1/64) = 1.07 for p = 64)
COND_POWERS = (8, 64)
#: default of ``excite --refine``: SDP iterations on the true cond after IPOPT (on the LWR4 spline bench, 20
#: iterations took the IPOPT optimum from 29.9 to 25.1, 40 to 24.9; docs/excitation.md)
REFINE_ITERATIONS = 20
#: the SDP refinement's grid: at most this many samples per second of the output (every 10th of a 1-kHz output)
REFINE_RATE = 100.0
#: metres the optimiser's floor is raised per unit of its margin (the 1 % margin: 1 cm above ``--z-min``)
WORKSPACE_MARGIN = 1.0


class ExcitationError(IdentificationError):
    """An excitation design cannot be made with the given options (names the option at fault)."""


# ---------------------------------------------------------------------------------------------
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
            ca = _casadi()
            qs = ca.SX.sym("q", self.n)
            self._ca = ca.Function("heights", [qs], [_sympy_casadi(*self._sym, qs)])
        return self._ca


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


# ---------------------------------------------------------------------------------------------
class FourierBasis:
    """Swevers' finite Fourier series with rest at ``t = 0`` (and at every period) built in.

    Per joint ``q_j(t) = q0_j + sum_{k=1..K} a_jk/(w k) sin(w k t) - b_jk/(w k) cos(w k t)``
    (Swevers et al. 1997, eq. 7), ``w = 2 pi f`` the base frequency. The design variables of a joint
    are ``x = (q0, a_1..a_{K-1}, b_1..b_{K-1})``; ``a_K = -sum_{k<K} a_k`` and
    ``b_K = -sum_{k<K} k b_k / K`` make ``dq(0) = ddq(0) = 0`` (hence at ``t = m / f`` too).

    Parameters
    ----------
    harmonics : int
        ``K >= 2``.
    base_frequency : float
        ``f`` [Hz].
    """

    kind = "fourier"

    def __init__(self, harmonics: int, base_frequency: float):
        if harmonics < 2:
            raise ExcitationError(f"--harmonics {harmonics}: at least 2 harmonics are needed to start and end at rest")
        if not base_frequency > 0:
            raise ExcitationError(f"--base-frequency {base_frequency:g}: must be a positive frequency in Hz")
        self.K = int(harmonics)
        self.w = 2 * math.pi * float(base_frequency)
        self.m = 2 * self.K - 1

    def matrices(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``Phi, Phi', Phi''`` at times ``t``, each (N, m)."""
        t = np.asarray(t, float)
        K, w = self.K, self.w
        k = np.arange(1, K + 1)
        S, C = np.sin(np.outer(t, w * k)), np.cos(np.outer(t, w * k))
        N = len(t)
        P, D, A = (np.zeros((N, self.m)) for _ in range(3))
        P[:, 0] = 1.0
        wk, wK = w * k[:-1], w * K
        # a_k (k < K), with a_K = -sum a_k
        P[:, 1:K] = S[:, :-1] / wk - S[:, -1:] / wK
        D[:, 1:K] = C[:, :-1] - C[:, -1:]
        A[:, 1:K] = -S[:, :-1] * wk + S[:, -1:] * wK
        # b_k (k < K), with b_K = -sum k b_k / K
        r = k[:-1] / K
        P[:, K:] = -C[:, :-1] / wk + r * C[:, -1:] / wK
        D[:, K:] = S[:, :-1] - r * S[:, -1:]
        A[:, K:] = C[:, :-1] * wk - r * C[:, -1:] * wK
        return P, D, A

    def coefficients(self, X: np.ndarray) -> dict:
        """``q0`` (n,), ``a``, ``b`` (n, K) of a design ``X`` (m, n) (eliminated harmonic included)."""
        K = self.K
        a = X[1:K].T
        b = X[K:].T
        ks = np.arange(1, K)
        aK = -a.sum(1)
        bK = -(b * ks).sum(1) / K
        return {"q0": X[0].tolist(), "a": np.column_stack([a, aK]).tolist(), "b": np.column_stack([b, bK]).tolist(),
                "base_frequency": self.w / (2 * math.pi)}


class PointToPointBasis:
    """Via-points joined by synchronised trapezoidal-acceleration (double-S) segments.

    Segment ``i`` (duration ``T``) moves every joint from via-point ``P_i`` to ``P_{i+1}`` along
    ``q = P_i + s(u) (P_{i+1} - P_i)``, ``u = (t - i T) / T``, with ``s`` the unit double-S profile of
    seven phases (jerk, constant acceleration, jerk, cruise, jerk, constant deceleration, jerk) of
    durations ``phases`` (fractions of ``T``); velocity and acceleration are zero at every via-point.
    The design variables of a joint are its via-points ``x = (P_0, ..., P_{m-1})``.

    Parameters
    ----------
    via_points : int
        ``m >= 2`` (the first is the start, the last the end).
    segment_time : float
        ``T`` [s].
    dwell : float
        Rest at each intermediate via-point [s].
    """

    kind = "p2p"
    PHASES = (0.1, 0.1, 0.1, 0.4, 0.1, 0.1, 0.1)

    def __init__(self, via_points: int, segment_time: float, dwell: float = 0.0):
        if via_points < 2:
            raise ExcitationError(f"--via-points {via_points}: at least 2 via-points are needed")
        self.m = int(via_points)
        self.T = float(segment_time)
        self.dwell = float(dwell)
        jerks = (1.0, 0.0, -1.0, 0.0, -1.0, 0.0, 1.0)
        self._phases = list(zip(self.PHASES, jerks))

    @property
    def duration(self) -> float:
        return (self.m - 1) * (self.T + self.dwell) - self.dwell

    def _unit(self, u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        P, V, A, p_end = _piecewise_jerk(self._phases, np.clip(u, 0.0, 1.0))
        return P / p_end, V / p_end, A / p_end

    def matrices(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, float)
        N = len(t)
        P, D, A = (np.zeros((N, self.m)) for _ in range(3))
        period = self.T + self.dwell
        seg = np.clip(np.floor(t / period + 1e-12).astype(int), 0, self.m - 2)
        u = np.clip((t - seg * period) / self.T, 0.0, 1.0)
        s, ds, dds = self._unit(u)
        rows = np.arange(N)
        P[rows, seg] = 1 - s
        P[rows, seg + 1] = s
        D[rows, seg] = -ds / self.T
        D[rows, seg + 1] = ds / self.T
        A[rows, seg] = -dds / self.T ** 2
        A[rows, seg + 1] = dds / self.T ** 2
        return P, D, A

    def coefficients(self, X: np.ndarray) -> dict:
        return {"via_points": X.tolist(), "segment_time": self.T, "dwell": self.dwell,
                "phases": list(self.PHASES)}


class SplineBasis:
    """Clamped cubic B-spline of ``coefficients`` control points per joint over ``[0, duration]``,
    at rest (``dq = ddq = 0``) at both ends (Rackl, Lampariello & Hirzinger 2012, "Robot excitation
    trajectories for dynamic parameter estimation using optimized B-splines", ICRA).

    Uniform knots with the end knots repeated four times; the first three control points are equal
    (``dq(0) = ddq(0) = 0``) and so are the last three. The design variables of a joint are
    ``x = (c_start, c_3, ..., c_{M-4}, c_end)``, ``M - 4`` of them. Unlike a Fourier series of a few
    harmonics, a spline can hold a joint near rest and then at its velocity limit, the velocity
    distribution the friction columns want (:func:`friction_ceiling`).

    Parameters
    ----------
    coefficients : int
        ``M >= 7`` control points per joint.
    duration : float
        [s].
    """

    kind = "spline"
    degree = 3

    def __init__(self, coefficients: int, duration: float):
        if coefficients < 7:
            raise ExcitationError(f"--coefficients {coefficients}: at least 7 control points are needed")
        if not duration > 0:
            raise ExcitationError(f"--duration {duration:g}: must be positive")
        self.M = int(coefficients)
        self.duration = float(duration)
        k = self.degree
        inner = np.linspace(0.0, self.duration, self.M - k + 1)
        self.knots = np.concatenate([[0.0] * k, inner, [self.duration] * k])
        self.m = self.M - 4
        # full control points = E @ x (the tied end points)
        E = np.zeros((self.M, self.m))
        E[:3, 0] = 1.0
        E[3:self.M - 3, 1:self.m - 1] = np.eye(self.M - 6)
        E[self.M - 3:, self.m - 1] = 1.0
        self._E = E

    def matrices(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        from scipy.interpolate import BSpline

        t = np.clip(np.asarray(t, float), 0.0, self.duration)
        out = []
        for d in range(3):
            B = np.zeros((len(t), self.M))
            for i in range(self.M):
                c = np.zeros(self.M)
                c[i] = 1.0
                spl = BSpline(self.knots, c, self.degree)
                B[:, i] = spl(t) if d == 0 else spl.derivative(d)(t)
            out.append(B @ self._E)
        return out[0], out[1], out[2]

    def coefficients(self, X: np.ndarray) -> dict:
        return {"control_points": (self._E @ X).tolist(), "knots": self.knots.tolist(), "degree": self.degree}


# ---------------------------------------------------------------------------------------------
def stacked_cond(model: IdentificationModel, q, dq, ddq) -> float:
    """Unscaled 2-norm condition number of the base regressor stacked over the samples."""
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(-1, len(model.BASE_NAMES))
    s = np.linalg.svd(W, compute_uv=False)
    return float(s[0] / s[-1]) if s[-1] > 0 else math.inf


def friction_ceiling(v_max: float) -> float:
    """Largest ``lambda_min`` of ``E[z z^T]``, ``z = (dq, sign dq, 1)``, over every distribution of a
    joint velocity on ``[-v_max, v_max]`` (time samples of any trajectory within the limit).

    By symmetry (``dq -> -dq`` leaves ``lambda_min`` unchanged) and concavity of ``lambda_min`` in the
    moment matrix, a symmetric distribution is optimal, so the moment matrix is
    ``[[a, b], [b, c]] (+) [1]`` with ``b = E|dq|``, ``a = E dq^2 <= v_max b``, ``c = P(dq != 0) <= 1``;
    ``lambda_min`` grows with ``a`` and ``c``: a one-dimensional maximisation over ``b``.
    """
    from scipy.optimize import minimize_scalar

    def neg(b: float) -> float:
        return -min(1.0, float(np.linalg.eigvalsh(np.array([[v_max * b, b], [b, 1.0]]))[0]))

    return -float(minimize_scalar(neg, bounds=(0.0, v_max), method="bounded").fun)


@dataclass(frozen=True)
class CondBound:
    """A lower bound on the condition number of the stacked base regressor over EVERY trajectory
    within the velocity limits (any duration, any number of samples N).

    ``cond(W) = sigma_max / sigma_min`` with
    ``sigma_max^2 >= N smax2`` (a column set whose squared norm per sample is a constant ``k s``:
    ``lambda_max`` of its Gram matrix ``>= N s``) and ``sigma_min^2 <= N smin2`` (the friction columns
    ``dq_j, sign dq_j, 1`` of joint ``j``, restricting the minimising vector to them:
    :func:`friction_ceiling` of ``dq_max_j``). Attributes: ``bound = sqrt(smax2 / smin2)``, and which
    columns give each.
    """

    bound: float
    smax2: float
    smax_columns: tuple[str, ...]
    smin2: float
    smin_joint: int

    def describe(self) -> str:
        return (f"cond >= {self.bound:.4g} for any trajectory within the velocity limits: sigma_max^2/N >= "
                f"{self.smax2:.4g} ({' + '.join(self.smax_columns)}: constant squared norm per sample), "
                f"sigma_min^2/N <= {self.smin2:.4g} (FV{self.smin_joint}, FS{self.smin_joint}, "
                f"OFF{self.smin_joint} at the velocity limit of joint {self.smin_joint})")


def cond_lower_bound(model: IdentificationModel, limits: Limits, *, checks: int = 64, seed: int = 0) -> CondBound | None:
    """:class:`CondBound` of a model under ``limits`` (None when the model has no friction columns).

    The structure the bound rests on is checked on ``checks`` random states (positions across the
    whole circle, velocities and accelerations of both signs): the friction columns of joint ``j``
    are ``dq_j, sign(dq_j), 1`` in row ``j`` only; for ``sigma_max``, single columns and pairs of
    columns that depend on ``q`` only and whose squared norm per sample is the same at every state (the
    offsets: 1; the first moments of a link whose frame origin stays on the fixed base axes: ``g^2``
    for the pair, their torque being ``g (c, s)`` of one angle) are used.
    """
    names = list(model.BASE_NAMES)
    n, nb = int(model.N_JOINTS), len(names)
    rng = np.random.default_rng(seed)
    q = rng.uniform(-math.pi, math.pi, (checks, n))
    dq = rng.uniform(-3, 3, (checks, n))
    ddq = rng.uniform(-10, 10, (checks, n))
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(checks, n, nb)
    W2 = np.asarray(model.regressor(q, 2 * dq + 1, -ddq + 3)).reshape(checks, n, nb)
    tol = 1e-9 * max(1.0, float(np.abs(W).max()))
    smin2, smin_joint = math.inf, 0
    for j in range(n):
        cols = [f"{k}{j + 1}" for k in ("FV", "FS", "OFF")]
        if not all(c in names for c in cols):
            continue
        want = np.zeros((3, checks, n))
        want[0, :, j], want[1, :, j], want[2, :, j] = dq[:, j], np.sign(dq[:, j]), 1.0
        got = np.stack([W[:, :, names.index(c)] for c in cols])
        if np.abs(got - want).max() > tol:
            continue
        c2 = friction_ceiling(float(limits.dq_max[j]))
        if c2 < smin2:
            smin2, smin_joint = c2, j + 1
    if not math.isfinite(smin2):
        return None
    q_only = [i for i in range(nb) if np.abs(W[:, :, i] - W2[:, :, i]).max() <= tol]
    per = {i: (W[:, :, i] ** 2).sum(1) for i in q_only}  # squared norm per sample
    best: tuple[float, tuple[str, ...]] = (0.0, ())
    for a_i, a in enumerate(q_only):
        if np.ptp(per[a]) <= 1e-9 * max(per[a].max(), 1.0) and per[a][0] > best[0]:
            best = (float(per[a][0]), (names[a],))
        for b in q_only[a_i + 1:]:
            tot = per[a] + per[b]
            if np.ptp(tot) <= 1e-9 * max(tot.max(), 1.0) and tot[0] / 2 > best[0]:
                best = (float(tot[0] / 2), (names[a], names[b]))
    if best[0] <= 0:
        return None
    return CondBound(math.sqrt(best[0] / smin2), best[0], best[1], smin2, smin_joint)


def predicted_sigma(model: IdentificationModel, q, dq, ddq, noise: float, chi_b=None) -> tuple[np.ndarray, np.ndarray | None]:
    """Predicted standard deviations of the base parameters for i.i.d. torque noise ``noise``.

    ``cov = noise^2 (W^T W)^-1`` (Gautier 1997, eq. 9, with the noise variance given instead of
    estimated from the residual). Returns ``sigma`` (nb,) and, when ``chi_b`` is given, the relative
    ``%sigma = 100 sigma / |chi_b|`` (NaN where ``chi_b`` is 0, or round-off of the regrouping: below
    1e-9 of the largest ``|chi_b|``, as a URDF's nominal inertias leave - a %sigma of 1e11 says nothing).
    """
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(-1, len(model.BASE_NAMES))
    cov = noise ** 2 * np.linalg.pinv(W.T @ W)
    sig = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if chi_b is None:
        return sig, None
    cb = np.abs(np.asarray(chi_b, float))
    cb = np.where(cb > 1e-9 * cb.max(initial=0.0), cb, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        pct = np.where(cb > 0, 100.0 * sig / np.where(cb > 0, cb, 1.0), np.nan)
    return sig, pct


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


def _constant_design(basis, n: int, centre: np.ndarray) -> np.ndarray:
    """Design ``X`` of the motion that stays at ``centre``: the constant term ``q0`` of a Fourier series;
    every control point or via-point at ``centre`` for a spline or point-to-point design (partitions of
    unity). (A least-squares fit of the constant on a few early samples, used before, left a Fourier or
    point-to-point "constant" that drifted away later in the period wherever the range is not centred
    on 0: random designs were then scaled about the wrong centre and left their position range.)"""
    X = np.outer(np.ones(basis.m), centre)
    if isinstance(basis, FourierBasis):
        X[1:] = 0.0
    return X


def _scale_into(basis, limits: Limits, X: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``X0 + k_j (X - X0)`` per joint, with the largest ``k_j`` that keeps joint j inside
    its position, velocity and acceleration limits at the times ``t`` (``X0``: rest at :attr:`Limits.centre`),
    then, with passive ranges, one common factor that keeps the passive joints inside theirs, and with a
    workspace floor, the largest common factor (bisection) that keeps every frame origin above it."""
    P, D, A = basis.matrices(t)
    X0 = _constant_design(basis, limits.n, limits.centre)
    up, down = limits.room()
    dX = X - X0
    dev = P @ dX
    with np.errstate(divide="ignore", invalid="ignore"):
        k = np.minimum.reduce([np.minimum(up / np.maximum(dev.max(0), 0.0), down / np.maximum(-dev.min(0), 0.0)) if limits.passive
                               else up / np.abs(dev).max(0), limits.dq_max / np.abs(D @ dX).max(0),
                               limits.ddq_max / np.abs(A @ dX).max(0)])
        k = np.where(np.isfinite(k), k, 1.0)
        if limits.passive:  # the passive positions are linear in the actuated ones: one factor for all joints
            C, _, lo, hi = limits.passive_rows()
            p0, pd = limits.passive_positions(limits.centre[None])[0], (dev * k) @ C.T
            s = np.min(np.r_[1.0, (hi - p0) / np.maximum(pd.max(0), 0.0), (p0 - lo) / np.maximum(-pd.min(0), 0.0)])
            k = k * (s if np.isfinite(s) else 1.0)
    X = X0 + dX * k
    if limits.workspace is not None:  # the floor is not linear in q: bisect a common factor towards the rest at the centre
        ws = limits.workspace

        def above(f: float) -> bool:
            return bool(np.all(ws.heights(P @ (X0 + f * (X - X0))) >= ws.z_min))
        if not above(1.0):
            lo_f, hi_f = 0.0, 1.0
            for _ in range(30):
                mid = (lo_f + hi_f) / 2
                lo_f, hi_f = (mid, hi_f) if above(mid) else (lo_f, mid)
            X = X0 + lo_f * (X - X0)
    return X


def random_trajectory(basis, limits: Limits, rng: np.random.Generator, t: np.ndarray, *, decay: float = 1.0) -> np.ndarray:
    """A random feasible design ``X`` (m, n): random coefficients (harmonic ``k`` with standard
    deviation ``k**-decay``; uniform via-points), scaled per joint so that the tightest of its
    position, velocity and acceleration limits is reached on the samples ``t`` (the usual random
    baseline of excitation design)."""
    n = limits.n
    centre = limits.centre
    X0 = _constant_design(basis, n, centre)
    if isinstance(basis, FourierBasis):
        ks = np.concatenate([np.arange(1, basis.K), np.arange(1, basis.K)]).astype(float)
        R = np.zeros((basis.m, n))
        R[1:] = rng.standard_normal((basis.m - 1, n)) * (ks ** -decay)[:, None]
        R[0] = rng.uniform(-0.3, 0.3, n) * (limits.q_max - limits.q_min) / 2
        X = X0 + R
    elif isinstance(basis, SplineBasis):
        # a random walk of the control points (uniform ones would be all acceleration)
        X = centre + np.cumsum(rng.standard_normal((basis.m, n)), axis=0) * (limits.q_max - limits.q_min) / 8
    else:
        X = rng.uniform(limits.q_min, limits.q_max, (basis.m, n))
    return _scale_into(basis, limits, X, t)


def friction_trajectory(basis, limits: Limits, rng: np.random.Generator, t: np.ndarray, duration: float, *,
                        cruise: float = 0.3, creep: float = 0.05) -> np.ndarray:
    """A feasible design whose every joint alternates slow motion and bursts at its velocity limit.

    The velocity distribution that maximises the smallest eigenvalue of a joint's friction block
    ``E[(dq, sign dq, 1)(dq, sign dq, 1)^T]`` (:func:`friction_ceiling`) puts a fraction of the time at
    ``+-dq_max`` and the rest at small nonzero speed. Per joint: the duration is cut into a random
    number of equal slots, each holding one burst of alternating sign at a random offset (the cruise
    fraction ``cruise`` of the duration in all, each burst's travel within the joint range), ramps at
    0.8 of the acceleration limit, ``creep * dq_max`` towards the next burst in between; the position
    is its integral, fitted by least squares in the basis and scaled into the limits
    (:func:`random_trajectory`'s scaling on the samples ``t``).
    """
    n = limits.n
    tt = np.linspace(0.0, duration, 4001)
    dt = tt[1] - tt[0]
    V = np.zeros((len(tt), n))
    for j in range(n):
        v, a = float(limits.dq_max[j]), 0.8 * float(limits.ddq_max[j])
        ramp = v / a
        span = (limits.q_max[j] - limits.q_min[j]) * 0.75  # room for the creeping between bursts
        fits = [k for k in (2, 4, 6, 8) if duration / k >= 2.5 * ramp + 0.2]
        nb = int(rng.choice(fits)) if fits else 2
        slot = duration / nb
        hold = max(0.0, min(cruise * slot, span / v - ramp, slot - 2 * ramp - 0.2))
        burst = hold + ramp  # the rate limiter adds a ramp at each end
        sign0 = float(rng.choice([-1.0, 1.0]))
        target = np.zeros(len(tt))
        for i in range(nb):
            sg = sign0 * (-1) ** i
            lo = i * slot + (0.1 if i else 0.3)
            hi = max(lo, (i + 1) * slot - burst - 2 * ramp - (0.3 if i == nb - 1 else 0.1))
            t0 = rng.uniform(lo, hi)
            target[(tt >= i * slot) & (tt < t0)] = sg * creep * v  # creeping towards this burst's direction
            target[(tt >= t0) & (tt < t0 + burst)] = sg * v
            target[(tt >= t0 + burst) & (tt < (i + 1) * slot)] = -sg * creep * v
        target[tt >= duration - 0.3] = 0.0
        target[tt < 0.1] = 0.0
        # rate-limit the target to the acceleration (ramps), starting and ending at rest
        vel = np.zeros(len(tt))
        for k in range(1, len(tt)):
            vel[k] = vel[k - 1] + np.clip(target[k] - vel[k - 1], -a * dt, a * dt)
        V[:, j] = vel
    Q = np.cumsum(V, axis=0) * dt
    Q += (limits.centre - (Q.max(0) + Q.min(0)) / 2)
    P, _, _ = basis.matrices(tt)
    X, *_ = np.linalg.lstsq(P, Q, rcond=None)
    return _scale_into(basis, limits, X, t)


# ---------------------------------------------------------------------------------------------
@dataclass
class ExcitationResult:
    """An optimised excitation trajectory and its figures.

    Attributes
    ----------
    t, q, dq, ddq : ndarray
        Output samples (``t`` (N,), the others (N, n)).
    X : ndarray (m, n)
        The design (see the basis).
    cond : float
        Unscaled condition number of the base regressor stacked over the output samples.
    limits_ok : bool
        Every output sample (and a 10x denser resampling) inside every limit.
    starts : list of dict
        Per random start: ``cond`` before and after IPOPT, IPOPT's return status.
    """

    basis: Any
    limits: Limits
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    X: np.ndarray
    cond: float
    limits_ok: bool
    usage: dict
    criterion: str
    starts: list = field(default_factory=list)
    wall_time: float = 0.0
    tau: np.ndarray | None = None


def _casadi():
    import casadi as ca  # heavy; only for the optimisation

    return ca


def _casadi_regressor(model: IdentificationModel):
    """The model's CasADi regressor ``(q, dq, ddq) -> Y``, or an :class:`ExcitationError` that says why there is none
    (a closed-loop robot has one when its closure is linear: parallelograms, coupled joints)."""
    if not hasattr(model, "casadi_regressor"):
        raise ExcitationError(f"{model.ROBOT}: the model has no casadi_regressor() (use a generated package: "
                              "symoro_gen.load_model)")
    try:
        return model.casadi_regressor()
    except ModelError as e:
        raise ExcitationError(f"{e}: excite cannot optimise a trajectory for it (identify and diagnose do work "
                              "on it)") from None


def design_information(model: IdentificationModel, basis, x, t: np.ndarray):
    """``W^T W / (n N)`` of the base regressor stacked over the samples ``t`` of the design ``x`` (a CasADi
    column of the design variables, ``X`` column-major: column j = joint j), as a CasADi expression from the
    generated model: the information matrix every criterion of :func:`optimise_excitation` is a function of
    (and the dual ratio that ``bench/bench_excite_mixture.py --price`` maximises)."""
    ca = _casadi()
    n = int(x.numel()) // int(basis.m)
    qs, dqs, ddqs = ca.MX.sym("q", n), ca.MX.sym("dq", n), ca.MX.sym("ddq", n)
    G = ca.Function("Yt", [qs, dqs, ddqs], [_casadi_regressor(model)(qs, dqs, ddqs).T])
    X = ca.reshape(x, basis.m, n)
    P, D, A = (ca.DM(M) for M in basis.matrices(t))
    Z = G.map(len(t))((P @ X).T, (D @ X).T, (A @ X).T)  # (nb, n N): [Y_1^T, Y_2^T, ...]
    return (Z @ Z.T) / (n * len(t))


def _build_nlp(model: IdentificationModel, basis, limits: Limits, t_obj: np.ndarray, t_con: np.ndarray,
               criterion: str, chi_b: np.ndarray | None, margin: float, power: int = COND_POWER) -> tuple[Any, dict]:
    ca = _casadi()
    n, m = limits.n, basis.m
    F = _casadi_regressor(model)  # (q, dq, ddq) -> Y (n x nb)
    qs, dqs, ddqs = ca.MX.sym("q", n), ca.MX.sym("dq", n), ca.MX.sym("ddq", n)
    Y = F(qs, dqs, ddqs)
    x = ca.MX.sym("x", m * n)
    X = ca.reshape(x, m, n)  # column-major: column j = design of joint j
    Po, Do, Ao = (ca.DM(M) for M in basis.matrices(t_obj))
    No = len(t_obj)
    M = design_information(model, basis, x, t_obj)
    if criterion == "cond":
        # cond(W)^2 = lambda_max / lambda_min of M, with the power means
        # lambda_max <= tr(M^p)^(1/p) <= nb^(1/p) lambda_max (and alike for M^-1): smooth, tight for large p.
        # Each squaring is renormalised by its trace (log tr(A^2p) = 2 log tr(A^p) + log tr(B^2),
        # B = A^p / tr(A^p)), so that large p neither overflows nor underflows.
        if power < 2 or power & (power - 1):
            raise ExcitationError(f"cond criterion power {power}: must be a power of 2")

        def log_tr_power(A):
            lt = ca.log(ca.trace(A))
            B = A / ca.trace(A)
            for _ in range(int(math.log2(power))):
                B2 = B @ B
                t2 = ca.trace(B2)
                lt = 2 * lt + ca.log(t2)
                B = B2 / t2
            return lt

        Mn = M / ca.trace(M)
        f = (log_tr_power(Mn) + log_tr_power(ca.inv(Mn))) / power
    elif criterion == "logdet":
        f = -ca.log(ca.det(M))
    else:
        raise ExcitationError(f"--criterion {criterion!r}: expected cond or logdet")
    lim = limits.shrunk(margin)
    Pc, Dc, Ac = basis.matrices(t_con)
    Nc = len(t_con)
    g = [ca.vec(ca.DM(Pc) @ X), ca.vec(ca.DM(Dc) @ X), ca.vec(ca.DM(Ac) @ X)]
    lbg = [np.repeat(lim.q_min, Nc), np.repeat(-lim.dq_max, Nc), np.repeat(-lim.ddq_max, Nc)]
    ubg = [np.repeat(lim.q_max, Nc), np.repeat(lim.dq_max, Nc), np.repeat(lim.ddq_max, Nc)]
    if lim.passive:  # passive joints of a linear closure: C q + offset within [lo, hi]
        Cp, off, lo, hi = lim.passive_rows()
        g.append(ca.vec(ca.DM(Pc) @ X @ ca.DM(Cp.T)))
        lbg.append(np.repeat(lo - off, Nc))
        ubg.append(np.repeat(hi - off, Nc))
    if lim.workspace is not None:  # every moving frame origin above the floor at every grid sample
        Hz = lim.workspace.casadi().map(Nc)((ca.DM(Pc) @ X).T)  # (frames, Nc)
        g.append(ca.vec(Hz))
        lbg.append(np.full(Hz.numel(), lim.workspace.z_min))
        ubg.append(np.full(Hz.numel(), np.inf))
    if chi_b is not None and lim.tau_max is not None:
        Hq = ca.Function("tau", [qs, dqs, ddqs], [Y @ ca.DM(chi_b)])
        T = Hq.map(No)((Po @ X).T, (Do @ X).T, (Ao @ X).T)  # (n, No)
        g.append(ca.vec(T.T))
        lbg.append(np.repeat(-lim.tau_max, No))
        ubg.append(np.repeat(lim.tau_max, No))
    nlp = {"x": x, "f": f, "g": ca.vertcat(*g)}
    return nlp, {"lbg": np.concatenate(lbg), "ubg": np.concatenate(ubg)}


class _Linearisation:
    """``M(X) = W^T W / N`` of the base regressor stacked over the samples ``t`` and its derivative
    ``dM/dX`` (the design enters ``q, dq, ddq`` linearly through the basis matrices), from the generated
    CasADi regressor and its Jacobian with respect to ``(q, dq, ddq)`` (one sample at a time, mapped
    over chunks of samples); with ``chi_b``, the torques ``W chi_b`` and their derivative too."""

    def __init__(self, model: IdentificationModel, basis, t: np.ndarray, chi_b: np.ndarray | None = None,
                 chunk: int = 100):
        ca = _casadi()
        self.n, self.nb, self.m = int(model.N_JOINTS), len(model.BASE_NAMES), int(basis.m)
        n = self.n
        qs, dqs, ddqs = ca.MX.sym("q", n), ca.MX.sym("dq", n), ca.MX.sym("ddq", n)
        Y = _casadi_regressor(model)(qs, dqs, ddqs)
        J = ca.jacobian(ca.vec(Y), ca.vertcat(qs, dqs, ddqs))  # (n nb, 3n), vec column-major
        self.P, self.D, self.A = basis.matrices(t)
        self.N = len(t)
        self.chunk = int(min(chunk, self.N))
        self.f = ca.Function("YJ", [qs, dqs, ddqs], [Y, J]).map(self.chunk)
        self.chi_b = None if chi_b is None else np.asarray(chi_b, float)

    def __call__(self, X: np.ndarray):
        """``M`` (nb, nb), ``dM`` (m, n, nb, nb) (``dM[k, j] = dM/dX[k, j]``) and, with ``chi_b``, the
        torques (N, n) and their derivative (N, n, m, n)."""
        n, nb, m, N, c = self.n, self.nb, self.m, self.N, self.chunk
        q, dq, ddq = self.P @ X, self.D @ X, self.A @ X
        M = np.zeros((nb, nb))
        G = np.zeros((m, n, nb, nb))
        with_tau = self.chi_b is not None
        tau, dtau = (np.zeros((N, n)), np.zeros((N, n, m, n))) if with_tau else (np.zeros((0, n)), np.zeros((0, n, m, n)))
        for s0 in range(0, N, c):
            idx = np.arange(s0, s0 + c)
            valid = idx < N
            idx = np.minimum(idx, N - 1)  # the last chunk is padded by repeating the last sample
            Yc, Jc = self.f(q[idx].T, dq[idx].T, ddq[idx].T)
            Ys = Yc.full().reshape(n, c, nb).transpose(1, 0, 2)[valid]  # (S, n, nb)
            # Jc (n nb, 3n c): sample s, variable v -> column s 3n + v; rows vec(Y) = b n + r
            dY = Jc.full().reshape(nb, n, c, 3 * n).transpose(2, 3, 1, 0)[valid]  # (S, 3n, n, nb)
            M += np.einsum("sra,srb->ab", Ys, Ys)
            H = np.matmul(Ys.transpose(0, 2, 1)[:, None], dY)  # (S, 3n, nb, nb): Y_s^T dY_s/dz_v
            rows = idx[valid]
            for w, B in enumerate((self.P, self.D, self.A)):
                Hw = H[:, w * n:(w + 1) * n].reshape(len(rows), n * nb * nb)
                G += (B[rows].T @ Hw).reshape(m, n, nb, nb)
            if with_tau:
                tau[rows] = Ys @ self.chi_b
                dT = dY @ self.chi_b  # (S, 3n, n): d tau_s / d z_v
                for w, B in enumerate((self.P, self.D, self.A)):
                    # dtau[s, r, k, j] += B[s, k] dT[s, w n + j, r]
                    dtau[rows] += np.einsum("sk,sjr->srkj", B[rows], dT[:, w * n:(w + 1) * n])
        dM = (G + G.transpose(0, 1, 3, 2)) / N
        return M / N, dM, (tau if with_tau else None), (dtau if with_tau else None)


def _cond2(M: np.ndarray) -> float:
    ev = np.linalg.eigvalsh(M)
    return float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf


def refine_excitation(model: IdentificationModel, basis, limits: Limits, X: np.ndarray, t_out: np.ndarray,
                      t_con: np.ndarray, *, iterations: int = 30, margin: float = 0.01, chi_b=None,
                      delta: float = 0.05, delta_min: float = 1e-4, delta_max: float = 0.5, check_times=None,
                      block: int = 16, progress=None) -> tuple[np.ndarray, list[dict]]:
    """Lower the TRUE condition number of a design by sequential semidefinite programming.

    The smooth power-mean criterion of the IPOPT stage is loose at the optimum of an eigenvalue problem,
    where the extreme eigenvalues of ``M = W^T W / N`` coalesce into clusters and ``cond`` is not
    differentiable (Overton 1992, "Large-scale optimization of eigenvalues", SIAM J. Optim. 2(1); Lewis
    & Overton 1996, "Eigenvalue optimization", Acta Numerica 5). Each iteration linearises the
    *matrix* ``M(X + D) ~ M(X) + sum_kj D_kj dM/dX_kj`` (not its eigenvalues, so that clusters are
    handled; :class:`_Linearisation`, from the generated CasADi regressor) and minimises the ratio
    ``lambda_max / lambda_min`` of the linearised matrix by Dinkelbach's parametric form (Dinkelbach
    1967, "On nonlinear fractional programming", Management Science 13(7)): the convex SDP

        minimise  lambda_max(M_lin(D)) - rho lambda_min(M_lin(D)),   rho = cond(W)^2 at X

    with ``M_lin`` compressed to the invariant subspaces of the two clusters (the eigenvectors of ``M(X)``
    whose eigenvalues are within a factor of 2 of ``lambda_max``, resp. ``lambda_min``, at most ``block``
    each: Overton's active eigenspaces, which keep the SDP small for any number of base parameters),
    subject to the position, velocity and acceleration limits of ``X + D`` on the grid ``t_con`` (and the
    knots of a spline basis) (tightened by ``margin``; a bound the current design already exceeds is relaxed to its current
    value), the sign of every moving output velocity kept (the Coulomb columns ``sign(dq)`` are piecewise
    constant: a velocity may fall to half its value, not cross zero, so that the linearisation holds), with
    ``chi_b`` and ``limits.tau_max`` the linearised torque limits at the output samples, and the
    trust region ``|D_kj| <= delta s_kj`` (``s_kj``: the change of coefficient ``k`` alone that spans a
    full limit of joint ``j``). Solved by cvxpy with Clarabel. The step is accepted when the true cond
    on ``t_out`` decreases and every limit holds on ``t_out`` and on ``check_times`` (default: 10x denser
    than ``t_out``, and the knots: :func:`dense_times`); the radius follows the usual trust-region rule on the ratio of actual to predicted
    decrease (Conn, Gould & Toint 2000, "Trust-region methods", alg. 6.1.1). Stops after ``iterations``
    SDPs, when ``delta < delta_min`` or when the SDP predicts no decrease. ``progress(record)`` is called
    after each SDP (with the iteration's record).

    Returns the refined design (never of larger cond than ``X``) and the history of the iterations
    (``cond`` at the start of each, ``delta``, ``predicted`` and ``actual`` decrease of ``cond^2``,
    ``accepted``, ``status`` of the SDP).
    """
    if not _has_cvxpy():
        raise ExcitationError("the SDP refinement needs cvxpy and clarabel: pip install 'symoro-gen[physical]'")
    import cvxpy as cp

    n, nb, m = limits.n, len(model.BASE_NAMES), basis.m
    X = np.asarray(X, float).copy()
    cb = None if chi_b is None or limits.tau_max is None else np.asarray(chi_b, float)
    lin = _Linearisation(model, basis, t_out, cb)
    check_times = dense_times(t_out, float(t_out[-1]), basis) if check_times is None else check_times
    lim = limits.shrunk(margin)
    knots = getattr(basis, "knots", None)
    Pc, Dc, Ac = basis.matrices(t_con if knots is None else np.union1d(t_con, np.clip(knots, 0.0, t_out[-1])))
    Do = basis.matrices(t_out)[1]
    with np.errstate(divide="ignore"):
        h = (limits.q_max - limits.q_min) / 2
        scale = np.minimum.reduce([h[None] / np.abs(Pc).max(0)[:, None], limits.dq_max[None] / np.abs(Dc).max(0)[:, None],
                                   limits.ddq_max[None] / np.abs(Ac).max(0)[:, None]])  # (m, n)
    scale = np.where(np.isfinite(scale), scale, 0.0)

    heights_jac = None if lim.workspace is None else _floor_linearisation(lim.workspace)

    def feasible(Xc: np.ndarray) -> bool:
        q, dq, ddq = basis_eval(basis, Xc, t_out)
        tau = None if cb is None else np.asarray(model.regressor(q, dq, ddq)) @ cb
        return bool(check_limits(limits, q, dq, ddq, tau)["ok"] and _inside(basis, limits, Xc, check_times))

    def cond2(Xc: np.ndarray) -> float:
        return stacked_cond(model, *basis_eval(basis, Xc, t_out)) ** 2

    def compress(dM: np.ndarray, U: np.ndarray) -> np.ndarray:
        """``U^T dM_i U`` of every design variable i, as the columns of a (k^2, m n) matrix."""
        k = U.shape[1]
        R = (dM.reshape(m * n * nb, nb) @ U).reshape(m * n, nb, k)
        return np.einsum("ax,iay->ixy", U, R).reshape(m * n, k * k).T

    history: list[dict] = []

    def record(rec: dict) -> None:
        history.append(rec)
        if progress is not None:
            progress(rec)

    M0, dM, tau0, dtau = lin(X)
    c2 = _cond2(M0)
    for it in range(int(iterations)):
        if delta < delta_min:
            break
        dq_out = Do @ X
        # the eigenspaces of the two clusters (Overton 1992): the SDP sees M_lin compressed to the eigenvectors of
        # M(X) within a factor of 2 of lambda_max and of lambda_min (at most `block` each)
        w, Q = np.linalg.eigh(M0)
        top = np.flatnonzero(w >= 0.5 * w[-1])[-block:]
        bot = np.flatnonzero(w <= 2.0 * w[0])[:block]
        U, V = Q[:, top], Q[:, bot]
        ku, kv = len(top), len(bot)
        BU, BV = compress(dM, U) / w[-1], compress(dM, V) / w[0]
        d = cp.Variable(m * n)
        smax, smin = cp.Variable(), cp.Variable()
        Dm = cp.reshape(d, (m, n), order="C")
        MU = np.diag(w[top] / w[-1]) + cp.reshape(BU @ d, (ku, ku), order="C")
        MV = np.diag(w[bot] / w[0]) + cp.reshape(BV @ d, (kv, kv), order="C")
        cons = [smax * np.eye(ku) - MU >> 0, MV - smin * np.eye(kv) >> 0, cp.abs(d) <= delta * scale.reshape(-1)]
        for Bm, lo, hi in ((Pc, lim.q_min, lim.q_max), (Dc, -lim.dq_max, lim.dq_max), (Ac, -lim.ddq_max, lim.ddq_max)):
            cur = Bm @ X
            cons += [Bm @ Dm <= np.maximum(hi - cur, 0.0), Bm @ Dm >= np.minimum(lo - cur, 0.0)]
        if lim.passive:
            Cp, _, lo, hi = lim.passive_rows()
            cur = lim.passive_positions(Pc @ X)
            cons += [Pc @ Dm @ Cp.T <= np.maximum(hi - cur, 0.0), Pc @ Dm @ Cp.T >= np.minimum(lo - cur, 0.0)]
        if heights_jac is not None and lim.workspace is not None:  # the frame heights linearised: h + J (Pc D) >= z_min
            hz, Jz = heights_jac(Pc @ X)
            E = Pc @ Dm
            cons += [cp.sum(cp.multiply(Jz[:, f, :], E), axis=1) >= np.minimum(lim.workspace.z_min - hz[:, f], 0.0)
                     for f in range(hz.shape[1])]
        # the Coulomb columns sign(dq) are piecewise constant: the sign of every moving output sample is kept,
        # so that the linearisation holds (a velocity may halve towards zero, not cross it)
        for j in range(n):
            sg = np.sign(dq_out[:, j])
            mv = sg != 0
            if mv.any():
                floor = 0.5 * np.minimum(np.abs(dq_out[mv, j]), 0.01 * limits.dq_max[j])
                cons.append(cp.multiply(sg[mv], Do[mv] @ Dm[:, j]) >= floor - np.abs(dq_out[mv, j]))
        if cb is not None and dtau is not None and tau0 is not None and lim.tau_max is not None:
            T = dtau.reshape(-1, m * n)
            cur = tau0.reshape(-1)
            tm = np.tile(lim.tau_max, len(t_out))
            cons += [T @ d <= np.maximum(tm - cur, 0.0), T @ d >= np.minimum(-tm - cur, 0.0)]
        # Dinkelbach: lambda_max - rho lambda_min with rho = lambda_max / lambda_min at X, divided by lambda_max
        # (each block scaled by its own extreme eigenvalue, so the SDP's data are O(1)); 0 at D = 0
        prob = cp.Problem(cp.Minimize(smax - smin), cons)
        rec: dict = {"iteration": it, "cond": math.sqrt(c2), "delta": delta, "block": [ku, kv]}
        try:
            with warnings.catch_warnings():  # "solution may be inaccurate": the status is recorded, the step checked
                warnings.simplefilter("ignore", UserWarning)
                prob.solve(solver="CLARABEL")
            status = prob.status
        except cp.error.SolverError as e:  # pragma: no cover - numerical failure of the solver
            status = f"solver error: {e}"
        rec["status"] = status
        if d.value is None or status not in ("optimal", "optimal_inaccurate"):
            rec.update(accepted=False, predicted=0.0, actual=0.0)
            record(rec)
            delta /= 4
            continue
        D = np.asarray(d.value).reshape(m, n)
        lu = np.linalg.eigvalsh(np.diag(w[top]) + (BU @ d.value).reshape(ku, ku) * w[-1])[-1]
        lv = np.linalg.eigvalsh(np.diag(w[bot]) + (BV @ d.value).reshape(kv, kv) * w[0])[0]
        pred = float(c2 - (lu / lv if lv > 0 else math.inf))
        rec["predicted"] = pred
        if not pred > 1e-8 * c2:
            rec.update(accepted=False, actual=0.0)
            record(rec)
            break  # the linearised problem sees no descent: a stationary point of the ratio
        Xn = X + D
        c2n = cond2(Xn)
        ok = feasible(Xn)
        actual = c2 - c2n
        rec["actual"] = actual
        rho = actual / pred
        accepted = bool(ok and actual > 0)
        rec["accepted"] = accepted
        record(rec)
        step = float(np.max(np.abs(D) / np.where(scale > 0, scale, 1.0)))
        if accepted:
            X = Xn
            M0, dM, tau0, dtau = lin(X)
            c2 = _cond2(M0)
        if not ok or rho < 0.25:
            delta = 0.5 * min(delta, step)
        elif rho > 0.75 and step >= 0.99 * delta:
            delta = min(2 * delta, delta_max)
    history.append({"iteration": len(history), "cond": math.sqrt(c2), "delta": delta, "final": True})
    return X, history


def _floor_linearisation(ws: Workspace):
    """``q (N, n) -> (h (N, k), J (N, k, n))``: the frame heights of ``ws`` and their Jacobians (CasADi)."""
    ca = _casadi()
    qs = ca.SX.sym("q", ws.n)
    h = ws.casadi()(qs)
    f = ca.Function("hJ", [qs], [h, ca.jacobian(h, qs)])

    def run(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        H, J = f.map(len(Q))(Q.T)
        k = len(ws.frames)
        return np.asarray(H).T, np.asarray(J).reshape(k, len(Q), ws.n).transpose(1, 0, 2)
    return run


def output_times(duration: float, rate: float) -> np.ndarray:
    """``0, 1/rate, ..., duration`` (the last sample at ``duration``)."""
    N = round(duration * rate)
    return np.arange(N + 1) / rate


def _optimise_start(model: IdentificationModel, basis, limits: Limits, solvers: list, bounds: dict, X_init: np.ndarray,
                    *, t_out: np.ndarray, t_con: np.ndarray, period: float, duration: float, margin: float,
                    cb: np.ndarray | None, refine: int, step, rec: dict) -> tuple[float, np.ndarray]:
    """One start of :func:`optimise_excitation`: the IPOPT stages in turn (``solvers``), then at most
    ``refine`` SDP iterations of :func:`refine_excitation`; ``step(k)`` reports ``k`` more of those steps
    done, ``rec`` (holding the start's ``cond_start``) receives the start's record. Returns the start's cond on ``t_out`` and its design, never
    worse than the start's own (IPOPT minimises a smooth bound of cond, which can fall while cond rises)."""
    n = limits.n
    x = X_init.T.reshape(-1)
    stage_conds, iters, status = [], 0, ""
    x_best, c_best = x, math.inf
    torques_ok = True
    if cb is not None and limits.tau_max is not None:
        tau = np.asarray(model.regressor(*basis_eval(basis, X_init, t_out))) @ cb
        torques_ok = bool(np.all(np.abs(tau) <= limits.tau_max * (1 + 1e-9)))
    if torques_ok and _inside(basis, limits, X_init, t_con):
        c_best = rec["cond_start"]  # a start within every limit, torques included, is a result too
    for solver in solvers:
        sol = solver(x0=x, lbg=bounds["lbg"], ubg=bounds["ubg"])
        step(1)
        stats = solver.stats()
        status, iters = stats.get("return_status", ""), iters + stats.get("iter_count", 0)
        x = np.asarray(sol["x"]).reshape(-1)
        stage_conds.append(stacked_cond(model, *basis_eval(basis, x.reshape(n, basis.m).T, t_out)))
        # a failed stage (e.g. IPOPT's Error_In_Step_Computation at a large p) can end worse than it
        # started: the start's result is its best feasible stage
        if stage_conds[-1] < c_best and _inside(basis, limits, x.reshape(n, basis.m).T, t_con):
            x_best, c_best = x, stage_conds[-1]
        elif stage_conds[-1] >= c_best:
            x = x_best
    X = (x_best if math.isfinite(c_best) else x).reshape(n, basis.m).T
    dense = dense_times(t_out, duration, basis)
    if not _inside(basis, limits, X, dense):
        X = _scale_into(basis, limits, X, dense)
    c = stacked_cond(model, *basis_eval(basis, X, t_out))
    rec.update(cond=c, status=status, iterations=iters, cond_stages=stage_conds)
    if refine:
        tr = time.perf_counter()
        # a periodic design repeats its samples every period: the refinement works on the first one (a design
        # of period 10 s over 60 s costs as much as over 10 s); the cond kept is recomputed on all of t_out
        t_ref = t_out[t_out <= period * (1 + 1e-12)] if period < duration else t_out
        # ... and on at most REFINE_RATE samples per second: its linearisation grows with the samples (2 GB at
        # 1 kHz on a 7-joint arm), a smooth design's cond does not (it is recomputed on every output sample)
        t_ref = np.union1d(t_ref[::max(1, int(round(1.0 / (REFINE_RATE * float(t_out[1] - t_out[0])))))], t_ref[-1:])
        X_r, hist = refine_excitation(model, basis, limits, X, t_ref, t_con, iterations=refine, margin=margin,
                                      chi_b=cb, check_times=dense_times(t_ref, float(t_ref[-1]), basis),
                                      progress=lambda _rec: step(1))
        step(refine - (len(hist) - 1))  # one record per SDP and a final one: the SDPs not run count as done
        c_r = stacked_cond(model, *basis_eval(basis, X_r, t_out))
        rec.update(cond_ipopt=c, cond=min(c, c_r), refine_sdps=len(hist) - 1,
                   refine_accepted=sum(1 for h in hist if h.get("accepted")),
                   refine_conds=[h["cond"] for h in hist],
                   refine_time=time.perf_counter() - tr)
        if c_r < c:
            X, c = X_r, c_r
    return c, X


#: the inputs of every start, for forked workers (:func:`optimise_excitation` with ``jobs > 1``): set just before
#: the pool forks and cleared after it, inherited by the children, never pickled (CasADi solvers do not pickle)
_FORKED: dict[str, Any] = {}


def _forked_start(s: int) -> tuple[float, np.ndarray, dict]:
    """Start ``s`` of :func:`optimise_excitation` in a forked worker: ``(cond, design, record)``."""
    f = _FORKED
    rec = dict(f["records"][s])
    c, X = f["run"](f["inits"][s], step=lambda k: None, rec=rec)
    return c, X, rec


def _worker_count(jobs: int | None, starts: int) -> int:
    """Processes for ``starts`` starts: ``jobs`` (0: one per CPU this process may use), at most one per
    start; 1 where processes cannot be forked (the starts' CasADi solvers cannot be sent to spawned ones)."""
    import multiprocessing as mp
    import os

    if jobs is not None and jobs < 0:
        raise ExcitationError(f"--jobs {jobs}: must be a number of processes >= 1, or 0 for one per CPU")
    if jobs is None or jobs == 1 or starts <= 1 or "fork" not in mp.get_all_start_methods():
        return 1
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(starts, cpus if jobs == 0 else jobs))


def optimise_excitation(model: IdentificationModel, basis, limits: Limits, duration: float, *, rate: float = 100.0,
                        criterion: str = "cond", starts: int = 4, seed: int = 0, chi_b=None,
                        samples: int | None = None, max_iter: int = 200, margin: float = 0.01,
                        pool: int | None = None, progress=None, powers=None, structured: int = 0,
                        initial=(), refine: int = 0, jobs: int | None = 1) -> ExcitationResult:
    """Optimise an excitation trajectory (IPOPT from ``starts`` seeded random feasible designs).

    Parameters
    ----------
    model : IdentificationModel
        With ``casadi_regressor()`` (a generated package).
    basis : FourierBasis or PointToPointBasis
    limits : Limits
    duration : float
        Length of the output trajectory [s] (for a Fourier design, a whole number of periods).
    rate : float
        Output sampling rate [Hz].
    criterion : {"cond", "logdet"}
        ``log tr(M) + log tr(M^-1)`` (bounds ``cond(W)^2`` within ``nb^2``) or ``-log det M``.
    starts, seed : int
        Random starts and the seed of their generator.
    pool : int, optional
        Random feasible designs drawn (default ``10 * starts``); the ``starts`` of lowest ``cond`` are
        the IPOPT starts (a multistart from the best of a random population, as FloBaRoID does).
    chi_b : array_like (nb,), optional
        Nominal base parameters: with ``limits.tau_max``, torque limits are imposed.
    samples : int, optional
        Samples of the criterion (default ``max(8 nb / n, 20 m)`` up to 200).
    max_iter : int
        IPOPT iterations per start.
    margin : float
        Fraction by which the limits are tightened in the optimisation (the output is checked
        against the full limits).
    powers : sequence of int, optional
        ``criterion="cond"``: the powers ``p`` of the smooth criterion run in turn from each start,
        each stage warm-started from the previous one (continuation; default :data:`COND_POWERS`),
        ``max_iter`` IPOPT iterations each.
    refine : int
        ``criterion="cond"``: at most this many iterations of :func:`refine_excitation` (sequential
        SDP on the true cond, trust region) applied to each start's IPOPT result; 0 skips it.
    progress : None, bool or callable
        Feedback (as in :func:`symoro_gen.progress.progress_updates`; None: a bar when the command line
        asks for one): one step per IPOPT stage and per SDP iteration of every start, the bar labelled
        with the starts done and the best cond so far.
    jobs : int, optional
        Processes the starts run in at once (forked workers, Linux; 0: one per CPU this process may use;
        default 1, in this process). The result is the same whatever ``jobs``: each start is computed alone
        from its own design, and the first start of the lowest cond is kept.

    Returns
    -------
    ExcitationResult
        The best start by the true unscaled ``cond`` over the output samples.
    """
    ca = _casadi()
    t0 = time.perf_counter()
    n, nb = limits.n, len(model.BASE_NAMES)
    if n != model.N_JOINTS:
        raise ExcitationError(f"{model.ROBOT}: limits for {n} joints, the model has {model.N_JOINTS}")
    if not (duration > 0 and rate > 0):
        raise ExcitationError("--duration and --rate must be positive")
    t_out = output_times(duration, rate)
    if len(t_out) * n < nb:
        raise ExcitationError(f"{model.ROBOT}: {len(t_out)} samples x {n} joints < {nb} base parameters; "
                              "increase --duration or --rate")
    if samples is None:
        samples = int(min(200, max(8 * nb // n + 1, 20 * basis.m, 40)))
    period = 2 * math.pi / basis.w if isinstance(basis, FourierBasis) else duration
    t_obj = np.arange(samples) * period / samples if isinstance(basis, FourierBasis) else np.linspace(0, duration, samples)
    nharm = basis.K if isinstance(basis, FourierBasis) else 8
    n_con = int(min(400, max(2 * samples, 40 * nharm)))
    t_con = np.linspace(0.0, period, n_con)
    cb = None if chi_b is None else np.asarray(chi_b, float)
    opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.max_iter": int(max_iter),
            "ipopt.hessian_approximation": "limited-memory", "ipopt.tol": 1e-6, "ipopt.acceptable_tol": 1e-4,
            "ipopt.sb": "yes"}
    stages = tuple(COND_POWERS if powers is None else powers) if criterion == "cond" else (COND_POWER,)
    solvers = []
    for p in stages:
        nlp, bounds = _build_nlp(model, basis, limits, t_obj, t_con, criterion, cb, margin, power=int(p))
        solvers.append(ca.nlpsol(f"excite_p{p}", "ipopt", nlp, opts))
    rng = np.random.default_rng(seed)
    lim_start = limits.shrunk(margin)
    best = None
    n_pool = max(int(starts), 10 * int(starts) if pool is None else int(pool))
    candidates: list[tuple[float, float, int, np.ndarray]] = []
    inits = [np.asarray(X, float) for X in initial]
    for i_pool in range(n_pool + int(structured) + len(inits)):
        if i_pool < len(inits):
            X_init = inits[i_pool]
        elif i_pool < len(inits) + int(structured):
            X_init = friction_trajectory(basis, lim_start, rng, t_con, duration)
        else:
            X_init = random_trajectory(basis, lim_start, rng, t_con)
        qdq = basis_eval(basis, X_init, t_out)
        Wc = np.asarray(model.regressor(*qdq)).reshape(-1, nb)
        sv = np.linalg.svd(Wc, compute_uv=False)
        # with torque limits, designs within them (the random ones are not held to them) rank first
        excess = 0.0
        if cb is not None and lim_start.tau_max is not None:
            tau0 = (Wc @ cb).reshape(-1, n)
            excess = max(0.0, float((np.abs(tau0) / lim_start.tau_max).max()) - 1.0)
        candidates.append((excess, float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf, len(candidates), X_init))
    candidates.sort(key=lambda c: (c[0], c[1], c[2]))
    n_refine = int(refine) if refine and criterion == "cond" else 0
    chosen = candidates[:int(starts)]
    records = [{"start": s, "cond_start": cond0, "powers": list(stages)} for s, (_, cond0, _, _) in enumerate(chosen)]
    run = functools.partial(_optimise_start, model, basis, limits, solvers, bounds, t_out=t_out, t_con=t_con,
                            period=period, duration=duration, margin=margin, cb=cb, refine=n_refine)
    outcome: list[tuple[float, np.ndarray] | None] = [None] * len(chosen)
    per_start = len(solvers) + n_refine
    counter = ProgressCounter(progress, total=len(chosen) * per_start, desc=f"excite {model.ROBOT}", unit="step")

    def label(what: str) -> str:
        got = [o[0] for o in outcome if o is not None]
        return f"excite {model.ROBOT}: {what}" + (f", best cond {min(got):.4g}" if got else "")

    try:
        n_jobs = _worker_count(jobs, len(chosen))
        if n_jobs > 1:
            import concurrent.futures as cf
            import multiprocessing as mp

            # forked workers inherit the CasADi solvers and the model (neither pickles); each returns its start
            _FORKED.update(run=run, inits=[X0 for *_, X0 in chosen], records=records)
            try:
                with cf.ProcessPoolExecutor(n_jobs, mp_context=mp.get_context("fork")) as pool_:
                    futures = {pool_.submit(_forked_start, s): s for s in range(len(chosen))}
                    counter.describe(label(f"{len(chosen)} starts in {n_jobs} processes"))
                    for k, fut in enumerate(cf.as_completed(futures), 1):
                        s = futures[fut]
                        c, X, records[s] = fut.result()
                        outcome[s] = (c, X)
                        counter.step(per_start)
                        counter.describe(label(f"{k}/{len(chosen)} starts done"))
            finally:
                _FORKED.clear()
        else:
            for s, (*_, X_init) in enumerate(chosen):
                counter.describe(label(f"start {s + 1}/{len(chosen)}"))
                outcome[s] = run(X_init, step=counter.step, rec=records[s])
    finally:
        counter.close()
    for o in outcome:  # the first of the lowest cond, whatever order the starts ended in
        if o is not None and (best is None or o[0] < best[0]):
            best = o
    assert best is not None
    cond, X = best
    q, dq, ddq = basis_eval(basis, X, t_out)
    tau = None if (cb is None or limits.tau_max is None) else np.asarray(model.regressor(q, dq, ddq)) @ cb
    chk = check_limits(limits, q, dq, ddq, tau)
    dq_d = basis_eval(basis, X, dense_times(t_out, duration, basis))
    chk_dense = check_limits(limits, *dq_d)
    return ExcitationResult(basis=basis, limits=limits, t=t_out, q=q, dq=dq, ddq=ddq, X=X, cond=cond,
                            limits_ok=bool(chk["ok"] and chk_dense["ok"]), usage=chk["usage"], criterion=criterion,
                            starts=records, wall_time=time.perf_counter() - t0, tau=tau)


def dense_times(t_out: np.ndarray, duration: float, basis=None) -> np.ndarray:
    """Ten times denser than the output samples (for the limit checks), with the knots of a spline basis
    (the acceleration of a cubic spline is piecewise linear: its extremes are at the knots)."""
    t = np.linspace(0.0, duration, 10 * (len(t_out) - 1) + 1)
    knots = getattr(basis, "knots", None)
    return t if knots is None else np.union1d(t, np.clip(knots, 0.0, duration))


def _inside(basis, limits: Limits, X: np.ndarray, t: np.ndarray) -> bool:
    return bool(check_limits(limits, *basis_eval(basis, X, t))["ok"])


def basis_eval(basis, X: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``q, dq, ddq`` (N, n) of the design ``X`` at times ``t``."""
    P, D, A = basis.matrices(t)
    return P @ X, D @ X, A @ X


def write_trajectory_csv(path, t, q, dq, ddq, *, force: bool = False) -> None:
    """CSV with header ``t,q1..qn,dq1..dqn,ddq1..ddqn`` (SI units, full precision). An existing file is
    replaced only when it is such a trajectory (the header marks it), unless ``force``."""
    n = q.shape[1]
    head = ["t"] + [f"q{j}" for j in range(1, n + 1)] + [f"dq{j}" for j in range(1, n + 1)] + [f"ddq{j}" for j in range(1, n + 1)]
    data = np.column_stack([t, q, dq, ddq])
    lines = [",".join(head)] + [",".join(f"{v:.17g}" for v in row) for row in data]
    write_output_text(path, "\n".join(lines) + "\n", force=force)


# ---------------------------------------------------------------------------------------------
def joint_numbers(model: IdentificationModel) -> tuple[int, ...]:
    """The robot joint of each design column ``q1..qn``: ``1..n``, or a closed-loop robot's actuated joints
    (``q3`` of a palletizer design is its joint 4)."""
    return tuple(getattr(model, "ACTUATED_JOINTS", range(1, int(model.N_JOINTS) + 1)))


def _joint_label(j: int, joints: tuple[int, ...] | None) -> str:
    """``"q<j+1>"`` and, when it is another robot joint, ``" (joint k)"``: the suffix of ``q, dq, ddq``."""
    k = j + 1 if joints is None else joints[j]
    return f"{j + 1}" + (f" (joint {k})" if k != j + 1 else "")


def passive_ranges(model: IdentificationModel, q: np.ndarray) -> dict[int, tuple[float, float]]:
    """``{joint: (min, max)}`` of the passive joints of a closed-loop robot over the design's positions ``q``
    (from the loop closure; the design's limits constrain the actuated joints only); ``{}`` for an open one."""
    closed: Any = model  # a ClosedLoopModel (IdentificationModel does not declare its closure)
    if not hasattr(closed, "closure"):
        return {}
    act = set(joint_numbers(model))
    z = np.zeros_like(q)
    qt = closed.closure(q, z, z).q
    joints = list(closed.kinematics.tree_joints)
    return {j: (float(qt[:, c].min()), float(qt[:, c].max())) for c, j in enumerate(joints) if j not in act}


def _floor_text(ws: Workspace, q: np.ndarray) -> str:
    """One sentence: the floor and the lowest height each moving frame origin reaches (m, base frame)."""
    low = ws.heights(q).min(0)
    return (f"floor z >= {ws.z_min:g} m (base frame): lowest frame origins " +
            ", ".join(f"{j}: {z:.3f}" for j, z in zip(ws.frames, low)) + " m")


def _passive_text(model: IdentificationModel, passive: dict[int, tuple[float, float]], limits: Limits) -> str:
    """One sentence: which robot joints the design's columns are, and the passive joints' ranges against
    their ``[limits]`` ranges when given (deg or m)."""
    given = {p.joint: (p.lo, p.hi) for p in limits.passive}
    robot = getattr(model, "robot")  # noqa: B009 - a ClosedLoopModel's (IdentificationModel does not declare it)

    def rng(j: int, lo: float, hi: float) -> str:
        f, u, d = (1.0, "m", 4) if robot.row(j).sigma == 1 else (180.0 / math.pi, "deg", 1)
        lim = f" (limits {f * given[j][0]:.{d}f} .. {f * given[j][1]:.{d}f})" if j in given else ""
        return f"joint {j} {f * lo:.{d}f} .. {f * hi:.{d}f} {u}{lim}"
    joints = joint_numbers(model)
    free = "" if given else " ([limits] has no passive_q_min/passive_q_max: not constrained)"
    return (f"closed loop: q1..q{len(joints)} are the actuated joints {', '.join(map(str, joints))}; the passive "
            f"joints move over " + ", ".join(rng(j, *r) for j, r in passive.items()) + free)


def plot_trajectory(result: ExcitationResult, path, *, robot: str = "", joints: tuple[int, ...] | None = None,
                    force: bool = False) -> None:
    """PNG file of every joint's ``q, dq, ddq`` against its limits (dashed), titled with the robot, the
    kind of design and its cond (written atomically; an existing PNG symoro-gen did not write is replaced
    only with ``force``); ``joints``: :func:`joint_numbers` for the labels."""
    title = (f"{robot + ': ' if robot else ''}{result.basis.kind} excitation, cond = {result.cond:.4g}, limits "
             f"{'respected' if result.limits_ok else 'VIOLATED'}")
    write_output_bytes(path, trajectory_figure_png(result, dpi=90, title=title, joints=joints), force=force)


def trajectory_figure_png(result: ExcitationResult, *, dpi: int = 80, max_points: int = 2000, title: str = "",
                          joints: tuple[int, ...] | None = None) -> bytes:
    """PNG (report style) of every joint's ``q, dq, ddq`` against its limits (dashed red), in deg or m;
    ``joints``: the robot joint of each column (:func:`joint_numbers`), named in the labels when it differs."""

    MplFigure, FigureCanvasAgg = require_matplotlib()
    lim, n = result.limits, result.limits.n
    ws = lim.workspace
    # a closed-loop robot's passive joints: one more row each (position only); a floor: one row of frame heights
    rows = n + len(lim.passive) + (ws is not None)
    base, head = 1.5 * rows + 0.9, (0.35 if title else 0.0)  # inches: the grid of axes, the title above it
    fig = MplFigure(figsize=(WIDTH_IN, base + head), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 3, squeeze=False, sharex=True)
    k = max(1, len(result.t) // max(max_points, 1))
    t = result.t[::k]
    passive = lim.passive_positions(result.q[::k])
    for i, p in enumerate(lim.passive):
        f, u = (1.0, "m") if p.prismatic else (180.0 / math.pi, "deg")
        ax = axes[n + i, 0]
        ax.plot(t, f * passive[:, i], lw=1, color="C1")
        for v in (p.lo, p.hi):
            ax.axhline(f * v, color="r", ls="--", lw=0.8)
        ax.set_ylabel(f"joint {p.joint}, passive [{u}]", fontsize=8)
        ax.tick_params(labelsize=7)
        for c in (1, 2):
            axes[n + i, c].set_visible(False)
    if ws is not None:
        ax = axes[-1, 0]
        for f, z in zip(ws.frames, ws.heights(result.q[::k]).T):
            ax.plot(t, z, lw=0.8, label=f"{f}")
        ax.axhline(ws.z_min, color="r", ls="--", lw=0.8)
        ax.set_ylabel("frame origins z [m]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6, ncol=2, loc="upper left", bbox_to_anchor=(1.02, 1.0), title="frame", title_fontsize=6)
        for c in (1, 2):
            axes[-1, c].set_visible(False)
    for j in range(n):
        f, u = (1.0, "m") if lim.is_prismatic(j) else (180.0 / math.pi, "deg")
        jl = _joint_label(j, joints)
        panels = ((f * result.q[::k, j], f * lim.q_min[j], f * lim.q_max[j], f"q{jl} [{u}]"),
                  (f * result.dq[::k, j], -f * lim.dq_max[j], f * lim.dq_max[j], f"dq{jl} [{u}/s]"),
                  (f * result.ddq[::k, j], -f * lim.ddq_max[j], f * lim.ddq_max[j], f"ddq{jl} [{u}/s2]"))
        for c, (y, lo, hi, lab) in enumerate(panels):
            ax = axes[j, c]
            ax.plot(t, y, lw=1)
            for v in (lo, hi):
                ax.axhline(v, color="r", ls="--", lw=0.8)
            ax.set_ylabel(lab, fontsize=8)
            ax.tick_params(labelsize=7)
    extra = rows > n
    for c in range(3):
        axes[n - 1 if c and extra else -1, c].set_xlabel("t [s]", fontsize=8)
        if c and extra:
            axes[n - 1, c].tick_params(labelbottom=True)
    if title:
        fig.suptitle(title, fontsize=9, y=1 - 0.12 / (base + head))
    fig.subplots_adjust(left=0.07, right=0.99, top=1 - (0.03 * base + head) / (base + head), bottom=0.5 / (base + head),
                        wspace=0.3, hspace=0.25)
    return _png(fig, dpi)


def excitation_report(result: ExcitationResult, model: IdentificationModel, *, noise: float, chi_b=None,
                      title: str | None = None, plots: bool = True):
    """:class:`~symoro_gen.report.Report` of an excitation design: the figures, the joint
    trajectories against the limits, the peak use of every limit, and the predicted standard
    deviation (and %sigma with nominal base parameters) of every base parameter for i.i.d. torque
    noise ``noise`` (:func:`predicted_sigma`, Gautier 1997 eq. 9)."""

    lim, n = result.limits, result.limits.n
    sig, pct = predicted_sigma(model, result.q, result.dq, result.ddq, noise, chi_b)
    worst = max(max(v) for v in result.usage.values())
    blocks: list = [Paragraph(
        f"{model.ROBOT}: {result.basis.kind} excitation, {len(result.t)} samples over {result.t[-1]:g} s; "
        f"criterion {result.criterion}; cond = {result.cond:.6g} (2-norm condition number of the base regressor "
        f"stacked over the output samples, unscaled); limits {'respected' if result.limits_ok else 'VIOLATED'} "
        f"at every output sample and on a 10x denser resampling (peak usage {worst:.3f}); "
        f"{len(result.starts)} IPOPT start(s), {result.wall_time:.1f} s.")]
    if lim.defaulted:
        blocks.append(Paragraph(f"The robot file gives no {', '.join(lim.defaulted)} in [limits]: the design used "
                                f"{lim.defaulted_text()}."))
    joints = joint_numbers(model)
    passive = passive_ranges(model, result.q)
    if passive:
        blocks.append(Paragraph(_passive_text(model, passive, lim)))
    if lim.workspace is not None:
        blocks.append(Paragraph(_floor_text(lim.workspace, result.q) + " (frame origins only: the links' extent is "
                                "the clearance given in --z-min)"))
    blocks.append(Heading("Joint trajectories against the limits"))
    if plots:
        blocks.append(Figure("trajectory", trajectory_figure_png(result, joints=joints),
                             caption="q, dq, ddq per joint (rows) against the limits (dashed red)"
                                     + ("; below, the passive joints' positions (closed loop)" if lim.passive else "")
                                     + ("; last, the height of every moving frame origin above the floor (dashed)"
                                        if lim.workspace is not None else "")))
    rows = []
    for j in range(n):
        f, u, d = (1.0, "m", 4) if lim.is_prismatic(j) else (180.0 / math.pi, "deg", 1)
        rows.append((_joint_label(j, joints), f"{f * result.q[:, j].min():.{d}f} .. {f * result.q[:, j].max():.{d}f} {u}",
                     f"{f * lim.q_min[j]:.{d}f} .. {f * lim.q_max[j]:.{d}f} {u}",
                     *(f"{result.usage[k][j]:.3f}" for k in ("q", "dq", "ddq")),
                     f"{result.usage['tau'][j]:.3f}" if "tau" in result.usage else "-"))
    qp = lim.passive_positions(result.q)
    for i, pr in enumerate(lim.passive):
        f, u, d = (1.0, "m", 4) if pr.prismatic else (180.0 / math.pi, "deg", 1)
        rows.append((f"joint {pr.joint} (passive)", f"{f * qp[:, i].min():.{d}f} .. {f * qp[:, i].max():.{d}f} {u}",
                     f"{f * pr.lo:.{d}f} .. {f * pr.hi:.{d}f} {u}", f"{result.usage['passive'][i]:.3f}", "-", "-", "-"))
    blocks.append(Table(("joint", "q range", "limits", "use q", "use dq", "use ddq", "use tau"),
                        tuple(rows), caption="Peak use of each limit (1 = at the limit; q about the range centre)"))
    blocks.append(Heading("Predicted precision of the base parameters"))
    cb = None if chi_b is None else np.asarray(chi_b, float)
    prow = []
    for i, name in enumerate(model.BASE_NAMES):
        nominal = "-" if cb is None else f"{cb[i]:.4g}"
        p = "-" if pct is None or not np.isfinite(pct[i]) else f"{pct[i]:.3g}"
        prow.append((name, nominal, f"{sig[i]:.4g}", p))
    blocks.append(Table(("parameter", "nominal", "sigma", "%sigma"), tuple(prow),
                        caption=f"sigma = noise sqrt(diag((W'W)^-1)) for torque noise {noise:g} N m "
                                f"(Gautier 1997 eq. 9); %sigma = 100 sigma / |nominal|"))
    if result.starts:
        blocks.append(Heading("Starts"))
        blocks.append(Table(("start", "cond at start", "cond optimised", "IPOPT status", "iterations"),
                            tuple((str(st["start"]), f"{st['cond_start']:.4g}", f"{st['cond']:.4g}", str(st["status"]),
                                   str(st["iterations"])) for st in result.starts),
                            caption="Random feasible starts (best of the pool) and IPOPT's result from each"))
    return Report(title or f"Excitation trajectory: {model.ROBOT}", tuple(blocks), footer=f"symoro_gen {__version__}")


def _has_cvxpy() -> bool:
    import importlib.util

    return importlib.util.find_spec("cvxpy") is not None and importlib.util.find_spec("clarabel") is not None


def add_excite_parser(sub) -> None:
    """Register ``symoro-gen excite``."""
    e = sub.add_parser("excite", help="optimal excitation trajectory (Fourier or point-to-point) -> CSV t,q,dq,ddq")
    e.add_argument("robot", help="robot name, robot .toml file (its [limits] are used) or generated package")
    e.add_argument("-o", "--output", required=True, help="CSV to write (header t,q1..qn,dq1..dqn,ddq1..ddqn)")
    e.add_argument("--kind", choices=("fourier", "p2p", "spline"), default="fourier",
                   help="Fourier series, point-to-point via-points, or a cubic B-spline (rest at both ends)")
    e.add_argument("--duration", type=float, default=10.0, help="seconds (Fourier: whole periods of the base frequency)")
    e.add_argument("--harmonics", type=int, default=5, help="Fourier harmonics per joint (>= 2)")
    e.add_argument("--base-frequency", type=float, default=None, help="Fourier base frequency [Hz] (default 1/duration)")
    e.add_argument("--via-points", type=int, default=8, help="p2p: via-points including start and end")
    e.add_argument("--coefficients", type=int, default=None,
                   help="spline: control points per joint (default 6 per second of --duration, at least 7)")
    e.add_argument("--structured-starts", type=int, default=0,
                   help="also draw this many designs whose joints alternate slow motion and bursts at the "
                        "velocity limit (the friction columns' optimum) into the pool of starts")
    e.add_argument("--dwell", type=float, default=0.0, help="p2p: rest at each intermediate via-point [s]")
    e.add_argument("--rate", type=float, default=100.0, help="output sampling rate [Hz]")
    e.add_argument("--seed", type=int, default=0)
    e.add_argument("--starts", type=int, default=4, help="random starts of IPOPT")
    e.add_argument("--pool", type=int, default=None,
                   help="random feasible designs drawn; the --starts best by cond start IPOPT (default 10 x --starts)")
    e.add_argument("--jobs", type=int, default=1,
                   help="run the starts in this many processes at once (0: one per CPU; Linux); the result is the same")
    e.add_argument("--max-iter", type=int, default=200, help="IPOPT iterations per start")
    e.add_argument("--samples", type=int, default=None, help="samples of the criterion (default from the size of the problem)")
    e.add_argument("--criterion", choices=("cond", "logdet"), default="cond")
    e.add_argument("--refine", type=int, default=None, metavar="N",
                   help="cond criterion: then at most N sequential-SDP iterations on the true cond (cvxpy + Clarabel, "
                        f"trust region) from each start's IPOPT result (default {REFINE_ITERATIONS} when cvxpy is "
                        "installed, the 'physical' extra; 0 skips it)")
    e.add_argument("--noise", type=float, default=1.0, help="torque-noise standard deviation for the predicted %%sigma [N m]")
    e.add_argument("--no-torque-limits", action="store_true", help="ignore tau_max even with nominal parameters")
    e.add_argument("--z-min", type=float, default=None, metavar="Z",
                   help="floor or table plane: every moving frame origin stays at z >= Z [m] in the base frame 0 "
                        "(add the links' radius as clearance)")
    e.add_argument("--json", help="write the figures (cond, limits_ok, predicted sigma...) as JSON here")
    e.add_argument("--plot", help="PNG of the joint trajectories against the limits")
    e.add_argument("--report", help="report (.html self-contained, or .md with its images beside it): trajectories "
                                    "against the limits, cond, limit usage, predicted %%sigma at --noise")
    e.add_argument("--force", action="store_true", help=FORCE_HELP)
    e.set_defaults(func=cmd_excite)


def cmd_excite(args) -> int:
    """``symoro-gen excite``: design, write CSV (and JSON, plot), print a summary."""

    if args.report:
        check_report_path(args.report)  # before the long optimisation
    if args.plot or args.report:
        require_matplotlib()  # the same: a missing extra is said before minutes of optimisation, not after
    robot, model = model_for(args.robot)
    n = model.N_JOINTS
    lim = limits_of(robot, n, model)
    if args.z_min is not None:
        lim = with_floor(lim, robot, model, args.z_min)
    if args.duration <= 0 or args.rate <= 0:
        raise ExcitationError("--duration and --rate must be positive")
    refine_note = None
    if args.refine is None:
        args.refine = REFINE_ITERATIONS if _has_cvxpy() else 0
        if not args.refine:
            refine_note = ("note: cvxpy is not installed, the SDP refinement of the true cond was skipped "
                           "(pip install 'symoro-gen[physical]')")
    if args.refine < 0:
        raise ExcitationError(f"--refine {args.refine}: must be a number of iterations >= 0")
    _worker_count(args.jobs, 1)  # a negative --jobs is said now, not after the pool of starts
    if args.refine and not _has_cvxpy():
        raise ExcitationError(f"--refine {args.refine} needs cvxpy and clarabel: pip install 'symoro-gen[physical]' "
                              "(or --refine 0)")
    if args.kind == "fourier":
        f = args.base_frequency or 1.0 / args.duration
        periods = args.duration * f
        if abs(periods - round(periods)) > 1e-6 or round(periods) < 1:
            raise ExcitationError(f"--duration {args.duration:g} is not a whole number of periods of "
                                  f"--base-frequency {f:g} Hz (the trajectory would not end at rest)")
        basis: Any = FourierBasis(args.harmonics, f)
    elif args.kind == "spline":
        basis = SplineBasis(args.coefficients or max(7, round(6 * args.duration)), args.duration)
    else:
        seg = (args.duration + args.dwell) / (args.via_points - 1) - args.dwell if args.via_points >= 2 else 1.0
        if seg <= 0:
            raise ExcitationError(f"--duration {args.duration:g} too short for {args.via_points} via-points with --dwell {args.dwell:g}")
        basis = PointToPointBasis(args.via_points, seg, args.dwell)
    chi_b = None
    nominal = robot.nominal_vector()
    if nominal is not None:
        chi_b = np.asarray(model.base_parameters(np.asarray(nominal)), float)
    res = optimise_excitation(model, basis, lim, args.duration, rate=args.rate, criterion=args.criterion,
                              starts=args.starts, seed=args.seed, max_iter=args.max_iter, samples=args.samples,
                              pool=args.pool, structured=args.structured_starts, refine=args.refine, jobs=args.jobs,
                              chi_b=None if args.no_torque_limits else chi_b)
    force = getattr(args, "force", False)
    write_trajectory_csv(args.output, res.t, res.q, res.dq, res.ddq, force=force)
    sig, pct = predicted_sigma(model, res.q, res.dq, res.ddq, args.noise, chi_b)
    passive = passive_ranges(model, res.q)
    out = {
        "robot": model.ROBOT, "kind": basis.kind, "criterion": res.criterion, "cond": res.cond,
        "limits_ok": res.limits_ok, "duration": args.duration, "rate": args.rate, "samples": len(res.t),
        "seed": args.seed, "limits": lim.as_dict(), "usage": res.usage,
        "torque_limits": bool(chi_b is not None and lim.tau_max is not None and not args.no_torque_limits),
        "noise": args.noise, "base_names": list(model.BASE_NAMES), "sigma": sig.tolist(),
        "sigma_pct": None if pct is None else [None if not np.isfinite(v) else float(v) for v in pct],
        "starts": res.starts, "wall_time": res.wall_time, "design": basis.coefficients(res.X),
        "joints": list(joint_numbers(model)),
        "workspace": None if lim.workspace is None else {
            "z_min": lim.workspace.z_min, "frames": list(lim.workspace.frames),
            "lowest_z": lim.workspace.heights(res.q).min(0).tolist()},
        "passive_ranges": {str(j): list(r) for j, r in passive.items()},
    }
    if args.json:
        write_output_text(args.json, json_output(out, "excite"), force=force)
    if args.plot:
        plot_trajectory(res, args.plot, robot=model.ROBOT, joints=joint_numbers(model), force=force)
    if args.report:
        write_report_files(excitation_report(res, model, noise=args.noise, chi_b=chi_b), args.report, force=force)
    if not args.quiet:
        worst = max(max(v) for v in res.usage.values())
        print(f"{model.ROBOT}: {basis.kind} excitation, {len(res.t)} samples at {args.rate:g} Hz -> {args.output}")
        print(f"cond = {res.cond:.6g} (base regressor, unscaled; random starts: "
              f"{', '.join(format(s['cond_start'], '.4g') for s in res.starts)}); limits_ok = {res.limits_ok} "
              f"(peak usage {worst:.3f}); {res.wall_time:.1f} s")
        refined = [st for st in res.starts if "refine_sdps" in st]
        if refined:
            print("SDP refinement of the true cond: " + "; ".join(
                f"{st['cond_ipopt']:.4g} -> {st['cond']:.4g} ({st['refine_accepted']} of {st['refine_sdps']} steps)"
                for st in refined))
        if refine_note:
            print(refine_note)
        if passive:
            print(_passive_text(model, passive, lim))
        if lim.workspace is not None:
            print(_floor_text(lim.workspace, res.q))
        if lim.defaulted:
            print(f"note: the robot file has no {', '.join(lim.defaulted)} in [limits]; used {lim.defaulted_text()} "
                  "(give them in [limits] if the robot's differ)")
    return 0 if res.limits_ok else 3

def _sympy_casadi(qa: tuple, exprs: list, q) -> Any:
    """The sympy expressions ``exprs`` in the symbols ``qa`` as one CasADi column in ``q`` (SX)."""
    ca = _casadi()
    vals = sp.lambdify([qa], exprs, modules=[{"sin": ca.sin, "cos": ca.cos}])([q[k] for k in range(len(qa))])
    return ca.vertcat(*[v if isinstance(v, ca.SX) else ca.SX(float(v)) for v in vals])
