"""Identification of a floating-base robot from base wrenches and joint torques.

The floating-base model (:class:`~symoro_gen.runtime.floating.FloatingModel`, Pinocchio's free-flyer
conventions) has ``6 + n`` rows per sample, the base wrench first. With contact wrenches ``f_c`` exerted by
the environment on the robot at frames ``c`` (force plates, F/T sensors), the equations of motion are

    ``Y_std(q, dq, ddq) chi = S^T tau + sum_c J_c^T f_c``,    ``S = [0_{n x 6}  I_n]``,

``J_c`` the ``6 x (6 + n)`` Jacobian of frame ``c`` in its own axes (Pinocchio's ``LOCAL``) and ``f_c``
(force, then moment about the frame's origin) in the same axes. Their rows are of two kinds
([AVN2014], the base-link equations of motion):

* ``"base"``: the 6 base rows, ``Y_base chi = sum_c J_c,base^T f_c`` (the contact wrenches carried to the base
  origin, in base axes). No joint torque is needed; they identify every identifiable inertial parameter, and
  none of the drive terms (``IA FV FS OFF`` act on the joint rows only).
* ``"joints"``: the ``n`` joint rows, ``Y_joints chi = tau + sum_c J_c,joints^T f_c``. The base link's
  parameters do not appear there.
* ``"both"``: all ``6 + n`` rows, each kind weighted by its own residual standard deviation with ``WLS``
  (RX-90 paper eq. 22 with the kinds, or with ``weighting="row"`` each of the ``6 + n`` row positions, in
  place of the joints).

Each kind is reduced to its own numeric rank: the independent columns of its rows, stacked over the samples,
in standard order (:func:`~symoro_gen.runtime.floating.numeric_base`, Gram-Schmidt [G1991]), and the
relations ``K`` of the others, so that the identified values estimate ``K @ chi_std``. Standard parameters
whose column of ``K`` is zero are reported as not identifiable from those rows. The fit is the fixed-base
estimators' (:func:`~symoro_gen.identification.estimators.fit_ols`, :func:`~.estimators.fit_wls`), with
their statistics ([GB-gains] eq. 17-22) but the covariance of :func:`with_sample_covariance`: the rows of one
sample share their noise (a contact wrench's through ``J_c^T``), the fit takes them as independent.

Base accelerations from an IMU: the model takes Pinocchio's spatial acceleration of the base
(``a - omega x v`` in base axes for a classical acceleration ``a`` of the base origin);
:func:`spatial_base_acceleration` converts. The dynamics do not depend on the base's linear velocity
(Galilean invariance), so with an IMU (no linear velocity) ``v = 0`` and the classical acceleration may be
passed directly. Payload columns are not used yet.
"""
from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation

from ..description.mdh import joint_sign, row_transform
from ..description.model import REVOLUTE, RobotDescription
from ..errors import IdentificationError, ModelError
from ..runtime.floating import FloatingModel, floating_states, numeric_base
from .estimators import REL_STD_WARN_PCT, Options, fit_ols, fit_wls, poorly_identified_warnings, tolerance_keywords
from .observation import ObservationSystem
from .result import IdentificationResult, relative_std_pct

#: the row kinds of :func:`floating_system`
KINDS = ("base", "joints", "both")
#: row groups of the WLS weighting: one per kind, or one per row position (6 base rows, then each joint)
WEIGHTINGS = ("kind", "row")
#: the rows of each kind among the ``6 + n`` rows of a sample
ROWS = {"base": slice(0, 6), "joints": slice(6, None), "both": slice(None)}


@dataclass(frozen=True)
class ContactWrench:
    """A wrench exerted by the environment on the robot at a named frame, per sample.

    Attributes
    ----------
    frame : str
        The frame's name (reported in errors).
    wrench : array (N, 6)
        Force, then moment about the frame's origin, in the frame's axes.
    jacobian : array (N, 6, 6 + n), optional
        The frame's Jacobian in its own axes (Pinocchio ``LOCAL``: linear, then angular velocity of the frame
        from ``dq``). Its first 6 columns carry the wrench to the base (``J_c,base^T f_c``), the others to the
        joints.
    transform : array (N, 4, 4), optional
        In place of the Jacobian, for the base rows only: the frame's pose in base axes (``T_0c``, the
        homogeneous transform from the frame to the base). ``J_c,base^T f_c = (R f, R m + p x R f)``, the
        wrench carried to the base origin ([F2008] sec. 2.8).
    """

    frame: str
    wrench: ArrayLike
    jacobian: ArrayLike | None = None
    transform: ArrayLike | None = None


