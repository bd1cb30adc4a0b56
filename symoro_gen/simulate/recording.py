"""Synthetic recordings: torques of a known model along a known motion, with gains and noise."""
from __future__ import annotations

import io
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, TypedDict

import numpy as np

from ..atomic import check_replaceable, write_text_atomic
from ..description.model import RobotDescription
from ..dynamics.numeric import inverse_dynamics
from ..preprocessing.drive_chain import joint_to_motor
from ..preprocessing.trajectory import Trajectory

if TYPE_CHECKING:
    from typing_extensions import Unpack

__all__ = ["true_torques", "simulate_recording", "write_recording_csv", "RecordingOptions", "RecordingSettings"]


class RecordingOptions(TypedDict, total=False):
    """How :func:`simulate_recording` logs the motion: the keywords of :class:`RecordingSettings`."""

    gains: Any
    noise_q: Any
    noise_tau: Any
    keep_derivatives: bool
    drive_chain: Any
    chunk_samples: int


@dataclass(frozen=True, eq=False)
class RecordingSettings:
    """How a simulated recording is logged.

    Attributes
    ----------
    gains : float or array_like (n,), optional
        Torque-sensor / drive gains (default 1): ``tau_measured = tau_true / gains``.
    noise_q, noise_tau : float or array_like (n,)
        Standard deviations of white Gaussian noise on positions [rad] and on the recorded torque signal.
    keep_derivatives : bool
        Also store the true ``dq``, ``ddq`` in the trajectory (default: only ``t, q, tau`` as a logger would).
    drive_chain : DriveChain, optional
        Return motor-side positions and torques (to test the loaders' drive-chain mapping).
    chunk_samples : int
        Samples per evaluation of the torques (:func:`true_torques`).
    """

    gains: Any = None
    noise_q: Any = 0.0
    noise_tau: Any = 0.0
    keep_derivatives: bool = False
    drive_chain: Any = None
    chunk_samples: int = 50_000

    @classmethod
    def of(cls, function: str, keywords: Mapping[str, Any]) -> RecordingSettings:
        """The settings of the keywords given to ``function`` (an unknown keyword is the TypeError Python
        raises for it)."""
        names = {f.name for f in fields(cls)}
        unknown = [k for k in keywords if k not in names]
        if unknown:
            raise TypeError(f"{function}() got an unexpected keyword argument {unknown[0]!r}")
        return cls(**keywords)


def true_torques(model_or_robot, q, dq, ddq, chi_std, chi_payload=None, *, chunk_samples: int = 50_000):
    """Joint torques ``tau = IDM(q, dq, ddq) chi`` (+ payload) in chunks of samples.

    Parameters
    ----------
    model_or_robot : RobotDescription or model
        A robot description (exact numeric Newton-Euler,
        :func:`symoro_gen.dynamics.numeric.inverse_dynamics`) or a model with ``torque(q, dq, ddq, chi_std)``
        (and ``payload_regressor`` when ``chi_payload`` is given).
    q, dq, ddq : array_like, shape (N, n)
    chi_std : array_like, shape (n_st,)
        Standard parameters (``STANDARD_NAMES`` / ``robot.standard_names`` order).
    chi_payload : array_like, shape (10,), optional

    Returns
    -------
    ndarray, shape (N, n)
    """
    q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
    chi = np.asarray(chi_std, float)
    pay = None if chi_payload is None else np.asarray(chi_payload, float)
    N = q.shape[0]
    out = np.empty_like(q)
    for s in range(0, N, max(1, int(chunk_samples))):
        e = min(N, s + chunk_samples)
        a, b, c = q[s:e], dq[s:e], ddq[s:e]
        if isinstance(model_or_robot, RobotDescription):
            if pay is not None and model_or_robot.payload is None:
                raise ValueError(f"robot {model_or_robot.name} has no payload frame; chi_payload must be None")
            out[s:e] = inverse_dynamics(model_or_robot, a, b, c, chi, pay)
        else:
            tau = np.asarray(model_or_robot.torque(a, b, c, chi), float)
            if pay is not None:
                tau = tau + np.asarray(model_or_robot.payload_regressor(a, b, c), float) @ pay
            out[s:e] = tau
    return out


