"""The library of candidate effects: each is a set of extra columns of ``W``.

A candidate *family* is one physical effect on one joint (or pair of joints, or all joints); when the
effect has a non-linear parameter (Stribeck velocity, ripple order) the family has one member per
value of a 1-D search grid, and the search counts in the multiple-testing correction. Columns are
evaluated on the full-rate band-pass signals and decimated in parallel with ``W`` (see
:mod:`.frame`), except the two linearisations around the current fit (``elasticity``, ``gain``),
which are evaluated on the decimated signals, and rebuilt around each new fit.

Kinds (names as in the JSON output) and their columns on the rows of joint j (q, dq, ddq band-pass
estimates from the measured positions; tau_hat the torque of the declared model fitted to the data,
low-passed like q - not the measured torque, whose noise is that of Y, see :mod:`.frame`; t the time
since the start of the recording):

==================  =====================================================================================
``stribeck``        ``sign(dq_j) exp(-(dq_j/v_s)^2)``, 1-D search over ``v_s`` (log grid 1-50 % of |dq_j|)
``load_friction``   ``|tau_hat,j| sign(dq_j)`` (dry friction growing with the transmitted torque)
``position_ripple`` ``sin(k q_j), cos(k q_j)``, order k >= 1 searched within the decimation band
``spring``          ``s, s^2, s^3`` with ``s = (q_j - c_j) / h_j`` (mid-range, half-range of q_j)
``elasticity``      ``(tau_hat(q - c tau_j e_j) - tau_hat(q)) / c`` (with the derivatives of tau_j on dq, ddq,
                    and the Coulomb term of joint j by its own secant): the torque error of a position
                    measured on the motor side, ``q_link = q_motor - tau/K`` (LWR4 paper eq. 17), as a
                    secant in ``c_j = 1/K_j`` [rad/(N m)] searched on a signed log grid and refined, on
                    *every* joint's rows; ``tau_j`` is the link-side model torque (the drive terms left
                    out, :func:`_link_torque`: motor-side friction does not pass through the spring)
``time_delay``      ``-d tau_hat,j / dt`` (``tau_meas(t) = tau(t - d)`` to first order in the lag d [s]);
                    one family per joint and one for all joints (same lag)
``gain``            ``tau_hat_j`` (model torque of joint j): ``Y_j = tau_j / g_j`` gives
                    ``Y_j = tau_hat_j + (1/g_j - 1) tau_hat_j``; identifiable only relative to the other
                    joints through the dynamic coupling (a common scale of all joints is not: it needs a
                    known payload, see :func:`symoro_gen.identification.sensor_gains`)
``drift``           ``t/T, (t/T)^2`` (T the longest identification experiment)
``coupling``        one-way ``k -> j``: ``ddq_k, dq_k`` on joint j rows; shared (coupled wrist, a motor
                    turning with ``q_j + q_k``): ``ddq_j + ddq_k, dq_j + dq_k, sign(dq_j + dq_k)`` on the
                    rows of j *and* k
``rotor_inertia``   ``ddq_j``
``offset``          ``1``
``joint_zero``      ``(tau_hat(q + c e_j) - tau_hat(q)) / c`` on *every* joint's rows (declared model at the
                    current fit, Coulomb terms left out): the torque error of an encoder zero offset
                    ``q_measured,j = q_true,j - c`` (see :mod:`.geometry`); scored as the tangent
                    ``d tau_hat / d q_j`` (``c = 0``), then rebuilt at the fitted offset (fixed point); one
                    family per joint whose zero the torque can see (:func:`.geometry.visible_zero_joints`,
                    all joints when the model is not given)
``link_length``     ``(d tau / d L) chi`` on *every* joint's rows, ``L`` the MDH ``d`` or ``r`` of one frame: the
                    numeric Newton-Euler torque's central difference at the standard parameters of the current
                    fit (:func:`.geometry.length_column`); one family per length torque data can see
                    (:func:`.geometry.visible_lengths`), only when the robot description is found; the
                    coefficient is the length error ``L_true - L_file`` [m]
``crosstalk``       ``tau_hat,i`` on the rows of joint j, one family per ordered pair of neighbouring joints
                    ``i = j +- 1`` (partner i): joint j's torque channel reads ``c`` times joint i's torque
                    (``tau_meas,j = tau_j + c tau_i``, the cross-sensitivity of a strain-gauge joint torque
                    sensor or a shared current-sense path; :func:`_crosstalk_column`)
``held_friction``   ``s_j`` in joint j's rest segments (:func:`.friction.rest_mask`), 0 elsewhere, ``s_j`` the
                    sign of the joint's last sliding velocity before the segment: a stopped drive keeps the
                    friction of its last sliding direction (the presliding bristles of the LuGre model,
                    Canudas de Wit et al. 1995, sec. 2; Dahl 1968), where the declared law has
                    ``sign(dq) = 0`` on average; the coefficient ``Fh`` is the held friction [N m]
                    (:func:`_held_sign`)
==================  =====================================================================================
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.special import erf

from ..model import IdentificationModel
from ..params import DRIVE_KINDS, split_name
from .frame import Experiment, Frame, attach_model_torque, model_torque
from .friction import rest_mask
from .geometry import (
    LengthColumns,
    decimated_zero_matrix,
    describe_length,
    describe_zero,
    length_joint,
    link_length_ready,
    revolute_joints,
    rigid_model,
    visible_lengths,
    visible_zero_joints,
)

__all__ = ["KINDS", "ALL", "CONTACT_KINDS", "Family", "FitContext", "make_families", "placebo_families", "describe_params",
           "nuisance_columns", "implausible", "GAIN_SCALE_RANGE", "MAX_DELAY_PHASE", "MAX_ZERO_OFFSET_DEG",
           "MAX_LINK_LENGTH_M",
           "MAX_CROSSTALK",
           "clear_elasticity_cache", "clear_loop_caches"]

KINDS = ("stribeck", "load_friction", "position_ripple", "spring", "elasticity", "time_delay", "gain",
         "drift", "coupling", "rotor_inertia", "offset", "joint_zero", "crosstalk",
         "held_friction", "link_length")
ALL = KINDS
#: the effects of a contact sensor on a floating-base robot's rows (not in :data:`KINDS`: a model that has contact
#: sensors offers them itself, ``candidate_families`` of :func:`make_families`): ``contact_offset`` a constant
#: offset ``o`` of the sensor's six components in its axes (``f_measured = f + o``, columns ``J_c^T e_i``),
#: ``contact_gain`` a gain error (``f_measured = (1 + g) f``, column ``J_c^T f_measured``, coefficient
#: ``gamma = g / (1 + g)``); their variant is the contact frame's name
CONTACT_KINDS = ("contact_offset", "contact_gain")

#: signal against which each kind is best seen (plots and the structure table)
REVEAL = {"stribeck": "dq", "load_friction": "tau_hat", "position_ripple": "q", "spring": "q",
          "elasticity": "tau_hat", "time_delay": "dtau_hat", "gain": "tau_hat", "drift": "t", "coupling": "ddq",
          "rotor_inertia": "ddq", "offset": "t", "placebo": "t", "joint_zero": "q", "link_length": "q",
          "crosstalk": "tau_hat", "held_friction": "dq"}

#: Stribeck velocity grid: ``n`` points from ``lo`` to ``hi`` times the 98th percentile of |dq_j|
STRIBECK_GRID = (0.01, 0.5, 8)
#: ... and never below this many standard deviations of the velocity noise: below it the sign of the
#: band-pass velocity chatters at reversals and its Coulomb column is smoothed by the noise (an
#: artefact of the processing, not friction)
STRIBECK_NOISE_FLOOR = 5.0
#: ripple orders tried (kept when ``k * |dq|_98 / (2 pi)`` lies below half the decimation cut-off); order 1 is
#: a once-per-turn torque of the joint (see :data:`ONCE_PER_TURN_CONDITION`)
RIPPLE_ORDERS = (1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32)
#: order 1 (``sin q_j, cos q_j``) is tried when the condition number of the unit-length columns
#: ``[1, sin q_j, cos q_j]`` over the joint's samples is at most this: a condition index above 30 marks
#: strong collinearity (Belsley, Kuh & Welsch 1980, Regression Diagnostics, ch. 3). Over a small range
#: ``cos q_j`` is a constant and ``sin q_j`` a line (an offset and the spring's linear term); about +-33 deg
#: of a sinusoidal motion reach 30, +-73 deg give 5. Over less than half a turn the pair lies almost in the
#: span of the spring's cubic (the sine's part outside ``[1, s, s^2, s^3]`` is 0.2 %, the cosine's 3.5 % at
#: +-73 deg): the two compete as two- and three-parameter descriptions of the same shape
ONCE_PER_TURN_CONDITION = 30.0
#: relative step of the central differences of the elasticity linearisation
ELASTIC_STEP = 1e-6
#: compliance grid of the elasticity search: +-ELASTIC_GRID values per sign, log-spaced, the largest
#: deflecting the joint by ELASTIC_MAX_DEFLECTION [rad] at the 98th percentile of |tau_j|, the smallest
#: ELASTIC_RANGE times less
ELASTIC_GRID = 5
ELASTIC_MAX_DEFLECTION = 0.05
ELASTIC_RANGE = 300.0
#: include the Coulomb secant in the elasticity column (off: at velocity reversals it is a sum of
#: pulses that correlate with the Coulomb errors the velocity noise causes there, and gave false
#: positives on noisy data; it matters only when Coulomb friction is large against the stiffness)
ELASTIC_COULOMB = False


@dataclass(frozen=True, eq=False)
class FitContext:
    """The current fit, for the candidates linearised around it.

    Attributes
    ----------
    model : IdentificationModel
        Generated-model interface.
    theta : dict name -> value
        Declared-model parameters (base + payload) of the current fit.
    predictions : dict
        ``id(frame) -> (r,)`` current model prediction (declared + added effects) on each frame.
    """

    model: IdentificationModel
    theta: dict
    predictions: dict = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class Family:
    """One candidate effect (one member per search value).

    Attributes
    ----------
    kind : str
    joint : int or None
        0-based joint whose equations it adds to (None: all joints).
    partner : int or None
        Other joint of a coupling.
    variant : str
        ``"one-way"`` / ``"shared"`` for couplings, ``"all"`` for the common time delay...
    params : tuple of str
        Short parameter names (``Fst``, ``mu``...).
    grid_label : str or None
        Name of the searched parameter; ``grid`` its values.
    reveal : str
        Row signal (key of ``Frame.sig``) the effect shows against.
    reveal_joint : int or None
        Joint of that signal (default ``joint``).
    depends_on_fit : bool
        Columns are a linearisation around the current fit (recomputed each round).
    build : callable
        ``build(frame, ctx) -> list of (r, p) arrays`` (one per grid value).
    build_at : callable, optional
        ``build_at(frame, ctx, value) -> (r, p)`` for any value of a continuous searched parameter
        (refined between grid points once the family is chosen).
    self_consistent : bool
        The searched parameter is the coefficient itself (a secant column): after each fit the column
        is rebuilt at the fitted coefficient (fixed point).
    rows : tuple of int, optional
        The joints (0-based) whose rows the columns act on and whose validation error must improve, when
        the family declares them itself (a contact sensor's offset or gain on a floating-base robot's rows,
        :data:`CONTACT_KINDS`: every row its wrench reaches); default (None): ``joint`` (and a shared
        partner), or every joint.
    """

    kind: str
    joint: int | None
    params: tuple[str, ...]
    build: Callable
    partner: int | None = None
    variant: str = ""
    grid_label: str | None = None
    grid: tuple[float, ...] = ()
    reveal: str = "t"
    reveal_joint: int | None = None
    depends_on_fit: bool = False
    placebo: bool = False
    info: tuple = ()
    build_at: Callable | None = None
    self_consistent: bool = False
    rows: tuple[int, ...] | None = None

    @property
    def key(self) -> tuple:
        return (self.kind, self.joint, self.partner, self.variant)

    @property
    def n_members(self) -> int:
        return max(1, len(self.grid))

    @property
    def p(self) -> int:
        return len(self.params)

    @property
    def label(self) -> str:
        if self.kind in CONTACT_KINDS:
            return f"{self.kind}[{self.variant}]"   # contact_gain[foot]: the sensor of contact frame foot
        if self.kind == "coupling":
            assert self.joint is not None and self.partner is not None  # a coupling names both joints
            a, b = self.joint + 1, self.partner + 1
            return f"coupling{a}{'<' if self.variant == 'one-way' else '+'}{b}"
        if self.kind == "link_length":
            return f"link_length{dict(self.info).get('frame', '')}{self.variant}"   # link_length3r
        if self.kind == "crosstalk" and self.joint is not None and self.partner is not None:
            return f"crosstalk{self.partner + 1}>{self.joint + 1}"   # source joint > channel it is read in
        return f"{self.kind}{'' if self.joint is None else self.joint + 1}"

    def names(self) -> tuple[str, ...]:
        """Full parameter names (columns of the augmented system)."""
        return tuple(f"{self.label}.{p}" for p in self.params)


# ------------------------------------------------------------------------------------------------
def _col(x):
    return np.asarray(x, float).reshape(-1, 1)


def _sign(x):
    return np.sign(x)


def _stats(frame: Frame):
    dq = frame.samples()["dq"]
    q = frame.samples()["q"]
    v98 = np.quantile(np.abs(dq), 0.98, axis=0)
    qmin, qmax = q.min(axis=0), q.max(axis=0)
    return v98, qmin, qmax


def make_families(frame: Frame, kinds: Sequence[str] = ALL, *, ripple_orders: Sequence[int] = RIPPLE_ORDERS,
                  stribeck_grid=STRIBECK_GRID, model: IdentificationModel | None = None) -> list[Family]:
    """Candidate families for the joints of ``frame`` (the identification frame fixes the search
    grids and scalings, reused unchanged on validation data).

    Parameters
    ----------
    frame : Frame
        Identification data.
    kinds : sequence of str
        Subset of :data:`KINDS`.
    model : IdentificationModel, optional
        The generated model: ``joint_zero`` families only for the joints whose zero the torque can see
        (:func:`.geometry.visible_zero_joints`) and with the joint's kind (angle or length); without it, on
        every joint, read as angles. A model with a method ``candidate_families(frame, kinds, families)``
        returns the final list from the library's ``families`` (it may replace some and add its own, e.g.
        :data:`CONTACT_KINDS`).
    """
    bad = [k for k in kinds if k not in KINDS]
    if bad:
        raise ValueError(f"unknown candidate kind(s) {bad}; known: {', '.join(KINDS)}")
    n = frame.n_joints
    st = _FrameScales.of(frame)
    out: list[Family] = []
    ks = set(kinds)
    for j in range(n):
        out += _friction_families(j, ks, st, stribeck_grid)
        out += _held_friction_families(j, ks)
        out += _position_families(j, ks, st, ripple_orders)
        out += _model_torque_families(j, ks, st)
        out += _signal_families(j, ks, st)
    out += _joint_zero_families(n, ks, model)
    out += _link_length_families(ks, model)
    out += _crosstalk_families(n, ks)
    out += _all_joint_families(n, ks)
    # a model with more to offer (a floating-base robot's rows: its contact sensors, and the gain and delay of a
    # drive on the drive's own torque where a contact wrench shares its row) gives the final list itself
    offer = getattr(model, "candidate_families", None)
    if callable(offer):
        out = list(offer(frame, ks, out))
    # columns that do not depend on the fit are the same in every round (the frames keep their q, dq,
    # ddq, t arrays when the model torque is re-attached): build them once per frame
    return [f if f.depends_on_fit else replace(f, build=_memo_build(f.build)) for f in out]


@dataclass(frozen=True, eq=False)
class _FrameScales:
    """What the identification frame fixes for the search grids and scalings of the candidates: per joint
    the 98th percentiles of |dq| and |tau|, the position range and the velocity noise; the longest
    experiment's duration and the lowest decimation cut-off."""

    v98: np.ndarray
    qmin: np.ndarray
    qmax: np.ndarray
    tau98: np.ndarray
    dq_noise: np.ndarray
    T: float
    fdec: float
    turn_cond: np.ndarray

    @classmethod
    def of(cls, frame: Frame) -> _FrameScales:
        v98, qmin, qmax = _stats(frame)
        tau98 = np.quantile(np.abs(frame.samples()["tau"]), 0.98, axis=0)
        dq_noise = np.max([ex.dq_noise for ex in frame.experiments], axis=0)
        T = max(float(ex.t[-1]) for ex in frame.experiments)
        T = T if T > 0 else 1.0
        fdec = min(ex.settings.decimation_cutoff_hz for ex in frame.experiments)
        return cls(v98, qmin, qmax, tau98, dq_noise, T, fdec, _turn_condition(np.asarray(frame.samples()["q"], float)))


