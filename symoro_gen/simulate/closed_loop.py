"""Forward dynamics from an identification model and a closed-loop (PID-controlled) robot simulator.

The direct dynamic model is obtained from the inverse one without new symbolic code (Khalil &
Dombre 2002, ch. 9, "computation of the direct dynamic model using the inverse one"): the IDM is
linear in the accelerations, ``tau = W(q, dq, ddq) chi = M(q) ddq + h(q, dq)``, so

* ``h(q, dq) = W(q, dq, 0) chi`` (Coriolis, centrifugal, gravity, friction, offsets),
* column ``i`` of ``M(q)`` is ``W(q, dq, e_i) chi - h(q, dq)``,
* ``ddq = M(q)^-1 (tau - h(q, dq))``.

One call of ``model.regressor`` with ``n + 1`` samples gives ``M`` and ``h`` at one state.

The closed-loop simulator reproduces what DIDIM (Gautier, Janot, Vandanjon 2013, [GJV2013]) and
IDIM-IV (Janot, Vandanjon, Gautier 2014, [JVG2014]) need: the robot, with parameters ``chi``,
tracking a reference ``q_r(t)`` with a digital PID position controller running at the data rate

    tau_k = Kp (q_r,k - q_k) + Kd (dq_r,k - dq_k) + Ki sum_{i<=k} (q_r,i - q_i) dt  [+ tau_ff,k]

held constant over each sampling period (zero-order hold), the plant integrated by fixed-step RK4
with ``substeps`` steps per period. The Coulomb friction ``FS sign(dq)`` is smoothed to
``FS tanh(dq / friction_eps)`` during integration (the sign makes the ODE discontinuous).
The recorded states satisfy ``tau_k = M(q_k) ddq_k + h(q_k, dq_k)`` exactly (with the smoothed
friction), and ``ddq_k`` is the acceleration at sample ``k``.
"""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from ..errors import IdentificationError
from ..model import IdentificationModel

__all__ = ["FRICTION_EPS", "DEFAULT_BANDWIDTH_HZ", "ClosedLoopResult", "ForwardDynamics", "PIDGains", "parameter_vector",
           "default_gains", "simulate_closed_loop"]

#: default smoothing velocity of the Coulomb friction during integration [rad/s or m/s]
FRICTION_EPS = 0.02
#: default closed-loop bandwidth of :func:`default_gains` [Hz] (capped at rate / 30, lowered for coupled joints)
DEFAULT_BANDWIDTH_HZ = 10.0
#: most RK4 substeps per sampling period chosen automatically
MAX_SUBSTEPS = 64


def parameter_vector(model: IdentificationModel, theta) -> np.ndarray:
    """Base-parameter vector (``model.BASE_NAMES`` order) from a vector or a name -> value mapping
    (missing names count as 0, e.g. the parameters cancelled by the essential procedure)."""
    names = tuple(model.BASE_NAMES)
    if isinstance(theta, Mapping):
        unknown = [k for k in theta if k not in names and k not in tuple(model.PAYLOAD_NAMES)]
        if unknown:
            raise IdentificationError(f"parameters {unknown} are not base parameters of {model.ROBOT}")
        return np.array([float(theta.get(n, 0.0)) for n in names])
    v = np.asarray(theta, float).reshape(-1)
    if v.size != len(names):
        raise IdentificationError(f"{v.size} parameter values for the {len(names)} base parameters of {model.ROBOT}")
    if not np.all(np.isfinite(v)):
        raise IdentificationError("the base-parameter vector has non-finite values")
    return v


