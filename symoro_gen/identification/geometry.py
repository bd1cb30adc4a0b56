"""Geometric parameters identified with the dynamic ones: the joint zeros (``identify --geometry joint_zero``)
and the link lengths ``d``, ``r`` of the MDH table (``identify --geometry length``).

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

A link-length error ``e`` (``L_true = L_file + e``) changes the torque to ``Y_std(q; L + e) chi``; the generated
model's regressor has the file's geometry substituted, so its torque ``tau(L + e) - tau(L)`` (numeric
Newton-Euler at the standard parameters of the current fit, :func:`standard_from_fit`) is taken out of the
recordings (:func:`correct_lengths`) and the same Gauss-Newton (:func:`gauss_newton`, one unknown per zero and
per length) fits ``e`` with the base parameters (:func:`fit_geometry`); which lengths torque data can see:
:func:`length_identifiability`. The Gauss-Newton column of a length is the assembly (affine in the torque) of
the torque field ``d tau / d L`` (:func:`length_torque_field`): the generated package's emitted ``dY_std/dg``
(:mod:`symoro_gen.emit.geometry`) at the file's geometry, i.e. the first iteration, where it is exact; the central
difference of the numeric Newton-Euler model once an iterate has moved the lengths (the emitted derivative is
that of the nominal geometry only), so the last linearisation (sigma, the stopping test) is the derivative at
the estimate.

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
from sympy import sympify

from ..description.mdh import row_values
from ..description.rewrite import RobotText, format_number
from ..dynamics.numeric import inverse_dynamics, numeric_regressor
from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.assembly import iter_kinematics, observation_settings
from ..observations.raw import full_rate_torque
from ..observations.system import ObservationSystem
from ..params import INERTIAL_KINDS, split_name
from ..runtime.model import geometry_terms_of
from .systems import stack_systems

__all__ = ["GEOMETRY_KINDS", "LENGTH_VISIBILITY_TOL", "MAX_LENGTH_M", "MAX_LENGTH_REACH", "GaussNewton",
           "GeometryProblem", "check_zero_joints", "emitted_length_columns", "emitted_length_terms", "LengthTerms", "LengthVisibility", "add_lengths", "apply_geometry", "arm_reach", "correct_lengths",
           "fit_geometry", "gauss_newton", "length_identifiability", "length_identifiability_text",
           "length_plausible", "parse_lengths", "standard_from_fit", "JOINT_ZERO_STEP", "LENGTH_FIELDS", "length_sensitivity", "length_visibility", "perturbed_robot", "STEP_FRACTION", "VISIBILITY_TOL", "GeometryFit", "ZeroVisibility",
           "add_zeros", "corrected_robot_text", "fit_zeros", "joint_zero_column", "joint_zero_secant", "joint_zero_visibility",
           "regressor_secant", "revolute_joints", "emitted_length_column", "length_torque_field", "numeric_geometry", "Tangent", "shift_zeros", "visible_zero_joints", "zero_identifiability",
           "zero_shares"]

#: the geometric parameters ``identify --geometry`` can fit
GEOMETRY_KINDS = ("joint_zero", "length")
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
    lengths : tuple of (int, str)
        ``(frame j, "d" or "r")`` of each MDH length fitted (``--geometry length``); ``length_values``,
        ``length_std`` their errors ``L_true - L_file`` [m] and standard deviations.
    length_identifiability : tuple of LengthVisibility
        Every length examined (:func:`length_identifiability`).
    reach : float
        Sum of the arm's nominal ``|d|`` and ``|r|`` [m] (the scale of :func:`length_plausible`).
    chi_std, chi_payload : ndarray, optional
        The standard parameters (``robot.standard_names`` order) and payload ones the length torque was
        evaluated with at the last iteration (:func:`correct_lengths`).
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
    lengths: tuple[tuple[int, str], ...] = ()
    length_values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    length_std: np.ndarray = field(default_factory=lambda: np.zeros(0))
    length_identifiability: tuple[LengthVisibility, ...] = ()
    reach: float = 0.0
    chi_std: np.ndarray | None = None
    chi_payload: np.ndarray | None = None

    def length_map(self) -> dict[tuple[int, str], float]:
        """``(frame, field)`` -> fitted length error [m]."""
        return {fl: float(v) for fl, v in zip(self.lengths, self.length_values)}

    def implausible_lengths(self) -> list[tuple[int, str, float]]:
        """The fitted lengths beyond :func:`length_plausible`: ``(frame, field, value)``."""
        return [(f, fl, float(v)) for (f, fl), v in zip(self.lengths, self.length_values)
                if not length_plausible(float(v), self.reach)]

    def _length_dict(self) -> dict:
        rows = [{"frame": f, "field": fl, "error_m": float(v), "error_m_std": float(s), "error_mm": 1e3 * float(v),
                 "error_mm_std": 1e3 * float(s), "plausible": length_plausible(float(v), self.reach)}
                for (f, fl), v, s in zip(self.lengths, self.length_values, self.length_std)]
        return {"lengths": rows,
                "lengths_not_identifiable": [{"frame": v.frame, "field": v.field, "reason": v.reason}
                                             for v in self.length_identifiability if not v.visible],
                "length_identifiability": [v.to_dict() for v in self.length_identifiability],
                "reach_m": float(self.reach)}

    def _length_lines(self, robot: str) -> list[str]:
        lines = [f"Link lengths identified with the dynamic parameters (Gauss-Newton, {self.iterations} iteration"
                 f"{'s' if self.iterations != 1 else ''}, {'converged' if self.converged else 'NOT converged'}; L_true = L_file + error; implausible beyond "
                 f"{MAX_LENGTH_M * 1e3:g} mm or {100 * MAX_LENGTH_REACH:g} % of the reach {self.reach:.3f} m):"]
        for (f, fl), v, s in zip(self.lengths, self.length_values, self.length_std):
            lines.append(f"  frame {f} {fl} {1e3 * float(v):+.3f} mm (sigma {1e3 * float(s):.3f} mm"
                         + (f", {abs(v) / s:.1f} sigma from 0" if s > 0 else "") + ")"
                         + ("" if length_plausible(float(v), self.reach) else
                            "  IMPLAUSIBLE: no machining or assembly error of a link (another model error, or the "
                            "excitation does not determine it); not written into a robot file"))
        lines.append(length_identifiability_text(self.length_identifiability, robot or "the robot"))
        return lines

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
        extra = self._length_dict() if "length" in self.kind else {}
        return {"parameters": self.kind, "zeros": zeros, **extra,
                "not_identifiable": [{"joint": v.joint + 1, "reason": v.reason}
                                     for v in self.identifiability if not v.visible],
                "identifiability": [v.to_dict() for v in self.identifiability],
                "iterations": self.iterations, "converged": self.converged,
                "max_step_over_sigma": [float(x) for x in self.steps],
                "robot_file": self.robot_file, "robot_out": self.robot_out}

    def summary(self, robot: str = "") -> str:
        lines = self._zero_lines(robot) if "joint_zero" in self.kind else []
        if "length" in self.kind:
            lines += self._length_lines(robot)
        if self.robot_out:
            lines.append(f"Corrected robot file written: {self.robot_out} (from {self.robot_file})")
        return "\n".join(lines)

    def _zero_lines(self, robot: str) -> list[str]:
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
        return lines


SystemsAt = Callable[[np.ndarray], tuple[ObservationSystem, ObservationSystem | None]]
FitAt = Callable[[ObservationSystem, ObservationSystem | None], Any]


def _stacked(su: ObservationSystem, sl: ObservationSystem | None) -> ObservationSystem:
    return stack_systems(su, sl) if sl is not None else su


def check_zero_joints(model: IdentificationModel, vis: Sequence[ZeroVisibility],
                       joints: Sequence[int] | None) -> tuple[int, ...]:
    """The joints (0-based) whose zero is fitted: ``joints`` or the visible ones; refused outside the arm or
    invisible."""
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
    return js


#: ``(g, fit) -> (unloaded system, loaded system or None)``: the identification rows at the geometric
#: corrections ``g`` (the fit ``fit``, None at the start, gives the dynamic parameters a correction needs)
GeneralSystemsAt = Callable[[np.ndarray, Any], tuple[ObservationSystem, ObservationSystem | None]]


@dataclass(frozen=True)
class GaussNewton:
    """The outcome of :func:`gauss_newton`: corrections ``g``, their standard deviations, the iterations, the
    last linear fit."""

    g: np.ndarray
    std: np.ndarray
    iterations: int
    converged: bool
    steps: tuple[float, ...]
    fit: Any


def _weights(res: Any, S: ObservationSystem) -> np.ndarray:
    w = np.ones(S.W.shape[0])
    if getattr(res, "joint_sigma", None) is not None:
        sig = np.asarray(res.joint_sigma, float)
        w = 1.0 / np.where(sig[S.joint] > 0, sig[S.joint], 1.0)
    return w


#: ``(c, g, fit, S) -> column c of d (W chi - Y) / d g on the rows of S``, or None for the central difference
Tangent = Callable[[int, np.ndarray, Any, ObservationSystem], "np.ndarray | None"]


def _jacobian(systems_at: GeneralSystemsAt, res: Any, g: np.ndarray, S: ObservationSystem, h: float,
              labels: Sequence[str], tangent: Tangent | None = None) -> np.ndarray:
    """``d (W chi - Y) / d g`` on the rows of ``S`` at the fit ``res``: the column ``tangent`` gives, else central
    differences of the assembled prediction minus the assembled measurement (a joint zero moves the angles, a
    length the torque)."""
    D = np.zeros((S.W.shape[0], g.size))
    for c in range(g.size):
        col = tangent(c, g, res, S) if tangent is not None else None
        if col is not None:
            D[:, c] = col
            continue
        e = np.zeros(g.size)
        e[c] = h
        Sp, Sm = _stacked(*systems_at(g + e, res)), _stacked(*systems_at(g - e, res))
        if Sp.W.shape != S.W.shape or Sm.W.shape != S.W.shape or not np.array_equal(Sp.joint, S.joint):
            raise IdentificationError(f"--geometry: the rows selected change with {labels[c]} "
                                      "(row selection by angle?)")
        D[:, c] = ((res.predict(Sp) - res.scaled_measurements(Sp))
                   - (res.predict(Sm) - res.scaled_measurements(Sm))) / (2 * h)
    return D


def gauss_newton(systems_at: GeneralSystemsAt, fit_at: FitAt, labels: Sequence[str], *, max_iterations: int = 20,
                 step_fraction: float = STEP_FRACTION, h: float = ASSEMBLY_STEP,
                 tangent: Tangent | None = None) -> GaussNewton:
    """Gauss-Newton on geometric corrections ``g`` (one per label), alternating with the linear fit of ``chi``.

    At each iteration: ``chi`` fitted at the current ``g``; the sensitivity ``D_c = d (W chi - Y)/d g_c`` by a
    central difference of the assembled rows (step ``h``), or the column ``tangent`` returns (the link lengths:
    :func:`length_tangent`); ``[W, D]`` solved for the corrections on the rows
    weighted as the fit weights them (WLS: ``1/sigma_j``); a step taken only when the weighted residual of the
    linear fit at the new ``g`` does not rise (halved up to :data:`MAX_HALVINGS` times otherwise: Gauss-Newton
    with step halving, Dennis & Schnabel 1983, ch. 6); stop when every ``|step| <= step_fraction sigma``.
    Standard deviations from the last linearisation, ``sigma^2 (A^T A)^-1`` (Gautier 1990)."""
    k = len(labels)
    g = np.zeros(k)
    sd = np.full(k, np.inf)
    steps: list[float] = []
    converged = False
    it = 0
    cached = None
    res = None
    while it < max_iterations:
        it += 1
        if cached is None:
            su, sl = systems_at(g, res)
            res = fit_at(su, sl)
        else:
            su, sl, res = cached
        S = _stacked(su, sl)
        D = _jacobian(systems_at, res, g, S, h, labels, tangent)
        w = _weights(res, S)
        cols = np.flatnonzero(np.linalg.norm(S.W, axis=0) > 0)
        A = np.hstack([S.W[:, cols], D]) * w[:, None]
        r = (res.scaled_measurements(S) - res.predict(S)) * w
        sol, *_ = np.linalg.lstsq(A, r, rcond=None)
        e_res = r - A @ sol
        dof = max(A.shape[0] - A.shape[1], 1)
        cov = float(e_res @ e_res) / dof * np.linalg.pinv(A.T @ A)
        sd = np.sqrt(np.maximum(np.diag(cov)[-k:], 0.0))
        step = sol[-k:]
        ratio = float(np.max(np.abs(step) / np.maximum(sd, 1e-300)))
        steps.append(ratio)
        if ratio <= step_fraction:
            g = g + step
            converged = True
            break
        rss = float(r @ r)
        cached = None
        for _ in range(MAX_HALVINGS + 1):
            su2, sl2 = systems_at(g + step, res)
            res2 = fit_at(su2, sl2)
            S2 = _stacked(su2, sl2)
            r2 = (res2.scaled_measurements(S2) - res2.predict(S2)) * w
            if float(r2 @ r2) <= rss:
                cached = (su2, sl2, res2)
                break
            step = step / 2
        if cached is None:   # no descent along the Gauss-Newton direction: g stays where it is
            break
        g = g + step
    return GaussNewton(g=g, std=sd, iterations=it, converged=converged, steps=tuple(steps), fit=res)


def fit_zeros(model: IdentificationModel, systems_at: SystemsAt, fit_at: FitAt, *,
              joints: Sequence[int] | None = None, max_iterations: int = 20, step_fraction: float = STEP_FRACTION,
              h: float = ASSEMBLY_STEP) -> GeometryFit:
    """Gauss-Newton on the zeros of ``joints`` (default: the visible ones), alternating with the linear fit
    (:func:`gauss_newton`).

    Parameters
    ----------
    systems_at : callable
        ``q0 -> (unloaded system, loaded system or None)``: the identification rows assembled from the
        recordings at ``q + q0`` (``q0`` over ``joints``), filtered and decimated as ``identify`` does.
    fit_at : callable
        ``(unloaded, loaded) -> IdentificationResult``: the linear fit of ``chi`` (OLS/WLS, a known payload).
    """
    vis = zero_identifiability(model)
    js = check_zero_joints(model, vis, joints)
    if not js:
        return GeometryFit(joints=(), offsets=np.zeros(0), std=np.zeros(0), revolute=(), iterations=0, converged=True,
                           steps=(), identifiability=vis)
    rev = revolute_joints(model)
    gn = gauss_newton(lambda g, _res: systems_at(g), fit_at, [f"the zero of joint {j + 1}" for j in js],
                      max_iterations=max_iterations, step_fraction=step_fraction, h=h)
    return GeometryFit(joints=js, offsets=gn.g, std=gn.std, revolute=tuple(bool(rev[j]) for j in js),
                       iterations=gn.iterations, converged=gn.converged, steps=gn.steps, identifiability=vis)


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
    torque (:func:`symoro_gen.dynamics.numeric.inverse_dynamics`) at the perturbed geometry: it needs only the
    description (the emitted ``d Y_std / d g`` of a generated package, :mod:`symoro_gen.emit.geometry`, is the
    same column, and the loop's :func:`symoro_gen.diagnostics.geometry.emitted_length_column` uses it). A length error is differentiated on the standard parameters, not the base ones: the
    base-parameter regrouping itself depends on the lengths (Khalil & Dombre 2002, ch. 12)."""
    plus = inverse_dynamics(perturbed_robot(robot, frame, fld, h), q, dq, ddq, chi_std, chi_payload)
    minus = inverse_dynamics(perturbed_robot(robot, frame, fld, -h), q, dq, ddq, chi_std, chi_payload)
    return (np.asarray(plus) - np.asarray(minus)) / (2 * h)


