"""The "plain expert model": the baseline the diagnosis loop must beat on every joint.

Base parameters of the declared model + per joint a smooth Coulomb friction ``Fc_j tanh(dq_j / v_j)``,
a viscous term ``Fv_j dq_j`` and an offset ``OFF_j``, solved by (weighted) least squares on the
filtered, decimated observation system (RX-90 paper eq. 14-16; WLS with per-joint weights
``1/sigma_j`` from the OLS residual, RX-90 paper eq. 10-11). The declared friction and offset
columns (``FS_j``, ``FV_j``, ``OFF_j``) are replaced by these, so a model declared without friction
(an imported URDF) gets them too. Each ``v_j`` is chosen by time-blocked cross-validation
(:func:`.friction.select_friction` restricted to the ``tanh`` law; :mod:`.stability` for the folds).

Errors are given on both metrics:

* ``rel_err``: ``||Y_j - W_j theta|| / ||Y_j||`` on the filtered, decimated system (the papers' metric);
* ``rel_err_raw``: the model evaluated at full rate on the band-pass states against the **raw measured
  torque** (edge samples of the filter dropped), per joint.

:class:`FilteredData` holds the full-rate band-pass states of a set of experiments and builds the
decimated columns of any function of them (decimated in parallel with ``Y``, so ``Y = W theta`` keeps
holding); :func:`stacked_regressor` stacks a regressor (N, n, k) into joint-major rows.
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial

import numpy as np

from ..errors import IdentificationError
from ..identification.assemble import observation_settings
from ..model import IdentificationModel
from ..preprocessing.filtering import FilterSettings, decimate, filter_and_differentiate
from ..preprocessing.trajectory import Trajectory
from .frame import noise_gains
from .friction import LawSearch, select_friction, velocity_grid
from .stability import N_FOLDS, time_blocks, wls_basis

__all__ = [
    "DeclaredFit",
    "ExpertModel",
    "expert_residuals",
    "FilteredData",
    "LinearFit",
    "expert_columns",
    "filtered_data",
    "fit_declared",
    "fit_expert",
    "fit_linear",
    "joint_rel_err",
    "no_worse",
    "stacked_regressor",
]

#: samples per call of the model's regressor
BATCH = 8192
#: index in :func:`.friction.velocity_grid` of the starting velocity scale of every joint
N_VELOCITY_START = 9


def stacked_regressor(model: IdentificationModel, q, dq, ddq) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Regressor rows of every sample, joint-major (all samples of joint 1, then joint 2...).

    Returns
    -------
    W : ndarray, shape (n N, k)
    joint : ndarray of int, shape (n N,)
        0-based joint of each row.
    sample : ndarray of int, shape (n N,)
        Sample index of each row.
    """
    R = np.asarray(model.regressor(np.asarray(q, float), np.asarray(dq, float), np.asarray(ddq, float)), float)
    N, n, k = R.shape
    W = R.transpose(1, 0, 2).reshape(n * N, k)
    return W, np.repeat(np.arange(n), N), np.tile(np.arange(N), n)


def joint_rel_err(e: np.ndarray, y: np.ndarray, joint: np.ndarray, n: int) -> np.ndarray:
    """``||e_j|| / ||y_j||`` per joint."""
    a = np.bincount(joint, weights=np.asarray(e, float) ** 2, minlength=n)
    b = np.bincount(joint, weights=np.asarray(y, float) ** 2, minlength=n)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.sqrt(a / b)


@dataclass(frozen=True, eq=False)
class _Exp:
    source: str
    settings: FilterSettings
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    tau: np.ndarray        # raw measured torque on the same (edge-trimmed) samples
    dq_noise: np.ndarray   # (n,) std of the white position noise left in the band-pass velocity

    def decimate(self, x: np.ndarray) -> np.ndarray:
        st = self.settings
        return decimate(x, st.n_d, ftype=st.ftype, cutoff_ratio=st.cutoff_ratio, source=self.source)