class ForwardDynamics:
    """Direct dynamic model ``ddq = M(q)^-1 (tau - h(q, dq))`` of a model with given base parameters.

    Parameters
    ----------
    model : IdentificationModel
    theta : array_like (len(BASE_NAMES),) or mapping name -> value
        Base parameters.
    friction_eps : float
        Coulomb friction smoothing: the columns of the parameters named ``FS*`` (``sign(dq_j)``) are
        multiplied by ``|tanh(dq_j / friction_eps)|``; 0 keeps the exact sign.
    """

    def __init__(self, model: IdentificationModel, theta, *, friction_eps: float = FRICTION_EPS):
        self.model = model
        self.n = int(model.N_JOINTS)
        self.theta = parameter_vector(model, theta)
        if not (friction_eps >= 0 and math.isfinite(friction_eps)):
            raise IdentificationError(f"friction_eps must be >= 0 and finite, got {friction_eps!r}")
        self.friction_eps = float(friction_eps)
        names = tuple(model.BASE_NAMES)
        fs = [i for i, nm in enumerate(names) if nm.upper().startswith("FS")]
        # joint of each Coulomb column: the digits after "FS" (FS3 -> joint index 2)
        joints = []
        for i in fs:
            digits = "".join(ch for ch in names[i][2:] if ch.isdigit())
            joints.append(int(digits) - 1 if digits else -1)
        keep = [(i, j) for i, j in zip(fs, joints) if 0 <= j < self.n]
        self._fs_cols = np.array([i for i, _ in keep], int)
        self._fs_joint = np.array([j for _, j in keep], int)
        self._eye = np.eye(self.n)
        self._Q = np.empty((self.n + 1, self.n))
        self._DQ = np.empty((self.n + 1, self.n))
        self._DDQ = np.vstack([np.zeros(self.n), self._eye])

    def _smooth_theta(self, dq: np.ndarray) -> np.ndarray:
        """(n,) parameter vector per sample where FS columns are scaled by |tanh(dq_j/eps)|."""
        if self.friction_eps == 0 or self._fs_cols.size == 0:
            return self.theta
        th = self.theta.copy()
        th[self._fs_cols] *= np.abs(np.tanh(dq[self._fs_joint] / self.friction_eps))
        return th

    def mass_and_bias(self, q, dq) -> tuple[np.ndarray, np.ndarray]:
        """``M(q)`` (n, n) and ``h(q, dq)`` (n,) at one state (one regressor call, n + 1 samples)."""
        self._Q[:] = q
        self._DQ[:] = dq
        W = np.asarray(self.model.regressor(self._Q, self._DQ, self._DDQ), float)
        tau = W @ self._smooth_theta(self._DQ[0])
        h = tau[0]
        M = (tau[1:] - h).T
        return 0.5 * (M + M.T), h

    def mass_matrix(self, q) -> np.ndarray:
        """Inertia matrix ``M(q)``, shape (n, n)."""
        return self.mass_and_bias(q, np.zeros(self.n))[0]

    def acceleration(self, q, dq, tau, check: bool = True) -> np.ndarray:
        """``ddq = M(q)^-1 (tau - h(q, dq))``, shape (n,).

        Parameters
        ----------
        check : bool
            Check that ``M(q)`` is positive definite (Cholesky) first.

        Raises
        ------
        IdentificationError
            ``M(q)`` is not positive definite (parameters that are not physical).
        """
        M, h = self.mass_and_bias(q, dq)
        if check:
            try:
                np.linalg.cholesky(M)
            except np.linalg.LinAlgError:
                raise IdentificationError(
                    f"the inertia matrix of these parameters is not positive definite at q = "
                    f"{np.round(np.asarray(q, float), 4).tolist()}: cannot simulate (eigenvalues "
                    f"{np.round(np.linalg.eigvalsh(M), 6).tolist()})") from None
        return np.linalg.solve(M, np.asarray(tau, float) - h)

    def stiffness(self, q, dq, delta: float = 1e-4) -> float:
        """Largest ``|eig(M^-1 dh/ddq)|`` at one state [1/s]: the fastest velocity mode (friction,
        Coriolis) an explicit integration step must resolve."""
        M, h = self.mass_and_bias(q, dq)
        D = np.empty((self.n, self.n))
        for i in range(self.n):
            _, hi = self.mass_and_bias(q, dq + delta * self._eye[i])
            D[:, i] = (hi - h) / delta
        try:
            A = np.linalg.solve(M, D)
        except np.linalg.LinAlgError:
            return math.inf
        return float(np.max(np.abs(np.linalg.eigvals(A))))


@dataclass(frozen=True)
class PIDGains:
    """Per-joint gains of the digital position controller (SI units: N m/rad, N m s/rad, N m/(rad s)).

    Attributes
    ----------
    kp, kd, ki : ndarray, shape (n,)
    """

    kp: np.ndarray
    kd: np.ndarray
    ki: np.ndarray

    def __post_init__(self) -> None:
        n = np.asarray(self.kp, float).reshape(-1).size
        for f in ("kp", "kd", "ki"):
            a = np.broadcast_to(np.asarray(getattr(self, f), float).reshape(-1), (n,)).copy()
            if not np.all(np.isfinite(a)) or np.any(a < 0):
                raise IdentificationError(f"controller gain {f} must be finite and >= 0, got {a.tolist()}")
            object.__setattr__(self, f, a)

    @property
    def n_joints(self) -> int:
        return int(self.kp.size)

    def to_dict(self) -> dict:
        return {"kp": self.kp.tolist(), "kd": self.kd.tolist(), "ki": self.ki.tolist()}