def emitted_length_columns(model: IdentificationModel, robot, chi_std: np.ndarray, lengths: Sequence[tuple[int, str]]
                           ) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None:
    """``(q, dq, ddq) -> (d tau / d L_i) chi`` (shape (N, n, len(lengths))) of each MDH length ``(frame, field)`` of
    ``lengths``, from one evaluation of the generated package's emitted derivative of the standard regressor at the
    nominal geometry (``geometry_columns``, :mod:`symoro_gen.emit.geometry`), or None when the model has none (a
    model built in memory, a wrapper, a package whose manifest omits it) or its standard parameters are not the
    description's: the caller then differentiates the numeric Newton-Euler model (:func:`length_sensitivity`). A
    constant the generator dropped (derivative identically 0) gives zeros. Without payload only: the emitted
    derivative has no payload columns."""
    columns = getattr(model, "geometry_columns", None)
    names = tuple(getattr(model, "GEOMETRY_NAMES", ()))
    std = tuple(getattr(model, "STANDARD_NAMES", ()))
    if columns is None or not names or set(std) != set(robot.standard_names):
        return None
    by = dict(zip(robot.standard_names, chi_std))
    chi_m = np.array([float(by[nm]) for nm in std])
    ks = [names.index(f"{fld}{int(f)}") if f"{fld}{int(f)}" in names else None for f, fld in lengths]

    def cols(q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        out = np.zeros(np.shape(q) + (len(ks),))
        if any(k is not None for k in ks):
            full = np.asarray(columns(q, dq, ddq, chi_m))
            for i, k in enumerate(ks):
                if k is not None:
                    out[:, :, i] = full[:, :, k]
        return out

    return cols


@dataclass(frozen=True)
class LengthTerms:
    """The entries of the emitted ``dY_std/dg`` (:meth:`symoro_gen.runtime.model.GeneratedModel.geometry_terms`)
    that the columns ``(d tau / d L_i) chi`` of a list of MDH lengths ``L_i`` are made of, so that maps linear in
    the torque (the decimation of the observation rows) are applied to them once and the columns of any
    parameter vector ``chi`` follow by one product (:meth:`matrix`): ``(d tau / d L_i) chi =
    sum_s values[..., s] chi[standard[s]]`` over the entries ``s`` with ``length[s] == i``.

    Attributes
    ----------
    values : callable
        ``(q, dq, ddq) -> (N, n, s)``: the entries at each sample, on each joint's torque.
    standard : ndarray of int, shape (s,)
        Index of each entry's standard parameter in the description's ``standard_names``.
    length : ndarray of int, shape (s,)
        Index of each entry's length in the list (a length the generator dropped, derivative identically 0, has
        none: its column is 0).
    n_lengths : int
    """

    values: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
    standard: np.ndarray
    length: np.ndarray
    n_lengths: int

    def matrix(self, chi_std: np.ndarray) -> np.ndarray:
        """``M`` (s, n_lengths) with ``values @ M`` the columns at the standard parameters ``chi_std`` (the
        description's order, as :func:`standard_from_fit` returns them)."""
        M = np.zeros((self.standard.size, self.n_lengths))
        M[np.arange(self.standard.size), self.length] = np.asarray(chi_std, float)[self.standard]
        return M


def emitted_length_terms(model: IdentificationModel, robot, lengths: Sequence[tuple[int, str]]) -> LengthTerms | None:
    """The :class:`LengthTerms` of the lengths ``(frame, field)`` from the generated package's emitted derivative
    (:func:`symoro_gen.runtime.model.geometry_terms_of`), or None when the model has none or its standard
    parameters are not the description's (as :func:`emitted_length_columns`). Without payload only."""
    terms = geometry_terms_of(model)
    names = tuple(getattr(model, "GEOMETRY_NAMES", ()))
    std = tuple(getattr(model, "STANDARD_NAMES", ()))
    if terms is None or not names or set(std) != set(robot.standard_names):
        return None
    ks = {names.index(f"{fld}{int(f)}"): i for i, (f, fld) in enumerate(lengths) if f"{fld}{int(f)}" in names}
    n = int(model.N_JOINTS)
    _, pairs = terms(np.zeros((1, n)), np.zeros((1, n)), np.zeros((1, n)))
    sel = np.flatnonzero(np.isin(pairs[:, 1], list(ks)))
    to_robot = {nm: k for k, nm in enumerate(robot.standard_names)}
    standard = np.array([to_robot[std[int(pairs[s, 0])]] for s in sel], dtype=int)
    length = np.array([ks[int(pairs[s, 1])] for s in sel], dtype=int)

    def values(q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        out: np.ndarray = terms(q, dq, ddq)[0][:, :, sel]
        return out

    return LengthTerms(values, standard, length, len(lengths))


def emitted_length_column(model: IdentificationModel, robot, chi_std: np.ndarray, f: int, fld: str
                          ) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray] | None:
    """``(q, dq, ddq) -> (d tau / d L) chi`` (shape (N, n)) of the one length ``fld`` of frame ``f``: the column of
    :func:`emitted_length_columns`, or None when the model has no emitted derivative."""
    cols = emitted_length_columns(model, robot, chi_std, [(f, fld)])
    if cols is None:
        return None

    def col(q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        out: np.ndarray = cols(q, dq, ddq)[:, :, 0]
        return out

    return col


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


# ------------------------------------------------------------------------------------------------
# link lengths fitted with the dynamic parameters (``identify --geometry length``)
# ------------------------------------------------------------------------------------------------
#: a length share outside the span of the standard regressor (and of the lengths before it) below this: not
#: identifiable (above the relative error of the central differences, ~1e-9)
LENGTH_VISIBILITY_TOL = 1e-5
#: beyond this [m] a fitted length error is no machining or assembly error of a link (the loop's prior,
#: docs/plausibility.md: a few mm plausible, beyond 20 mm doubtful): flagged implausible, never written
MAX_LENGTH_M = 0.05
#: ... nor beyond this share of the arm's reach (sum of its nominal |d| and |r|)
MAX_LENGTH_REACH = 0.10
LENGTH_ZERO_REASON = ("no torque changes with it (a translation of the base under uniform gravity, or a frame no link "
                      "mass is carried by)")
LENGTH_ABSORBED_REASON = ("the base parameters absorb it (its sensitivity column lies in the span of the standard "
                          "regressor: the first moments of the links beyond it take the change)")
LENGTH_PRISMATIC_REASON = "r of a prismatic joint is its joint variable: a joint zero (--geometry joint_zero)"


def length_plausible(value: float, reach: float) -> bool:
    """A length error within :data:`MAX_LENGTH_M` and :data:`MAX_LENGTH_REACH` of the reach."""
    lim = MAX_LENGTH_M if reach <= 0 else min(MAX_LENGTH_M, MAX_LENGTH_REACH * reach)
    return abs(value) <= lim


def arm_reach(robot) -> float:
    """Sum of the nominal ``|d|`` and ``|r|`` of every frame [m] (joint variables at 0)."""
    subs = robot.geometry_subs()
    tot = 0.0
    for row in robot.rows:
        vals = row_values(row, subs)
        tot += abs(float(vals[3])) + abs(float(np.asarray(vals[5]).ravel()[0]))
    return tot


@dataclass(frozen=True)
class LengthVisibility:
    """Whether torque data can see the error of one MDH length (``d`` or ``r`` of frame ``frame``)."""

    frame: int
    field: str
    share: float
    visible: bool
    reason: str = ""

    def to_dict(self) -> dict:
        return {"frame": self.frame, "field": self.field, "share_outside_base": float(self.share),
                "identifiable": self.visible, "reason": self.reason or None}


def _candidate_lengths(robot) -> list[tuple[int, str]]:
    return [(int(r.j), fld) for r in robot.rows for fld in LENGTH_FIELDS]


_LENGTH_VISIBILITY: dict = {}   # id(robot) -> (robot, result): the default measure of a robot, computed once


def length_identifiability(robot, *, tol: float = LENGTH_VISIBILITY_TOL, rng: np.random.Generator | None = None,
                           n_samples: int = 30, n_theta: int = 2, model: IdentificationModel | None = None
                           ) -> tuple[LengthVisibility, ...]:
    """Per frame and length (``d``, ``r``), whether torque data can see its error: the share of its sensitivity
    column (:func:`length_sensitivity`) outside the span of the standard regressor and of the columns of the
    visible lengths before it (frames in order, ``d`` before ``r``), the smallest over ``n_theta`` random
    standard parameter vectors, on ``n_samples`` random configurations (as :func:`zero_shares` for zeros; the
    lengths one another can stand for are counted once). The lengths of a frame on the base (a translation of
    the whole arm) and of a frame that carries no inertial parameter are 0 without computing. ``model``: the
    generated model of ``robot``, whose standard regressor spans the same space as the numeric one, faster."""
    if rng is None:
        got = _LENGTH_VISIBILITY.get(id(robot))
        if got is not None and got[0] is robot and (tol, n_samples, n_theta) == got[1]:
            return got[2]
        out = _length_shares(robot, tol, np.random.default_rng(0), n_samples, n_theta, model)
        _LENGTH_VISIBILITY[id(robot)] = (robot, (tol, n_samples, n_theta), out)
        return out
    return _length_shares(robot, tol, rng, n_samples, n_theta, model)


def _standard_rows(robot, model: IdentificationModel | None, q, dq, ddq) -> np.ndarray:
    """The standard regressor in ``robot.standard_names`` order: the generated model's when it has the same
    names, else the numeric Newton-Euler one."""
    names = tuple(robot.standard_names)
    if model is not None and set(getattr(model, "STANDARD_NAMES", ())) == set(names):
        W = np.asarray(model.standard_regressor(q, dq, ddq), float)
        idx = [tuple(model.STANDARD_NAMES).index(nm) for nm in names]
        return W[:, :, idx]
    return numeric_regressor(robot, q, dq, ddq)[0]


def _massless(robot, frame: int) -> bool:
    """No inertial parameter on the frame or any frame it carries."""
    sub, todo = set(), [int(frame)]
    while todo:
        f = todo.pop()
        sub.add(f)
        todo += [int(c) for c in robot.children(f)]
    for nm in robot.standard_names:
        try:
            kind, f, _ = split_name(nm)
        except ValueError:
            continue
        if kind in INERTIAL_KINDS and f in sub:
            return False
    return True


def _nominal_length_column(robot, model: IdentificationModel | None, chi: np.ndarray, q, dq, ddq, frame: int,
                           fld: str) -> np.ndarray:
    """``d tau / d L`` at the nominal geometry: the emitted derivative of ``model`` (:func:`emitted_length_column`)
    when it has one, else the central difference of the numeric Newton-Euler model (:func:`length_sensitivity`)."""
    emitted = emitted_length_column(model, robot, chi, frame, fld) if model is not None else None
    if emitted is not None:
        return emitted(q, dq, ddq)
    return length_sensitivity(robot, chi, q, dq, ddq, frame, fld)


def _length_shares(robot, tol: float, rng: np.random.Generator, n_samples: int, n_theta: int,
                   model: IdentificationModel | None = None) -> tuple[LengthVisibility, ...]:
    n = robot.n_joints
    q, dq, ddq = _random_motion(n, n_samples, rng)
    W = _standard_rows(robot, model, q, dq, ddq)
    W = W.reshape(n_samples * n, -1)
    U, s, _ = np.linalg.svd(W, full_matrices=False)
    U = U[:, s > s[0] * 1e-10] if s.size and s[0] > 0 else U[:, :0]
    chis = [rng.standard_normal(W.shape[1]) for _ in range(n_theta)]
    bases = [U for _ in chis]
    out = []
    prismatic = {int(r.j) for r in robot.joints if int(r.sigma) == 1}
    for frame, fld in _candidate_lengths(robot):
        if fld == "r" and frame in prismatic:
            out.append(LengthVisibility(frame, fld, 0.0, False, LENGTH_PRISMATIC_REASON))
            continue
        if int(robot.row(frame).ant) == 0 or _massless(robot, frame):
            out.append(LengthVisibility(frame, fld, 0.0, False, LENGTH_ZERO_REASON))
            continue
        shares, zero, cols = [], True, []
        for chi, B in zip(chis, bases):
            col = _nominal_length_column(robot, model, chi, q, dq, ddq, frame, fld).reshape(-1)
            cols.append(col)
            nc = float(np.linalg.norm(col))
            if nc <= 1e-9 * max(float(np.linalg.norm(W @ chi)), 1e-300):
                shares.append(0.0)
                continue
            zero = False
            shares.append(float(np.linalg.norm(col - B @ (B.T @ col))) / nc)
        vis = min(shares) > tol
        if vis:   # the next lengths are judged beyond this one
            for t, (B, col) in enumerate(zip(bases, cols)):
                r = col - B @ (B.T @ col)
                bases[t] = np.hstack([B, (r / np.linalg.norm(r))[:, None]])
        out.append(LengthVisibility(frame, fld, min(shares), vis,
                                    "" if vis else (LENGTH_ZERO_REASON if zero else LENGTH_ABSORBED_REASON)))
    return tuple(out)


def length_identifiability_text(vis: Sequence[LengthVisibility], robot: str) -> str:
    """The identifiability printout for the link lengths: which errors torque data can see, why not the others."""
    seen = [f"frame {v.frame} {v.field}" for v in vis if v.visible]
    lines = [f"Link lengths of {robot} seen by torque data (gravity and inertial effects): "
             + (", ".join(seen) if seen else "none")]
    for v in vis:
        if not v.visible:
            lines.append(f"  frame {v.frame} {v.field}: not identifiable, {v.reason}")
    return "\n".join(lines)


def parse_lengths(spec: Sequence[str] | None, robot, vis: Sequence[LengthVisibility]) -> tuple[tuple[int, str], ...]:
    """The lengths ``--geometry-frames`` names (``3r``, ``4d``, or ``3`` for both of frame 3's visible ones;
    default: every visible length). A frame the robot lacks, a field not ``d``/``r`` or an invisible length is
    refused naming the robot file, the frame and the field."""
    if spec is None:
        return tuple((v.frame, v.field) for v in vis if v.visible)
    frames = {int(r.j) for r in robot.rows}
    by = {(v.frame, v.field): v for v in vis}
    out: list[tuple[int, str]] = []
    for item in spec:
        m = re.fullmatch(r"\s*(\d+)\s*([a-zA-Z]*)\s*", str(item))
        if m is None:
            raise IdentificationError(f"--geometry-frames {item!r}: a frame number and a field (d or r), e.g. 3r")
        f, fld = int(m.group(1)), m.group(2).lower()
        if f not in frames:
            raise IdentificationError(f"--geometry-frames {item!r}: {robot.file} has no frame j = {f} "
                                      f"(frames {min(frames)}..{max(frames)})")
        if fld and fld not in LENGTH_FIELDS:
            raise IdentificationError(f"--geometry-frames {item!r}: frame {f} of {robot.file}: field {fld!r} is no "
                                      "length; one of d, r")
        for fl in ((fld,) if fld else LENGTH_FIELDS):
            v = by.get((f, fl))
            if v is None or not v.visible:
                if not fld:
                    continue
                why = v.reason if v is not None else "not examined"
                raise IdentificationError(f"--geometry-frames {item!r}: frame {f} field {fl} of {robot.file} is not "
                                          f"identifiable from torque data: {why}")
            if (f, fl) not in out:
                out.append((f, fl))
    return tuple(out)


_PINV: dict = {}   # id(model) -> (model, pinv of its base-from-standard map): constant, computed once


def _base_pinv(model: IdentificationModel) -> np.ndarray:
    """``pinv(K)`` of the model's base-from-standard map ``K`` (base, standard), computed once per model."""
    got = _PINV.get(id(model))
    if got is not None and got[0] is model:
        return got[1]
    K = np.asarray(model.base_parameters(np.eye(len(tuple(model.STANDARD_NAMES)))), float).T   # (base, standard)
    if K.shape[0] != len(tuple(model.BASE_NAMES)):
        raise IdentificationError(f"{model.ROBOT}: the base parameters of the model ({len(tuple(model.BASE_NAMES))}) "
                                  f"are not its base_parameters map's ({K.shape[0]}): no standard parameters for "
                                  "the length sensitivity (a declared friction law replaces base columns)")
    P = np.linalg.pinv(K)
    _PINV[id(model)] = (model, P)
    return P


def standard_from_fit(model: IdentificationModel, robot, theta: Mapping[str, float]
                      ) -> tuple[np.ndarray, np.ndarray | None]:
    """Standard parameters (``robot.standard_names`` order) whose base parameters are the fit's (minimum norm:
    ``pinv(K) chi_b``, ``K`` the model's base-from-standard map) and the payload ones (``robot.payload_names``).
    Any other choice differs by a null-space vector whose length sensitivity lies in the span of the
    regressor, which the linear part of the fit absorbs."""
    std_names = tuple(model.STANDARD_NAMES)
    chi_b = np.array([float(theta.get(nm, 0.0)) for nm in model.BASE_NAMES])
    chi = _base_pinv(model) @ chi_b
    by = dict(zip(std_names, chi))
    chi_std = np.array([float(by.get(nm, 0.0)) for nm in robot.standard_names])
    pay = tuple(robot.payload_names)
    chi_pay = np.array([float(theta.get(nm, 0.0)) for nm in pay]) if pay else None
    return chi_std, chi_pay


def _lengthened(robot, lengths: Sequence[tuple[int, str]], values: Sequence[float] | np.ndarray):
    out = robot
    for (f, fld), v in zip(lengths, values):
        out = perturbed_robot(out, f, fld, float(v))
    return out


_NUMERIC: dict = {}   # id(robot) -> (robot, the same robot with its geometry substituted)


def numeric_geometry(robot):
    """``robot`` with its geometric constants substituted into the MDH rows (numbers and the joint variables
    only, ``values`` empty): the same numeric Newton-Euler torque (:func:`inverse_dynamics` substitutes the same
    values), without the symbolic substitution on every call, which costs more than the recursion on a few
    thousand samples. Cached per robot (the last few)."""
    got = _NUMERIC.get(id(robot))
    if got is not None and got[0] is robot:
        return got[1]
    subs = robot.geometry_subs()
    fields = ("gamma", "b", "alpha", "d", "theta", "r")
    rows = tuple(dc_replace(r, **{f: sympify(getattr(r, f)).xreplace(subs) for f in fields}) for r in robot.rows)
    out = dc_replace(robot, rows=rows, values={})
    if len(_NUMERIC) > 16:
        _NUMERIC.clear()
    _NUMERIC[id(robot)] = (robot, out)
    return out


def correct_lengths(model: IdentificationModel, robot, trajectories: Sequence[Any], options: Any,
                    lengths: Sequence[tuple[int, str]], values: Sequence[float] | np.ndarray, chi_std: np.ndarray,
                    chi_payload: np.ndarray | None = None) -> tuple[Any, ...]:
    """The recordings with the torque of the length errors ``values`` taken out: ``tau - (tau(L + dL) - tau(L))``
    (numeric Newton-Euler at the standard parameters ``chi_std``), evaluated on the band-pass kinematics the
    assembly evaluates ``W`` on (:func:`~symoro_gen.observations.assembly.iter_kinematics` with ``options``), so
    that the model of the file's geometry fits them. The secant is exact; the edge samples the assembly drops
    are left as recorded."""
    if not len(lengths) or not np.any(np.asarray(values) != 0):
        return tuple(trajectories)
    moved, robot = numeric_geometry(_lengthened(robot, lengths, values)), numeric_geometry(robot)
    out = []
    for tr in trajectories:
        st = observation_settings(tr, options)
        tau = np.array(tr.tau, float, copy=True)
        pay = chi_payload if tr.loaded else None
        for a, b, q, dq, ddq in iter_kinematics(model, tr, options, st):
            d = inverse_dynamics(moved, q, dq, ddq, chi_std, pay) - inverse_dynamics(robot, q, dq, ddq, chi_std, pay)
            tau[st.edge_samples + a:st.edge_samples + b] -= d
        out.append(dc_replace(tr, tau=tau))
    return tuple(out)


def length_torque_field(model: IdentificationModel, robot, trajectories: Sequence[Any], options: Any,
                        lengths: Sequence[tuple[int, str]], values: Sequence[float] | np.ndarray, i: int,
                        chi_std: np.ndarray, chi_payload: np.ndarray | None = None, *, h: float = 1e-6
                        ) -> tuple[np.ndarray, ...]:
    """Per recording, ``d tau / d L_i`` of length ``i`` at the lengths ``L_file + values`` (shape of ``tau``;
    zero on the edge samples the assembly drops), evaluated on the band-pass kinematics as
    :func:`correct_lengths` evaluates the torque it takes out. At the nominal geometry (every ``values`` 0) on
    an unloaded recording it is the generated package's emitted derivative (:func:`emitted_length_column`: exact,
    no difference step); elsewhere (the lengths moved by an iterate, a loaded payload, a package without the
    derivative) the central difference (step ``h`` [m]) of the numeric Newton-Euler torque at ``L_file + values``,
    the column the central difference of the assembled rows in :func:`gauss_newton` took before."""
    f, fld = lengths[i]
    nominal = not np.any(np.asarray(values, float) != 0)
    emitted = emitted_length_column(model, robot, chi_std, f, fld) if nominal else None
    moved = _lengthened(robot, lengths, values)
    plus, minus = (numeric_geometry(perturbed_robot(moved, f, fld, x)) for x in (h, -h))
    out = []
    for tr in trajectories:
        st = observation_settings(tr, options)
        T = np.zeros(np.shape(tr.tau))
        pay = chi_payload if tr.loaded else None
        for a, b, q, dq, ddq in iter_kinematics(model, tr, options, st):
            if emitted is not None and pay is None:
                d = emitted(q, dq, ddq)
            else:
                d = (inverse_dynamics(plus, q, dq, ddq, chi_std, pay) - inverse_dynamics(minus, q, dq, ddq, chi_std, pay)) / (2 * h)
            T[st.edge_samples + a:st.edge_samples + b] = d
        out.append(T)
    return tuple(out)


def _minus_torque(trajectories: Sequence[Any], fields: Sequence[np.ndarray], s: float) -> tuple[Any, ...]:
    return tuple(dc_replace(tr, tau=np.asarray(tr.tau, float) - s * T) for tr, T in zip(trajectories, fields))


AssembleAt = Callable[[Sequence[Any], Sequence[Any]], tuple[ObservationSystem, ObservationSystem | None]]


@dataclass(frozen=True)
class GeometryProblem:
    """What :func:`fit_geometry` corrects: the recordings, the assembly options the length torque is evaluated
    with, the zeros (0-based joints) and the lengths ``(frame, field)`` fitted."""

    unloaded: tuple[Any, ...]
    loaded: tuple[Any, ...]
    options: Any
    joints: tuple[int, ...] = ()
    lengths: tuple[tuple[int, str], ...] = ()

    def corrected(self, model: IdentificationModel, robot, trajectories: Sequence[Any], g: np.ndarray,
                  chi: tuple[np.ndarray, np.ndarray | None] | None) -> tuple[Any, ...]:
        """``trajectories`` at the corrections ``g`` (zeros then lengths): angles shifted by the zeros, the
        torque of the length errors taken out (with the standard parameters ``chi``; none without)."""
        kz = len(self.joints)
        out = shift_zeros(trajectories, self.joints, g[:kz]) if kz else tuple(trajectories)
        if self.lengths and chi is not None:
            out = correct_lengths(model, robot, out, self.options, self.lengths, g[kz:], chi[0], chi[1])
        return out


def fit_geometry(model: IdentificationModel, robot, problem: GeometryProblem, assemble_at: AssembleAt,
                 fit_at: FitAt, *, kinds: Sequence[str], max_iterations: int = 20,
                 step_fraction: float = STEP_FRACTION) -> GeometryFit:
    """Joint zeros and link lengths fitted together with the dynamic parameters (:func:`gauss_newton`): a zero
    moves the recorded angles (:func:`shift_zeros`), a length error adds the torque of the arm with that
    length, taken out of the recordings (:func:`correct_lengths`) with the standard parameters of the current
    fit (:func:`standard_from_fit`). ``assemble_at(unloaded, loaded)`` assembles the rows as ``identify`` does.
    Identifiability of the zeros and of the lengths recorded for the printout."""
    vis = zero_identifiability(model) if "joint_zero" in kinds else ()
    lvis = length_identifiability(robot, model=model) if "length" in kinds else ()
    js, ls = problem.joints, problem.lengths
    labels = [f"the zero of joint {j + 1}" for j in js] + [f"frame {f} {fl}" for f, fl in ls]
    rev = revolute_joints(model) if js else np.ones(0, bool)

    def systems_at(g: np.ndarray, res: Any):
        chi = standard_from_fit(model, robot, res.parameter_map()) if (ls and res is not None) else None
        return assemble_at(problem.corrected(model, robot, problem.unloaded, g, chi),
                           problem.corrected(model, robot, problem.loaded, g, chi))

    shifted: dict = {}   # the recordings at the zeros of g, no length torque taken out, and their rows

    def tangent(c: int, g: np.ndarray, res: Any, S: ObservationSystem) -> np.ndarray | None:
        """Column ``c`` of a length: ``A T`` of the assembly's linear map ``A`` of the torque and the length's
        torque field ``T`` (:func:`length_torque_field`), as the rows of the recordings with ``s T`` taken out
        minus those without, over ``s``: the assembly is affine in the torque, so this forward difference is
        exact whatever ``s`` (no truncation error), and the recordings need not be corrected first."""
        if c < len(js) or res is None:
            return None
        key = g[:len(js)].tobytes()
        if shifted.get("key") != key:
            tu, tl = (problem.corrected(model, robot, t, g, None) for t in (problem.unloaded, problem.loaded))
            shifted.update(key=key, tu=tu, tl=tl, S=_stacked(*assemble_at(tu, tl)))
        tu, tl, S0 = shifted["tu"], shifted["tl"], shifted["S"]
        chi, pay = standard_from_fit(model, robot, res.parameter_map())
        i = c - len(js)
        fu, fl = (length_torque_field(model, robot, t, problem.options, ls, g[len(js):], i, chi, pay) for t in (tu, tl))
        s = ASSEMBLY_STEP
        Sp = _stacked(*assemble_at(_minus_torque(tu, fu, s), _minus_torque(tl, fl, s)))
        for X in (S0, Sp):
            if X.W.shape != S.W.shape or not np.array_equal(X.joint, S.joint):
                raise IdentificationError(f"--geometry: the rows selected change with {labels[c]} "
                                          "(row selection by torque saturation?)")
        return ((res.predict(Sp) - res.scaled_measurements(Sp)) - (res.predict(S0) - res.scaled_measurements(S0))) / s

    if labels:
        # the lengths are in metres, the zeros in radians: the same difference step suits both (ASSEMBLY_STEP)
        gn = gauss_newton(systems_at, fit_at, labels, max_iterations=max_iterations, step_fraction=step_fraction,
                          tangent=tangent if ls else None)
        g, sd, it, conv, steps = gn.g, gn.std, gn.iterations, gn.converged, gn.steps
        chi = standard_from_fit(model, robot, gn.fit.parameter_map()) if ls else (None, None)
    else:
        g, sd, it, conv, steps, chi = np.zeros(0), np.zeros(0), 0, True, (), (None, None)
    kz = len(js)
    return GeometryFit(joints=js, offsets=g[:kz], std=sd[:kz], revolute=tuple(bool(rev[j]) for j in js),
                       iterations=it, converged=conv, steps=steps, identifiability=tuple(vis),
                       kind=",".join(kinds), lengths=ls, length_values=g[kz:], length_std=sd[kz:],
                       length_identifiability=tuple(lvis), reach=arm_reach(robot), chi_std=chi[0], chi_payload=chi[1])


def apply_geometry(model: IdentificationModel, robot, fit: GeometryFit, trajectories: Sequence[Any],
                   options: Any) -> tuple[Any, ...]:
    """The recordings corrected by a fitted geometry: the zeros added to the angles, the torque of the length
    errors taken out (the standard parameters of the last iteration)."""
    out = shift_zeros(trajectories, fit.joints, fit.offsets) if fit.joints else tuple(trajectories)
    if fit.lengths and fit.chi_std is not None:
        out = correct_lengths(model, robot, out, options, fit.lengths, fit.length_values, fit.chi_std, fit.chi_payload)
    return out


def add_lengths(text: RobotText, lengths: Mapping[tuple[int, str], float]) -> str:
    """Add the length errors (``(frame, field)`` -> error [m]) to the ``d``/``r`` lines of their ``[[frames]]``
    entries in ``text`` (a number gets the sum, an expression ``"RL3"`` becomes ``"RL3 + 0.004"``); returns them
    as text for a header comment. A field not on a line of its own is refused naming the file, frame and field."""
    for (f, fld), v in sorted(lengths.items()):
        text.edit_value(f, fld, partial(_lengthened_value, c=float(v)))
    return ", ".join(f"frame {f} {fld} {1e3 * v:+.4g} mm" for (f, fld), v in sorted(lengths.items()))


def _lengthened_value(old: str, c: float) -> str:
    """The TOML value ``old`` (a number, or a quoted expression) plus ``c``."""
    s = old.strip()
    if s.startswith('"'):
        sign = "-" if c < 0 else "+"
        return f'"{s[1:-1].strip()} {sign} {format_number(abs(c))}"'
    return format_number(float(s) + c)
