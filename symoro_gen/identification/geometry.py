"""Geometric parameters identified with the dynamic ones: the joint zeros (``identify --geometry joint_zero``).

An encoder whose zero is off by ``q0_j`` reads ``q_j = q_true,j - q0_j``; the torque the arm transmits is that of
the true angle, ``tau = Y_std(q + q0, dq, ddq) chi`` (velocities and accelerations, derivatives of the angle,
are unchanged). ``tau`` is linear in the dynamic parameters ``chi`` and not in the geometry, so the zeros are
found by Gauss-Newton on the IDIM equations ``Y = W(q + q0) chi`` alternating with the linear fit of ``chi`` at
the corrected geometry (the base-parameter regrouping depends on the geometry): the sensitivity
``d (W chi) / d q0_j`` is taken at the current estimate ``chi``, the linearised system ``[W, D] [d chi; d q0]``
solved, and the two repeated until the step of every zero is below a fraction of its standard deviation
(Khalil & Dombre 2002, *Modeling, Identification and Control of Robots*, ch. 11: the calibration model linearised
in the parameter errors, solved iteratively; Hollerbach & Wampler 1996, "The calibration index and taxonomy for
robot kinematic calibration methods", IJRR 15(6): joint offsets are among the parameters of every calibration
model; statistics of the last linearisation as the OLS ones, Gautier 1990, ``sigma^2 (A^T A)^-1``).

Which zeros torque data can see (:func:`zero_identifiability`): a zero is seen only through the
configuration-dependent torque (gravity, inertial coupling). The first joint of an arm whose axis 1 is along
gravity changes nothing (its column is 0); the last joint of a chain only rotates its link's inertial
parameters, which the base parameters absorb (its column is in the span of the base regressor). Those are
reported as not identifiable, never fitted.

The corrected robot file (:func:`corrected_robot_text`): the fitted zeros added to the constant part of the
frames' ``theta`` (revolute) or ``r`` (prismatic): ``theta = "q"`` becomes ``theta = "q + q0"``, the rest of the
file unchanged, with a header comment naming the file it came from.
"""
from __future__ import annotations

import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from dataclasses import replace as dc_replace
from functools import partial
from typing import Any

import numpy as np

from ..description.rewrite import RobotText, format_number
from ..dynamics.numeric import inverse_dynamics, numeric_regressor
from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.raw import full_rate_torque
from ..observations.system import ObservationSystem
from .systems import stack_systems

__all__ = ["GEOMETRY_KINDS", "JOINT_ZERO_STEP", "LENGTH_FIELDS", "length_sensitivity", "length_visibility", "perturbed_robot", "STEP_FRACTION", "VISIBILITY_TOL", "GeometryFit", "ZeroVisibility",
           "add_zeros", "corrected_robot_text", "fit_zeros", "joint_zero_column", "joint_zero_secant", "joint_zero_visibility",
           "regressor_secant", "revolute_joints", "shift_zeros", "visible_zero_joints", "zero_identifiability",
           "zero_shares"]

#: the geometric parameters ``identify --geometry`` can fit
GEOMETRY_KINDS = ("joint_zero",)
#: beyond this a fitted zero is no encoder zero error (the loop's prior, ``diagnostics/plausibility.py``: an
#: offset of a few degrees is typical, tens of degrees impossible): reported as implausible
MAX_ZERO_DEG = 20.0
#: the Gauss-Newton iterations stop when every zero's step is below this fraction of its standard deviation
STEP_FRACTION = 0.01
#: halvings of a Gauss-Newton step that does not lower the weighted residual before the iterations stop
MAX_HALVINGS = 5
#: step [rad or m] of the central difference of the assembled prediction in a joint zero (the assembly's filters
#: pass a constant shift of q unchanged, so the difference is that of the regressor at the filtered angles)
ASSEMBLY_STEP = 1e-5

#: step [rad or m] of the central difference of the torque in the joint angle
JOINT_ZERO_STEP = 1e-6
#: a joint zero is invisible when the share of its column's norm outside the span of the regressor (on random
#: configurations and random parameters) is below this
VISIBILITY_TOL = 1e-6


