"""Joint zero offsets: their torque column, and which of them torque data can see.

An encoder whose zero is off by ``q0_j`` reads ``q_j = q_true,j - q0_j``; the torque the arm transmits is
that of the true angle, ``tau_true = tau(q + q0_j e_j, dq, ddq)`` (the velocity and acceleration, derivatives of
the angle, are unchanged). To first order in ``q0_j``

    ``tau_true = tau(q) + q0_j d tau / d q_j``,

linear in ``q0_j`` with the column ``d tau / d q_j`` evaluated with the current fit of the dynamic parameters
(Hollerbach & Wampler 1996, "The calibration index and taxonomy for robot kinematic calibration methods",
IJRR 15(6): joint offsets are among the parameters of every kinematic calibration model; Khalil & Dombre 2002,
*Modeling, Identification and Control of Robots*, ch. 11, the geometric calibration model linearised in the
parameter errors). The base-parameter regrouping of a revolute joint does not depend on the joint angle
(Khalil & Dombre, ch. 12), so ``d W_b / d q_j chi`` is the exact derivative of the model torque; for a
prismatic joint ``q0_j`` is a zero error of a length and the same holds.

A zero offset is seen only through the configuration-dependent torque (gravity, inertial coupling): the
first joint of an arm whose axis 1 is vertical changes nothing (its column is 0), the last joint of a chain
only rotates its link's inertial parameters (its column is in the span of the regressor, absorbed by the
base parameters). :func:`joint_zero_visibility` measures this on the generated model.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from dataclasses import replace as dc_replace

import numpy as np

from ..model import IdentificationModel
from ..observations.raw import full_rate_torque
from .frame import build_frame, common_bandwidth

__all__ = ["JOINT_ZERO_STEP", "VISIBILITY_TOL", "describe_zero", "joint_zero_column", "joint_zero_secant",
           "joint_zero_visibility", "invisible_zero_note", "regressor_secant", "JointZeroFit",
           "decimated_zero_matrix", "fit_joint_zeros", "revolute_joints", "visible_zero_joints"]

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


def joint_zero_visibility(model: IdentificationModel, *, rng: np.random.Generator | None = None,
                          n_samples: int = 40, n_theta: int = 3) -> np.ndarray:
    """Per joint, the share of the joint zero column's norm that no base-parameter change can produce: the
    relative norm of its residual after projection on the span of the base regressor, over ``n_samples`` random
    configurations (angles in [-pi, pi], standard normal velocities and accelerations), the smallest over
    ``n_theta`` random base-parameter vectors (a column identically 0 counts 0). 0 (below
    :data:`VISIBILITY_TOL`): torque data cannot see the zero of this joint whatever the parameters (the first
    joint about a vertical axis, the last joint of a chain: its offset rotates only its own link's inertia, which
    the base parameters absorb)."""
    rng = np.random.default_rng(0) if rng is None else rng
    n = int(model.N_JOINTS)
    names = tuple(model.BASE_NAMES)
    q, dq, ddq = _random_motion(n, n_samples, rng)
    W = np.asarray(model.regressor(q, dq, ddq), float).reshape(n_samples * n, len(names))
    U, s, _ = np.linalg.svd(W, full_matrices=False)
    U = U[:, s > s[0] * 1e-10] if s.size and s[0] > 0 else U[:, :0]
    thetas = [dict(zip(names, rng.standard_normal(len(names)))) for _ in range(n_theta)]
    out = np.zeros(n)
    for j in range(n):
        shares = []
        for th in thetas:
            col = joint_zero_column(model, th, q, dq, ddq, j).reshape(-1)
            ref = float(np.linalg.norm(full_rate_torque(model, th, q, dq, ddq, False, skip_prefix=("FS",))))
            nc = float(np.linalg.norm(col))
            if nc <= 1e-9 * max(ref, 1e-300):
                shares.append(0.0)
                continue
            r = col - U @ (U.T @ col)
            shares.append(float(np.linalg.norm(r)) / nc)
        out[j] = min(shares)
    return out


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


def invisible_zero_note(model: IdentificationModel) -> list[str]:
    """One sentence naming the joints whose zero offset torque data cannot see (empty when every joint's can):
    the loop tries no ``joint_zero`` candidate there."""
    seen = set(visible_zero_joints(model))
    hidden = [j + 1 for j in range(int(model.N_JOINTS)) if j not in seen]
    if not hidden:
        return []
    which = ", ".join(str(j) for j in hidden)
    many = len(hidden) > 1
    return [f"the zero offset{'s' if many else ''} of joint{'s' if many else ''} {which} {'are' if many else 'is'} "
            "invisible to torque data (no "
            "configuration-dependent torque changes with the angle, or the base parameters absorb the change: a first joint about "
            "a vertical axis, the last joint of a chain): no joint_zero candidate there"]


def describe_zero(value: float, std: float, revolute: bool) -> dict:
    """Physical reading of a joint zero offset (``rad``/``m`` and, for a revolute joint, degrees)."""
    if revolute:
        return {"offset_rad": float(value), "offset_deg": float(np.degrees(value)),
                "offset_deg_std": float(np.degrees(std))}
    return {"offset_m": float(value), "offset_m_std": float(std)}


# ------------------------------------------------------------------------------------------------
# joint zeros fitted with the dynamic parameters (Gauss-Newton)
# ------------------------------------------------------------------------------------------------
def decimated_zero_matrix(frame, model: IdentificationModel, j: int, c: float = 0.0) -> np.ndarray:
    """``(W(q + c e_j) - W(q)) / c`` (``c = 0``: ``d W / d q_j``) of the frame's columns (base, then payload on
    the loaded experiments), evaluated at full rate on each experiment's signals and decimated in parallel
    with the frame's ``W`` (a :class:`.frame.Frame`), shape (r, len(BASE_NAMES) + len(PAYLOAD_NAMES))."""
    p = len(tuple(model.BASE_NAMES)) + len(tuple(getattr(model, "PAYLOAD_NAMES", ())))

    def f(ex, a: int, b: int) -> np.ndarray:
        dW = regressor_secant(model, ex.q[a:b], ex.dq[a:b], ex.ddq[a:b], j, c, loaded=ex.loaded)
        if dW.shape[2] == p:
            return dW
        out = np.zeros((b - a, ex.q.shape[1], p))
        out[:, :, :dW.shape[2]] = dW   # (payload columns 0 on an unloaded experiment)
        return out

    # over bounded stretches of samples: the full-rate tangent of a 7-joint arm at 1 kHz is ~20 times W
    return frame.full_rate_columns_batched(f, p)