def default_gains(model: IdentificationModel, theta, q_ref, dt: float, *, bandwidth_hz: float | None = None,
                  damping: float = 1.0, friction_eps: float = FRICTION_EPS, max_rate_product: float = 1.0) -> PIDGains:
    """PD gains placing each joint, decoupled, at ``bandwidth_hz`` with damping ``damping``.

    ``Kp_j = m_j w^2``, ``Kd_j = 2 zeta w m_j``, ``Ki_j = 0``, with ``w = 2 pi f`` and ``m_j`` the smallest
    inertia seen by joint j alone, ``1 / (M(q)^-1)_jj``, over (up to 30) samples of ``q_ref``;
    ``f = bandwidth_hz`` (default :data:`DEFAULT_BANDWIDTH_HZ`), capped at ``1 / (30 dt)`` and lowered
    until the fastest velocity mode of the coupled loop, ``max_q rho(M(q)^-1 Kd) dt``, is at most
    ``max_rate_product`` (the held torque of a digital loop is unstable beyond about 2).

    Returns
    -------
    PIDGains
    """
    fd = ForwardDynamics(model, theta, friction_eps=friction_eps)
    q_ref = np.atleast_2d(np.asarray(q_ref, float))
    idx = np.unique(np.linspace(0, q_ref.shape[0] - 1, min(30, q_ref.shape[0])).astype(int))
    Minv = [np.linalg.pinv(fd.mass_matrix(q_ref[i])) for i in idx]
    m = np.min([1.0 / np.abs(np.diag(Mi)) for Mi in Minv], axis=0)
    f = min(DEFAULT_BANDWIDTH_HZ if bandwidth_hz is None else float(bandwidth_hz), 1.0 / (30.0 * dt))
    w = 2 * math.pi * f
    rho = max(float(np.max(np.abs(np.linalg.eigvals(Mi * (2 * damping * w * m)[None, :])))) for Mi in Minv) * dt
    if rho > max_rate_product:
        w *= max_rate_product / rho
    return PIDGains(kp=m * w * w, kd=2 * damping * w * m, ki=np.zeros_like(m))


@dataclass(frozen=True, eq=False)
class ClosedLoopResult:
    """A simulated closed-loop run, sampled at the reference's instants.

    Attributes
    ----------
    t : ndarray (N,)
    q, dq, ddq : ndarray (N, n)
        Simulated (noise-free) states; ``ddq[k]`` is the acceleration at ``t[k]`` under ``tau[k]``.
    tau : ndarray (N, n)
        Controller output (the joint torque), held over ``[t_k, t_k+1)``.
    q_ref, dq_ref : ndarray (N, n)
    substeps : int
        RK4 steps per sampling period.
    """

    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    tau: np.ndarray
    q_ref: np.ndarray
    dq_ref: np.ndarray
    substeps: int

    def tracking_error(self) -> np.ndarray:
        """RMS of ``q_ref - q`` per joint."""
        return np.sqrt(np.mean((self.q_ref - self.q) ** 2, axis=0))


def _auto_substeps(fd: ForwardDynamics, q_ref, dq_ref, dt: float) -> int:
    idx = np.unique(np.linspace(0, q_ref.shape[0] - 1, min(12, q_ref.shape[0])).astype(int))
    lam = 0.0
    for i in idx:
        for v in (dq_ref[i], np.zeros(fd.n)):  # at rest the smoothed Coulomb slope is steepest
            lam = max(lam, fd.stiffness(q_ref[i], v))
    if not math.isfinite(lam):
        return MAX_SUBSTEPS
    # RK4 is stable on the negative real axis for h*lam < 2.78; keep a margin
    return int(min(MAX_SUBSTEPS, max(1, math.ceil(dt * lam / 2.0))))