def _torque(model: IdentificationModel, theta: Mapping[str, float], q, dq, ddq, loaded) -> np.ndarray:
    """Model torque of the fit ``theta`` (Coulomb terms left out: they do not depend on the angle), the loaded
    samples (boolean mask or None) with the payload columns."""
    out = full_rate_torque(model, theta, q, dq, ddq, False, skip_prefix=("FS",))
    if loaded is not None and np.any(loaded):
        out[loaded] = full_rate_torque(model, theta, q[loaded], dq[loaded], ddq[loaded], True, skip_prefix=("FS",))
    return out


def joint_zero_secant(model: IdentificationModel, theta: Mapping[str, float], q, dq, ddq, j: int, c: float,
                      loaded=None) -> np.ndarray:
    """``(tau(q + c e_j) - tau(q)) / c`` of the model of ``theta`` on every joint (shape (N, n)): the torque error of
    a zero offset ``c`` of joint j per unit offset; ``c = 0`` gives the tangent ``d tau / d q_j`` (central
    difference, step :data:`JOINT_ZERO_STEP`). With the coefficient equal to ``c`` (the loop's fixed point) the
    column times the coefficient is the exact torque change ``tau(q + c e_j) - tau(q)``."""
    q = np.asarray(q, float)
    dq, ddq = np.asarray(dq, float), np.asarray(ddq, float)

    def shifted(s: float) -> np.ndarray:
        a = q.copy()
        a[:, j] += s
        return _torque(model, theta, a, dq, ddq, loaded)

    if c == 0.0:
        h = JOINT_ZERO_STEP
        return (shifted(h) - shifted(-h)) / (2 * h)
    return (shifted(c) - _torque(model, theta, q, dq, ddq, loaded)) / c


def joint_zero_column(model: IdentificationModel, theta: Mapping[str, float], q, dq, ddq, j: int,
                      loaded=None) -> np.ndarray:
    """The tangent ``d tau / d q0_j`` (shape (N, n), every joint's torque): see :func:`joint_zero_secant`."""
    return joint_zero_secant(model, theta, q, dq, ddq, j, 0.0, loaded)


def regressor_secant(model: IdentificationModel, q, dq, ddq, j: int, c: float, loaded: bool = False) -> np.ndarray:
    """``(W(q + c e_j) - W(q)) / c`` of the base regressor (with the payload columns after the base ones when
    ``loaded``), shape (N, n, p); ``c = 0``: the tangent ``d W / d q_j`` (central difference, step
    :data:`JOINT_ZERO_STEP`). Independent of the parameters: the joint zero column of a fit ``chi`` is this
    times ``chi`` (the regrouping of the base parameters does not depend on the angle)."""
    q = np.asarray(q, float)

    def reg(s: float) -> np.ndarray:
        a = q.copy()
        a[:, j] += s
        W = np.asarray(model.regressor(a, dq, ddq), float)
        if loaded and tuple(getattr(model, "PAYLOAD_NAMES", ())):
            W = np.concatenate([W, np.asarray(model.payload_regressor(a, dq, ddq), float)], axis=2)
        return W

    if c == 0.0:
        h = JOINT_ZERO_STEP
        return (reg(h) - reg(-h)) / (2 * h)
    return (reg(c) - reg(0.0)) / c


