"""What a recording's joints do beyond their noise: joints that do not move, torques at their limit.

Two checks that the identification commands run on every recording before using it:

* **motion at the noise level** (:func:`noise_level_joints`): a joint held still reads its encoder noise.
  Its positions then have a flat spectrum, which the filters' rule (99.9 % of the position energy below
  ``f_dyn``, :func:`~symoro_gen.preprocessing.filtering.estimate_dynamics_bandwidth`) would read as a
  bandwidth at the Nyquist frequency: no low-pass, no decimation, the accelerations of every joint
  differentiated noise. Definition: the noise of joint j is the standard deviation of its white
  measurement noise estimated from the second differences of ``q_j`` (``median |Δ²q_j| / (0.6745 √6)``,
  robust to the motion, which is smooth; at least a quantisation step ``/ √12``); its motion is the RMS of
  ``q_j`` about its mean. The joint moves at the noise level when its motion is below ``NOISE_MOTION_FACTOR``
  (30) times its noise: then the noise carries more than 0.1 % of the joint's position energy, the share
  the bandwidth rule leaves above ``f_dyn``. Such a joint is left out of the rule, named in a warning, and
  treated as still by ``--drop-unexcited`` (:func:`hold_still`: its position held at its median, so its
  velocity and acceleration are zero and the parameters of its own motion have zero columns).
* **saturated torque** (:func:`saturation_mask`): samples of ``tau_j`` at the torque limit ``tau_max`` the
  robot file's ``[limits]`` declares, or in a plateau of at least ``SATURATION_RUN`` (5) consecutive samples
  at the column's maximum or minimum (a drive's current limit below the declared one). A clipped torque is not the torque the model
  predicts: the identification is biased unless those rows are left out (``--drop-saturated``: the rows of
  joint j whose decimation filter puts more than 1 % of its weight on saturated samples of ``tau_j``; the
  other joints' rows of the same instants are kept, their torques are measured).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from .trajectory import Trajectory

__all__ = ["NOISE_MOTION_FACTOR", "SATURATION_RUN", "noise_sigma", "motion_rms", "noise_level_joints",
           "hold_still", "saturation_mask", "still_warnings", "saturation_warnings", "still_text", "saturation_text",
           "constant_torque_warnings"]

#: a joint whose position RMS is below this factor x its noise moves at the noise level
NOISE_MOTION_FACTOR = 30.0
#: consecutive samples at a torque column's extreme that make a plateau (saturation without a declared limit)
SATURATION_RUN = 5
#: relative tolerance (of the declared limit, or of the column's range) of "at the limit"
SATURATION_TOL = 1e-6


def noise_sigma(q) -> np.ndarray:
    """Per joint: the standard deviation of white measurement noise on ``q`` (shape (N, n)), from the median
    of the absolute second differences (``Var Δ²e = 6 σ²``), at least the quantisation step / √12."""
    q = np.asarray(q, float)
    if q.ndim == 1:
        q = q[:, None]
    if q.shape[0] < 4:
        return np.zeros(q.shape[1])
    sig, step = np.empty(q.shape[1]), np.zeros(q.shape[1])
    for j in range(q.shape[1]):          # one joint at a time: temporaries of one column, not of the recording
        c = np.ascontiguousarray(q[:, j])
        sig[j] = np.median(np.abs(np.diff(c, n=2))) / (0.6745 * np.sqrt(6.0))
        d1 = np.abs(np.diff(c))
        pos = d1[d1 > 0]
        step[j] = float(pos.min()) if pos.size else 0.0
    return np.maximum(sig, step / np.sqrt(12.0))


def motion_rms(q) -> np.ndarray:
    """Per joint: the RMS of the position about its mean."""
    q = np.asarray(q, float)
    if q.ndim == 1:
        q = q[:, None]
    return np.array([float(np.ascontiguousarray(q[:, j]).std()) for j in range(q.shape[1])])   # one column at a time


def noise_level_joints(q, factor: float = NOISE_MOTION_FACTOR) -> tuple[int, ...]:
    """0-based joints of ``q`` (N, n) whose motion (:func:`motion_rms`) is below ``factor`` x their noise
    (:func:`noise_sigma`); a constant joint is one of them."""
    m, s = motion_rms(q), noise_sigma(q)
    return tuple(int(j) for j in np.flatnonzero(m <= factor * s))


def hold_still(trajectory: Trajectory, joints: Sequence[int]) -> Trajectory:
    """``trajectory`` with the positions of ``joints`` (0-based) held at their median (recorded velocities
    and accelerations of those joints set to zero): a joint that does not move beyond its noise, as still."""
    if not joints:
        return trajectory
    js = list(joints)
    q = np.array(trajectory.q, float)
    q[:, js] = np.median(q[:, js], axis=0)
    kw: dict = {"q": q}
    for k in ("dq", "ddq"):
        a = getattr(trajectory, k)
        if a is not None:
            a = np.array(a, float)
            a[:, js] = 0.0
            kw[k] = a
    return replace(trajectory, **kw)


def _plateaus(x: np.ndarray, at: np.ndarray, run: int) -> np.ndarray:
    """``at`` restricted to its runs of at least ``run`` consecutive True samples."""
    out = np.zeros(x.shape, bool)
    idx = np.flatnonzero(np.diff(np.r_[0, at.astype(np.int8), 0]))
    for a, b in zip(idx[::2], idx[1::2]):
        if b - a >= run:
            out[a:b] = True
    return out


def saturation_mask(tau, tau_max: Sequence[float] | None = None, run: int = SATURATION_RUN) -> np.ndarray:
    """Boolean (N, n): the samples of ``tau`` (N, n) at a torque limit.

    The samples in runs of at least ``run`` consecutive samples at the column's maximum or minimum (to
    ``SATURATION_TOL`` of its range), and with ``tau_max`` (one per joint, the robot file's ``[limits]``)
    those with ``|tau_j| >= tau_max_j`` (to a relative ``SATURATION_TOL``)."""
    tau = np.asarray(tau, float)
    if tau.ndim == 1:
        tau = tau[:, None]
    out = np.zeros(tau.shape, bool)
    for j in range(tau.shape[1]):
        x = tau[:, j]
        if tau_max is not None and j < len(tau_max) and np.isfinite(tau_max[j]) and tau_max[j] > 0:
            out[:, j] = np.abs(x) >= tau_max[j] * (1.0 - SATURATION_TOL)
        lo, hi = float(x.min()), float(x.max())
        if hi - lo <= 0:
            continue
        tol = SATURATION_TOL * (hi - lo)
        out[:, j] |= _plateaus(x, x >= hi - tol, run) | _plateaus(x, x <= lo + tol, run)
    return out


def still_text(q) -> str | None:
    """The joints of ``q`` (N, n) that move at the noise level (:func:`noise_level_joints`) with their motion and
    noise, ``"joint 2 (position RMS 1e-05, noise 1e-05)"``, or None when every joint moves."""
    js = noise_level_joints(q)
    if not js:
        return None
    m, s = motion_rms(q), noise_sigma(q)
    return ", ".join(f"joint {j + 1} (position RMS {m[j]:.2g}, noise {s[j]:.2g})" for j in js)


def saturation_text(tau, tau_max: Sequence[float] | None = None) -> str | None:
    """The torques of ``tau`` (N, n) with saturated samples (:func:`saturation_mask`), their share of the samples
    and how they were found, or None when no sample is at a limit."""
    share = saturation_mask(tau, tau_max).mean(axis=0)
    js = np.flatnonzero(share > 0)
    if not js.size:
        return None
    how = (f"at tau_max of the robot file or in plateaus of >= {SATURATION_RUN} samples" if tau_max is not None
           else f"plateaus of >= {SATURATION_RUN} samples")
    what = ", ".join(f"tau{j + 1} at its limit {100 * share[j]:.1f} % of the samples" for j in js)
    return f"{what} ({how})"


def constant_torque_warnings(trajectories: Sequence[Trajectory]) -> list[str]:
    """One warning per recording and joint whose torque is the same in every sample: no measured torque (a
    channel the logger did not record, the wrong column), naming the file, the joint and the file's column. A
    measured torque varies (noise at least, and the gravity and inertial loads of any motion) [GB-gains] eq. 4."""
    out = []
    for tr in trajectories:
        tau = np.asarray(tr.tau, float)
        if tau.shape[0] < 2:
            continue
        cols = (tr.meta or {}).get("columns", {}).get("tau")
        own = cols if cols and not (tr.meta or {}).get("drive_chain") and len(cols) == tau.shape[1] else None
        for j in np.flatnonzero(np.ptp(tau, axis=0) == 0):
            col = f" (column {own[j]})" if own else ""
            out.append(f"{tr.source}: the torque of joint {j + 1}{col} is constant ({tau[0, j]:g} in every sample): "
                       "not a measured torque (a channel not logged, or the wrong column?); its equations fit "
                       "nothing")
    return out


def still_warnings(trajectories: Sequence[Trajectory], *, held: bool = False, option: bool = True) -> list[str]:
    """One warning per recording with joints that move at the noise level (:func:`noise_level_joints`),
    naming the file, the joints and the option (``held``: ``--drop-unexcited`` was given; ``option`` False: the
    command has no such option, e.g. ``diagnose``, which refuses a joint still in every recording)."""
    out = []
    for tr in trajectories:
        what = still_text(tr.q)
        if what is None:
            continue
        if not option:
            out.append(f"{tr.source}: {what} does not move beyond its noise in this recording: left out of the "
                       "filters' rule; its own parameters are identified from the other recordings")
        elif held:
            out.append(f"{tr.source}: {what} does not move beyond its noise: held still (--drop-unexcited), "
                       "left out of the filters' rule; the parameters of its own motion are not identified")
        else:
            out.append(f"{tr.source}: {what} does not move beyond its noise: left out of the filters' rule; the "
                       "parameters of its own motion (rotor inertia, friction...) are fitted to noise: give "
                       "--drop-unexcited to treat it as still and report them as not identified")
    return out


def saturation_warnings(trajectories: Sequence[Trajectory], tau_max: Sequence[float] | None = None, *,
                        dropped: bool = False) -> list[str]:
    """One warning per recording with saturated torque samples (:func:`saturation_mask`), naming the file, the
    joints with their share of samples and the option (``dropped``: ``--drop-saturated`` was given)."""
    out = []
    for tr in trajectories:
        what = saturation_text(tr.tau, tau_max)
        if what is None:
            continue
        if dropped:
            out.append(f"{tr.source}: {what}: those rows are left out (--drop-saturated)")
        else:
            out.append(f"{tr.source}: {what}: a clipped torque biases the identification: give "
                       "--drop-saturated to leave those rows out")
    return out
