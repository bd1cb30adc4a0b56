"""Recordings of floating-base robots: the log format, its reading and its filtering.

A floating-base log (docs/floating-base.md, "Log format") is a table (``.csv`` and the other delimited texts, or
``.parquet``) with a header naming its columns:

=====================================  ==============================================================================
``t``                                  time [s], strictly increasing
``qx qy qz qw``                        base orientation, unit quaternion (base axes to world axes), from the IMU's
                                       attitude filter or a motion-capture pose
``px py pz``                           optional: base origin in the world [m] (motion capture)
``gyro_x gyro_y gyro_z``               optional: base angular velocity in base axes [rad/s] (IMU gyroscope)
``acc_x acc_y acc_z``                  optional: accelerometer at the base origin, in base axes [m/s^2]: the specific
                                       force ``R^T (a - g)``, ``g`` the robot file's gravity
``q1 .. qn``                           joint positions (the robot's joint order)
``tau1 .. taun``                       optional: joint torques (needed for the joint rows)
``<frame>_fx _fy _fz _mx _my _mz``     per contact frame: the wrench exerted by the environment on the robot, force
                                       then moment about the frame's origin, in the frame's axes (an F/T sensor's;
                                       ``<frame>`` a frame's ``name`` in the robot file or ``frame<j>``)
=====================================  ==============================================================================

Filtering (:func:`filter_floating`), the same cut-off for every signal:

* joint positions: the fixed-base band-pass derivatives ([G1997]; [GB-gains] eq. 14-16: zero-phase Butterworth
  low-pass and central differences), the cut-off and decimation factor by Gautier's rules
  (:func:`~symoro_gen.preprocessing.filtering.choose_filter_settings`) from the joint positions;
* base orientation: **not filtered** as numbers (a quaternion is not a vector: each sample is normalised and used as
  logged). Angular velocity: the gyroscope low-passed by the same Butterworth filter; without a gyroscope (a
  motion-capture pose), the SO(3) log of the relative rotations ``log(R_{k-1}^T R_{k+1}) / (2 dt)`` (central, in
  base axes; [F2008] sec. 2.3 ``exp``/``log`` of SO(3)), low-passed the same way. Angular acceleration: central
  differences of that low-passed angular velocity;
* base linear acceleration: the accelerometer low-passed, plus ``R^T g`` (the classical acceleration of the base
  origin in base axes); without an accelerometer, the second central difference of the low-passed motion-capture
  position, rotated into base axes. The base's linear velocity is set to 0: the dynamics do not depend on it
  once the classical acceleration is given (Galilean invariance, :mod:`symoro_gen.identification.floating`);
* joint torques and contact wrenches: not band-passed; they enter the right-hand side ``Y``, which is decimated in
  parallel with the regressor's columns by the same filter ([GB-gains] eq. 15-16).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..errors import DataFileError, Problem
from .filtering import FilterSettings, choose_filter_settings, differentiate, lowpass_positions
from .readers.common import Table, raise_malformed
from .readers.parquet import is_parquet, read_parquet_table
from .readers.text import TEXT_SUFFIXES, read_table

__all__ = ["FloatingRecording", "FloatingSignals", "read_floating", "filter_floating", "WRENCH_SUFFIXES",
           "quaternion_matrices", "so3_log"]

#: the six columns of a contact frame's wrench, after ``<frame>``
WRENCH_SUFFIXES = ("_fx", "_fy", "_fz", "_mx", "_my", "_mz")
QUATERNION = ("qx", "qy", "qz", "qw")
POSITION = ("px", "py", "pz")
GYRO = ("gyro_x", "gyro_y", "gyro_z")
ACCEL = ("acc_x", "acc_y", "acc_z")
#: a logged quaternion's norm may differ from 1 by this much (it is normalised)
QUATERNION_NORM_TOL = 1e-2


@dataclass(frozen=True, eq=False)
class FloatingRecording:
    """One floating-base log as read (SI units, rows as in the file).

    ``quaternion`` (N, 4) ``x y z w``; ``position``, ``gyro``, ``accel`` (N, 3) or None; ``q`` (N, n); ``tau``
    (N, n) or None; ``contacts`` frame name -> (N, 6); ``unused``: the file's other columns."""

    source: str
    t: NDArray[np.float64]
    quaternion: NDArray[np.float64]
    q: NDArray[np.float64]
    tau: NDArray[np.float64] | None
    position: NDArray[np.float64] | None
    gyro: NDArray[np.float64] | None
    accel: NDArray[np.float64] | None
    contacts: dict[str, NDArray[np.float64]]
    unused: tuple[str, ...] = ()

    @property
    def n_samples(self) -> int:
        return int(self.t.shape[0])