@dataclass(frozen=True)
class FloatingMeasurements:
    """Samples of a floating-base robot in Pinocchio's free-flyer conventions.

    Attributes
    ----------
    q, dq, ddq : arrays (N, 7 + n), (N, 6 + n), (N, 6 + n)
        As :meth:`FloatingModel.standard_regressor` takes them (base orientation and rates from an IMU or a
        motion-capture pose).
    base_wrench : array (N, 6), optional
        An external wrench already carried to the base origin, in base axes (force, then moment).
    tau : array (N, n), optional
        Joint torques (needed for the ``"joints"`` and ``"both"`` kinds).
    contacts : sequence of ContactWrench
        Contact wrenches at named frames, added to both kinds of rows through their Jacobians.
    """

    q: ArrayLike
    dq: ArrayLike
    ddq: ArrayLike
    base_wrench: ArrayLike | None = None
    tau: ArrayLike | None = None
    contacts: Sequence[ContactWrench] = field(default_factory=tuple)


@dataclass(frozen=True, eq=False)
class FloatingSystem:
    """The system of one kind of rows, reduced to its own numeric rank.

    Attributes
    ----------
    kind : str
    system : ObservationSystem
        Rows grouped by kind (group 0: base rows, 1: joint rows) or by row position (``weighting="row"``);
        columns: the independent standard columns of those rows.
    relations : array (n_identifiable, n_standard)
        ``K``: the identified values estimate ``K @ chi_std``.
    not_identifiable : tuple of str
        Standard parameters whose column of ``K`` is zero (absent from every identifiable combination).
    """

    kind: str
    system: ObservationSystem
    relations: NDArray[np.float64]
    not_identifiable: tuple[str, ...]
    columns: NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))
    #: the number of samples ``N``: row ``r N + s`` of the system is row position ``r`` of sample ``s``
    samples: int = 0


@dataclass(frozen=True, eq=False)
class FloatingIdentification:
    """An identification of one kind of rows: the fixed-base result and the reduction it was made on."""

    kind: str
    result: IdentificationResult
    relations: NDArray[np.float64]
    not_identifiable: tuple[str, ...]
    columns: NDArray[np.intp] = field(default_factory=lambda: np.zeros(0, np.intp))

    def combinations(self, chi_std: ArrayLike) -> NDArray[np.float64]:
        """``K @ chi_std``: what ``result.values`` estimates, for given standard parameters."""
        out: NDArray[np.float64] = self.relations @ np.asarray(chi_std, float)
        return out


def spatial_base_acceleration(dq: ArrayLike, classical: ArrayLike) -> NDArray[np.float64]:
    """The base's spatial linear acceleration ``a - omega x v`` (base axes, rows ``(N, 3)``) of the classical
    acceleration ``a`` of its origin, ``omega = dq[:, 3:6]`` and ``v = dq[:, 0:3]`` ([F2008] sec. 2.11)."""
    d = np.atleast_2d(np.asarray(dq, float))
    a = np.atleast_2d(np.asarray(classical, float))
    out: NDArray[np.float64] = a - np.cross(d[:, 3:6], d[:, 0:3])
    return out


