"""The identified model at full rate against the raw measured torque (the ``rel_err_raw`` metric).

The papers' relative error norm ``||rho_j|| / ||Y_j||`` (LWR4 paper Table III; RX-90 paper eq. 16-19)
is computed on the filtered, decimated system: the decimation low-pass removes the torque noise above
its cut-off, so that number says how well the model explains the *filtered* torque. What a user
compares with the recording is the torque as measured: ``rel_err_raw`` evaluates the identified model
``IDM(q, dq, ddq) chi`` at every full-rate sample, on the band-pass states of the assembly, against
the unfiltered measured torque ``tau`` (scaled by identified gains, ``tau = g v``, eq. 4 of the RX-90
paper), per joint. The two differ by the torque noise outside the decimated band and by what the
decimation filter smooths.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping

import numpy as np
from numpy.typing import ArrayLike

from ..model import IdentificationModel
from ..preprocessing.filtering import FilterSettings
from ..preprocessing.trajectory import Trajectory
from .assembly import Assembly, ExperimentSignals, iter_kinematics
from .options import AssemblyOptions

__all__ = ["REGRESSOR_BATCH", "full_rate_torque", "raw_error_sums", "raw_error_sums_streamed", "rel_err_raw"]

#: samples per call of the model's regressor: its output (``n nb`` floats per sample, 3.6 MB for a 7-joint arm
#: with 64 base columns) is the transient of :func:`full_rate_torque`; the torques do not depend on the split
REGRESSOR_BATCH = 1024


def full_rate_torque(model: IdentificationModel, theta: Mapping[str, float], q: np.ndarray, dq: np.ndarray,
                     ddq: np.ndarray, loaded: bool = False, *, batch: int = REGRESSOR_BATCH,
                     skip_prefix: tuple[str, ...] = ()) -> np.ndarray:
    """``IDM(q, dq, ddq) chi`` of the declared model (base + payload columns) at every sample (IDIM eq. 2).

    Parameters
    ----------
    model : IdentificationModel
    theta : mapping name -> value
        Parameters by column name (``BASE_NAMES``, ``PAYLOAD_NAMES``); missing ones count as 0.
    q, dq, ddq : ndarray, shape (N, n)
    loaded : bool
        Add the payload columns.
    skip_prefix : tuple of str
        Parameters whose name starts with one of these count as 0 (e.g. ``("FS",)``).

    Returns
    -------
    ndarray, shape (N, n)
    """
    base = tuple(model.BASE_NAMES)
    tb = np.array([0.0 if nm.startswith(skip_prefix) and skip_prefix else float(theta.get(nm, 0.0)) for nm in base])
    pay = tuple(getattr(model, "PAYLOAD_NAMES", ())) if loaded else ()
    tp = np.array([float(theta.get(nm, 0.0)) for nm in pay])
    use_pay = bool(pay) and bool(np.any(tp != 0))
    N = q.shape[0]
    out = np.empty((N, q.shape[1]))
    for s in range(0, N, batch):
        e = min(N, s + batch)
        out[s:e] = np.asarray(model.regressor(q[s:e], dq[s:e], ddq[s:e]), float) @ tb
        if use_pay:
            out[s:e] += np.asarray(model.payload_regressor(q[s:e], dq[s:e], ddq[s:e]), float) @ tp
    return out


def raw_error_sums(model: IdentificationModel, theta: Mapping[str, float], assembly: Assembly, *,
                   gains: ArrayLike | None = None, extra: Callable[[ExperimentSignals], np.ndarray] | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Per joint, ``sum (g_j tau_j - tau_hat_j)^2`` and ``sum (g_j tau_j)^2`` over every full-rate
    sample of the assembly's experiments (edge samples dropped, no row selection).

    Parameters
    ----------
    model : IdentificationModel
    theta : mapping name -> value
        The identified parameters (``IdentificationResult.parameter_map()``).
    assembly : Assembly
        Built with ``keep_signals=True``; payload columns count on loaded experiments when the
        assembly has them.
    gains : array_like, shape (n,), optional
        Per-joint gains applied to the measured torque (``tau = g v``).
    extra : callable, optional
        ``extra(signals) -> (M, n)`` added to the model torque (columns of effects outside the model).

    Returns
    -------
    rho2, y2 : ndarray, shape (n,)
    """
    if not assembly.signals:
        raise ValueError("the assembly kept no signals (AssemblyOptions.keep_signals=False): "
                         "cannot compute the raw-torque error")
    n = assembly.signals[0].q.shape[1]
    g = np.ones(n) if gains is None else np.asarray(gains, float).reshape(-1)[:n]
    rho2, y2 = np.zeros(n), np.zeros(n)
    for sg in assembly.signals:
        pred = full_rate_torque(model, theta, sg.q, sg.dq, sg.ddq,
                                loaded=sg.loaded and assembly.options.payload_columns)
        if extra is not None:
            pred = pred + extra(sg)
        y = sg.tau_raw * g
        rho2 += np.sum((y - pred) ** 2, axis=0)
        y2 += np.sum(y ** 2, axis=0)
    return rho2, y2