@dataclass(frozen=True, eq=False)
class FilteredData:
    """Band-pass states at full rate and the decimated torque rows of a set of experiments.

    Attributes
    ----------
    experiments : tuple
        Per experiment: ``settings``, full-rate ``q, dq, ddq`` (band-pass, edges dropped) and ``tau``
        (raw measured torque on the same samples).
    Y : ndarray, shape (r,)
        Decimated measured torques, joint-major, experiment after experiment within a joint.
    joint, row_experiment, row_index : ndarray of int, shape (r,)
        Joint (0-based), experiment and decimated-sample index of each row.
    """

    experiments: tuple
    Y: np.ndarray
    joint: np.ndarray
    row_experiment: np.ndarray
    row_index: np.ndarray

    @property
    def n_joints(self) -> int:
        return self.experiments[0].q.shape[1]

    @property
    def dq_noise(self) -> np.ndarray:
        """Standard deviation of the position noise left in the band-pass velocity, per joint (largest over
        the experiments; from the part of ``q`` above the cut-off, :func:`.frame.noise_gains`)."""
        return np.max([ex.dq_noise for ex in self.experiments], axis=0)

    def columns(self, f: Callable[[_Exp], np.ndarray]) -> np.ndarray:
        """Decimated rows of per-sample columns: ``f(experiment) -> (M, n, p)`` (slice ``[:, j, :]`` is the
        value on joint ``j``'s row) evaluated at full rate, decimated in parallel with ``Y``; (r, p)."""
        out: np.ndarray | None = None
        n = self.n_joints
        for e, ex in enumerate(self.experiments):
            full = np.asarray(f(ex), float)
            M, _, p = full.shape
            if out is None:
                out = np.zeros((self.Y.size, p))
            dec = ex.decimate(full.reshape(M, n * p)).reshape(-1, n, p)
            for j in range(n):
                m = (self.row_experiment == e) & (self.joint == j)
                out[m] = dec[self.row_index[m], j, :]
        return out if out is not None else np.zeros((self.Y.size, 0))

    def joint_columns(self, j: int, f: Callable[[np.ndarray], np.ndarray], p: int) -> np.ndarray:
        """Columns ``f(dq_j full rate) -> (M, p)`` on the rows of joint ``j`` (zeros elsewhere), decimated
        in parallel with ``Y``: the ``columns`` hook of :func:`.friction.select_friction`."""
        out = np.zeros((self.Y.size, p))
        for e, ex in enumerate(self.experiments):
            dec = ex.decimate(np.asarray(f(ex.dq[:, j]), float).reshape(-1, p))
            m = (self.row_experiment == e) & (self.joint == j)
            out[m] = dec[self.row_index[m]]
        return out

    def blocks(self, n_blocks: int = N_FOLDS) -> np.ndarray:
        """Contiguous time blocks of the rows (:func:`.stability.time_blocks`)."""
        return time_blocks(self.row_experiment, self.row_index, n_blocks)


def filtered_data(trajectories: Sequence[Trajectory], *, dynamics_bandwidth_hz: float | None = None,
                  **filter_kw) -> FilteredData:
    """Band-pass filter and decimate experiments with the assembler's rules
    (:func:`symoro_gen.identification.assemble.observation_settings`, same keywords)."""
    exps, Ys, J, RE, RI = [], [], [], [], []
    trajs = list(trajectories)
    if not trajs:
        raise ValueError("filtered_data: no trajectory given")
    for tr in trajs:
        st = observation_settings(tr, dynamics_bandwidth_hz=dynamics_bandwidth_hz, **filter_kw)
        qf, dq, ddq = filter_and_differentiate(tr.q, st.fs, st.cutoff_hz, st.order, source=tr.source)
        e = st.edge_samples
        seg = slice(e, tr.n_samples - e)
        hp, dv = noise_gains(st.fs, st.cutoff_hz, st.order)
        q_noise = np.std(np.asarray(tr.q, float)[seg] - qf[seg], axis=0) / max(hp, 1e-12)
        exps.append(_Exp(tr.source, st, qf[seg], dq[seg], ddq[seg], np.asarray(tr.tau, float)[seg], q_noise * dv))
    n = trajs[0].n_joints
    decs = [ex.decimate(ex.tau) for ex in exps]
    for j in range(n):
        for e, d in enumerate(decs):
            Ys.append(d[:, j])
            J.append(np.full(d.shape[0], j))
            RE.append(np.full(d.shape[0], e))
            RI.append(np.arange(d.shape[0]))
    return FilteredData(tuple(exps), np.concatenate(Ys), np.concatenate(J), np.concatenate(RE), np.concatenate(RI))


