"""Physical models of the effects the diagnosis looks for, to inject into simulated recordings.

These are the *true* effects (exact time shift, exact deflection, Stribeck curve on the true
velocity...), written independently of the linearised candidate columns of :mod:`.candidates`,
so that a simulation with an injected effect tests the diagnosis against known truth.

Typical use::

    t, q, dq, ddq = fourier_trajectory(...)
    tau = true_torques(model, q, dq, ddq, chi)
    q_meas, tau_meas = inject_effect("stribeck", t, q, dq, ddq, tau, joint=1, Fst=1.5, vs=0.05)
    tr = Trajectory(t, q_meas + noise, tau_meas + noise)
"""
from __future__ import annotations

import numpy as np

__all__ = ["inject_effect", "EFFECT_PARAMETERS"]

#: parameters of each kind (joint-side SI units)
EFFECT_PARAMETERS = {
    "stribeck": ("Fst [N m] extra static friction", "vs [rad/s] Stribeck velocity"),
    "load_friction": ("mu [-] friction per N m of transmitted torque",),
    "position_ripple": ("amplitude [N m]", "k [-] periods per radian of the joint", "phase [rad]"),
    "spring": ("stiffness [N m/rad]", "q0 [rad] rest position", "cubic [N m/rad^3]"),
    "elasticity": ("K [N m/rad] joint stiffness (the recorded position is q + tau/K)",),
    "time_delay": ("delay [s] (torque recorded late: tau_meas(t) = tau(t - delay))",),
    "gain": ("g [-] gain (tau_meas = tau / g)",),
    "drift": ("rate [N m/s]", "quadratic [N m/s^2]"),
    "coupling": ("partner [0-based joint]", "ia [kg m^2]", "fv [N m s/rad]", "fs [N m]", "shared [bool]"),
    "rotor_inertia": ("ia [kg m^2]",),
    "offset": ("offset [N m]",),
    "joint_zero": ("q0 [rad or m] encoder zero offset (the recorded position is q - q0)",),
}


def inject_effect(kind: str, t, q, dq, ddq, tau, *, joint: int | None, **p):
    """Recorded positions and torques of a robot with an effect its model lacks.

    Parameters
    ----------
    kind : str
        One of :data:`EFFECT_PARAMETERS`.
    t : array_like, shape (N,)
        Time [s].
    q, dq, ddq : array_like, shape (N, n)
        True joint motion.
    tau : array_like, shape (N, n)
        Torques of the declared model (true parameters) along the motion.
    joint : int or None
        0-based joint (None: all joints, for ``time_delay`` and ``gain``).
    **p
        Parameters of the kind (see :data:`EFFECT_PARAMETERS`).

    Returns
    -------
    (q_meas, tau_meas) : ndarrays, shape (N, n)
    """
    t = np.asarray(t, float)
    q = np.array(q, float)
    dq = np.asarray(dq, float)
    ddq = np.asarray(ddq, float)
    tau = np.array(tau, float)
    out_q, out_tau = q.copy(), tau.copy()
    js = list(range(q.shape[1])) if joint is None else [joint]
    if kind == "stribeck":
        for j in js:
            out_tau[:, j] += p["Fst"] * np.exp(-(dq[:, j] / p["vs"]) ** 2) * np.sign(dq[:, j])
    elif kind == "load_friction":
        for j in js:
            out_tau[:, j] += p["mu"] * np.abs(tau[:, j]) * np.sign(dq[:, j])
    elif kind == "position_ripple":
        for j in js:
            out_tau[:, j] += p["amplitude"] * np.sin(p["k"] * q[:, j] + p.get("phase", 0.0))
    elif kind == "spring":
        for j in js:
            x = q[:, j] - p.get("q0", 0.0)
            out_tau[:, j] += p["stiffness"] * x + p.get("cubic", 0.0) * x ** 3
    elif kind == "elasticity":
        for j in js:
            out_q[:, j] = q[:, j] + tau[:, j] / p["K"]
    elif kind == "time_delay":
        d = float(p["delay"])
        for j in js:
            out_tau[:, j] = np.interp(t - d, t, tau[:, j])
    elif kind == "gain":
        for j in js:
            out_tau[:, j] = tau[:, j] / p["g"]
    elif kind == "drift":
        x = t - t[0]
        for j in js:
            out_tau[:, j] += p["rate"] * x + p.get("quadratic", 0.0) * x ** 2
    elif kind == "coupling":
        k = int(p["partner"])
        for j in js:
            if p.get("shared", False):
                a = ddq[:, j] + ddq[:, k]
                v = dq[:, j] + dq[:, k]
                extra = p.get("ia", 0.0) * a + p.get("fv", 0.0) * v + p.get("fs", 0.0) * np.sign(v)
                out_tau[:, j] += extra
                out_tau[:, k] += extra
            else:
                out_tau[:, j] += p.get("ia", 0.0) * ddq[:, k] + p.get("fv", 0.0) * dq[:, k]
    elif kind == "rotor_inertia":
        for j in js:
            out_tau[:, j] += p["ia"] * ddq[:, j]
    elif kind == "offset":
        for j in js:
            out_tau[:, j] += p["offset"]
    elif kind == "joint_zero":
        for j in js:   # the torque is that of the true angle; the encoder reads it q0 short
            out_q[:, j] = q[:, j] - p["q0"]
    else:
        raise ValueError(f"unknown effect kind {kind!r}; known: {', '.join(EFFECT_PARAMETERS)}")
    return out_q, out_tau