def raw_error_sums_streamed(model: IdentificationModel, theta: Mapping[str, float],
                            trajectories: Iterable[Trajectory], options: AssemblyOptions,
                            settings: Iterable[FilterSettings], *, gains: ArrayLike | None = None,
                            batch: int = REGRESSOR_BATCH) -> tuple[np.ndarray, np.ndarray]:
    """:func:`raw_error_sums` without the full-rate signals: the experiments are filtered again block after
    block (:func:`~symoro_gen.observations.assembly.iter_kinematics`, the assembly's blocks) and each block's
    model torque compared with its raw measured torque, so memory stays bounded whatever the length.

    Parameters
    ----------
    trajectories : iterable of Trajectory
        The assembled experiments, in order.
    options : AssemblyOptions
        The assembly's options (payload columns count on loaded experiments when set).
    settings : iterable of FilterSettings
        Each experiment's filters (``ExperimentReport.settings``), not chosen again.
    batch : int
        Samples per regressor call.

    Returns
    -------
    rho2, y2 : ndarray, shape (n,)
    """
    rho2 = y2 = None
    for traj, st in zip(trajectories, settings):
        n = traj.n_joints
        if rho2 is None or y2 is None:
            rho2, y2 = np.zeros(n), np.zeros(n)
        g = np.ones(n) if gains is None else np.asarray(gains, float).reshape(-1)[:n]
        e = st.edge_samples
        for a, b, q, dq, ddq in iter_kinematics(model, traj, options, st):
            pred = full_rate_torque(model, theta, q, dq, ddq, loaded=traj.loaded and options.payload_columns,
                                    batch=batch)
            y = np.asarray(traj.tau[e + a:e + b], float) * g
            rho2 += np.sum((y - pred) ** 2, axis=0)
            y2 += np.sum(y ** 2, axis=0)
    if rho2 is None or y2 is None:
        raise ValueError("raw_error_sums_streamed: no experiment given")
    return rho2, y2


def rel_err_raw(model: IdentificationModel, theta: Mapping[str, float], assemblies: Iterable[Assembly], *,
                gains: ArrayLike | None = None) -> np.ndarray:
    """``||g_j tau_j - IDM_j chi|| / ||g_j tau_j||`` per joint over the full-rate samples of all the
    assemblies (raw measured torque, model on the filtered states), shape (n,)."""
    total = None
    for a in assemblies:
        r, y = raw_error_sums(model, theta, a, gains=gains)
        total = (r, y) if total is None else (total[0] + r, total[1] + y)
    if total is None:
        raise ValueError("no assembly given")
    with np.errstate(divide="ignore", invalid="ignore"):
        out: np.ndarray = np.sqrt(total[0] / total[1])
    return out