@dataclass(frozen=True, eq=False)
class FloatingSignals:
    """A recording filtered (full rate): the model's ``q`` (N, 7 + n), ``dq``, ``ddq`` (N, 6 + n) in Pinocchio's
    free-flyer conventions, the raw ``tau`` and contact wrenches, the filters, and where the base's rates came
    from (``orientation``: ``"gyroscope"`` or ``"pose (SO(3) log differences)"``; ``acceleration``:
    ``"accelerometer"`` or ``"pose (second differences)"``)."""

    recording: FloatingRecording
    q: NDArray[np.float64]
    dq: NDArray[np.float64]
    ddq: NDArray[np.float64]
    settings: FilterSettings
    orientation: str
    acceleration: str


def _table(path: str) -> Table:
    if not Path(path).exists():
        raise DataFileError([Problem(path, "", "", "file not found")])
    if is_parquet(path):
        return read_parquet_table(path)
    if Path(path).suffix.lower() in TEXT_SUFFIXES:
        tab = read_table(path)
        if tab.names is None:
            raise DataFileError([Problem(path, "line 1", "", "no header line: a floating-base log names its columns "
                                         "(t, qx qy qz qw, gyro_x.., acc_x.., q1..qn, tau1..taun, <frame>_fx..)")])
        raise_malformed(tab)
        return tab
    raise DataFileError([Problem(path, "", "", f"unknown data format {Path(path).suffix!r} for a floating-base log "
                                 "(expected .csv, .txt, .tsv, .dat or .parquet)")])


def _group(tab: Table, names: tuple[str, ...], required: str | None, probs: list[Problem]) -> NDArray[np.float64] | None:
    """The columns ``names`` (all or none), or None; ``required``: what needs them (a missing one is a problem)."""
    have = [n in (tab.names or ()) for n in names]
    if not any(have) and required is None:
        return None
    if not all(have):
        missing = [n for n, h in zip(names, have) if not h]
        why = f" ({required})" if required else f" (the group {' '.join(names)} is given whole or not at all)"
        probs.append(Problem(tab.file, "header", missing[0], f"missing column(s) {', '.join(missing)}{why}"))
        return None
    idx = [(tab.names or []).index(n) for n in names]
    return np.asarray(tab.data[:, idx], float)


def read_floating(path: str | os.PathLike[str], n_joints: int, frames: tuple[str, ...] | None = None
                  ) -> FloatingRecording:
    """Read a floating-base log (module docstring: the columns). ``frames``: the contact frames expected (default:
    every ``<frame>_fx`` group of the header).

    Raises
    ------
    DataFileError
        Naming the file, the column and the rows: a missing column, a non-finite value, a time that does not
        increase, a quaternion far from unit norm, no angular-velocity or acceleration source.
    """
    path = os.fspath(path)
    tab = _table(path)
    names = list(tab.names or [])
    probs: list[Problem] = []
    t = _group(tab, ("t",), "the time", probs)
    quat = _group(tab, QUATERNION, "the base orientation", probs)
    q = _group(tab, tuple(f"q{j}" for j in range(1, n_joints + 1)), f"the {n_joints} joint positions", probs)
    tau = _group(tab, tuple(f"tau{j}" for j in range(1, n_joints + 1)), None, probs)
    pos, gyro, acc = (_group(tab, g, None, probs) for g in (POSITION, GYRO, ACCEL))
    found = tuple(n[: -len("_fx")] for n in names if n.endswith("_fx"))
    wanted = found if frames is None else frames
    contacts = {}
    for f in wanted:
        w = _group(tab, tuple(f + s for s in WRENCH_SUFFIXES), f"the wrench of contact frame {f!r}", probs)
        if w is not None:
            contacts[f] = w
    if gyro is None and pos is None and quat is not None:
        probs.append(Problem(path, "header", "gyro_x", "no angular-velocity source: give gyro_x gyro_y gyro_z, or a "
                             "motion-capture pose (px py pz with the quaternion)"))
    if acc is None and pos is None:
        probs.append(Problem(path, "header", "acc_x", "no base-acceleration source: give acc_x acc_y acc_z, or the "
                             "motion-capture position px py pz"))
    if probs:
        raise DataFileError(probs)
    assert t is not None and quat is not None and q is not None
    _check_values(tab, probs)
    t = t[:, 0]
    bad_t = np.flatnonzero(np.diff(t) <= 0)
    if bad_t.size:
        probs.append(Problem(path, f"line {int(tab.lines[bad_t[0] + 1])}", "t", f"time not strictly increasing "
                             f"({bad_t.size} step(s), the first at row {bad_t[0] + 2})"))
    norm = np.linalg.norm(quat, axis=1)
    off = np.flatnonzero(np.abs(norm - 1) > QUATERNION_NORM_TOL)
    if off.size:
        probs.append(Problem(path, f"line {int(tab.lines[off[0]])}", "qx qy qz qw", f"quaternion of norm "
                             f"{norm[off[0]]:.4g} ({off.size} row(s) beyond 1 +- {QUATERNION_NORM_TOL:g}, the first "
                             f"at row {off[0] + 1})"))
    if probs:
        raise DataFileError(probs)
    used = {"t", *QUATERNION, *(f"q{j}" for j in range(1, n_joints + 1))}
    used |= {f"tau{j}" for j in range(1, n_joints + 1)} if tau is not None else set()
    for group, vals in ((POSITION, pos), (GYRO, gyro), (ACCEL, acc)):
        used |= set(group) if vals is not None else set()
    used |= {f + s for f in contacts for s in WRENCH_SUFFIXES}
    return FloatingRecording(path, t, quat / norm[:, None], q, tau, pos, gyro, acc, contacts,
                             tuple(n for n in names if n not in used))