def _turn_condition(q: np.ndarray) -> np.ndarray:
    """Per joint, the condition number of the unit-length columns ``[1, sin q_j, cos q_j]`` over the samples
    ``q`` (N, n) (:data:`ONCE_PER_TURN_CONDITION`); inf for a joint that does not move."""
    out = np.full(q.shape[1], np.inf)
    for j in range(q.shape[1]):
        A = np.stack([np.ones(q.shape[0]), np.sin(q[:, j]), np.cos(q[:, j])], 1)
        nrm = np.linalg.norm(A, axis=0)
        if q.shape[0] >= 3 and np.all(nrm > 0):
            sv = np.linalg.svd(A / nrm, compute_uv=False)
            out[j] = sv[0] / sv[-1] if sv[-1] > 0 else np.inf
    return out


def _friction_families(j: int, ks: set[str], st: _FrameScales, stribeck_grid) -> list[Family]:
    """Stribeck and load-dependent friction of joint j."""
    v98, dq_noise = st.v98, st.dq_noise
    out: list[Family] = []
    if "stribeck" in ks and v98[j] > 0:
        lo, hi, m = stribeck_grid
        vlo = max(lo * v98[j], STRIBECK_NOISE_FLOOR * dq_noise[j])
        grid = tuple(float(v) for v in np.geomspace(vlo, max(hi * v98[j], 2 * vlo), int(m)))

        def b_str(fr, ctx, j=j, grid=grid):
            X = fr.full_rate_columns(
                lambda ex: {j: np.stack([_sign(ex.dq[:, j]) * np.exp(-(ex.dq[:, j] / vs) ** 2) for vs in grid], 1)},
                len(grid))
            return [X[:, i:i + 1] for i in range(len(grid))]

        def b_str_at(fr, ctx, vs, j=j):
            return fr.full_rate_columns(
                lambda ex: {j: _col(_sign(ex.dq[:, j]) * np.exp(-(ex.dq[:, j] / vs) ** 2))}, 1)

        out.append(Family("stribeck", j, ("Fst",), b_str, grid_label="vs", grid=grid, reveal="dq",
                          build_at=b_str_at))
    if "load_friction" in ks:
        out.append(Family("load_friction", j, ("mu",), lambda fr, ctx, j=j: [fr.full_rate_columns(
            lambda ex: {j: _col(np.abs(ex.tau_hat[:, j]) * _sign(ex.dq[:, j]))}, 1)], reveal="tau_hat",
            depends_on_fit=True))
    return out


