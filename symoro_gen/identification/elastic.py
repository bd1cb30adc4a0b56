"""Elastic joints in identification: link positions from motor-side ones, and the joint stiffness and damping
from two-encoder recordings.

Spong's flexible-joint model ([Spong1987]): the transmission of an elastic joint passes to the link the torque
``tau = K (theta - q) + D (dtheta - dq)``, ``theta = q_m / N`` the motor position seen on the joint side.

* :func:`link_side` (``identify --positions motor``): the recordings' positions are motor-side (``q_m / N``,
  the LWR4's); the link positions used by the model are ``q = positions - tau / K`` on the declared elastic
  joints ([LWR4-TLS] eq. 17), their velocities and accelerations then come from the corrected ``q`` through the
  usual filter chain (the recorded ones are dropped).
* :func:`estimate_stiffness` (two-encoder logs, a ``q_link`` column beside the motor positions): ``K`` and ``D``
  of each declared elastic joint by linear least squares of the transmitted torque ``tau`` on the deflection
  ``delta = q_m / N - q_link`` and its rate, ``tau = K delta + D ddelta + c`` (``c``: a torque offset), with the
  OLS standard deviations from the residual ([GB-gains] eq. 17-21).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..description.elastic import ElasticJoint
from ..description.model import RobotDescription
from ..errors import OptionError
from ..preprocessing.filtering import lowpass_positions
from ..preprocessing.trajectory import Trajectory
from .result import json_float

__all__ = ["POSITION_SIDES", "StiffnessEstimate", "elastic_columns", "estimate_stiffness", "link_side"]

#: the values of ``identify --positions``: the logged positions are link-side (default) or motor-side
POSITION_SIDES = ("link", "motor")


def elastic_columns(robot: RobotDescription) -> list[tuple[int, ElasticJoint]]:
    """``(column of the recordings, elastic joint)`` of every declared elastic joint (columns: the model's joints,
    :attr:`RobotDescription.model_joints`)."""
    cols = {r.j: i for i, r in enumerate(robot.model_joints)}
    return [(cols[e.joint], e) for e in robot.elastic if e.joint in cols]


def _require_elastic(robot: RobotDescription, what: str) -> list[tuple[int, ElasticJoint]]:
    cols = elastic_columns(robot)
    if not cols:
        raise OptionError(f"{what}: robot {robot.name} ({robot.file}) declares no elastic joint: add "
                          "elastic = {K = ...} to the frames of its elastic joints (or at the top level), "
                          "docs/robot-file.md#elastic-joints")
    return cols


def link_side(robot: RobotDescription, trajectories: Sequence[Trajectory]) -> tuple[Trajectory, ...]:
    """The recordings with link positions ``q = positions - tau / K`` on the declared elastic joints ([LWR4-TLS]
    eq. 17; the link lags the motor under load: ``theta - q = tau / K``). Recorded velocities and accelerations
    are dropped, so that the filter chain differentiates the corrected positions. Raises
    :class:`~symoro_gen.errors.OptionError` when the robot declares no elastic joint."""
    cols = _require_elastic(robot, "--positions motor")
    out = []
    for tr in trajectories:
        if tr.deflection is not None:
            raise OptionError(f"--positions motor: {tr.source} has a link-side position (q_link column): the model "
                              "already uses it, leave --positions motor out (K and D are then estimated from the "
                              "two encoders)")
        q = np.array(tr.q, float)
        for i, e in cols:
            q[:, i] = tr.q[:, i] - e.deflection(tr.tau[:, i])
        meta = dict(tr.meta, positions="motor side, corrected by tau/K on joints "
                    + ", ".join(str(e.joint) for _, e in cols))
        out.append(replace(tr, q=q, dq=None, ddq=None, meta=meta))
    return tuple(out)


@dataclass(frozen=True)
class StiffnessEstimate:
    """``K``, ``D`` (and a torque offset) of each declared elastic joint, with OLS standard deviations."""

    joints: tuple[int, ...]
    K: tuple[float, ...]
    K_std: tuple[float, ...]
    D: tuple[float, ...]
    D_std: tuple[float, ...]
    offset: tuple[float, ...]
    declared_K: tuple[float, ...]
    declared_D: tuple[float, ...]
    rel_err: tuple[float, ...]
    samples: int

    def to_dict(self) -> dict:
        """The ``elasticity`` block of identify's JSON (docs/json-output.md)."""
        return {"method": "ols: tau = K delta + D d(delta)/dt + offset, delta = q_motor/N - q_link",
                "samples": self.samples,
                "joints": [{"joint": j, "K": k, "K_std": ks, "D": d, "D_std": ds, "offset": c,
                            "declared_K": dk, "declared_D": dd, "rel_err": json_float(r)}
                           for j, k, ks, d, ds, c, dk, dd, r in zip(self.joints, self.K, self.K_std, self.D,
                                                                     self.D_std, self.offset, self.declared_K,
                                                                     self.declared_D, self.rel_err)]}

    def summary(self) -> str:
        """The text block of ``identify``'s summary."""
        lines = ["Joint stiffness and damping (two encoders: tau = K (q_motor/N - q_link) + D d/dt(...) + offset, "
                 "OLS):",
                 "  joint   K [N m/rad]      sigma      D [N m s/rad]   sigma    declared K, D   rel.err"]
        for j, k, ks, d, ds, dk, dd, r in zip(self.joints, self.K, self.K_std, self.D, self.D_std, self.declared_K,
                                              self.declared_D, self.rel_err):
            lines.append(f"  {j:5d}  {k:12.5g}  {ks:10.3g}  {d:12.5g}  {ds:10.3g}    {dk:g}, {dd:g}   {r:.4f}")
        return "\n".join(lines)