@dataclass(frozen=True)
class JointZeroFit:
    """Joint zero offsets identified with the dynamic parameters.

    Attributes
    ----------
    joints : tuple of int
        0-based joints whose zero was fitted.
    offsets, std : ndarray
        Offsets ``q0`` [rad or m] (``q_true = q_measured + q0``) and their standard deviations (OLS).
    theta : dict
        The frame's parameters (base, payload) fitted at those offsets; ``theta_std`` their standard deviations.
    iterations : int
    converged : bool
    rel_err : ndarray
        Per joint relative error norm of the final fit.
    """

    joints: tuple[int, ...]
    offsets: np.ndarray
    std: np.ndarray
    theta: dict
    theta_std: dict
    iterations: int
    converged: bool
    rel_err: np.ndarray

    def describe(self, revolute: Sequence[bool] | None = None) -> list[str]:
        out = []
        for k, j in enumerate(self.joints):
            rev = True if revolute is None else bool(revolute[j])
            v, s = float(self.offsets[k]), float(self.std[k])
            out.append(f"joint {j + 1} zero offset: {np.degrees(v):.4g} deg (sigma {np.degrees(s):.2g} deg)" if rev
                       else f"joint {j + 1} zero offset: {1e3 * v:.4g} mm (sigma {1e3 * s:.2g} mm)")
        return out