def _held_friction_families(j: int, ks: set[str]) -> list[Family]:
    """The friction joint j holds at rest (:func:`_held_sign`)."""
    if "held_friction" not in ks:
        return []
    return [Family("held_friction", j, ("Fh",), lambda fr, ctx, j=j: [fr.full_rate_columns(
        lambda ex: {j: _col(_held_sign(ex, j))}, 1)], reveal="dq")]


def _held_sign(ex: Experiment, j: int) -> np.ndarray:
    """Joint j's held-friction column of one experiment (full rate): in each rest segment of the joint
    (:func:`.friction.rest_mask`) the sign of its sliding velocity just before the segment (the mean band-pass
    velocity over the quarter period ``1 / (4 f_dyn)`` before it), 0 elsewhere and in a segment the
    experiment starts with (no sliding direction known)."""
    rest = rest_mask(ex)[:, j]
    out = np.zeros(rest.shape[0])
    if not rest.any():
        return out
    st = ex.settings
    w = max(1, int(round(st.fs / (4.0 * st.dynamics_bandwidth_hz))))
    edges = np.diff(np.concatenate([[0], rest.astype(np.int8), [0]]))
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
        if a == 0:
            continue
        out[a:b] = np.sign(np.mean(ex.dq[max(0, a - w):a, j]))
    return out