def simulate_recording(model_or_robot, t, q, dq, ddq, chi_std, *, chi_payload=None,
                       rng: np.random.Generator | None = None, source: str = "<simulated>", loaded: bool | None = None,
                       **logging: Unpack[RecordingOptions]) -> Trajectory:
    """A recording as a controller would log it, from a known model and motion.

    ``tau_measured = tau_true / gains + noise_tau * N(0, 1)``, ``q_measured = q + noise_q * N(0, 1)``:
    a gain ``g_j != 1`` models a torque-sensor gain (LWR4 paper eq. 4, ``tau = g v``) or a drive gain
    (RX-90 paper eq. 13), so identifying ``g`` from the recording recovers the value given here.

    Parameters
    ----------
    model_or_robot : RobotDescription or model
        See :func:`true_torques`.
    t : array_like, shape (N,)
        Time [s].
    q, dq, ddq : array_like, shape (N, n)
        The true motion (e.g. from :func:`fourier_trajectory` or :func:`ptp_trajectory`).
    chi_std : array_like, shape (n_st,)
        True standard parameters.
    chi_payload : array_like, shape (10,), optional
        True payload parameters; the recording is then ``loaded`` (unless told otherwise).
    rng : numpy.random.Generator
        Required when there is noise.
    source : str
        Name of the recording (messages).
    loaded : bool, optional
        Default: ``chi_payload is not None``.
    **logging
        How the motion is logged (:class:`RecordingSettings`): ``gains``, ``noise_q``, ``noise_tau``,
        ``keep_derivatives``, ``drive_chain``, ``chunk_samples``.

    Returns
    -------
    Trajectory
        ``meta`` holds ``simulated``, ``gains``, ``noise_q``, ``noise_tau``.
    """
    log = RecordingSettings.of("simulate_recording", logging)
    gains, noise_q, noise_tau, drive_chain = log.gains, log.noise_q, log.noise_tau, log.drive_chain
    q = np.atleast_2d(np.asarray(q, float))
    N, n = q.shape
    tau = true_torques(model_or_robot, q, dq, ddq, chi_std, chi_payload, chunk_samples=log.chunk_samples)
    g = np.ones(n) if gains is None else np.broadcast_to(np.asarray(gains, float), (n,)).copy()
    if np.any(g == 0) or not np.all(np.isfinite(g)):
        raise ValueError(f"gains must be finite and non-zero, got {gains!r}")
    tau_meas = tau / g
    nq = np.broadcast_to(np.asarray(noise_q, float), (n,))
    nt = np.broadcast_to(np.asarray(noise_tau, float), (n,))
    if (np.any(nq != 0) or np.any(nt != 0)) and rng is None:
        raise ValueError("noise requested: pass rng=np.random.default_rng(seed)")
    q_meas = q
    if np.any(nq != 0):
        assert rng is not None  # checked above
        q_meas = q + rng.standard_normal(q.shape) * nq
    if np.any(nt != 0):
        assert rng is not None
        tau_meas = tau_meas + rng.standard_normal(tau_meas.shape) * nt
    dq_out = np.asarray(dq, float) if log.keep_derivatives else None
    ddq_out = np.asarray(ddq, float) if log.keep_derivatives else None
    if drive_chain is not None:
        q_meas, tau_meas, dq_out, ddq_out = joint_to_motor(drive_chain, q_meas, tau_meas, dq_out, ddq_out)
    meta = {"simulated": True, "gains": g.tolist(), "noise_q": nq.tolist(), "noise_tau": nt.tolist(),
            "motor_side": drive_chain is not None}
    return Trajectory(t=np.asarray(t, float), q=q_meas, tau=tau_meas, dq=dq_out, ddq=ddq_out, source=source,
                      loaded=(chi_payload is not None) if loaded is None else bool(loaded), meta=meta)


def write_recording_csv(path, recording: Trajectory, *, force: bool = False) -> None:
    """Write a recording as the CSV that ``symoro-gen identify`` reads: ``t,q1..qn,tau1..taun``.

    One header line, then one row per sample (full precision), written atomically. An existing file is
    never replaced without ``force`` (it may be a measured recording: its format is the same).

    Parameters
    ----------
    path : str or PathLike
    recording : Trajectory
        Its ``t``, ``q`` and ``tau`` are written (velocities and accelerations are not).
    force : bool
        Replace an existing file.

    Raises
    ------
    OutputError
        ``path`` exists and ``force`` is false (nothing written).
    """
    check_replaceable(path, force, owner="never", label="recording")
    n = recording.q.shape[1]
    head = ",".join(["t"] + [f"q{j + 1}" for j in range(n)] + [f"tau{j + 1}" for j in range(n)])
    buf = io.StringIO()
    np.savetxt(buf, np.column_stack([recording.t, recording.q, recording.tau]), delimiter=",", header=head,
               comments="")
    write_text_atomic(path, buf.getvalue())