def _check_values(tab: Table, probs: list[Problem]) -> None:
    """Non-finite values: one problem per column, naming its rows (file lines)."""
    bad = ~np.isfinite(tab.data)
    for c in np.flatnonzero(bad.any(axis=0)):
        rows = np.flatnonzero(bad[:, c])
        probs.append(Problem(tab.file, f"line {int(tab.lines[rows[0]])}", (tab.names or [])[c],
                             f"{rows.size} non-finite value(s), the first at row {rows[0] + 1}"))
    if probs:
        raise DataFileError(probs)


def quaternion_matrices(quat: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(N, 3, 3)`` rotation matrices of unit quaternions ``x y z w`` (base axes to world axes)."""
    x, y, z, w = quat.T
    return np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                     np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                     np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], -2)


def so3_log(R: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(N, 3)``: the rotation vectors of rotation matrices ``(N, 3, 3)`` (SO(3) log, angles below pi)."""
    c = np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)
    angle = np.arccos(c)
    v = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]], -1)
    s = np.sin(angle)
    scale = np.where(s > 1e-9, angle / np.where(s > 1e-9, 2 * s, 1.0), 0.5 + angle ** 2 / 12)
    out: NDArray[np.float64] = v * scale[:, None]
    return out


def _pose_rates(R: NDArray[np.float64], dt: float) -> NDArray[np.float64]:
    """Angular velocity in base axes from orientations: ``log(R_{k-1}^T R_{k+1}) / (2 dt)``, one-sided at the ends."""
    w = np.empty((R.shape[0], 3))
    Rt = np.transpose(R, (0, 2, 1))
    w[1:-1] = so3_log(Rt[:-2] @ R[2:]) / (2 * dt)
    w[0] = so3_log(Rt[:1] @ R[1:2])[0] / dt
    w[-1] = so3_log(Rt[-2:-1] @ R[-1:])[0] / dt
    return w


def filter_floating(rec: FloatingRecording, gravity, *, cutoff_hz: float | None = None, n_d: int | None = None
                    ) -> FloatingSignals:
    """The model's states of a recording (module docstring): joints band-passed, base rates from the gyroscope or
    the pose, base acceleration from the accelerometer or the pose, one Butterworth cut-off for all."""
    dt_all = np.diff(rec.t)
    dt = float(np.median(dt_all))
    fs = 1.0 / dt
    st = choose_filter_settings(fs, rec.q, cutoff_hz=cutoff_hz, n_d=n_d)
    fc, order = st.cutoff_hz, st.order

    def low(x: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.asarray(lowpass_positions(x, fs, fc, order, source=rec.source))

    qf = low(rec.q)
    dqj, ddqj = differentiate(qf, dt), differentiate(qf, dt, second=True)
    R = quaternion_matrices(rec.quaternion)
    Rt = np.transpose(R, (0, 2, 1))
    if rec.gyro is not None:
        w, orientation = low(rec.gyro), "gyroscope"
    else:
        w, orientation = low(_pose_rates(R, dt)), "pose (SO(3) log differences)"
    dw = differentiate(w, dt)
    if rec.accel is not None:
        a = low(rec.accel) + Rt @ np.asarray(gravity, float)
        acceleration = "accelerometer"
    else:
        assert rec.position is not None
        a = np.einsum("kij,kj->ki", Rt, differentiate(low(rec.position), dt, second=True))
        acceleration = "pose (second differences)"
    N = rec.n_samples
    base_pos = rec.position if rec.position is not None else np.zeros((N, 3))
    q = np.hstack([base_pos, rec.quaternion, qf])
    dq = np.hstack([np.zeros((N, 3)), w, dqj])
    ddq = np.hstack([a, dw, ddqj])
    return FloatingSignals(rec, q, dq, ddq, st, orientation, acceleration)
