"""Joint zero offsets and link lengths: their torque columns, and which of them torque data can see.

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
base parameters). :func:`joint_zero_visibility` measures this on the generated model. The model-level functions (the column,
the secants, the visibility) live in :mod:`symoro_gen.identification.geometry`, shared with
``identify --geometry joint_zero``; they are re-exported here.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from dataclasses import replace as dc_replace

import numpy as np

from ..description import load_robot
from ..description.model import RobotDescription
from ..dynamics.numeric import inverse_dynamics
from ..errors import SymoroError
from ..identification.geometry import (
    JOINT_ZERO_STEP,
    VISIBILITY_TOL,
    LengthTerms,
    emitted_length_column,
    emitted_length_columns,
    emitted_length_terms,
    joint_zero_column,
    joint_zero_secant,
    joint_zero_visibility,
    length_identifiability,
    perturbed_robot,
    regressor_secant,
    revolute_joints,
    standard_from_fit,
    visible_zero_joints,
)
from ..model import IdentificationModel
from ..preprocessing.filtering import decimation_filter
from .frame import build_frame, common_bandwidth

__all__ = ["JOINT_ZERO_STEP", "VISIBILITY_TOL", "describe_zero", "joint_zero_column", "joint_zero_secant",
           "joint_zero_visibility", "invisible_zero_note", "regressor_secant", "JointZeroFit",
           "decimated_zero_matrix", "fit_joint_zeros", "revolute_joints", "visible_zero_joints", "LENGTH_STEP",
           "describe_length", "description_of", "emitted_length_column", "rigid_model", "length_column", "length_columns", "LengthColumns", "length_joint", "link_length_ready",
           "visible_lengths"]

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
    return frame.full_rate_columns_batched(_SampleReuse(f), p)


class _SampleReuse:
    """``fn(ex, a, b)`` (columns of samples ``a:b``, a function of each sample's signals) that evaluates each
    sample once over the consecutive stretches of :meth:`.frame.Frame.full_rate_columns_batched`: a stretch's
    buffer starts the filter window (``L - 1`` samples, 1600 for a decimation by 80) before the end of the
    previous one, so a wide set of columns (short stretches) would evaluate most samples twice. The samples of
    the last ``keep`` evaluated ones are taken from them (the same numbers: each sample's columns do not depend on
    the others). The samples kept are those of the window (``L`` from the experiment's filter settings): a few
    MB (1601 samples of the LWR4's 163 length entries on 7 joints: 15 MB)."""

    def __init__(self, fn):
        self.fn, self.keep = fn, 0
        self._ex: object = None
        self._chunks: list[tuple[int, np.ndarray]] = []   # contiguous (first sample, values), oldest first

    def __call__(self, ex, a: int, b: int) -> np.ndarray:
        if ex is not self._ex:
            st = ex.settings
            fir = st.ftype == "fir" and st.n_d > 1
            self.keep = decimation_filter(st.n_d, ftype="fir", cutoff_ratio=st.cutoff_ratio).size if fir else 0
            self._ex, self._chunks = ex, []
        end = self._chunks[-1][0] + self._chunks[-1][1].shape[0] if self._chunks else a
        start = self._chunks[0][0] if self._chunks else a
        if not start <= a <= end:
            self._chunks, end = [], a
        parts = [v[max(a - c, 0):min(b, end) - c] for c, v in self._chunks if c + v.shape[0] > a and c < min(b, end)]
        if b > end:
            fresh = np.asarray(self.fn(ex, end, b), float)
            parts.append(fresh)
            self._chunks.append((end, fresh))
            while self._chunks and self._chunks[0][0] + self._chunks[0][1].shape[0] <= b - self.keep:
                self._chunks.pop(0)
        return parts[0] if len(parts) == 1 else np.concatenate(parts)


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


# ------------------------------------------------------------------------------------------------
# link lengths: the loop's ``link_length`` candidates
# ------------------------------------------------------------------------------------------------
_DESCRIPTIONS: dict = {}   # id(model) -> (model, robot description or None)


def description_of(model: IdentificationModel):
    """The robot description (MDH table) of a generated model, or None: the model's own ``robot`` /
    ``description`` attribute, else the robot file of its name (``robots/<ROBOT>.toml``) when its geometry
    values and standard parameters are the model's. Without it the loop tries no ``link_length`` candidate."""
    got = _DESCRIPTIONS.get(id(model))
    if got is not None and got[0] is model:
        return got[1]
    desc = getattr(model, "robot", None) or getattr(model, "description", None)
    if not isinstance(desc, RobotDescription):
        try:
            desc = load_robot(str(model.ROBOT))
        except SymoroError:
            desc = None
    if desc is not None:
        same = (desc.n_joints == int(model.N_JOINTS) and set(desc.standard_names) == set(model.STANDARD_NAMES)
                and all(abs(float(desc.values.get(k, math.nan)) - float(v)) <= 1e-12
                        for k, v in dict(getattr(model, "GEOMETRY", {}) or {}).items()))
        desc = desc if same else None
    _DESCRIPTIONS[id(model)] = (model, desc)
    return desc


def rigid_model(model: IdentificationModel) -> IdentificationModel:
    """The model under any friction-law wrappers (``wrapped``, :class:`symoro_gen.identification.friction_law.
    LawSplicedModel`): they replace friction columns only, which no length changes, so the length column is the
    rigid model's at the fit's kept base parameters (a replaced friction parameter counts as 0 there: its
    standard column does not depend on the geometry)."""
    seen = 0
    while hasattr(model, "wrapped") and seen < 8:
        model = model.wrapped
        seen += 1
    return model


def link_length_ready(model: IdentificationModel) -> bool:
    """Whether the loop can build ``link_length`` columns for this model: its robot description is found and
    the base parameters of the rigid model under any friction-law wrapper (:func:`rigid_model`) are the
    generated model's."""
    model = rigid_model(model)
    if description_of(model) is None:
        return False
    try:
        K = np.asarray(model.base_parameters(np.eye(len(tuple(model.STANDARD_NAMES)))), float)
    except (AttributeError, ValueError):
        return False
    return K.shape[-1] == len(tuple(model.BASE_NAMES))


def visible_lengths(model: IdentificationModel) -> tuple[tuple[int, str], ...]:
    """``(frame, field)`` of the MDH lengths torque data can see (:func:`length_identifiability`); empty
    without a robot description."""
    robot = description_of(model)
    if robot is None:
        return ()
    return tuple((v.frame, v.field) for v in length_identifiability(robot, model=model) if v.visible)


def length_joint(model: IdentificationModel, frame: int) -> int | None:
    """0-based joint a frame's length belongs to: the frame's own joint, or the nearest moving antecedent of a
    fixed frame (None: on the base)."""
    robot = description_of(model)
    if robot is None:
        return None
    cols = {int(r.j): k for k, r in enumerate(robot.joints)}
    f = int(frame)
    while f > 0:
        if f in cols:
            return cols[f]
        f = int(robot.row(f).ant)
    return None


_PERTURBED: dict = {}   # (id(robot), frame, field) -> (robot, plus, minus)


def _pair(robot, frame: int, fld: str):
    key = (id(robot), int(frame), fld)
    got = _PERTURBED.get(key)
    if got is None or got[0] is not robot:
        got = (robot, perturbed_robot(robot, frame, fld, LENGTH_STEP), perturbed_robot(robot, frame, fld, -LENGTH_STEP))
        _PERTURBED[key] = got
    return got[1], got[2]


#: step [m] of the central difference of the torque in a link length
LENGTH_STEP = 1e-6


def length_columns(frame, ctx_model: IdentificationModel, theta, lengths: Sequence[tuple[int, str]]) -> np.ndarray:
    """``(d tau / d L_i) chi`` of each MDH length ``(frame, field)`` of ``lengths`` on the rows of every joint (shape
    (r, len(lengths))): the generated package's emitted derivative (:func:`emitted_length_columns`, one evaluation
    for every length) or, without one or on loaded experiments, the central difference of the numeric
    Newton-Euler torque, at the standard parameters of the current fit (:func:`standard_from_fit`), evaluated at
    full rate on the frame's signals and decimated in parallel with ``W`` (a :class:`.frame.Frame`). A length
    error ``e`` adds ``e`` times its column (Khalil & Dombre 2002, ch. 11: the calibration model linearised in
    the parameter errors)."""
    robot = description_of(ctx_model)
    assert robot is not None   # families exist only with a description (link_length_ready)
    chi, pay = standard_from_fit(rigid_model(ctx_model), robot, theta)
    pairs = [_pair(robot, f, fld) for f, fld in lengths]
    emitted = emitted_length_columns(rigid_model(ctx_model), robot, chi, lengths)

    def fn(ex, a: int, b: int) -> np.ndarray:
        p = pay if ex.loaded else None
        q, dq, ddq = ex.q[a:b], ex.dq[a:b], ex.ddq[a:b]
        if emitted is not None and p is None:
            return emitted(q, dq, ddq)
        return np.stack([(inverse_dynamics(plus, q, dq, ddq, chi, p) - inverse_dynamics(minus, q, dq, ddq, chi, p))
                         / (2 * LENGTH_STEP) for plus, minus in pairs], axis=2)

    return frame.full_rate_columns_batched(fn, len(lengths))


def length_column(frame, ctx_model: IdentificationModel, theta, f: int, fld: str) -> np.ndarray:
    """The column (shape (r, 1)) of the one length ``fld`` of frame ``f``: :func:`length_columns`."""
    return length_columns(frame, ctx_model, theta, [(f, fld)])


class LengthColumns:
    """The columns of a set of lengths (:func:`length_columns`), built once for all of them per frame and fit.

    The loop's link-length families of one round share a fit (``theta``) and a few frames (the identification
    rows, the held-out ones), and the emitted derivative evaluates every geometric constant at once. The column
    is linear in the parameters, ``(d tau / d L) chi = (dY_std / dL) chi``, and so is the parallel decimation
    (a FIR filter and a down-sampling): the decimation of the product is the product of the decimated entries of
    ``dY_std / dL`` (:class:`symoro_gen.identification.geometry.LengthTerms`, only those the generated kernel
    evaluates, for these lengths). Those are decimated once per frame from its second fit on (its signal arrays,
    across rounds: the last two frames held, ``r x s`` float64 each, ``s`` the entries: 163 for the 11 lengths of the
    LWR4) and each fit's columns are one product with them. Without the emitted derivative, or on loaded experiments (the emitted derivative has no
    payload columns), every fit's columns are evaluated at full rate (:func:`length_columns`). The columns of the
    last ``keep`` (frame, fit) pairs are held too (decimated rows: ``r x len(lengths)`` each)."""

    def __init__(self, model: IdentificationModel, lengths: Sequence[tuple[int, str]], keep: int = 4):
        self.model, self.lengths, self.keep = model, tuple(lengths), keep
        self._held: list[tuple[object, dict, np.ndarray]] = []

    def column(self, frame, theta: dict, i: int) -> np.ndarray:
        """The column (shape (r, 1)) of ``lengths[i]`` on ``frame`` at the fit ``theta``."""
        for fr, th, X in self._held:
            if fr is frame and th == theta:
                return X[:, i:i + 1].copy()
        X = self._columns(frame, theta)
        self._held = [*self._held[-(self.keep - 1):], (frame, dict(theta), X)] if self.keep > 1 else [(frame, dict(theta), X)]
        return X[:, i:i + 1].copy()

    def _columns(self, frame, theta: dict) -> np.ndarray:
        got = self._decimated_terms(frame)
        if got is None:
            return length_columns(frame, self.model, theta, self.lengths)
        terms, T = got
        robot = description_of(self.model)
        chi, _ = standard_from_fit(rigid_model(self.model), robot, theta)
        X: np.ndarray = T @ terms.matrix(chi)
        return X

    def _decimated_terms(self, frame) -> tuple[LengthTerms, np.ndarray] | None:
        """The emitted entries of ``dY_std / dL`` on the frame's rows, decimated in parallel with ``W`` (kept
        across rounds, whose families are new objects: :data:`_LENGTH_TERMS`); None without the emitted
        derivative or with a loaded experiment."""
        if any(ex.loaded for ex in frame.experiments):
            return None
        rigid = rigid_model(self.model)
        key = frame.signal_arrays()
        for mdl, lengths, arrs, terms, T in _LENGTH_TERMS:
            if (mdl is rigid and lengths == self.lengths and len(arrs) == len(key)
                    and all(a is b for a, b in zip(arrs, key))):
                return (terms, T) if terms is not None else None
        if not any(len(arrs) == len(key) and all(a is b for a, b in zip(arrs, key)) for arrs in _LENGTH_SEEN):
            # a frame's first fit: its columns at full rate (a frame the loop uses once, the last round's, is
            # never worth the wider build, which would land on the loop's memory high-water mark)
            _LENGTH_SEEN.append(key)
            del _LENGTH_SEEN[:-_LENGTH_TERMS_SIZE]
            return None
        del _LENGTH_TERMS[:-(_LENGTH_TERMS_SIZE - 1) or len(_LENGTH_TERMS)]   # the oldest freed before the build
        robot = description_of(self.model)
        terms = None if robot is None else emitted_length_terms(rigid, robot, self.lengths)
        T = np.zeros((0, 0))
        if terms is not None:
            def fn(ex, a: int, b: int, terms: LengthTerms = terms) -> np.ndarray:
                return terms.values(ex.q[a:b], ex.dq[a:b], ex.ddq[a:b])

            # short stretches and calls: the entries are ~15 times as wide as the columns (the reuse of the
            # filter window's samples keeps the kernel's evaluations at one per sample)
            T = frame.full_rate_columns_batched(_SampleReuse(fn), terms.standard.size, batch_bytes=_TERMS_BATCH_BYTES,
                                                call_samples=64)
            T.setflags(write=False)
        _LENGTH_TERMS.append((rigid, self.lengths, key, terms, T))
        del _LENGTH_TERMS[:-_LENGTH_TERMS_SIZE]
        return (terms, T) if terms is not None else None


#: full-rate bytes of a stretch of the entries of ``dY_std / dL`` decimated at once (the frame's default is 16 MB)
_TERMS_BATCH_BYTES = 4 * 2 ** 20

#: decimated entries of ``dY_std / dL`` kept (per model, lengths and frame; ``r x s`` float64 each, ``s`` the
#: entries: 163 for the 11 visible lengths of the LWR4, 6.6 MB on the 120 s bench's identification frame): the
#: identification and acceptance frames of a round
_LENGTH_TERMS_SIZE = 2
_LENGTH_TERMS: list = []   # [(rigid model, lengths, frame arrays, LengthTerms or None, decimated entries)]
_LENGTH_SEEN: list = []    # [frame arrays] of the frames whose columns were built at full rate once


def describe_length(frame: int, fld: str, value: float, std: float) -> dict:
    """Physical reading of a link-length error: metres and millimetres, the frame and the field (0 ``d``,
    1 ``r``)."""
    return {"length_m": float(value), "length_mm": 1e3 * float(value), "length_mm_std": 1e3 * float(std),
            "frame": float(frame), "field_r": float(fld == "r")}