def _position_families(j: int, ks: set[str], st: _FrameScales, ripple_orders: Sequence[int]
                        ) -> list[Family]:
    """Position ripple and spring of joint j. Orders k >= 2 need half a period inside the joint's range
    (``k * span >= pi``); order 1, a once-per-turn torque, needs ``sin q_j, cos q_j`` told apart from a
    constant (:data:`ONCE_PER_TURN_CONDITION`)."""
    v98, qmin, qmax, fdec = st.v98, st.qmin, st.qmax, st.fdec
    out: list[Family] = []
    if "position_ripple" in ks:
        span = qmax[j] - qmin[j]
        orders = tuple(float(k) for k in ripple_orders
                       if (not math.isfinite(fdec) or k * v98[j] / (2 * math.pi) <= 0.5 * fdec)
                       and (st.turn_cond[j] <= ONCE_PER_TURN_CONDITION if k == 1 else k * span >= math.pi))
        if orders:
            def b_rip(fr, ctx, j=j, orders=orders):
                X = fr.full_rate_columns(lambda ex: {j: np.concatenate(
                    [np.stack([np.sin(k * ex.q[:, j]), np.cos(k * ex.q[:, j])], 1) for k in orders], 1)},
                    2 * len(orders))
                return [X[:, 2 * i:2 * i + 2] for i in range(len(orders))]

            out.append(Family("position_ripple", j, ("a_sin", "a_cos"), b_rip, grid_label="k", grid=orders,
                              reveal="q"))
    if "spring" in ks and qmax[j] > qmin[j]:
        c, h = 0.5 * (qmax[j] + qmin[j]), 0.5 * (qmax[j] - qmin[j])

        def b_spr(fr, ctx, j=j, c=c, h=h):
            def f(ex):
                s = (ex.q[:, j] - c) / h
                return {j: np.stack([s, s * s, s * s * s], 1)}
            return [fr.full_rate_columns(f, 3)]

        out.append(Family("spring", j, ("k1", "k2", "k3"), b_spr, reveal="q",
                          info=(("center", float(c)), ("half_range", float(h)))))
    return out


def _model_torque_families(j: int, ks: set[str], st: _FrameScales) -> list[Family]:
    """Elasticity, time delay and gain of joint j (columns built on the model torque of the current fit)."""
    tau98 = st.tau98
    out: list[Family] = []
    if "elasticity" in ks and tau98[j] > 0:
        c_hi = ELASTIC_MAX_DEFLECTION / tau98[j]
        mags = np.geomspace(c_hi / ELASTIC_RANGE, c_hi, ELASTIC_GRID)
        grid = tuple(float(x) for x in np.concatenate([-mags[::-1], mags]))

        def b_el(fr, ctx, j=j, grid=grid):
            return [_elasticity_smooth(fr, ctx, j, c) + _elasticity_coulomb(fr, ctx, j, c) for c in grid]

        def b_el_at(fr, ctx, c, j=j):
            return _elasticity_smooth(fr, ctx, j, c) + _elasticity_coulomb(fr, ctx, j, c)

        out.append(Family("elasticity", j, ("c",), b_el, grid_label="c_search", grid=grid, reveal="tau_hat",
                          depends_on_fit=True, build_at=b_el_at, self_consistent=True))
    if "time_delay" in ks:
        out.append(Family("time_delay", j, ("d",), lambda fr, ctx, j=j: [fr.full_rate_columns(
            lambda ex: {j: _col(-ex.dtau_hat[:, j])}, 1)], reveal="dtau_hat", depends_on_fit=True))
    if "gain" in ks:
        out.append(Family("gain", j, ("gamma",), lambda fr, ctx, j=j: [_gain_column(fr, ctx, j)],
                          reveal="tau_hat", depends_on_fit=True))
    return out


def _signal_families(j: int, ks: set[str], st: _FrameScales) -> list[Family]:
    """Drift in time, rotor inertia and offset of joint j."""
    T = st.T
    out: list[Family] = []
    if "drift" in ks:
        out.append(Family("drift", j, ("a1", "a2"), lambda fr, ctx, j=j, T=T: [fr.full_rate_columns(
            lambda ex: {j: np.stack([ex.t / T, (ex.t / T) ** 2], 1)}, 2)], reveal="t"))
    if "rotor_inertia" in ks:
        out.append(Family("rotor_inertia", j, ("IA",), lambda fr, ctx, j=j: [fr.full_rate_columns(
            lambda ex: {j: _col(ex.ddq[:, j])}, 1)], reveal="ddq"))
    if "offset" in ks:
        out.append(Family("offset", j, ("OFF",), lambda fr, ctx, j=j: [fr.full_rate_columns(
            lambda ex: {j: np.ones((ex.n_samples, 1))}, 1)], reveal="t"))
    return out


def _joint_zero_families(n: int, ks: set[str], model: IdentificationModel | None) -> list[Family]:
    """Encoder zero offset of each joint whose zero the torque can see (:mod:`.geometry`)."""
    if "joint_zero" not in ks:
        return []
    joints = tuple(range(n)) if model is None else visible_zero_joints(model)
    rev = np.ones(n, bool) if model is None else revolute_joints(model)
    out = []
    for j in joints:
        def b_zero(fr, ctx, j=j):
            return [_joint_zero_build(fr, ctx, j, 0.0)]

        def b_zero_at(fr, ctx, c, j=j):
            return _joint_zero_build(fr, ctx, j, float(c))

        out.append(Family("joint_zero", j, ("q0",), b_zero, reveal="q", depends_on_fit=True, build_at=b_zero_at,
                          self_consistent=True, info=(("revolute", bool(rev[j])),)))
    return out