def _array(robot: str, name: str, x: ArrayLike, shape: tuple[int, ...]) -> NDArray[np.float64]:
    a = np.asarray(x, float)
    if a.shape != shape:
        raise IdentificationError(f"{robot}: {name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise IdentificationError(f"{robot}: {name} is not finite at sample {bad[0]}")
    return a


def measured_rows(model: FloatingModel, data: FloatingMeasurements, need_tau: bool) -> NDArray[np.float64]:
    """``(N, 6 + n)``: the right-hand sides ``S^T tau + sum_c J_c^T f_c (+ base_wrench)`` (joint rows zero
    without ``tau`` unless ``need_tau``, which makes a missing ``tau`` an error)."""
    n, robot = model.N_JOINTS, model.ROBOT
    N = np.atleast_2d(np.asarray(data.q, float)).shape[0]
    rows = np.zeros((N, 6 + n))
    if data.base_wrench is not None:
        rows[:, :6] += _array(robot, "base_wrench", data.base_wrench, (N, 6))
    if data.tau is not None:
        rows[:, 6:] += _array(robot, "tau", data.tau, (N, n))
    elif need_tau:
        raise IdentificationError(f"{robot}: the joint rows need joint torques (tau, shape ({N}, {n}))")
    for c in data.contacts:
        f = _array(robot, f"contact {c.frame!r}: wrench", c.wrench, (N, 6))
        if c.jacobian is not None:
            J = _array(robot, f"contact {c.frame!r}: jacobian", c.jacobian, (N, 6, 6 + n))
            rows += np.einsum("kri,kr->ki", J, f)
        elif c.transform is not None and not need_tau:
            rows[:, :6] += wrench_at_base(_array(robot, f"contact {c.frame!r}: transform", c.transform, (N, 4, 4)), f)
        else:
            raise IdentificationError(
                f"{robot}: contact {c.frame!r}: give its jacobian (N, 6, {6 + n})"
                + ("" if c.transform is None else "; a transform only carries the wrench to the base rows"))
    return rows


def wrench_at_base(transform: NDArray[np.float64], wrench: NDArray[np.float64]) -> NDArray[np.float64]:
    """``(N, 6)``: wrenches (force, moment about the frame's origin, frame axes) carried to the base origin in
    base axes by the frames' poses ``T_0c`` (N, 4, 4): ``(R f, R m + p x R f)`` ([F2008] sec. 2.8)."""
    R, p = transform[:, :3, :3], transform[:, :3, 3]
    force = np.einsum("kij,kj->ki", R, wrench[:, :3])
    moment = np.einsum("kij,kj->ki", R, wrench[:, 3:]) + np.cross(p, force)
    out: NDArray[np.float64] = np.hstack([force, moment])
    return out


def floating_system(model: FloatingModel, data: FloatingMeasurements, kind: str = "base",
                    weighting: str = "kind") -> FloatingSystem:
    """The stacked system of ``kind`` (``"base"``, ``"joints"`` or ``"both"``) reduced to its own numeric rank
    (module docstring)."""
    if kind not in KINDS:
        raise IdentificationError(f"{model.ROBOT}: kind must be one of {KINDS}, got {kind!r}")
    if weighting not in WEIGHTINGS:
        raise IdentificationError(f"{model.ROBOT}: weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    (q, dq, ddq), _ = floating_states(model.ROBOT, model.N_JOINTS, data.q, data.dq, data.ddq)
    W = model.standard_regressor(q, dq, ddq)
    Y = measured_rows(model, data, need_tau=kind != "base")
    return stacked_system(model, W, Y, kind, weighting)


def stacked_system(model: FloatingModel, W: NDArray[np.float64], Y: NDArray[np.float64], kind: str = "base",
                   weighting: str = "kind") -> FloatingSystem:
    """The system of ``kind`` from samples already evaluated: the standard regressor ``W`` (N, 6 + n, p) and
    the right-hand sides ``Y`` (N, 6 + n), e.g. decimated in parallel ([GB-gains] eq. 15-16)."""
    if kind not in KINDS:
        raise IdentificationError(f"{model.ROBOT}: kind must be one of {KINDS}, got {kind!r}")
    if weighting not in WEIGHTINGS:
        raise IdentificationError(f"{model.ROBOT}: weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    sel = ROWS[kind]
    W, Y = W[:, sel, :], Y[:, sel]
    position = np.arange(model.N_ROWS)[sel]
    if weighting == "row":
        group = position - position[0]
    else:
        group = (position >= 6).astype(int) - int(position[0] >= 6)
    # rows grouped (all rows of group 0 first, ...), as ObservationSystem expects
    order = np.argsort(group, kind="stable")
    Wr = W[:, order, :].transpose(1, 0, 2).reshape(-1, W.shape[2])
    Yr = Y[:, order].T.reshape(-1)
    rows_group = np.repeat(group[order], W.shape[0])
    kept, K = numeric_base(Wr)
    if kept.size == 0:
        raise IdentificationError(f"{model.ROBOT}: the {kind} rows identify no parameter")
    names = combination_names(model.STANDARD_NAMES, kept, K)
    absent = tuple(n for i, n in enumerate(model.STANDARD_NAMES) if not np.any(K[:, i]))
    system = ObservationSystem(W=Wr[:, kept], Y=Yr, names=names, joint=rows_group)
    return FloatingSystem(kind, system, K, absent, kept, W.shape[0])


def combination_names(standard: Sequence[str], kept: NDArray[np.intp], K: NDArray[np.float64]) -> tuple[str, ...]:
    """The identified combinations' names: a standard parameter's name where its row of ``K`` is that parameter
    alone, else its name with ``R`` (regrouped, as the fixed-base base parameters ``XX2R``): only the first are
    standard values (``export-urdf --params`` takes them)."""
    out = []
    for r, i in enumerate(kept):
        alone = np.count_nonzero(np.abs(K[r]) > 1e-12 * np.abs(K[r]).max()) == 1 and abs(K[r, i] - 1) < 1e-12
        out.append(standard[i] if alone else standard[i] + "R")
    return tuple(out)


def identify_floating(model: FloatingModel, data: FloatingMeasurements, kind: str = "base", method: str = "wls",
                      weighting: str = "kind", **tolerances: Any) -> FloatingIdentification:
    """IDIM-OLS or -WLS of ``kind``'s rows alone (or of both kinds, each weighted by its own sigma with WLS)
    on the system of :func:`floating_system`; ``tolerances``: those of the fixed-base estimators."""
    tol = tolerance_keywords("identify_floating", tolerances)
    return fit_system(model, floating_system(model, data, kind, weighting), method, **tol)


def fit_system(model: FloatingModel, fs: FloatingSystem, method: str = "wls", band: float = 1.0,
               **tol: Any) -> FloatingIdentification:
    """IDIM-OLS or -WLS of a system of :func:`floating_system` or :func:`stacked_system`; the covariance of
    :func:`with_sample_covariance` (``band``: the share of the decimated band the decimation filter passes,
    1 for samples not decimated)."""
    if method == "ols":
        res = fit_ols(fs.system, **tol)
    elif method == "wls":
        res = fit_wls(fs.system, **tol)
    else:
        raise IdentificationError(f"{model.ROBOT}: method must be 'ols' or 'wls', got {method!r}")
    if fs.samples:
        res = with_sample_covariance(res, fs.system, fs.samples, band,
                                     tol.get("rel_std_warn_pct", REL_STD_WARN_PCT))
    return FloatingIdentification(fs.kind, res, fs.relations, fs.not_identifiable, fs.columns)


def with_sample_covariance(res: IdentificationResult, system: ObservationSystem, samples: int,
                           band: float = 1.0, rel_std_warn_pct: float = REL_STD_WARN_PCT) -> IdentificationResult:
    """``res`` with the covariance of its estimates from the rows' noise correlated within a sample.

    The estimates are unchanged. The OLS/WLS covariance ``sigma^2 (A'A)^-1`` (RX-90 eq. 20, ``A`` the weighted
    system) takes the rows as independent, but a contact wrench's noise reaches several rows of one sample through
    ``J_c^T f_c`` (base rows and joint rows), and an IMU's through the base's columns of ``W``. With the weighted
    residuals ``E`` (N samples x m row positions) and the weighted rows ``A_s`` (m x c) of sample ``s``, the
    within-sample covariance is pooled over the samples, ``S = E'E / N * R / (R - c)`` (``R = N m`` rows; the
    factor ``R / (R - c)`` makes its trace unbiased for independent rows as eq. 19's ``r - c``), and

        ``cov = (A'A)^-1 (sum_s A_s' S A_s) (A'A)^-1``,

    the sandwich of White (1980) and Liang & Zeger (1986) with a common within-cluster (here: within-sample)
    covariance in place of each cluster's ``e_s e_s'``: the latter (the cluster-robust estimate) has rank at most
    ``N`` and is unreliable when the combinations are nearly as many as the (decimated) samples, the common
    ``S`` (m (m + 1) / 2 entries from ``R`` residuals) is not; what it leaves out is the noise's covariance
    changing with the configuration (``J_c`` with ``q``). For independent rows of equal variance per row
    position ``S`` is diagonal and the sandwich is the usual covariance with per-position variances.

    ``band``: samples decimated in parallel ([GB-gains] eq. 15-16) keep white noise's spectrum flat over the share
    ``band`` of the decimated band the decimation filter passes (``cutoff_ratio``) only; the residuals' variance is
    ``band`` times the level the slowly varying columns see, so the covariance is divided by ``band`` (as the
    loop's candidate tests on floating systems do). Serial correlation is not estimated from the residuals: the
    fit removes the residuals' low-frequency part, where the columns are. The warning naming the poorly identified
    parameters is made again from the new standard deviations (``rel_std_warn_pct``).
    """
    if (res.residual is None or system.W.shape[0] % samples or res.sigma <= 0 or res.values.size != system.W.shape[1]
            or not np.all(np.isfinite(res.cov))):
        return res
    m = system.W.shape[0] // samples
    c = res.values.size
    w = np.ones(system.W.shape[0]) if res.joint_sigma is None else 1.0 / res.joint_sigma[system.joint]
    A = (system.W * w[:, None]).reshape(m, samples, c)
    E = (res.residual * w).reshape(m, samples).T
    n_rows = m * samples
    if n_rows <= c:
        return res
    S = E.T @ E / samples * n_rows / (n_rows - c)
    vals, vecs = np.linalg.eigh(S)
    half = vecs * np.sqrt(np.clip(vals, 0.0, None))            # S = half half'
    T = np.einsum("ij,isc->jsc", half, A).reshape(-1, c)        # half' A_s, stacked
    bread = res.cov / res.sigma ** 2                            # (A'A)^-1 as the fit inverted it
    cov = bread @ (T.T @ T) @ bread / band
    cov = 0.5 * (cov + cov.T)
    std = np.where(np.isfinite(res.std), np.sqrt(np.clip(np.diag(cov), 0.0, None)), res.std)
    warnings = [w for w in res.warnings if "poorly identified (%sigma" not in w]
    warnings += poorly_identified_warnings(res.names, res.values, std, Options(rel_std_warn_pct=rel_std_warn_pct),
                                           hint="")  # a floating base has no --essential
    return replace(res, cov=cov, std=std, rel_std_pct=relative_std_pct(res.values, std), warnings=tuple(warnings))


#: the drive terms of one joint in the standard names (``FV3``: frame 3's viscous friction)
_DRIVE_NAME = re.compile(r"^(IA|FV|FS|OFF)(\d+)$")


@dataclass(frozen=True, eq=False)
class RowsAsJoints:
    """The rows of a floating-base model as the "joints" of a fixed-base
    :class:`~symoro_gen.model.IdentificationModel`, so that the fixed-base loop (:func:`symoro_gen.diagnostics.diagnose`)
    analyses the residual of each equation kind ([AVN2014]: the base-link and the joint equations of motion).

    Joints ``0..5`` are the base-wrench rows (``FX0 .. MZ0``), ``6 + c`` the joint row of column ``c``: the base
    rows depend on the joints' motion, so both kinds come together (logs with joint torques). Each sample's
    signals, as :meth:`regressor` takes them: ``q`` (N, 6 + n) the base position and the rotation vector of its orientation (the quaternion's SO(3) log,
    [F2008] sec. 2.3), then the joint positions; ``dq``, ``ddq`` the free-flyer velocity and spatial acceleration
    (Pinocchio's, base axes), then the joints'. The measured side of each row (the "torque") is
    ``S^T tau + sum_c J_c^T f_c`` (:func:`measured_rows`): the contact wrenches moved to the measured side, so the
    joint rows read ``tau_j + J_c,j^T f_c = Y_j chi`` as a fixed-base joint ``tau_j = Y_j chi``.

    The columns are the numeric base ``kept`` of those rows (:func:`stacked_system`), named as the identified
    combinations, with the drive terms renamed to their row: ``FV<j>`` of the joint in column ``c`` is
    ``FV<7 + c>`` here, the name the fixed-base loop gives the friction, offset and inertia of joint ``6 + c``."""

    model: FloatingModel
    kept: NDArray[np.intp]
    names: tuple[str, ...]

    @classmethod
    def of(cls, model: FloatingModel, robot: RobotDescription, W: NDArray[np.float64]) -> RowsAsJoints:
        """The numeric base of the rows of the samples' standard regressor ``W`` (k, 6 + n, p)."""
        col = {r.j: c for c, r in enumerate(robot.joints)}
        Wr = W.transpose(1, 0, 2).reshape(-1, W.shape[2])
        kept, K = numeric_base(Wr)
        names = []
        for nm in combination_names(model.STANDARD_NAMES, kept, K):
            m = _DRIVE_NAME.match(nm)
            names.append(f"{m.group(1)}{7 + col[int(m.group(2))]}" if m and int(m.group(2)) in col else nm)
        return cls(model, kept, tuple(names))

    @property
    def ROBOT(self) -> str:  # noqa: N802 - the generated contract's names
        return str(self.model.ROBOT)

    @property
    def N_JOINTS(self) -> int:  # noqa: N802
        return int(self.model.N_ROWS)

    @property
    def BASE_NAMES(self) -> tuple[str, ...]:  # noqa: N802
        return self.names

    @property
    def STANDARD_NAMES(self) -> tuple[str, ...]:  # noqa: N802
        return tuple(self.model.STANDARD_NAMES)

    @property
    def PAYLOAD_NAMES(self) -> tuple[str, ...]:  # noqa: N802
        return ()

    def model_state(self, q: ArrayLike) -> NDArray[np.float64]:
        """``q`` (N, 6 + n) of :meth:`regressor` -> the floating model's ``q`` (N, 7 + n), quaternion ``x y z w``."""
        q = np.atleast_2d(np.asarray(q, float))
        out: NDArray[np.float64] = np.hstack([q[:, :3], Rotation.from_rotvec(np.array(q[:, 3:6])).as_quat(), q[:, 6:]])
        return out

    @staticmethod
    def signals(q: ArrayLike) -> NDArray[np.float64]:
        """The floating model's ``q`` (N, 7 + n) -> the position part of :meth:`regressor`'s signals (N, 6 + n)."""
        q = np.atleast_2d(np.asarray(q, float))
        out: NDArray[np.float64] = np.hstack([q[:, :3], Rotation.from_quat(np.array(q[:, 3:7])).as_rotvec(), q[:, 7:]])
        return out

    def regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """(N, 6 + n, len(names)): the standard regressor's kept columns."""
        dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (dq, ddq))
        W = np.asarray(self.model.standard_regressor(self.model_state(q), dq, ddq), float)
        out: NDArray[np.float64] = W[:, :, self.kept]
        return out


def frame_number(robot: RobotDescription, frame: str) -> int:
    """The frame ``frame`` names: the ``name`` of a ``[[frames]]`` entry, or ``frame<j>`` (``frame0``: the base)."""
    for row in robot.rows:
        if row.name is not None and str(row.name) == frame:
            return row.j
    if frame.startswith("frame") and frame[5:].isdigit() and int(frame[5:]) <= len(robot.rows):
        return int(frame[5:])
    names = [str(r.name) for r in robot.rows if r.name is not None]
    raise IdentificationError(f"{robot.file or robot.name}: no frame {frame!r} (frames are named frame0..frame"
                              f"{len(robot.rows)}" + (f" or {', '.join(names)}" if names else "") + ")")


def frame_jacobian(robot: RobotDescription, q_joints: ArrayLike, frame: int
                   ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(T_0c (N, 4, 4), J_c (N, 6, 6 + n))``: the pose of MDH frame ``frame`` in base axes and its Jacobian in
    its own axes (Pinocchio's ``LOCAL``, free-flyer columns first) at joint positions ``q_joints`` (N, n).

    Forward kinematics by the MDH transforms (:func:`~symoro_gen.description.mdh.row_transform`, [KK1986]);
    the columns ([F2008] sec. 2.9): base linear velocity ``R^T``, base angular velocity ``R^T [p]x^T``;
    a revolute joint ``i`` on the path with axis ``a_i`` (its frame's z, signed as ``q`` enters ``theta``) at
    ``p_i``: ``R^T (a_i x (p - p_i))`` and ``R^T a_i``; a prismatic one ``R^T a_i`` and 0."""
    qj = np.atleast_2d(np.asarray(q_joints, float))
    N = qj.shape[0]
    col = {r.j: k for k, r in enumerate(robot.joints)}
    subs = robot.geometry_subs()
    T: dict[int, NDArray[np.float64]] = {0: np.broadcast_to(np.eye(4), (N, 4, 4))}
    path = [*robot.ancestors(frame), frame] if frame else [0]
    for j in sorted(set(path) - {0}):
        row = robot.row(j)
        T[j] = T[row.ant] @ row_transform(row, subs, qj[:, col[j]] if j in col else np.zeros(N))
    Tc = np.array(T[frame])
    R, p = Tc[:, :3, :3], Tc[:, :3, 3]
    Rt = np.transpose(R, (0, 2, 1))
    J = np.zeros((N, 6, 6 + len(robot.joints)))
    J[:, :3, :3] = Rt
    J[:, :3, 3:6] = -Rt @ _skew(p)
    J[:, 3:, 3:6] = Rt
    for j in path:
        if j not in col:
            continue
        a = T[j][:, :3, 2] * joint_sign(robot.row(j))
        if robot.row(j).sigma == REVOLUTE:
            J[:, :3, 6 + col[j]] = np.einsum("kij,kj->ki", Rt, np.cross(a, p - T[j][:, :3, 3]))
            J[:, 3:, 6 + col[j]] = np.einsum("kij,kj->ki", Rt, a)
        else:
            J[:, :3, 6 + col[j]] = np.einsum("kij,kj->ki", Rt, a)
    return Tc, J


def _skew(p: NDArray[np.float64]) -> NDArray[np.float64]:
    S = np.zeros(p.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -p[..., 2], p[..., 1], -p[..., 0]
    S[..., 1, 0], S[..., 2, 0], S[..., 2, 1] = p[..., 2], -p[..., 1], p[..., 0]
    return S


@dataclass(frozen=True, eq=False)
class RelationsModel:
    """The identified combinations of a floating-base ``identify`` JSON as a model with base parameters: its
    ``BASE_NAMES`` the combinations' names, ``base_parameters(chi_std) = K chi_std`` with the JSON's relations ``K``
    (``floating.relations``). What :func:`~symoro_gen.identification.physical.standard_set_from_result` needs to
    find a physically consistent standard set reproducing them (``export-urdf/-mjcf --from``)."""

    ROBOT: str
    STANDARD_NAMES: tuple[str, ...]
    BASE_NAMES: tuple[str, ...]
    relations: NDArray[np.float64]
    PAYLOAD_NAMES: tuple[str, ...] = ()

    @classmethod
    def from_result(cls, robot: RobotDescription, result: Any, source: str) -> RelationsModel:
        """From the JSON of a floating-base identification (``source`` names it in errors)."""
        try:
            fl = result["floating"]
            K = np.array(fl["relations"], float)
            names = tuple(result["parameters"]["names"])
            standard = tuple(fl["standard_names"])
        except (KeyError, TypeError, ValueError):
            raise ModelError(f"{source}: not a floating-base result of `symoro-gen identify` (no 'floating' "
                             f"relations) for the floating-base robot {robot.file or robot.name}") from None
        if standard != tuple(robot.standard_names) or K.shape != (len(names), len(standard)):
            raise ModelError(f"{source}: its standard parameters ('floating.standard_names') are not those of "
                             f"{robot.file or robot.name}")
        return cls(robot.name, standard, names, K)

    def base_parameters(self, chi_std: ArrayLike) -> NDArray[np.float64]:
        out: NDArray[np.float64] = np.asarray(chi_std, float) @ self.relations.T
        return out