def _random_motion(n: int, m: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    q = rng.uniform(-np.pi, np.pi, size=(m, n))
    return q, rng.standard_normal((m, n)), rng.standard_normal((m, n))


def revolute_joints(model: IdentificationModel, *, rng: np.random.Generator | None = None,
                    n_samples: int = 8) -> np.ndarray:
    """Per joint, whether its variable is an angle: the regressor is ``2 pi``-periodic in it (a prismatic joint's
    length enters it polynomially). A joint the regressor does not depend on counts as revolute."""
    rng = np.random.default_rng(0) if rng is None else rng
    n = int(model.N_JOINTS)
    q, dq, ddq = _random_motion(n, n_samples, rng)
    W0 = np.asarray(model.regressor(q, dq, ddq), float)
    scale = max(float(np.abs(W0).max()), 1e-300)
    out = np.ones(n, bool)
    for j in range(n):
        a = q.copy()
        a[:, j] += 2 * np.pi
        out[j] = float(np.abs(np.asarray(model.regressor(a, dq, ddq), float) - W0).max()) <= 1e-8 * scale
    return out


def zero_shares(model: IdentificationModel, *, rng: np.random.Generator | None = None, n_samples: int = 40,
                n_theta: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Per joint, the share of the joint zero column's norm that no base-parameter change can produce (see
    :func:`joint_zero_visibility`), and whether the column is identically 0 (no configuration-dependent
    torque changes with the angle) rather than in the span of the base regressor (absorbed)."""
    rng = np.random.default_rng(0) if rng is None else rng
    n = int(model.N_JOINTS)
    names = tuple(model.BASE_NAMES)
    q, dq, ddq = _random_motion(n, n_samples, rng)
    W = np.asarray(model.regressor(q, dq, ddq), float).reshape(n_samples * n, len(names))
    U, s, _ = np.linalg.svd(W, full_matrices=False)
    U = U[:, s > s[0] * 1e-10] if s.size and s[0] > 0 else U[:, :0]
    thetas = [dict(zip(names, rng.standard_normal(len(names)))) for _ in range(n_theta)]
    out = np.zeros(n)
    zero = np.zeros(n, bool)
    for j in range(n):
        shares = []
        zeros = []
        for th in thetas:
            col = joint_zero_column(model, th, q, dq, ddq, j).reshape(-1)
            ref = float(np.linalg.norm(full_rate_torque(model, th, q, dq, ddq, False, skip_prefix=("FS",))))
            nc = float(np.linalg.norm(col))
            if nc <= 1e-9 * max(ref, 1e-300):
                shares.append(0.0)
                zeros.append(True)
                continue
            r = col - U @ (U.T @ col)
            shares.append(float(np.linalg.norm(r)) / nc)
            zeros.append(False)
        out[j] = min(shares)
        zero[j] = all(zeros)
    return out, zero


def joint_zero_visibility(model: IdentificationModel, *, rng: np.random.Generator | None = None,
                          n_samples: int = 40, n_theta: int = 3) -> np.ndarray:
    """Per joint, the share of the joint zero column's norm that no base-parameter change can produce: the
    relative norm of its residual after projection on the span of the base regressor, over ``n_samples`` random
    configurations (angles in [-pi, pi], standard normal velocities and accelerations), the smallest over
    ``n_theta`` random base-parameter vectors (a column identically 0 counts 0). 0 (below
    :data:`VISIBILITY_TOL`): torque data cannot see the zero of this joint whatever the parameters (the first
    joint about a vertical axis, the last joint of a chain: its offset rotates only its own link's inertia, which
    the base parameters absorb)."""
    return zero_shares(model, rng=rng, n_samples=n_samples, n_theta=n_theta)[0]


_VISIBILITY: dict = {}   # id(model) -> (model, shares): the default measure of a generated model, computed once


def visible_zero_joints(model: IdentificationModel, *, tol: float = VISIBILITY_TOL,
                        rng: np.random.Generator | None = None) -> tuple[int, ...]:
    """0-based joints whose zero offset torque data can see (:func:`joint_zero_visibility` above ``tol``)."""
    if rng is None:
        got = _VISIBILITY.get(id(model))
        if got is None or got[0] is not model:
            got = (model, joint_zero_visibility(model))
            _VISIBILITY[id(model)] = got
        share = got[1]
    else:
        share = joint_zero_visibility(model, rng=rng)
    return tuple(int(j) for j in np.flatnonzero(share > tol))


# ------------------------------------------------------------------------------------------------
# which zeros torque data can see, per robot
# ------------------------------------------------------------------------------------------------
ZERO_COLUMN_REASON = ("no configuration-dependent torque changes with its angle (the sensitivity column "
                      "d tau/d q0 is 0: e.g. a first joint about the gravity axis)")
ABSORBED_REASON = ("the base parameters absorb it (the sensitivity column lies in the span of the base regressor: "
                   "e.g. the last joint of a chain, whose offset only rotates its own link's inertia)")


@dataclass(frozen=True)
class ZeroVisibility:
    """Whether torque data can see the zero of one joint.

    Attributes
    ----------
    joint : int
        0-based joint.
    share : float
        Share of the sensitivity column's norm outside the span of the base regressor (:func:`zero_shares`).
    visible : bool
        ``share`` above :data:`VISIBILITY_TOL`.
    reason : str
        Why not (empty when visible).
    """

    joint: int
    share: float
    visible: bool
    reason: str = ""

    def to_dict(self) -> dict:
        return {"joint": self.joint + 1, "share_outside_base": float(self.share), "identifiable": self.visible,
                "reason": self.reason or None}


def zero_identifiability(model: IdentificationModel, *, tol: float = VISIBILITY_TOL) -> tuple[ZeroVisibility, ...]:
    """Per joint, whether torque data can see its zero, and why not (:func:`zero_shares` on random
    configurations and parameters of the generated model)."""
    share, zero = zero_shares(model)
    out = []
    for j in range(int(model.N_JOINTS)):
        vis = bool(share[j] > tol)
        why = "" if vis else (ZERO_COLUMN_REASON if zero[j] else ABSORBED_REASON)
        out.append(ZeroVisibility(joint=j, share=float(share[j]), visible=vis, reason=why))
    return tuple(out)


def identifiability_text(vis: Sequence[ZeroVisibility], robot: str) -> str:
    """The identifiability printout: which joints' zeros torque data can see, why the others not."""
    seen = [v.joint + 1 for v in vis if v.visible]
    lines = [f"Joint zeros of {robot} seen by torque data (gravity and inertial effects): "
             + (", ".join(f"joint {j}" for j in seen) if seen else "none")]
    for v in vis:
        if not v.visible:
            lines.append(f"  joint {v.joint + 1}: not identifiable, {v.reason}")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------
# Gauss-Newton on the zeros, alternating with the linear fit of chi
# ------------------------------------------------------------------------------------------------
def shift_zeros(trajectories: Sequence[Any], joints: Sequence[int], offsets: Sequence[float] | np.ndarray) -> tuple[Any, ...]:
    """The recordings at the corrected angles ``q + q0`` (``q0`` on ``joints``, 0-based)."""
    out = []
    for tr in trajectories:
        q = np.array(tr.q, float, copy=True)
        for j, c in zip(joints, offsets):
            q[:, j] += float(c)
        out.append(dc_replace(tr, q=q))
    return tuple(out)


@dataclass(frozen=True)
class GeometryFit:
    """Joint zeros identified with the dynamic parameters (``identify --geometry joint_zero``).

    Attributes
    ----------
    joints : tuple of int
        0-based joints whose zero was fitted (the visible ones).
    offsets, std : ndarray
        ``q0`` [rad or m] (``q_true = q_measured + q0``) and its standard deviation (last linearisation).
    revolute : tuple of bool
        Per fitted joint, whether it is an angle.
    iterations : int
    converged : bool
        The last step of every zero was below :data:`STEP_FRACTION` of its standard deviation.
    steps : tuple of float
        Per iteration, the largest ``|step| / sigma``.
    identifiability : tuple of ZeroVisibility
        Every joint.
    robot_file : str
        The robot file the geometry came from.
    robot_out : str, optional
        The corrected robot file written (``-o/--robot-out``).
    """

    joints: tuple[int, ...]
    offsets: np.ndarray
    std: np.ndarray
    revolute: tuple[bool, ...]
    iterations: int
    converged: bool
    steps: tuple[float, ...]
    identifiability: tuple[ZeroVisibility, ...]
    robot_file: str = ""
    robot_out: str | None = None
    kind: str = field(default="joint_zero")

    def offset_map(self) -> dict[int, float]:
        """0-based joint -> fitted zero [rad or m]."""
        return {j: float(v) for j, v in zip(self.joints, self.offsets)}

    def to_dict(self) -> dict:
        zeros = []
        for k, j in enumerate(self.joints):
            v, s = float(self.offsets[k]), float(self.std[k])
            row: dict[str, Any] = {"joint": j + 1}
            if self.revolute[k]:
                row.update(offset_rad=v, offset_rad_std=s, offset_deg=math.degrees(v), offset_deg_std=math.degrees(s),
                           plausible=abs(math.degrees(v)) <= MAX_ZERO_DEG)
            else:
                row.update(offset_m=v, offset_m_std=s)
            zeros.append(row)
        return {"parameters": self.kind, "zeros": zeros,
                "not_identifiable": [{"joint": v.joint + 1, "reason": v.reason}
                                     for v in self.identifiability if not v.visible],
                "identifiability": [v.to_dict() for v in self.identifiability],
                "iterations": self.iterations, "converged": self.converged,
                "max_step_over_sigma": [float(x) for x in self.steps],
                "robot_file": self.robot_file, "robot_out": self.robot_out}

    def summary(self, robot: str = "") -> str:
        lines = [f"Joint zeros identified with the dynamic parameters (Gauss-Newton, {self.iterations} iteration"
                 f"{'s' if self.iterations != 1 else ''}, {'converged' if self.converged else 'NOT converged'}; "
                 "q_true = q_measured + q0):"]
        for k, j in enumerate(self.joints):
            v, s = float(self.offsets[k]), float(self.std[k])
            if self.revolute[k]:
                lines.append(f"  joint {j + 1} zero offset {math.degrees(v):+.4f} deg (sigma {math.degrees(s):.4f} deg"
                             f"{', ' + f'{abs(v) / s:.1f}' + ' sigma from 0' if s > 0 else ''})"
                             + (f"  IMPLAUSIBLE: beyond {MAX_ZERO_DEG:g} deg, no encoder zero error (it stands for another "
                                "model error, a frame or sign convention, or the excitation does not determine it)" if abs(math.degrees(v)) > MAX_ZERO_DEG else ""))
            else:
                lines.append(f"  joint {j + 1} zero offset {1e3 * v:+.4f} mm (sigma {1e3 * s:.4f} mm)")
        lines.append(identifiability_text(self.identifiability, robot or "the robot"))
        if self.robot_out:
            lines.append(f"Corrected robot file written: {self.robot_out} (from {self.robot_file})")
        return "\n".join(lines)


SystemsAt = Callable[[np.ndarray], tuple[ObservationSystem, ObservationSystem | None]]
FitAt = Callable[[ObservationSystem, ObservationSystem | None], Any]


def _stacked(su: ObservationSystem, sl: ObservationSystem | None) -> ObservationSystem:
    return stack_systems(su, sl) if sl is not None else su


def fit_zeros(model: IdentificationModel, systems_at: SystemsAt, fit_at: FitAt, *,
              joints: Sequence[int] | None = None, max_iterations: int = 20, step_fraction: float = STEP_FRACTION,
              h: float = ASSEMBLY_STEP) -> GeometryFit:
    """Gauss-Newton on the zeros of ``joints`` (default: the visible ones), alternating with the linear fit.

    Parameters
    ----------
    systems_at : callable
        ``q0 -> (unloaded system, loaded system or None)``: the identification rows assembled from the
        recordings at ``q + q0`` (``q0`` over ``joints``), filtered and decimated as ``identify`` does.
    fit_at : callable
        ``(unloaded, loaded) -> IdentificationResult``: the linear fit of ``chi`` (OLS/WLS, a known payload).

    At each iteration: ``chi`` fitted at the current zeros; the sensitivity ``D_j = d (W chi)/d q0_j`` by a
    central difference of the assembled prediction (step ``h``); ``[W, D]`` solved for the corrections on the
    rows weighted as the fit weights them (WLS: ``1/sigma_j``); stop when every ``|step| <= step_fraction
    sigma``.
    """
    vis = zero_identifiability(model)
    seen = tuple(v.joint for v in vis if v.visible)
    n = int(model.N_JOINTS)
    js = seen if joints is None else tuple(int(j) for j in joints)
    bad = [j + 1 for j in js if not 0 <= j < n]
    if bad:
        raise IdentificationError(f"--geometry joint_zero: joint(s) {bad} outside 1..{n} of {model.ROBOT}")
    hidden = [j + 1 for j in js if j not in seen]
    if hidden:
        raise IdentificationError(f"--geometry joint_zero: the zero of joint(s) {hidden} of {model.ROBOT} is not "
                                  "identifiable from torque data (absorbed by the base parameters or no "
                                  "configuration-dependent torque)")
    rev = revolute_joints(model)
    k = len(js)
    q0 = np.zeros(k)
    sd = np.full(k, np.inf)
    steps: list[float] = []
    converged = False
    it = 0
    if k == 0:
        return GeometryFit(joints=(), offsets=q0, std=np.zeros(0), revolute=(), iterations=0, converged=True,
                           steps=(), identifiability=vis)
    cached = None
    while it < max_iterations:
        it += 1
        if cached is None:
            su, sl = systems_at(q0)
            res = fit_at(su, sl)
        else:
            su, sl, res = cached
        S = _stacked(su, sl)
        y = res.scaled_measurements(S)
        pred = res.predict(S)
        D = np.zeros((S.W.shape[0], k))
        for c in range(k):
            e = np.zeros(k)
            e[c] = h
            Sp, Sm = _stacked(*systems_at(q0 + e)), _stacked(*systems_at(q0 - e))
            if Sp.W.shape != S.W.shape or Sm.W.shape != S.W.shape or not np.array_equal(Sp.joint, S.joint):
                raise IdentificationError("--geometry joint_zero: the rows selected change with the joint zero "
                                          f"of joint {js[c] + 1} (row selection by angle?)")
            D[:, c] = (res.predict(Sp) - res.predict(Sm)) / (2 * h)
        w = np.ones(S.W.shape[0])
        if getattr(res, "joint_sigma", None) is not None:
            sig = np.asarray(res.joint_sigma, float)
            w = 1.0 / np.where(sig[S.joint] > 0, sig[S.joint], 1.0)
        cols = np.flatnonzero(np.linalg.norm(S.W, axis=0) > 0)
        A = np.hstack([S.W[:, cols], D]) * w[:, None]
        r = (y - pred) * w
        sol, *_ = np.linalg.lstsq(A, r, rcond=None)
        e_res = r - A @ sol
        dof = max(A.shape[0] - A.shape[1], 1)
        cov = float(e_res @ e_res) / dof * np.linalg.pinv(A.T @ A)
        sd = np.sqrt(np.maximum(np.diag(cov)[-k:], 0.0))
        step = sol[-k:]
        ratio = float(np.max(np.abs(step) / np.maximum(sd, 1e-300)))
        steps.append(ratio)
        if ratio <= step_fraction:
            q0 = q0 + step
            converged = True
            break
        # a step is taken only when the weighted residual of the linear fit at the new zeros decreases (halved
        # up to MAX_HALVINGS times otherwise: Gauss-Newton with step halving, Dennis & Schnabel 1983, ch. 6)
        rss = float(r @ r)
        cached = None
        for _ in range(MAX_HALVINGS + 1):
            su2, sl2 = systems_at(q0 + step)
            res2 = fit_at(su2, sl2)
            S2 = _stacked(su2, sl2)
            r2 = (res2.scaled_measurements(S2) - res2.predict(S2)) * w
            if float(r2 @ r2) <= rss:
                cached = (su2, sl2, res2)
                break
            step = step / 2
        if cached is None:   # no descent along the Gauss-Newton direction: the zeros stay where they are
            break
        q0 = q0 + step
    return GeometryFit(joints=js, offsets=q0, std=sd, revolute=tuple(bool(rev[j]) for j in js), iterations=it,
                       converged=converged, steps=tuple(steps), identifiability=vis)


# ------------------------------------------------------------------------------------------------
# the corrected robot file
# ------------------------------------------------------------------------------------------------


def _shifted_expr(old: str, c: float) -> str:
    """The joint-variable expression ``old`` (``"q"``, ``"q - pi/2"``, ``"-q"``...) at ``q + c``."""
    s = old.strip()
    sign = "-" if c < 0 else "+"
    if re.fullmatch(r"q(\s*[-+].*)?", s):   # q [+- const]: append the offset
        return f"{s} {sign} {format_number(abs(c))}"
    return re.sub(r"\bq\b", f"(q {sign} {format_number(abs(c))})", s)


def add_zeros(text: RobotText, robot, offsets: Mapping[int, float]) -> str:
    """Add the zeros ``offsets`` (model joint, 0-based -> ``q0``) of ``robot`` to the joint variable of their
    ``[[frames]]`` entries in ``text``: ``theta = "q"`` -> ``theta = "q + q0"`` (``r`` for a prismatic joint).
    Returns the zeros as text for a header comment (``joint 2 +0.5 deg``). A frame whose joint variable is not on
    a ``theta = "..."`` / ``r = "..."`` line of its own is refused naming the file, the frame and the field."""
    joints = robot.model_joints
    for j, c in sorted(offsets.items()):
        row = joints[j]
        text.edit_string(int(row.j), "theta" if int(row.sigma) == 0 else "r", partial(_shifted_expr, c=float(c)))
    return ", ".join(f"joint {j + 1} {math.degrees(c) if int(joints[j].sigma) == 0 else c:+.6g}"
                     f"{' deg' if int(joints[j].sigma) == 0 else ' m'}" for j, c in sorted(offsets.items()))


def corrected_robot_text(robot, offsets: Mapping[int, float], *, note: str = "") -> str:
    """The robot file of ``robot`` (its ``file``) with the zeros ``offsets`` (model joint, 0-based -> ``q0``)
    added to the joint variable of their ``[[frames]]`` entries (:func:`add_zeros`), every other line
    unchanged, and header comments naming the source file and ``note``."""
    text = RobotText(str(robot.file))
    zeros = add_zeros(text, robot, offsets)
    head = [f"Corrected by symoro-gen identify --geometry joint_zero from the robot file {text.path}",
            f"identified joint zeros added to theta/r: {zeros or 'none'}"]
    return text.text(head + ([note] if note else []))


# ------------------------------------------------------------------------------------------------
# link lengths (d, r of a frame): sensitivities by finite differences of the numeric Newton-Euler model
# ------------------------------------------------------------------------------------------------
#: the MDH lengths whose errors :func:`length_sensitivity` differentiates
LENGTH_FIELDS = ("d", "r")


def perturbed_robot(robot, frame: int, fld: str, delta: float):
    """``robot`` with ``delta`` [m] added to the MDH length ``fld`` (``d`` or ``r``) of frame ``frame`` (its
    ``j``); for a prismatic joint's ``r`` it is a zero error of the joint variable."""
    import sympy as sp

    if fld not in LENGTH_FIELDS:
        raise IdentificationError(f"length error of frame {frame}: field {fld!r}, one of {', '.join(LENGTH_FIELDS)}")
    rows = list(robot.rows)
    hit = [k for k, r in enumerate(rows) if int(r.j) == int(frame)]
    if not hit:
        raise IdentificationError(f"length error: {robot.file}: no frame j = {frame}")
    k = hit[0]
    rows[k] = dc_replace(rows[k], **{fld: sp.sympify(getattr(rows[k], fld)) + sp.Float(delta)})
    return dc_replace(robot, rows=tuple(rows))


def length_sensitivity(robot, chi_std, q, dq, ddq, frame: int, fld: str, *, h: float = 1e-6,
                       chi_payload=None) -> np.ndarray:
    """``d tau / d L`` (shape (N, n)) of the MDH length ``L`` = ``fld`` (``d`` or ``r``) of frame ``frame``, at
    the standard parameters ``chi_std``: a central difference (step ``h`` [m]) of the numeric Newton-Euler
    torque (:func:`symoro_gen.dynamics.numeric.inverse_dynamics`) at the perturbed geometry. The generated
    models do not emit ``d Y / d g`` (their regressor is symbolic in the joint variables only, the geometry
    substituted), so a length error is differentiated on the standard parameters, not the base ones: the
    base-parameter regrouping itself depends on the lengths (Khalil & Dombre 2002, ch. 12)."""
    plus = inverse_dynamics(perturbed_robot(robot, frame, fld, h), q, dq, ddq, chi_std, chi_payload)
    minus = inverse_dynamics(perturbed_robot(robot, frame, fld, -h), q, dq, ddq, chi_std, chi_payload)
    return (np.asarray(plus) - np.asarray(minus)) / (2 * h)


def length_visibility(robot, frame: int, fld: str, *, rng: np.random.Generator | None = None,
                      n_samples: int = 30, n_theta: int = 3) -> float:
    """Share of the length sensitivity's norm outside the span of the standard regressor at the nominal
    geometry (random configurations, random standard parameters; the smallest over ``n_theta``): 0 when the
    inertial parameters absorb the length error (torque data cannot see it), as :func:`zero_shares` for zeros."""
    rng = np.random.default_rng(0) if rng is None else rng
    n = robot.n_joints
    q, dq, ddq = _random_motion(n, n_samples, rng)
    W, _ = numeric_regressor(robot, q, dq, ddq)
    W = W.reshape(n_samples * n, -1)
    U, s, _ = np.linalg.svd(W, full_matrices=False)
    U = U[:, s > s[0] * 1e-10] if s.size and s[0] > 0 else U[:, :0]
    shares = []
    for _ in range(n_theta):
        chi = rng.standard_normal(W.shape[1])
        col = length_sensitivity(robot, chi, q, dq, ddq, frame, fld).reshape(-1)
        nc = float(np.linalg.norm(col))
        if nc <= 1e-9 * max(float(np.linalg.norm(W @ chi)), 1e-300):
            shares.append(0.0)
            continue
        shares.append(float(np.linalg.norm(col - U @ (U.T @ col))) / nc)
    return min(shares)