def _link_length_families(ks: set[str], model: IdentificationModel | None) -> list[Family]:
    """A length error of each MDH ``d``/``r`` torque data can see (:mod:`.geometry`; none without the model or
    its robot description). ``joint`` is the joint of the frame (reveal: its angle), ``variant`` the field."""
    if "link_length" not in ks or model is None or not link_length_ready(model):
        return []
    out = []
    lengths = visible_lengths(model)
    shared = LengthColumns(model, lengths)   # one full-rate pass per round for every length
    for i, (f, fld) in enumerate(lengths):
        def build(fr, ctx, i=i):   # the model checked by link_length_ready: its base names
            return [shared.column(fr, ctx.theta, i)]

        out.append(Family("link_length", length_joint(model, f), (fld,), build, variant=fld, reveal="q",
                          depends_on_fit=True, info=(("frame", f), ("field", fld))))
    return out


def _crosstalk_families(n: int, ks: set[str]) -> list[Family]:
    """Cross-talk into joint j's torque channel from each neighbouring joint ``i = j +- 1`` (the neighbours only:
    their cables and drives sit side by side; a pair further apart would need a reason of its own, and every
    family more raises the round's Bonferroni factor)."""
    if "crosstalk" not in ks:
        return []
    out = []
    for j in range(n):
        for i in (j - 1, j + 1):
            if 0 <= i < n:
                out.append(Family("crosstalk", j, ("c",), lambda fr, ctx, j=j, i=i: [_crosstalk_column(fr, j, i)],
                                  partner=i, reveal="tau_hat", reveal_joint=i, depends_on_fit=True))
    return out


def _crosstalk_column(frame: Frame, j: int, i: int) -> np.ndarray:
    """Joint i's model torque (the smoothed ``tau_hat``, as the ``gain`` column) on the rows of joint j: the
    torque of joint i read, times ``c``, in joint j's channel."""
    X = np.zeros((frame.n_rows, 1))
    rows = frame.rows_of(j)
    X[rows, 0] = frame.sig["tau_hat"][rows, i]
    return X


def _joint_zero_build(frame: Frame, ctx: FitContext, m: int, c: float) -> np.ndarray:
    """Joint m's zero-offset column on the rows of every joint: the secant ``(W(q + c e_m) - W(q)) / c`` of the
    declared regressor (``c = 0``: the tangent, :func:`.geometry.regressor_secant`) evaluated at full rate and
    decimated in parallel with ``W`` (so that it shares W's filter edges: on the decimated signals the edge
    rows differ and the part of the column outside W's span is concentrated there), times the declared
    parameters of the current fit. The column is linear in the parameters and so is the decimation: the
    decimated tangent does not depend on the fit and is kept per frame (:func:`_zero_matrix`)."""
    D, names = _zero_matrix(frame, ctx.model, m, c)
    th = np.array([float(ctx.theta.get(nm, 0.0)) for nm in names])
    return (D @ th).reshape(-1, 1)


#: decimated regressor tangents kept (per frame and joint; each at most the size of ``W``, only its columns
#: that the angle changes): the joints of the identification and acceptance frames of a 7-joint arm, and one
#: more; the secants of the fixed point (an accepted effect's, a few per round) are recomputed
_ZERO_CACHE_SIZE = 15
_ZERO_CACHE: list = []   # [(frame arrays, joint, parameter names, matrix, its columns' names)], most recent last


def _zero_matrix(frame: Frame, model: IdentificationModel, m: int, c: float) -> tuple[np.ndarray, tuple[str, ...]]:
    """The decimated secant (``c = 0``: tangent) of the regressor in joint m's angle and the names of its
    columns: those of the rigid model under any friction law (:func:`.geometry.rigid_model`; a law's columns
    are functions of the velocity, their derivative in the angle is 0, and the columns it replaces, ``FS``
    and ``FV``, are too), so that a law chosen during the loop, which renames the parameters, leaves the kept
    tangent valid; only the columns that are not 0 on every row are kept (the Coulomb, viscous, offset and
    rotor-inertia columns, and the inertial ones of the links before joint m, are)."""
    rigid = rigid_model(model)
    names = tuple(rigid.BASE_NAMES) + tuple(getattr(rigid, "PAYLOAD_NAMES", ()))
    if c != 0.0:
        return decimated_zero_matrix(frame, rigid, m, c), names
    key = frame.signal_arrays()
    for arrs, jj, nms, D, kept in _ZERO_CACHE:
        if jj == m and nms == names and len(arrs) == len(key) and all(a is b for a, b in zip(arrs, key)):
            return D, kept
    full = decimated_zero_matrix(frame, rigid, m, c)
    cols = np.flatnonzero(np.any(full != 0.0, axis=0))
    D = np.ascontiguousarray(full[:, cols])
    D.setflags(write=False)
    kept = tuple(names[k] for k in cols)
    _ZERO_CACHE.append((key, m, names, D, kept))
    del _ZERO_CACHE[:-_ZERO_CACHE_SIZE]
    return D, kept


def _all_joint_families(n: int, ks: set[str]) -> list[Family]:
    """The effects of several joints: one time delay of every joint, couplings of joint pairs."""
    out: list[Family] = []
    if "time_delay" in ks and n > 1:
        out.append(Family("time_delay", None, ("d",), lambda fr, ctx: [fr.full_rate_columns(
            lambda ex: {k: _col(-ex.dtau_hat[:, k]) for k in range(n)}, 1)], variant="all", reveal="dtau_hat",
            depends_on_fit=True))
    if "coupling" in ks:
        for j in range(n):
            for k in range(n):
                if k == j:
                    continue
                out.append(Family("coupling", j, ("IA", "FV"), lambda fr, ctx, j=j, k=k: [fr.full_rate_columns(
                    lambda ex: {j: np.stack([ex.ddq[:, k], ex.dq[:, k]], 1)}, 2)], partner=k, variant="one-way",
                    reveal="ddq", reveal_joint=k))
                if k > j:
                    def b_sh(fr, ctx, j=j, k=k):
                        def f(ex):
                            a = ex.ddq[:, j] + ex.ddq[:, k]
                            v = ex.dq[:, j] + ex.dq[:, k]
                            X = np.stack([a, v, _sign(v)], 1)
                            return {j: X, k: X}
                        return [fr.full_rate_columns(f, 3)]

                    out.append(Family("coupling", j, ("IAm", "FVm", "FSm"), b_sh, partner=k, variant="shared",
                                      reveal="ddq", reveal_joint=k))
    return out


#: frames whose columns a memoised family keeps (identification, validation, and one more)
_MEMO_FRAMES = 3