def simulate_closed_loop(model: IdentificationModel, theta, t, q_ref, dq_ref=None, *, gains: PIDGains | None = None,
                         q0=None, dq0=None, tau_ff=None, friction_eps: float = FRICTION_EPS,
                         substeps: int | None = None, max_tracking_error: float = math.pi) -> ClosedLoopResult:
    """Simulate the robot tracking ``q_ref`` under a digital PID controller (see the module docstring).

    Parameters
    ----------
    model : IdentificationModel
    theta : array_like or mapping
        Base parameters of the simulated robot (``BASE_NAMES`` order or name -> value).
    t : array_like (N,)
        Sampling instants [s]; the controller runs at the median step ``dt`` (a logger's time-stamp
        jitter is ignored, as the filters of the assembly do).
    q_ref : array_like (N, n)
        Reference positions.
    dq_ref : array_like (N, n), optional
        Reference velocities (default: central differences of ``q_ref``).
    gains : PIDGains, optional
        Default :func:`default_gains` (PD at 10 Hz computed from ``theta``).
    q0, dq0 : array_like (n,), optional
        Initial state (default ``q_ref[0]``, ``dq_ref[0]``).
    tau_ff : array_like (N, n), optional
        Feed-forward torque added to the controller output.
    friction_eps : float
        Coulomb smoothing velocity (:class:`ForwardDynamics`).
    substeps : int, optional
        RK4 steps per sampling period; default from the fastest velocity mode along the reference
        (``ceil(dt * lambda / 2)``, at most :data:`MAX_SUBSTEPS`).
    max_tracking_error : float
        The simulation stops with an error when ``|q_ref - q|`` exceeds this [rad or m] (diverged).

    Returns
    -------
    ClosedLoopResult

    Raises
    ------
    IdentificationError
        Bad shapes, non-physical parameters (``M`` not positive definite) or a diverging simulation.
    """
    t = np.asarray(t, float).reshape(-1)
    q_ref = np.atleast_2d(np.asarray(q_ref, float))
    n = int(model.N_JOINTS)
    N = t.size
    if q_ref.shape != (N, n):
        raise IdentificationError(f"q_ref has shape {q_ref.shape}, expected ({N}, {n}) for {N} instants of {model.ROBOT}")
    if N < 3:
        raise IdentificationError("the reference needs at least 3 samples")
    dt = float(np.median(np.diff(t)))
    if not (dt > 0 and math.isfinite(dt)):
        raise IdentificationError("the instants t must increase")
    dq_ref = np.gradient(q_ref, dt, axis=0) if dq_ref is None else np.atleast_2d(np.asarray(dq_ref, float))
    if dq_ref.shape != (N, n):
        raise IdentificationError(f"dq_ref has shape {dq_ref.shape}, expected ({N}, {n})")
    ff = np.zeros((N, n)) if tau_ff is None else np.atleast_2d(np.asarray(tau_ff, float))
    if ff.shape != (N, n):
        raise IdentificationError(f"tau_ff has shape {ff.shape}, expected ({N}, {n})")
    fd = ForwardDynamics(model, theta, friction_eps=friction_eps)
    if gains is None:
        gains = default_gains(model, fd.theta, q_ref, dt, friction_eps=friction_eps)
    if gains.n_joints != n:
        raise IdentificationError(f"{gains.n_joints} controller gains for {n} joints")
    ns = _auto_substeps(fd, q_ref, dq_ref, dt) if substeps is None else int(substeps)
    if ns < 1:
        raise IdentificationError(f"substeps must be >= 1, got {substeps}")
    h = dt / ns
    q = np.empty((N, n))
    dq = np.empty((N, n))
    ddq = np.empty((N, n))
    tau = np.empty((N, n))
    x = np.asarray(q_ref[0] if q0 is None else q0, float).reshape(n).copy()
    v = np.asarray(dq_ref[0] if dq0 is None else dq0, float).reshape(n).copy()
    integ = np.zeros(n)
    acc = fd.acceleration
    for k in range(N):
        e = q_ref[k] - x
        if not (np.all(np.isfinite(e)) and np.max(np.abs(e)) <= max_tracking_error):
            raise IdentificationError(
                f"the closed-loop simulation diverged at t = {t[k] - t[0]:.4g} s from its start (tracking error "
                f"{np.round(e, 3).tolist()}): parameters far from physical, or gains too high for the rate")
        integ += e * dt
        u = gains.kp * e + gains.kd * (dq_ref[k] - v) + gains.ki * integ + ff[k]
        q[k], dq[k], tau[k] = x, v, u
        a1 = acc(x, v, u)
        ddq[k] = a1
        if k == N - 1:
            break
        try:
            for s in range(ns):
                if s:
                    a1 = acc(x, v, u, False)
                k1x, k1v = v, a1
                k2x, k2v = v + 0.5 * h * k1v, acc(x + 0.5 * h * k1x, v + 0.5 * h * k1v, u, False)
                k3x, k3v = v + 0.5 * h * k2v, acc(x + 0.5 * h * k2x, v + 0.5 * h * k2v, u, False)
                k4x, k4v = v + h * k3v, acc(x + h * k3x, v + h * k3v, u, False)
                x = x + h / 6 * (k1x + 2 * k2x + 2 * k3x + k4x)
                v = v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
        except np.linalg.LinAlgError:
            raise IdentificationError(
                f"the inertia matrix of these parameters is singular near t = {t[k] - t[0]:.4g} s from the start: "
                f"cannot simulate") from None
    return ClosedLoopResult(t=t, q=q, dq=dq, ddq=ddq, tau=tau, q_ref=q_ref, dq_ref=dq_ref, substeps=ns)