def _split_names(model: IdentificationModel) -> tuple[list[int], list[str]]:
    """Indices of the declared columns kept by the expert model (friction and offsets dropped)."""
    n = model.N_JOINTS
    drop = {f"{p}{j}" for p in ("FS", "FV", "OFF") for j in range(1, n + 1)}
    keep = [i for i, nm in enumerate(model.BASE_NAMES) if nm not in drop]
    return keep, [model.BASE_NAMES[i] for i in keep]


def expert_columns(model: IdentificationModel, q, dq, ddq, v) -> np.ndarray:
    """Per-sample expert regressor (N, n, k'): the declared base columns without ``FS/FV/OFF``, then per
    joint ``tanh(dq_j/v_j)``, ``dq_j``, ``1`` on its own row (names :meth:`ExpertModel.names`)."""
    keep, _ = _split_names(model)
    q, dq, ddq = (np.atleast_2d(np.asarray(x, float)) for x in (q, dq, ddq))
    N, n = q.shape
    v = np.broadcast_to(np.asarray(v, float), (n,))
    out = np.zeros((N, n, len(keep) + 3 * n))
    for s in range(0, N, BATCH):
        e = min(N, s + BATCH)
        out[s:e, :, :len(keep)] = np.asarray(model.regressor(q[s:e], dq[s:e], ddq[s:e]), float)[:, :, keep]
    for j in range(n):
        c = len(keep) + 3 * j
        out[:, j, c] = np.tanh(dq[:, j] / v[j])
        out[:, j, c + 1] = dq[:, j]
        out[:, j, c + 2] = 1.0
    return out


@dataclass(frozen=True)
class ExpertModel:
    """A fitted expert model.

    Attributes
    ----------
    names : tuple of str
        Column names: kept base parameters, then ``FC<j>, FV<j>, OFF<j>`` per joint.
    theta : ndarray
    v : ndarray, shape (n,)
        Velocity scales of the tanh Coulomb laws [rad/s or m/s].
    method : str
        ``ols`` or ``wls``.
    cv_rel_err : ndarray, shape (n,)
        Out-of-fold (time-blocked) relative error of each joint at its chosen ``v``.
    rel_err : ndarray, shape (n,)
        Identification error on the filtered system.
    """

    names: tuple
    theta: np.ndarray
    v: np.ndarray
    method: str
    cv_rel_err: np.ndarray
    rel_err: np.ndarray

    def torque(self, model: IdentificationModel, q, dq, ddq) -> np.ndarray:
        """Model torque (N, n) at the given states."""
        return expert_columns(model, q, dq, ddq, self.v) @ self.theta

    def errors(self, model: IdentificationModel, data: FilteredData) -> tuple[np.ndarray, np.ndarray]:
        """``(rel_err, rel_err_raw)`` per joint on ``data``: filtered decimated system, and full rate against
        the raw measured torque."""
        return _errors(lambda q, dq, ddq: expert_columns(model, q, dq, ddq, self.v), self.theta, data)