def _memo_build(build: Callable) -> Callable:
    """``build(frame, ctx)`` remembered per frame (keyed on the identity of its signal arrays, held so that
    an identity is not reused) for a family whose columns do not depend on the fit: the decimation of
    the full-rate columns is the bulk of a round otherwise. The columns are returned read-only."""
    cache: list = []   # [(arrays, columns)], most recent last

    def run(frame: Frame, ctx: FitContext):
        key = frame.signal_arrays()
        for arrs, cols in cache:
            if len(arrs) == len(key) and all(a is b for a, b in zip(arrs, key)):
                return list(cols)
        cols = build(frame, ctx)
        for X in cols:
            X.setflags(write=False)
        cache.append((key, cols))
        del cache[:-_MEMO_FRAMES]
        return list(cols)
    return run


def nuisance_columns(frame: Frame, names: Sequence[str], dq_noise: np.ndarray) -> np.ndarray:
    """Columns absorbing the Coulomb-column error that velocity noise causes at reversals.

    The declared model's Coulomb column of joint j is ``sign(dq_j)`` of the *band-pass* velocity; with a
    velocity noise of standard deviation ``s_j`` the torque actually follows, on average,
    ``erf(dq_j / (sqrt(2) s_j))`` of it. The column ``erf(dq_j / (sqrt(2) s_j)) - sign(dq_j)`` (one per joint
    with a Coulomb parameter ``FS<j>`` in ``names`` and ``s_j > 0``) is added to the design the candidates
    are scored against, so that this processing artefact is not taken for Stribeck friction or
    anything else concentrated at reversals.

    Returns
    -------
    ndarray, shape (r, m)
    """
    cols = []
    for j in range(frame.n_joints):
        s = float(dq_noise[j])
        if s <= 0 or not any(nm.startswith("FS") and nm[2:].rstrip("R") == str(j + 1) for nm in names):
            continue
        cols.append(frame.full_rate_columns(_smoothed_sign_gap(j, s), 1))
    return np.hstack(cols) if cols else np.zeros((frame.n_rows, 0))


def _smoothed_sign_gap(j: int, s: float) -> Callable[[Experiment], dict[int, np.ndarray]]:
    """The full-rate column ``erf(dq_j / (sqrt(2) s)) - sign(dq_j)`` of joint j of an experiment."""
    def column(ex: Experiment) -> dict[int, np.ndarray]:
        return {j: _col(erf(ex.dq[:, j] / (math.sqrt(2.0) * s)) - _sign(ex.dq[:, j]))}
    return column


def placebo_families(frame: Frame, rng: np.random.Generator, per_joint: int, *, n_sines: int = 3) -> list[Family]:
    """Placebo candidates on each joint's rows, ``per_joint`` of each sort: 2 columns of random smooth
    functions of time (random frequencies between ``1/T`` and the dynamics bandwidth), and 2 random
    linear combinations of every joint's standardised position, velocity and acceleration. They have
    no physical meaning; an effect must do better than all of them (a calibration of the null that
    makes no white-noise assumption)."""
    out = []
    T = max(float(ex.t[-1]) for ex in frame.experiments) or 1.0
    fmax = max(ex.settings.dynamics_bandwidth_hz for ex in frame.experiments)
    for j in range(frame.n_joints):
        for i in range(per_joint):
            f = np.exp(rng.uniform(math.log(1.0 / T), math.log(max(fmax, 2.0 / T)), size=(2, n_sines)))
            ph = rng.uniform(0, 2 * math.pi, size=(2, n_sines))

            def b(fr, ctx, j=j, f=f, ph=ph):
                return [fr.full_rate_columns(lambda ex: {j: np.stack(
                    [np.sin(2 * math.pi * f[c][:, None] * ex.t[None, :] + ph[c][:, None]).sum(0) for c in range(2)],
                    1)}, 2)]

            out.append(Family("placebo", j, ("p1", "p2"), b, variant=f"time#{i + 1}", reveal="t", placebo=True))
    # motion placebos: random combinations of every joint's standardised q, dq, ddq - as smooth and as
    # locked to the (often repeated) excitation as the physical candidates, so a coincidental fit of a
    # deterministic artefact that repeats in the validation data is not taken for an effect
    S = frame.samples()
    scale = {k: np.maximum(np.std(S[k], axis=0), 1e-300) for k in ("q", "dq", "ddq")}
    center = {k: np.mean(S[k], axis=0) for k in ("q", "dq", "ddq")}
    n = frame.n_joints
    for j in range(n):
        for i in range(per_joint):
            coef = rng.standard_normal((2, 3, n))

            def bm(fr, ctx, j=j, coef=coef):
                def f(ex):
                    cols = []
                    for c in range(2):
                        x = sum(((getattr(ex, k) - center[k]) / scale[k]) @ coef[c, a]
                                for a, k in enumerate(("q", "dq", "ddq")))
                        cols.append(x)
                    return {j: np.stack(cols, 1)}
                return [fr.full_rate_columns(f, 2)]

            out.append(Family("placebo", j, ("p1", "p2"), bm, variant=f"motion#{i + 1}", reveal="t", placebo=True))
    return out


# ------------------------------------------------------------------------------------------------
def _rows_by_sample(frame: Frame, j: int) -> np.ndarray:
    """Rows of joint j in sample order (sample s of :meth:`Frame.samples` is the s-th row of joint j)."""
    return frame.rows_of(j)


def _gain_column(frame: Frame, ctx: FitContext, j: int) -> np.ndarray:
    """The declared model's torque of joint j on its rows (the smoothed ``tau_hat``, see
    :func:`.frame.attach_model_torque`, rather than ``W chi`` whose acceleration noise is the residual's)."""
    X = np.zeros((frame.n_rows, 1))
    rows = frame.rows_of(j)
    X[rows, 0] = frame.sig["tau_hat"][rows, j]
    return X


_UNSHIFTED: dict = {}   # one-entry cache of the unshifted model torque (frame, context) of the elasticity secant


def clear_loop_caches() -> None:
    """Forget what the loop's candidate builds keep by frame identity: the decimated joint-zero tangents
    (:data:`_ZERO_CACHE`) and the elasticity secant's model torques (:func:`clear_elasticity_cache`, which hold
    the frames themselves). The diagnosis calls it once the loop's frames are done with: the report builds its
    columns on other frames, so these would only hold memory through its refits (a cache miss recomputes the
    same numbers)."""
    _ZERO_CACHE.clear()
    clear_elasticity_cache()


def clear_elasticity_cache() -> None:
    """Forget the unshifted model torque the elasticity secant caches by frame and context identity (to be
    called around a pass that builds columns on a frame whose identity may be reused)."""
    _UNSHIFTED.clear()
    _LINK.clear()