def _rate(t: np.ndarray, x: np.ndarray, cutoff_hz: float | None) -> np.ndarray:
    """Central-difference derivative of ``x`` (optionally low-pass filtered first, zero phase)."""
    if cutoff_hz is not None:
        fs = 1.0 / float(np.median(np.diff(t)))
        if cutoff_hz < 0.45 * fs:
            x = lowpass_positions(x[:, None], fs, cutoff_hz)[:, 0]
    return np.gradient(x, t, axis=0)


def estimate_stiffness(robot: RobotDescription, trajectories: Sequence[Trajectory], *,
                       cutoff_hz: float | None = None) -> StiffnessEstimate:
    """``K``, ``D`` of each declared elastic joint from recordings with a measured deflection
    (:attr:`Trajectory.deflection`: ``q_m / N - q_link``, a two-encoder log read with a ``q_link`` column).

    Per joint, the rows of every recording are stacked: ``tau = K delta + D ddelta/dt + c`` solved by OLS;
    ``sigma^2 = |residual|^2 / (rows - 3)``, the standard deviations the diagonal of ``sigma^2 (A^T A)^-1``
    ([GB-gains] eq. 17-21). ``rel_err`` is ``|residual| / |tau|``. ``cutoff_hz``: low-pass the deflection before
    differentiating it (none by default). Raises :class:`~symoro_gen.errors.OptionError` without elastic joints
    or without a deflection in the recordings.
    """
    cols = _require_elastic(robot, "stiffness from two encoders")
    with_defl = [tr for tr in trajectories if tr.deflection is not None]
    if not with_defl:
        raise OptionError("stiffness from two encoders: no recording has a link-side position (a q_link column "
                          "beside the motor-side q; docs/data-files.md)")
    out: dict[str, list[float]] = {k: [] for k in ("K", "K_std", "D", "D_std", "c", "r")}
    n_rows = 0
    for i, _e in cols:
        A_parts, y_parts = [], []
        for tr in with_defl:
            assert tr.deflection is not None
            d = np.asarray(tr.deflection[:, i], float)
            dd = _rate(tr.t, d, cutoff_hz)
            A_parts.append(np.column_stack([d, dd, np.ones_like(d)]))
            y_parts.append(np.asarray(tr.tau[:, i], float))
        A, y = np.vstack(A_parts), np.concatenate(y_parts)
        n_rows = y.size
        theta, *_ = np.linalg.lstsq(A, y, rcond=None)
        res = y - A @ theta
        dof = max(y.size - A.shape[1], 1)
        s2 = float(res @ res) / dof
        cov = s2 * np.linalg.pinv(A.T @ A)
        std = np.sqrt(np.maximum(np.diag(cov), 0.0))
        out["K"].append(float(theta[0]))
        out["K_std"].append(float(std[0]))
        out["D"].append(float(theta[1]))
        out["D_std"].append(float(std[1]))
        out["c"].append(float(theta[2]))
        ny = float(np.linalg.norm(y))
        out["r"].append(float(np.linalg.norm(res)) / ny if ny > 0 else float("nan"))
    return StiffnessEstimate(joints=tuple(e.joint for _, e in cols), K=tuple(out["K"]), K_std=tuple(out["K_std"]),
                             D=tuple(out["D"]), D_std=tuple(out["D_std"]), offset=tuple(out["c"]),
                             declared_K=tuple(e.K for _, e in cols), declared_D=tuple(e.D for _, e in cols),
                             rel_err=tuple(out["r"]), samples=n_rows)