def _errors(cols: Callable, theta: np.ndarray, data: FilteredData) -> tuple[np.ndarray, np.ndarray]:
    n = data.n_joints
    pred = data.columns(lambda ex: cols(ex.q, ex.dq, ex.ddq)) @ theta
    filt = joint_rel_err(data.Y - pred, data.Y, data.joint, n)
    num, den = np.zeros(n), np.zeros(n)
    for ex in data.experiments:
        for s in range(0, ex.q.shape[0], BATCH):
            e = min(ex.q.shape[0], s + BATCH)
            err = ex.tau[s:e] - cols(ex.q[s:e], ex.dq[s:e], ex.ddq[s:e]) @ theta
            num += np.sum(err ** 2, axis=0)
            den += np.sum(ex.tau[s:e] ** 2, axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return filt, np.sqrt(num / den)


@dataclass(frozen=True)
class DeclaredFit:
    """The declared model (``model.BASE_NAMES``) fitted by (weighted) LS on the same rows: the "before"."""

    theta: np.ndarray
    method: str
    rel_err: np.ndarray

    def errors(self, model: IdentificationModel, data: FilteredData) -> tuple[np.ndarray, np.ndarray]:
        """``(rel_err, rel_err_raw)`` per joint on ``data`` (see :meth:`ExpertModel.errors`)."""
        return _errors(lambda q, dq, ddq: _regressor(model, q, dq, ddq), self.theta, data)


def _regressor(model: IdentificationModel, q, dq, ddq) -> np.ndarray:
    out = []
    for s in range(0, q.shape[0], BATCH):
        e = min(q.shape[0], s + BATCH)
        out.append(np.asarray(model.regressor(q[s:e], dq[s:e], ddq[s:e]), float))
    return np.concatenate(out)


@dataclass(frozen=True, eq=False)
class LinearFit:
    """Any per-sample regressor ``columns(q, dq, ddq) -> (N, n, k)`` fitted by (weighted) LS."""

    columns: Callable
    theta: np.ndarray
    method: str
    rel_err: np.ndarray

    def errors(self, data: FilteredData) -> tuple[np.ndarray, np.ndarray]:
        """``(rel_err, rel_err_raw)`` per joint on ``data`` (see :meth:`ExpertModel.errors`)."""
        return _errors(self.columns, self.theta, data)


def fit_linear(columns: Callable, data: FilteredData, *, method: str = "ols") -> LinearFit:
    """Fit the coefficients of a per-sample regressor ``columns(q, dq, ddq) -> (N, n, k)`` on ``data``
    (decimated in parallel with ``Y``) by ``method`` (``ols``/``wls``) least squares."""
    method = method.lower()
    if method not in ("ols", "wls"):
        raise IdentificationError(f"linear fit: unknown method {method!r}; use 'ols' or 'wls'")

    def batched(q, dq, ddq):
        return np.concatenate([np.asarray(columns(q[s:s + BATCH], dq[s:s + BATCH], ddq[s:s + BATCH]), float)
                               for s in range(0, q.shape[0], BATCH)])
    W = data.columns(lambda ex: batched(ex.q, ex.dq, ex.ddq))
    theta = _wls(W, data.Y, data.joint, data.n_joints, method)
    return LinearFit(columns, theta, method, joint_rel_err(data.Y - W @ theta, data.Y, data.joint, data.n_joints))


def fit_declared(model: IdentificationModel, data: FilteredData, *, method: str = "ols") -> DeclaredFit:
    """Fit the declared model's base parameters by ``method`` (``ols``/``wls``) LS on ``data``."""
    method = method.lower()
    if method not in ("ols", "wls"):
        raise IdentificationError(f"declared fit: unknown method {method!r}; use 'ols' or 'wls'")
    W = data.columns(lambda ex: _regressor(model, ex.q, ex.dq, ex.ddq))
    theta = _wls(W, data.Y, data.joint, data.n_joints, method)
    return DeclaredFit(theta, method, joint_rel_err(data.Y - W @ theta, data.Y, data.joint, data.n_joints))


def _wls(M: np.ndarray, y: np.ndarray, joint: np.ndarray, n: int, method: str) -> np.ndarray:
    _, pinv, rank = wls_basis(M)
    theta = pinv @ y
    if method == "wls":
        e = y - M @ theta
        cnt = np.bincount(joint, minlength=n).astype(float)
        rss = np.bincount(joint, weights=e ** 2, minlength=n)
        sig = np.sqrt(rss / np.maximum(cnt - rank * cnt / max(y.size, 1), 1.0))
        sig = np.maximum(sig, 1e-9 * max(sig.max(), 1e-300))
        w = 1.0 / sig[joint]
        _, pinv, _ = wls_basis(M * w[:, None])
        theta = pinv @ (y * w)
    return theta


def _tanh_column(x: np.ndarray, v: float) -> np.ndarray:
    """The smooth Coulomb column ``tanh(dq / v)``, shape (M, 1)."""
    return np.tanh(x / v)[:, None]


def fit_expert(model: IdentificationModel, data: FilteredData, *, method: str = "ols",
               n_folds: int = N_FOLDS) -> ExpertModel:
    """Fit the expert model on ``data`` (:func:`filtered_data` of the identification experiments).

    ``v_j`` is searched for each joint in turn (log grid then refinement, :func:`.friction.select_friction`
    with the ``tanh`` law only) with the other joints at their current scales (start: 0.05 times the
    95th percentile of ``|dq_j|``); then every coefficient is solved by ``method`` least squares.
    """
    method = method.lower()
    if method not in ("ols", "wls"):
        raise IdentificationError(f"expert model: unknown method {method!r}; use 'ols' or 'wls'")
    n = data.n_joints
    if n != model.N_JOINTS:
        raise IdentificationError(f"expert model: the data have {n} joints, model {model.ROBOT} has {model.N_JOINTS}")
    keep, kept_names = _split_names(model)
    names = tuple(kept_names) + tuple(f"{p}{j}" for j in range(1, n + 1) for p in ("FC", "FV", "OFF"))
    dq_all = np.concatenate([ex.dq for ex in data.experiments])
    v = np.array([velocity_grid(dq_all[:, j])[N_VELOCITY_START] for j in range(n)])
    blocks = data.blocks(n_folds)
    base = data.columns(lambda ex: expert_columns(model, ex.q, ex.dq, ex.ddq, v))
    weights = None
    if method == "wls":
        e = data.Y - base @ _wls(base, data.Y, data.joint, n, "ols")
        sig = np.sqrt(np.bincount(data.joint, weights=e ** 2, minlength=n)
                      / np.maximum(np.bincount(data.joint, minlength=n), 1))
        weights = 1.0 / np.maximum(sig, 1e-9 * max(sig.max(), 1e-300))[data.joint]
    k0 = len(keep)
    cv = np.zeros(n)
    for j in range(n):
        c = k0 + 3 * j
        A = np.delete(base, [c, c + 1], axis=1)
        ch = select_friction(A, data.Y, data.joint, j, np.zeros(data.Y.size), blocks, weights=weights,
                             columns=partial(data.joint_columns, j),
                             search=LawSearch(laws=("tanh",), min_gain=0.0, v_grid=velocity_grid(dq_all[:, j])))
        tanh = next(c_ for c_ in ch.candidates if c_.law == "tanh")
        v[j] = tanh.param
        cv[j] = tanh.cv_rel_err
        base[:, c] = data.joint_columns(j, partial(_tanh_column, v=float(v[j])), 1)[:, 0]
    theta = _wls(base, data.Y, data.joint, n, method)
    rel = joint_rel_err(data.Y - base @ theta, data.Y, data.joint, n)
    return ExpertModel(names, theta, v, method, cv, rel)



#: contiguous time blocks of the paired comparison of two models (:func:`no_worse`)
N_COMPARE_BLOCKS = 10


def _block_shares(e, y, joint, experiment, index, j, n_blocks):
    m = np.asarray(joint) == j
    b = time_blocks(np.asarray(experiment)[m], np.asarray(index)[m], n_blocks)
    den = float(np.sum(np.asarray(y)[m] ** 2))
    return np.bincount(b, weights=np.asarray(e)[m] ** 2, minlength=n_blocks) / den


def no_worse(a: dict, b: dict, n_joints: int, *, n_blocks: int = N_COMPARE_BLOCKS, z: float = 2.0
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Is model ``a`` no worse than model ``b`` on each joint, beyond the noise of the comparison?

    ``a`` and ``b`` hold validation residuals ``e``, measured torques ``y`` and, per row, ``joint``,
    ``experiment`` and time ``index`` (each on its own rows: the two models may drop different edge
    samples). The difference of the squared relative errors, ``rel_a^2 - rel_b^2``, is a sum over
    ``n_blocks`` contiguous time blocks of each experiment, ``d_k = ||e_a,k||^2/||y_a||^2 -
    ||e_b,k||^2/||y_b||^2``; its standard error is ``sqrt(K) std(d_k)`` (blocks long against the residual's
    correlation time are nearly independent; the block-to-block spread measures how much the difference
    would change on another recording of the same kind). ``a`` is *worse* on a joint only when
    ``rel_a^2 - rel_b^2 > z * SE`` (one-sided, ``z = 2``: about 2.5 %).

    Returns
    -------
    ok : ndarray of bool, shape (n,)
    diff : ndarray, shape (n,)
        ``rel_a^2 - rel_b^2``.
    se : ndarray, shape (n,)
        Its standard error.
    """
    ok, diff, se = np.zeros(n_joints, bool), np.zeros(n_joints), np.zeros(n_joints)
    for j in range(n_joints):
        sa = _block_shares(a["e"], a["y"], a["joint"], a["experiment"], a["index"], j, n_blocks)
        sb = _block_shares(b["e"], b["y"], b["joint"], b["experiment"], b["index"], j, n_blocks)
        d = sa - sb
        diff[j] = float(d.sum())
        se[j] = float(np.sqrt(d.size) * np.std(d, ddof=1))
        ok[j] = diff[j] <= z * se[j]
    return ok, diff, se


def expert_residuals(model: IdentificationModel, ex_model: ExpertModel, data: FilteredData) -> tuple[dict, dict]:
    """Validation residuals of a fitted expert model for :func:`no_worse`: on the filtered, decimated rows,
    and at full rate against the raw measured torque."""
    def cols(q, dq, ddq):
        return expert_columns(model, q, dq, ddq, ex_model.v)
    pred = data.columns(lambda ex: cols(ex.q, ex.dq, ex.ddq)) @ ex_model.theta
    filt = dict(e=data.Y - pred, y=data.Y, joint=data.joint, experiment=data.row_experiment, index=data.row_index)
    E, Yr, Jr, Xr, Ir = [], [], [], [], []
    n = data.n_joints
    for k, ex in enumerate(data.experiments):
        M = ex.q.shape[0]
        err = ex.tau - np.concatenate([cols(ex.q[s:s + BATCH], ex.dq[s:s + BATCH], ex.ddq[s:s + BATCH])
                                       for s in range(0, M, BATCH)]) @ ex_model.theta
        for j in range(n):
            E.append(err[:, j])
            Yr.append(ex.tau[:, j])
            Jr.append(np.full(M, j))
            Xr.append(np.full(M, k))
            Ir.append(np.arange(M))
    raw = dict(e=np.concatenate(E), y=np.concatenate(Yr), joint=np.concatenate(Jr), experiment=np.concatenate(Xr),
               index=np.concatenate(Ir))
    return filt, raw