def _elasticity_smooth(frame: Frame, ctx: FitContext, m: int, c: float) -> np.ndarray:
    """Secant ``(tau_hat(x - c d) - tau_hat(x)) / c`` of the model torque (all joints' rows, Coulomb terms
    left out, see :func:`_elasticity_coulomb`) with ``x = (q, dq, ddq)`` and ``d`` = joint m's model
    torque and its derivatives on joint m: the torque error of a link position ``q_m - c tau_m``
    measured as ``q_m``. ``c -> 0`` gives the tangent ``-d tau_hat / d eps``."""
    S = frame.samples()
    q, dq, ddq = S["q"], S["dq"], S["ddq"]
    L = _link_torque(frame, ctx)
    d0, d1, d2 = L["tau_hat"][:, m], L["dtau_hat"][:, m], L["ddtau_hat"][:, m]
    loaded = np.array([frame.experiments[e].loaded for e in S["experiment"]], bool)

    def torque(sg):
        a, b, cc = q.copy(), dq.copy(), ddq.copy()
        a[:, m] += sg * d0
        b[:, m] += sg * d1
        cc[:, m] += sg * d2
        out = model_torque(ctx.model, ctx.theta, a, b, cc, False, skip_prefix=("FS",))
        if loaded.any():
            out[loaded] = model_torque(ctx.model, ctx.theta, a[loaded], b[loaded], cc[loaded], True,
                                       skip_prefix=("FS",))
        return out

    if c == 0.0:
        h = ELASTIC_STEP / max(float(np.abs(d0).max()), 1e-12)
        J = -(torque(h) - torque(-h)) / (2 * h)
    else:
        key = (id(frame), id(ctx))
        if _UNSHIFTED.get("key") != key:   # tau_hat(x) is the same for every joint and every c
            _UNSHIFTED.clear()
            _UNSHIFTED.update(key=key, tau=torque(0.0))
        J = (torque(-c) - _UNSHIFTED["tau"]) / c
    X = np.zeros((frame.n_rows, 1))
    for j in range(frame.n_joints):
        rows = _rows_by_sample(frame, j)
        X[rows, 0] = J[:, j]
    return X


_LINK: dict = {}   # link-side model torque of the elasticity deflection, by (frame, context) identity


def _link_torque(frame: Frame, ctx: FitContext) -> dict[str, np.ndarray]:
    """The torque the elastic element carries, per decimated sample: the current fit's model torque without
    the drive terms (``DRIVE_KINDS``: rotor inertia, viscous and Coulomb friction, offset, which act on the
    motor side of the gear), low-passed and differentiated like ``tau_hat`` (:func:`.frame.attach_model_torque`).

    A motor-side encoder reads ``q_link + tau_link / K`` with ``tau_link = M(q) ddq + C(q, dq) dq + g(q)`` the
    torque through the spring (Spong 1987, eq. 2-3; LWR4 paper eq. 17). Deflecting by the model torque with its
    Coulomb term instead puts ``c FS sign(dq)`` - chattering with the velocity noise at every reversal - and its
    derivatives into the shifted velocity and acceleration: pulses on every joint's rows that correlate with the
    Coulomb errors the velocity noise causes there, fitted on the identification data (p = 1e-50 for the LWR4's
    joint 4 at K = 3000 N m/rad, 500 Hz) and predicting the acceptance data worse."""
    key = (id(frame), id(ctx))
    held = _LINK.get(key)
    if held is not None and held[0] is frame and held[1] is ctx:
        return held[2]
    theta = {nm: (0.0 if _is_drive(nm) else float(v)) for nm, v in ctx.theta.items()}
    S = attach_model_torque(frame, ctx.model, theta).samples()
    out = {k: S[k] for k in ("tau_hat", "dtau_hat", "ddtau_hat")}
    if len(_LINK) >= 4:   # the frames of a round (identification, acceptance) and of the one before
        del _LINK[next(iter(_LINK))]
    _LINK[key] = (frame, ctx, out)
    return out


def _is_drive(name: str) -> bool:
    try:
        return split_name(name)[0] in DRIVE_KINDS
    except ValueError:   # a payload parameter
        return False


def _coulomb_value(theta: dict, j: int) -> float:
    for nm, v in theta.items():
        if nm.startswith("FS") and nm[2:].rstrip("R") == str(j + 1):
            return float(v)
    return 0.0


def _elasticity_coulomb(frame: Frame, ctx: FitContext, m: int, c: float) -> np.ndarray:
    """Secant of the Coulomb term of joint m: with the link velocity ``dq_m - c dtau_m`` the torque has
    ``FS_m sign(dq_m - c dtau_m)`` where the model has ``FS_m sign(dq_m)``; the column is their decimated
    difference divided by c (the sign function has no useful tangent)."""
    fs = _coulomb_value(ctx.theta, m)
    if not ELASTIC_COULOMB or fs == 0.0 or c == 0.0:
        return np.zeros((frame.n_rows, 1))
    def column(ex: Experiment) -> dict[int, np.ndarray]:
        assert ex.dtau_hat is not None  # the model torque is attached before the candidates are built
        return {m: _col(fs * (_sign(ex.dq[:, m] - c * ex.dtau_hat[:, m]) - _sign(ex.dq[:, m])) / c)}

    return frame.full_rate_columns(column, 1)


#: a ``gain`` effect's scale ``1 + gamma`` must lie in this range: a torque sensor or drive gain off by more
#: than a factor 2 (or of the wrong sign) is a units or sign error of the data, not a calibration effect
GAIN_SCALE_RANGE = (0.5, 2.0)
#: a ``time_delay`` effect's ``|d|`` must be at most ``MAX_DELAY_PHASE / (2 pi f_dyn)``: its column is the
#: first-order expansion ``tau(t - d) = tau(t) - d dtau/dt``, whose error at the top of the dynamics band
#: ``f_dyn`` is ``(2 pi f_dyn d)^2 / 2`` of the torque (50 % at 1 rad): beyond it the fitted "delay" is
#: whatever ``-dtau/dt`` correlates with, not a lag
MAX_DELAY_PHASE = 1.0
#: a ``joint_zero`` offset must be at most this many degrees: encoder zero errors of an arm are of the order of a
#: degree (Hollerbach & Wampler 1996; Khalil & Dombre 2002, ch. 11); tens of degrees are a wrong joint
#: convention of the robot file (its MDH theta offset), and far from the tangent the column linearises
MAX_ZERO_OFFSET_DEG = 20.0
#: a ``link_length`` error must be at most this [m]: machining and assembly errors of a link are of the order of
#: a millimetre (ISO 2768-1 general tolerances, "very coarse" class: +-4 mm for 400-1000 mm; Mooring, Roth &
#: Driels 1991, *Fundamentals of Manipulator Calibration*, ch. 1: link-length errors of a few mm); 5 cm is a
#: wrong robot file (another arm, a missing link), and the linearised column no longer holds
MAX_LINK_LENGTH_M = 0.05
#: a ``crosstalk`` share ``|c|`` must be at most this: half of another joint's torque in a channel is a swapped or
#: mixed-up channel of the data (a wiring or conversion error), not the cross-sensitivity of a sensor
MAX_CROSSTALK = 0.5