def fit_joint_zeros(model: IdentificationModel, trajectories, joints: Sequence[int] | None = None, *,
                    max_iterations: int = 20, tol: float = 1e-9, dynamics_bandwidth_hz: float | None = None,
                    **filter_kw) -> JointZeroFit:
    """Identify joint zero offsets together with the base parameters by Gauss-Newton on the IDIM equations
    ``Y = W(q + q0) chi``: at each step the observation system is assembled at the corrected angles and
    ``[W, (d W/d q_j) chi]`` is solved for the parameter and offset corrections (the model is linear in ``chi``,
    the offset enters through the joint angle; Khalil & Dombre 2002, ch. 11-12, a calibration model
    linearised in the parameter errors). ``joints`` (0-based): default, those whose zero torque data can see
    (:func:`visible_zero_joints`); an invisible joint is refused."""
    trajs = list(trajectories)
    if max_iterations < 1:
        raise ValueError(f"joint_zero: max_iterations must be at least 1, got {max_iterations}")
    n = int(model.N_JOINTS)
    seen = visible_zero_joints(model)
    js = tuple(seen) if joints is None else tuple(int(j) for j in joints)
    bad = [j + 1 for j in js if not 0 <= j < n]
    if bad:
        raise ValueError(f"joint_zero: joint(s) {bad} outside 1..{n} of {model.ROBOT}")
    hidden = [j + 1 for j in js if j not in seen]
    if hidden:
        raise ValueError(f"joint_zero: the zero offset of joint(s) {hidden} of {model.ROBOT} is invisible to torque "
                         "data (absorbed by the base parameters or no configuration-dependent torque)")
    fdyn = dynamics_bandwidth_hz if dynamics_bandwidth_hz is not None else common_bandwidth(trajs)
    q0 = np.zeros(len(js))
    converged = False
    n_iter = 0
    while n_iter < max_iterations:
        n_iter += 1
        shifted = []
        for tr in trajs:
            q = np.array(tr.q, float, copy=True)
            for k, j in enumerate(js):
                q[:, j] += q0[k]
            shifted.append(dc_replace(tr, q=q))
        F = build_frame(model, shifted, dynamics_bandwidth_hz=fdyn, **filter_kw)
        W, Y = F.system.W, F.system.Y
        names = tuple(F.system.names)
        chi = np.linalg.lstsq(W, Y, rcond=None)[0]
        full = tuple(model.BASE_NAMES) + tuple(getattr(model, "PAYLOAD_NAMES", ()))
        th_full = np.array([dict(zip(names, chi)).get(nm, 0.0) for nm in full])
        D = np.stack([decimated_zero_matrix(F, model, j) @ th_full for j in js], axis=1)
        A = np.hstack([W, D])
        sol = np.linalg.lstsq(A, Y - W @ chi, rcond=None)[0]
        step = sol[W.shape[1]:]
        q0 = q0 + step
        if np.all(np.abs(step) <= tol * max(1.0, float(np.abs(q0).max()))):
            converged = True
            break
    # statistics of the last linearisation (OLS, Gautier 1990: sigma^2 (A^T A)^-1)
    r, p = A.shape
    e = Y - W @ chi - A @ sol
    s2 = float(e @ e) / max(r - p, 1)
    cov = s2 * np.linalg.pinv(A.T @ A)
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    chi_new = chi + sol[:W.shape[1]]
    J = F.system.joint
    num = np.bincount(J, weights=e ** 2, minlength=n)
    den = np.bincount(J, weights=Y ** 2, minlength=n)
    rel = np.sqrt(num / np.maximum(den, 1e-300))
    return JointZeroFit(joints=js, offsets=q0, std=sd[W.shape[1]:], theta=dict(zip(names, chi_new)),
                        theta_std=dict(zip(names, sd[:W.shape[1]])), iterations=n_iter, converged=converged,
                        rel_err=rel)