def implausible(family: Family, values, *, f_dyn: float) -> str | None:
    """Why an effect's identified parameters are physically impossible for the effect it names (None when
    they are not): a ``gain`` scale outside :data:`GAIN_SCALE_RANGE`, a ``time_delay`` beyond the validity
    of its first-order column (:data:`MAX_DELAY_PHASE` at the dynamics bandwidth ``f_dyn`` [Hz]), a revolute
    ``joint_zero`` offset beyond :data:`MAX_ZERO_OFFSET_DEG`, a
    ``crosstalk`` share beyond :data:`MAX_CROSSTALK`, a negative ``held_friction`` (a stopped drive pushing on
    in the direction it came from is not friction), a
    negative viscous or Coulomb coefficient of a shared motor (``coupling``, variant ``shared``: the
    motor's friction, absent from the declared model, dissipates). The loop does not add a candidate
    that makes any effect implausible (:mod:`.core`)."""
    v = [float(x) for x in values]
    k = family.kind
    if k == "contact_gain":
        lo, hi = GAIN_SCALE_RANGE
        scale = 1.0 / (1.0 - v[0]) if v[0] != 1 else math.inf   # f_measured = (1 + g) f, gamma = g / (1 + g)
        if not lo <= scale <= hi:
            return (f"gain scale {scale:.3g} of the sensor at {family.variant} outside [{lo:g}, {hi:g}] (a sign or "
                    "units error of its wrench in the data, if it is real)")
    elif k == "gain":
        lo, hi = GAIN_SCALE_RANGE
        scale = 1.0 + v[0]
        if not lo <= scale <= hi:
            whose = "the joints'" if family.joint is None else f"joint {family.joint + 1}'s"
            return (f"gain scale {scale:.3g} outside [{lo:g}, {hi:g}] (a sign or units error of {whose} torque in "
                    f"the data, if it is real)")
    elif k == "time_delay":
        d_max = MAX_DELAY_PHASE / (2 * math.pi * float(f_dyn))
        if abs(v[0]) > d_max:
            return (f"delay {v[0]:.3g} s beyond the first-order column's validity |d| <= {d_max:.3g} s "
                    f"(1 rad at the dynamics bandwidth {float(f_dyn):.3g} Hz)")
    elif k == "joint_zero" and bool(dict(family.info).get("revolute", True)):
        if abs(math.degrees(v[0])) > MAX_ZERO_OFFSET_DEG:
            return (f"zero offset {math.degrees(v[0]):.3g} deg of joint {(family.joint or 0) + 1} beyond "
                    f"{MAX_ZERO_OFFSET_DEG:g} deg (a wrong theta convention of its row in the robot file, not an "
                    "encoder zero error)")
    elif k == "link_length" and abs(v[0]) > MAX_LINK_LENGTH_M:
        info = dict(family.info)
        return (f"length error {1e3 * v[0]:+.3g} mm of frame {info.get('frame')} field {info.get('field')} beyond "
                f"{1e3 * MAX_LINK_LENGTH_M:g} mm (a wrong robot file, not a machining or assembly error)")
    elif k == "crosstalk" and abs(v[0]) > MAX_CROSSTALK:
        return (f"cross-talk of {100 * v[0]:.3g} % of joint {(family.partner or 0) + 1}'s torque in joint "
                f"{(family.joint or 0) + 1}'s channel beyond {100 * MAX_CROSSTALK:g} % (channels swapped or mixed in the "
                "data, not a sensor's cross-sensitivity)")
    elif k == "held_friction" and v[0] < 0:
        return (f"negative held friction ({v[0]:.3g} N m) of joint {(family.joint or 0) + 1}: at rest the friction "
                "keeps the sign of the last sliding direction")
    elif k == "coupling" and family.variant == "shared":
        bad = [f"{p} = {x:.3g}" for p, x in zip(family.params, v) if p in ("FVm", "FSm") and x < 0]
        if bad:
            return f"negative friction of the shared motor ({', '.join(bad)})"
    return None


def describe_params(family: Family, value, values: np.ndarray, std: np.ndarray) -> dict:
    """Physical reading of an effect's identified parameters (units in the keys' docs).

    Returns
    -------
    dict
        E.g. ``{"vs": ..., "Fst": ...}`` for Stribeck, ``{"K": ...}`` [N m/rad] for elasticity,
        ``{"delay_s": ...}``, ``{"scale": ..., "g": ...}`` for gain, ``{"k": ..., "amplitude": ...}``.
    """
    v = [float(x) for x in values]
    out: dict = {}
    if family.grid and value is not None:
        out[family.grid_label] = float(value)
    k = family.kind
    if k == "elasticity":
        out["K_Nm_per_rad"] = (1.0 / v[0]) if v[0] != 0 else math.inf
    elif k == "time_delay":
        out["delay_s"] = v[0]
    elif k == "gain":
        out["scale"] = 1.0 + v[0]
        out["g"] = 1.0 / (1.0 + v[0]) if v[0] != -1 else math.inf
    elif k == "contact_gain":   # gamma = g / (1 + g) of f_measured = (1 + g) f
        g = v[0] / (1.0 - v[0]) if v[0] != 1 else math.inf
        out["g"] = g
        out["scale"] = 1.0 + g
        out["g_std"] = float(np.asarray(std, float).reshape(-1)[0]) / (1.0 - v[0]) ** 2 if v[0] != 1 else math.inf
    elif k == "position_ripple":
        out["amplitude"] = math.hypot(v[0], v[1])
        out["phase_rad"] = math.atan2(v[1], v[0])
    elif k == "spring":
        info = dict(family.info)
        out.update(info)
        out["dtau_dq_at_center"] = v[0] / info.get("half_range", 1.0)
    elif k == "held_friction":
        out["Fh_Nm"] = v[0]
    elif k == "crosstalk":
        out["share"] = v[0]
        out["percent"] = 100.0 * v[0]
        if family.partner is not None:
            out["from_joint"] = float(family.partner + 1)   # 1-based, as in the text
    elif k == "link_length":
        info = dict(family.info)
        out.update(describe_length(int(info.get("frame", 0)), str(info.get("field", "")), v[0],
                                   float(np.asarray(std, float).reshape(-1)[0])))
    elif k == "joint_zero":
        out.update(describe_zero(v[0], float(np.asarray(std, float).reshape(-1)[0]),
                                 bool(dict(family.info).get("revolute", True))))
    return out
