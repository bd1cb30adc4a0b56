"""Compositional candidate library: a physical effect modulated by a signal (the loop's composed candidates).

A composed candidate on joint ``j`` is ``effect_j(row) * m(row)``: extra columns on the rows of joint
``j`` (zeros elsewhere), linear in new coefficients once its grid parameter is fixed.

Effects (columns on joint ``j``'s rows)
    ``viscous``  ``dq_j``; ``coulomb`` ``sign(dq_j)`` (or ``tanh(dq_j/v)`` with ``coulomb_v``);
    ``ripple``   ``sin(k q_j), cos(k q_j)`` with the order ``k`` searched over :data:`RIPPLE_ORDERS` (the
                 orders with ``k range(q_j) >= pi``: over a smaller range it is a constant or a spring);
    ``constant`` ``1`` (a gravity-like constant torque or an offset); ``inertia`` ``ddq_j``.
A composed candidate that is a plain candidate of the loop (:mod:`.candidates`) is not in the library:
``constant`` by a position (``spring``), by ``time`` (``drift``), ``ripple`` by its own joint's position
(a function of ``q_j`` alone: ``spring`` and ``position_ripple``).
Modulating signals (the documented set)
    ``time``     time since the start of each experiment;
    ``q_own``    the joint's own position ``q_j``; ``q_other`` the position ``q_i`` of every other joint
                 ``i`` (one candidate per ``i``);
    ``abs_tau``, ``tau``  ``|tau_hat_j|`` and ``tau_hat_j``, the torque transmitted according to the
                 current fit (not the measured torque, whose noise is that of ``y``);
    ``abs_dq``   ``|dq_j|``;
    ``temperature`` a temperature column, when the data provide one (per row, or per joint);
    ``step``     ``H(t - t_s)``, a change at an unknown time ``t_s`` (time since the start of each
                 experiment) searched over :data:`N_STEP_TIMES` quantiles of ``t`` between 10 and 90 %:
                 "a part gripped half-way through the recording".
Continuous signals are standardised on the joint's rows, ``m = (s - mean) / std``, so the composed
column is the *change* of the effect with the signal; the effect itself at the mean level is the
declared model's (friction, offset, rotor inertia) or a plain candidate's accepted before (a plain
position ripple): pass it in ``A``. The step is not centred. A composed column (almost) in the span of
``A`` (less than ``IDENTIFIABILITY_TOL`` of its norm outside) is skipped.

The composed ``coulomb`` by ``abs_tau`` is the load-dependent friction ``mu |tau_hat_j| sign(dq_j)`` of the
plain ``load_friction`` candidate (:mod:`.candidates`; Armstrong-Helouvry, Dupont & Canudas de Wit 1994,
sec. 2.1: the normal force in the gear teeth grows with the transmitted torque) with the signal centred:
``c sign(dq_j) (|tau_hat_j| - m) / s`` is ``(c / s) |tau_hat_j| sign(dq_j)`` plus a change ``-c m / s`` of
the declared ``FS_j``. Named, it is reported in that law's parametrization (:func:`as_load_friction`):
kind ``load_friction``, ``mu = c / s`` and its standard deviation ``sigma_c / s``.

Each composed candidate is named in words (:meth:`Composed.describe`), e.g. "viscous friction of joint 3
growing with |tau_hat3|", "constant (gravity-like) torque on joint 2 appearing at t = 12.1 s".

Testing and multiple-testing control
------------------------------------
Each candidate is tested on the rows given (all joints, the model's coefficients re-fitted with it) by
a Wald test of its *modulated* coefficients with a HAC (Newey-West) covariance, never smaller than the
white-noise one (as :mod:`.core`). The plain effect's columns (:meth:`Composed.plain_columns`, e.g. a
ripple of the same order, a constant, ``dq_j``) are added to the model for that test (partialled out)
when they are not in it already, so a plain effect the model lacks is not taken for a modulated one
(on the LWR4 recordings a plain ripple of joint 7 otherwise passes as "modulated by" any signal that
differs between the experiments); a change in time of friction is tested at equal speed (the speed
modulation of the same effect partialled out too, :meth:`Composed.confounder_columns`); the reported decrease of the joint's residual is the modulation's. A *family* is one (effect, joint, signal, source joint); its grid
(ripple orders x step times) is searched and its smallest p-value is Bonferroni-corrected by the
number of grid points ``G`` (``min(1, G p_min)``). The family-wise error over the whole composed
library - every effect x signal x joint combination - is then controlled by Holm's step-down
procedure (Holm 1979): sorted ``p_(1) <= ... <= p_(m)``, reject while ``p_(i) <= alpha / (m - i + 1)``;
the adjusted p-values are reported. So the number of combinations *and* of grid points counts.
Signal products of decimated rows approximate the decimation of the products (exact when the
cut-off is well above the bandwidth of both factors); a caller with full-rate signals can pass its own
columns through :meth:`Composed.columns`.
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..errors import IdentificationError
from .stability import wls_basis
from .stats import hac_covariance, hac_lag, holm, segments_of, single_threaded_blas, span_product, wald_test

__all__ = [
    "EFFECTS",
    "N_STEP_TIMES",
    "RIPPLE_ORDERS",
    "SIGNALS",
    "Composed",
    "ComposedResult",
    "RowSignals",
    "as_load_friction",
    "holm",
    "library",
    "load_friction_mu",
    "score_composed",
]

EFFECTS = ("viscous", "coulomb", "ripple", "constant", "inertia")
SIGNALS = ("time", "q_own", "q_other", "abs_tau", "tau", "abs_dq", "temperature", "step")
#: modulations in time: of a friction effect they are tested at equal speed (:meth:`Composed.confounder_columns`)
TIME_SIGNALS = ("time", "step")
#: ripple orders (periods per turn of the joint) searched
RIPPLE_ORDERS = (1, 2, 3, 4, 5, 6, 8, 12, 16)
#: step times searched (quantiles of the time since start between 10 % and 90 %)
N_STEP_TIMES = 17
#: family-wise level
ALPHA = 0.01
#: modulating signals correlated above this on a joint's rows are aliases (one result lists the others)
ALIAS_CORRELATION = 0.995
#: a column with less than this share of its norm outside the model's span is skipped
IDENTIFIABILITY_TOL = 1e-3
#: floor of 1 - h_ii in the HC3 scaling of the residual
MIN_ONE_MINUS_LEVERAGE = 0.05
#: most stacked columns of the composed tests computed together (:meth:`_Tester.batch`)
BATCH_COLUMNS = 64

_EFFECT_WORDS = {"viscous": "viscous friction", "coulomb": "Coulomb friction", "ripple": "position ripple",
                 "constant": "constant (gravity-like) torque", "inertia": "inertia"}


@dataclass(frozen=True, eq=False)
class RowSignals:
    """Signals at each row of a stacked observation system (all joints per row).

    Attributes
    ----------
    joint : ndarray of int, shape (r,)
        0-based joint of the row.
    t : ndarray, shape (r,)
        Time since the start of the row's experiment [s].
    q, dq, ddq : ndarray, shape (r, n)
    tau_hat : ndarray, shape (r, n), optional
        Model torque of the current fit (needed by ``abs_tau``/``tau``).
    temperature : ndarray, shape (r,) or (r, n), optional
    """

    joint: np.ndarray
    t: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    tau_hat: np.ndarray | None = None
    temperature: np.ndarray | None = None

    def __post_init__(self):
        r = np.shape(self.joint)[0]
        for nm in ("t", "q", "dq", "ddq", "tau_hat", "temperature"):
            x = getattr(self, nm)
            if x is not None and np.shape(x)[0] != r:
                raise ValueError(f"RowSignals: {nm} has {np.shape(x)[0]} rows, joint has {r}")

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    def subset(self, rows: np.ndarray) -> RowSignals:
        """The signals of some rows (boolean mask or indices), e.g. the training rows of a fold."""
        def take(x):
            return None if x is None else np.asarray(x)[rows]
        return RowSignals(take(self.joint), take(self.t), take(self.q), take(self.dq), take(self.ddq),
                          take(self.tau_hat), take(self.temperature))

    @property
    def n_rows(self) -> int:
        return self.joint.size


@dataclass(frozen=True)
class Composed:
    """One composed candidate: ``effect`` of ``joint`` modulated by ``signal``.

    Attributes
    ----------
    effect : str
    joint : int
        0-based.
    signal : str
    source : int or None
        Joint whose signal modulates (``q_other``), else None.
    order : int or None
        Ripple order.
    step_time : float or None
        ``t_s`` of a ``step`` [s].
    coulomb_v : float or None
        Velocity scale of a smooth Coulomb effect (None: ``sign``).
    center, scale : float or None
        Fixed standardisation of the modulating signal (:meth:`standardised_on`); None: the mean and
        standard deviation of the rows the columns are built on. A model fitted on identification rows
        and evaluated on validation rows needs the identification values on both.
    """

    effect: str
    joint: int
    signal: str
    source: int | None = None
    order: int | None = None
    step_time: float | None = None
    coulomb_v: float | None = None
    center: float | None = None
    scale: float | None = None

    @property
    def family(self) -> tuple:
        """(effect, joint, signal, source): the unit of the multiple-testing count."""
        return (self.effect, self.joint, self.signal, self.source)

    def _effect(self, sig: RowSignals, rows: np.ndarray) -> np.ndarray:
        j = self.joint
        if self.effect == "viscous":
            return sig.dq[rows, j][:, None]
        if self.effect == "coulomb":
            d = sig.dq[rows, j]
            return (np.sign(d) if self.coulomb_v is None else np.tanh(d / self.coulomb_v))[:, None]
        if self.effect == "ripple":
            a = self.order * sig.q[rows, j]
            return np.column_stack([np.sin(a), np.cos(a)])
        if self.effect == "constant":
            return np.ones((rows.size, 1))
        if self.effect == "inertia":
            return sig.ddq[rows, j][:, None]
        raise ValueError(f"unknown effect {self.effect!r}; use one of {EFFECTS}")

    def _signal(self, sig: RowSignals, rows: np.ndarray) -> np.ndarray:
        j = self.joint
        s = self.signal
        if s == "step":
            return (sig.t[rows] >= self.step_time).astype(float)
        if s == "time":
            x = sig.t[rows]
        elif s == "q_own":
            x = sig.q[rows, j]
        elif s == "q_other":
            x = sig.q[rows, self.source]
        elif s in ("abs_tau", "tau"):
            if sig.tau_hat is None:
                raise IdentificationError(f"composed candidate {s}: no model torque tau_hat given")
            x = sig.tau_hat[rows, j]
            x = np.abs(x) if s == "abs_tau" else x
        elif s == "abs_dq":
            x = np.abs(sig.dq[rows, j])
        elif s == "temperature":
            if sig.temperature is None:
                raise IdentificationError("composed candidate temperature: the data have no temperature column")
            T = np.asarray(sig.temperature, float)
            x = T[rows] if T.ndim == 1 else T[rows, j]
        else:
            raise ValueError(f"unknown modulating signal {s!r}; use one of {SIGNALS}")
        if self.center is not None:
            sd = float(self.scale or 0.0)
            return (x - self.center) / sd if sd > 0 else np.zeros_like(x)
        sd = float(np.std(x))
        return (x - x.mean()) / sd if sd > 0 else np.zeros_like(x)

    def standardised_on(self, sig: RowSignals) -> Composed:
        """This candidate with the standardisation of its signal fixed to the mean and standard deviation on
        the joint's rows of ``sig`` (the identification rows), so its columns mean the same on other rows."""
        if self.signal == "step":
            return self
        rows = np.flatnonzero(sig.joint == self.joint)
        x = replace(self, center=0.0, scale=1.0)._signal(sig, rows)
        return replace(self, center=float(x.mean()), scale=float(np.std(x)))

    @property
    def modulation(self) -> str:
        """The modulating signal as a short token: ``abs_tau``, ``q_other:q3``, ``step:t=12.1``..."""
        if self.signal == "q_other":
            return f"q_other:q{(self.source or 0) + 1}"
        if self.signal == "step":
            return f"step:t={self.step_time:.4g}"
        return self.signal

    def columns(self, sig: RowSignals) -> np.ndarray:
        """Columns (r, p) on the rows of the joint (zeros elsewhere)."""
        rows = np.flatnonzero(sig.joint == self.joint)
        E = self._effect(sig, rows)
        X = np.zeros((sig.n_rows, E.shape[1]))
        X[rows] = E * self._signal(sig, rows)[:, None]
        return X

    def plain_columns(self, sig: RowSignals) -> np.ndarray:
        """The unmodulated effect's columns (r, p) on the joint's rows: partialled out of every test, so that a
        composed candidate is evidence of the *modulation*, not of the effect itself."""
        rows = np.flatnonzero(sig.joint == self.joint)
        E = self._effect(sig, rows)
        X = np.zeros((sig.n_rows, E.shape[1]))
        X[rows] = E
        return X

    def confounder_columns(self, sig: RowSignals) -> np.ndarray:
        """Columns (r, c) partialled out of the test besides the plain effect (c = 0 for most candidates).

        A change *in time* (``time``, ``step``) of a friction effect (``viscous``, ``coulomb``) is confounded
        with the effect's dependence on the joint's own speed whenever the motion before and after differs
        (point-to-point moves, a faster second half): a viscous law that is not linear in ``dq_j`` looks
        like a viscous coefficient that changes at the instant the speeds change. So the speed modulation
        of the same effect, ``effect_j * |dq_j|`` and ``effect_j * dq_j^2`` (standardised on the joint's
        rows), is partialled out: what is left is a change in time *at equal speed* (Armstrong-Helouvry,
        Dupont & Canudas de Wit 1994, sec. 2: friction depends on velocity first, on temperature and wear
        - time - only at a given velocity)."""
        if self.signal not in TIME_SIGNALS or self.effect not in ("viscous", "coulomb"):
            return np.zeros((sig.n_rows, 0))
        rows = np.flatnonzero(sig.joint == self.joint)
        E = self._effect(sig, rows)
        a = np.abs(sig.dq[rows, self.joint])
        X = np.zeros((sig.n_rows, 2))
        for k, x in enumerate((a, a * a)):
            sd = float(np.std(x))
            X[rows, k] = E[:, 0] * ((x - x.mean()) / sd if sd > 0 else 0.0)
        return X

    def magnitude(self, sig: RowSignals, coefficients: Sequence[float] | np.ndarray) -> dict[str, float]:
        """The size of the fitted term on the joint's rows of ``sig``, in the units of its plain kind's prior
        (:func:`.plausibility.effect_plausibility`): ``{"amplitude": A}`` for a ripple - ``A`` the 98th
        percentile over the rows of the local amplitude ``|(a_s m + p_s, a_c m + p_c)|`` of ``sin k q_j, cos k
        q_j`` (``a``: the modulated coefficients, ``m`` the standardised signal, ``p`` the plain coefficients
        when the term carries them, the model lacking the plain effect) -, ``{"torque": T}`` for the other effects,
        ``T`` the 98th percentile of the torque ``|E (a m + p)|`` the term adds (``E`` the effect's column:
        ``1``, ``sign dq_j``, ``dq_j``, ``ddq_j``). The 98th percentile, as the joint's torque range ``tau98``
        it is judged against. ``coefficients``: the modulated ones (:meth:`names` order), then the plain ones
        if any. Empty when the signal cannot be evaluated on ``sig`` (a model torque or temperature
        missing) or the joint has no rows."""
        rows = np.flatnonzero(sig.joint == self.joint)
        k = len(self.names())
        b = np.asarray(coefficients, float)
        if rows.size == 0 or b.size not in (k, 2 * k):
            return {}
        try:
            m = self._signal(sig, rows)
        except IdentificationError:
            return {}
        p = b[k:] if b.size == 2 * k else np.zeros(k)
        local = m[:, None] * b[None, :k] + p[None, :]     # the effect's coefficients at each row
        if self.effect == "ripple":
            return {"amplitude": float(np.quantile(np.hypot(local[:, 0], local[:, 1]), 0.98))}
        E = self._effect(sig, rows)[:, 0]
        return {"torque": float(np.quantile(np.abs(E * local[:, 0]), 0.98))}

    def names(self) -> tuple[str, ...]:
        """Coefficient names, e.g. ``viscous3*abs_tau3``."""
        j = self.joint + 1
        base = {"viscous": f"FV{j}", "coulomb": f"FS{j}", "constant": f"OFF{j}", "inertia": f"IA{j}"}
        src = {"time": "t", "q_own": f"q{j}", "q_other": f"q{(self.source or 0) + 1}", "abs_tau": f"abs_tau{j}",
               "tau": f"tau{j}", "abs_dq": f"abs_dq{j}", "temperature": "T",
               "step": f"step{self.step_time:.4g}" if self.step_time is not None else "step"}[self.signal]
        if self.effect == "ripple":
            return (f"RS{j}_{self.order}*{src}", f"RC{j}_{self.order}*{src}")
        return (f"{base[self.effect]}*{src}",)

    def describe(self, coefficients: Sequence[float] | None = None) -> str:
        """The candidate in words; with its fitted ``coefficients`` the direction ("growing"/"decreasing")."""
        j = self.joint + 1
        eff = _EFFECT_WORDS[self.effect]
        if self.effect == "ripple":
            eff = f"position ripple of order {self.order}"
        if self.effect == "coulomb" and self.coulomb_v is not None:
            eff = f"smooth Coulomb friction (v = {self.coulomb_v:.3g})"
        on = f"{eff} {'of' if self.effect in ('viscous', 'coulomb', 'inertia') else 'on'} joint {j}"
        if self.signal == "step":
            return f"{on} appearing at t = {self.step_time:.3g} s (a step: e.g. a part gripped)" \
                if self.effect == "constant" else f"{on} changing at t = {self.step_time:.3g} s (a step)"
        what = {"time": "time since the start of the experiment", "q_own": f"q{j}",
                "q_other": f"q{(self.source or 0) + 1}", "abs_tau": f"|\u03c4\u0302{j}|", "tau": f"\u03c4\u0302{j}",
                "abs_dq": f"|dq{j}|", "temperature": "temperature"}[self.signal]
        if self.effect in ("ripple", "constant") or coefficients is None:
            verb = "whose amplitude changes with" if self.effect == "ripple" else "changing with"
            return f"{on} {verb} {what}"
        return f"{on} {'growing' if float(np.sum(coefficients)) > 0 else 'decreasing'} with {what}"


def _step_times(t: np.ndarray, n: int = N_STEP_TIMES) -> np.ndarray:
    return np.unique(np.round(np.quantile(t, np.linspace(0.1, 0.9, n)), 9))


def library(sig: RowSignals, *, joints: Sequence[int] | None = None, effects: Sequence[str] = EFFECTS,
            signals: Sequence[str] = SIGNALS, ripple_orders: Sequence[int] = RIPPLE_ORDERS,
            n_step_times: int = N_STEP_TIMES, coulomb_v: float | Sequence[float] | None = None) -> list[list[Composed]]:
    """Every composed candidate, grouped by family (a list of grid members per family).

    ``temperature`` is skipped when ``sig.temperature`` is None, ``abs_tau``/``tau`` when ``sig.tau_hat``
    is None. ``coulomb_v``: velocity scale(s) of the smooth Coulomb effect, per joint or one for all
    (e.g. the law chosen by :func:`.friction.select_friction`); None: ``sign``.
    """
    bad = [e for e in effects if e not in EFFECTS] + [s for s in signals if s not in SIGNALS]
    if bad:
        raise ValueError(f"compose.library: unknown effects/signals {bad}; effects {EFFECTS}, signals {SIGNALS}")
    n = sig.n_joints
    js = range(n) if joints is None else joints
    cv = [None] * n if coulomb_v is None else list(np.broadcast_to(np.asarray(coulomb_v, float), (n,)))
    fams: list[list[Composed]] = []
    for j in js:
        rows = sig.joint == j
        span = float(np.ptp(sig.q[rows, j])) if rows.any() else 0.0
        for eff in effects:
            # a ripple of order k is a ripple (not a constant or a smooth spring) only when the joint moves
            # over at least half its period: k * range(q_j) >= pi
            orders = tuple(k for k in ripple_orders if k * span >= math.pi) if eff == "ripple" else (None,)
            if not orders:
                continue
            for s in signals:
                if s == "temperature" and sig.temperature is None:
                    continue
                if s in ("abs_tau", "tau") and sig.tau_hat is None:
                    continue
                if eff == "constant" and s in ("q_own", "q_other"):
                    continue       # position-dependent torques: the spring/ripple candidates of the loop
                if eff == "ripple" and s == "q_own":
                    # a function of q_j alone: q_j sin(k q_j) is a smooth position-dependent torque plus ripples
                    # of neighbouring orders, the loop's spring and position_ripple candidates (over a small range
                    # it fits a missing spring as well as the spring does)
                    continue
                if eff == "constant" and s == "time":
                    continue       # a torque changing linearly in time: the loop's drift candidate (t/T, (t/T)^2)
                sources = [i for i in range(n) if i != j] if s == "q_other" else [None]
                steps = _step_times(sig.t[rows], n_step_times) if s == "step" else (None,)
                for src in sources:
                    fams.append([Composed(eff, j, s, src, k, ts, cv[j]) for k in orders for ts in steps])
    return fams


@dataclass(frozen=True)
class ComposedResult:
    """A tested composed family (its best grid member).

    Attributes
    ----------
    candidate : Composed
    n_grid : int
        Grid points searched in its family.
    p_value : float
        Best member's Wald p-value (HAC), before any correction.
    p_family : float
        ``min(1, n_grid p_value)``.
    p_adjusted : float
        Holm-adjusted over all families tested.
    coefficients : ndarray
    rss_drop : float
        Relative decrease of the weighted residual sum of squares of the joint's rows.
    significant : bool
        ``p_adjusted < alpha``.
    description : str
    aliases : tuple of Composed
        Candidates of the same effect whose modulating signal is the same on these data (correlation
        above ``ALIAS_CORRELATION``, e.g. joints driven by one waveform): the data cannot tell them apart;
        they are not listed separately.
    """

    candidate: Composed
    n_grid: int
    p_value: float
    p_family: float
    p_adjusted: float
    coefficients: np.ndarray
    rss_drop: float
    significant: bool
    description: str
    aliases: tuple = ()


class _Tester:
    def __init__(self, A, y, w, joint, groups):
        self.w = w
        self.joint = joint
        U, _, rank = wls_basis(A * w[:, None], pinv=False)   # the basis only: no pseudo-inverse at the peak
        self.U, self.rank = U, rank
        yw = y * w
        self.e0 = yw - U @ (U.T @ yw)
        self.lev0 = np.einsum("ij,ij->i", U, U)
        self.segs = segments_of(groups, y.size)
        self.lag = hac_lag(self.e0, groups)
        self.rss_joint = np.bincount(joint, weights=self.e0 ** 2, minlength=int(joint.max()) + 1)

    def with_plain(self, P):
        """Basis, residual, leverage, rank and joint RSS with the plain effect's columns ``P`` added to the
        model (the part of them outside its span; none when they are already in it)."""
        base = (self.U, self.e0, self.lev0, self.rank, self.rss_joint)
        if P is None or not P.shape[1]:
            return base
        Pw = P * self.w[:, None]
        Pp = Pw - self.U @ (self.U.T @ Pw)
        keep = np.einsum("ij,ij->j", Pp, Pp) > IDENTIFIABILITY_TOL ** 2 * np.maximum(np.einsum("ij,ij->j", Pw, Pw),
                                                                                      1e-300)
        if not keep.any():
            return base
        Q, R = np.linalg.qr(Pp[:, keep])
        Q = Q[:, np.abs(np.diag(R)) > 1e-10 * np.abs(np.diag(R)).max()]
        e0 = self.e0 - Q @ (Q.T @ self.e0)
        rss = np.bincount(self.joint, weights=e0 ** 2, minlength=self.rss_joint.size)
        return (np.hstack([self.U, Q]), e0, self.lev0 + np.einsum("ij,ij->i", Q, Q), self.rank + Q.shape[1], rss)

    def __call__(self, X, j, P=None, base=None):
        U, e0, lev0, rank, rss_joint = self.with_plain(P) if base is None else base
        Xw = X * self.w[:, None]
        Xp = Xw - U @ span_product(U, Xw)
        G = Xp.T @ Xp
        # a column (almost) in the span of the model is "already in the model" (as IDENTIFIABILITY_TOL of .core)
        if not np.all(np.diag(G) > IDENTIFIABILITY_TOL ** 2 * np.maximum(np.einsum("ij,ij->j", Xw, Xw), 1e-300)):
            return None
        try:
            Ginv = np.linalg.inv(G)
        except np.linalg.LinAlgError:
            return None
        b = Ginv @ (Xp.T @ e0)
        e = e0 - Xp @ b
        r, p = e.size, X.shape[1]
        dof = max(r - rank - p, 1)
        lev = np.einsum("ij,ij->i", Xp @ Ginv, Xp) + lev0   # diag(Xp Ginv Xp^T)
        e3 = e / np.clip(1.0 - lev, MIN_ONE_MINUS_LEVERAGE, 1.0)
        S = hac_covariance(Xp * e3[:, None], max_lag=self.lag, segments=self.segs)
        Ch = Ginv @ S @ Ginv * (r / dof)
        Ci = Ginv * float(e @ e) / dof
        pv = max(wald_test(b, Ch, dof)[1], wald_test(b, Ci, dof)[1])
        m = self.joint == j
        drop = 1.0 - float(np.sum(e[m] ** 2)) / max(rss_joint[j], 1e-300)
        return pv, b, drop

    def batch(self, X: np.ndarray, p: int, j: int, base) -> list:
        """``[self(X_i, j, base=base) for X_i in X's blocks of p columns]``: the candidates of joint ``j`` with ``p``
        columns each, stacked in ``X`` (r, m p; overwritten), tested together. The products with the basis
        (``U^T X`` on the joint's rows, ``U (U^T X)``), the Gram matrices (the diagonal ``p x p`` blocks of the
        stacked columns' Gram matrix) and the HAC sums (:func:`.stats.hac_covariance` of the stacked scores,
        whose diagonal blocks are each candidate's) are one matrix product over the stacked columns instead of
        one per candidate. The same formulas as :meth:`__call__` (HC3-scaled scores, the Wald tests of the HAC
        and white-noise covariances, None for a column in the span or a singular Gram matrix); the sums are
        ordered differently, so the numbers agree to rounding (``tests/diagnostics/test_compose_speed.py``)."""
        U, e0, lev0, rank, rss_joint = base
        r, m = e0.size, X.shape[1] // p
        X *= self.w[:, None]
        norm = np.maximum(np.einsum("ij,ij->j", X, X), 1e-300)
        X -= U @ span_product(U, X)         # the stacked columns projected out of the model's span
        # a column (almost) in the span of the model is "already in the model" (as in __call__)
        ok = np.all((np.einsum("ij,ij->j", X, X) > IDENTIFIABILITY_TOL ** 2 * norm).reshape(m, p), axis=1)
        out: list = [None] * m
        if not ok.any():
            return out
        Gfull = X.T @ X
        G = np.stack([Gfull[i * p:(i + 1) * p, i * p:(i + 1) * p] for i in range(m)])
        Ginv = np.zeros_like(G)
        try:
            Ginv[ok] = np.linalg.inv(G[ok])
        except np.linalg.LinAlgError:     # a singular Gram matrix: that candidate is skipped, as in __call__
            for i in np.flatnonzero(ok):
                try:
                    Ginv[i] = np.linalg.inv(G[i])
                except np.linalg.LinAlgError:
                    ok[i] = False
        X3 = X.reshape(r, m, p)
        b = np.einsum("kij,kj->ki", Ginv, (X.T @ e0).reshape(m, p))
        e = e0[:, None] - sum(X3[:, :, a] * b[:, a] for a in range(p))
        dof = max(r - rank - p, 1)
        # diag(Xp Ginv Xp^T) of each candidate: p^2 products of its columns (p is 1 or 2 in the library)
        lev = sum(X3[:, :, a] * X3[:, :, c] * Ginv[:, a, c] for a in range(p) for c in range(p)) + lev0[:, None]
        X3 *= (e / np.clip(1.0 - lev, MIN_ONE_MINUS_LEVERAGE, 1.0))[:, :, None]     # the HC3-scaled scores
        del lev
        S = hac_covariance(X, max_lag=self.lag, segments=self.segs)
        eT = np.ascontiguousarray(e.T)   # each candidate's residual, its sums of squares taken as in __call__
        del e
        rows = self.joint == j
        for i in np.flatnonzero(ok):
            blk = slice(i * p, (i + 1) * p)
            Ch = Ginv[i] @ S[blk, blk] @ Ginv[i] * (r / dof)
            Ci = Ginv[i] * float(eT[i] @ eT[i]) / dof
            pv = max(wald_test(b[i], Ch, dof)[1], wald_test(b[i], Ci, dof)[1])
            out[i] = (pv, b[i], 1.0 - float(np.sum(eT[i][rows] ** 2)) / max(rss_joint[j], 1e-300))
        return out


@single_threaded_blas
def score_composed(A: np.ndarray, y: np.ndarray, sig: RowSignals, *, weights: np.ndarray | None = None,
                  groups: np.ndarray | None = None, alpha: float = ALPHA,
                  families: list[list[Composed]] | None = None, **library_kw) -> list[ComposedResult]:
    """Test every composed family against the current model ``y ~ A``; most significant first.

    Parameters
    ----------
    A : ndarray, shape (r, k)
        Current design (declared model + accepted effects).
    y : ndarray, shape (r,)
    sig : RowSignals
        Signals at the rows of ``A``.
    weights : ndarray, shape (r,), optional
        Row weights (WLS ``1/sigma_joint``).
    groups : ndarray, shape (r,), optional
        Contiguous-time segments for the HAC covariance (``joint * 100000 + experiment``); default per joint.
    alpha : float
        Family-wise level (Holm over families, Bonferroni over each family's grid).
    families : list, optional
        :func:`library` output (default ``library(sig, **library_kw)``).

    Returns
    -------
    list of ComposedResult
        Sorted by adjusted p-value then by decrease of the joint's residual.
    """
    A = np.asarray(A, float)
    y = np.asarray(y, float)
    if A.shape[0] != y.size or sig.n_rows != y.size:
        raise ValueError(f"score_composed: A {A.shape}, y {y.shape} and signals ({sig.n_rows} rows) disagree")
    if not 0 < alpha < 1:
        raise ValueError(f"score_composed: alpha must lie in (0, 1), got {alpha!r}")
    w = np.ones(y.size) if weights is None else np.asarray(weights, float)
    groups = sig.joint if groups is None else groups
    fams = library(sig, **library_kw) if families is None else families
    tester = _Tester(A, y, w, np.asarray(sig.joint), groups)
    outs = _tests_by_plain(tester, fams, sig)
    rows = []
    for f, fam in enumerate(fams):
        best = None
        for i, c in enumerate(fam):
            out = outs[f, i]
            if out is None:
                continue
            if best is None or out[0] < best[1][0] or (out[0] == best[1][0] and out[2] > best[1][2]):
                best = (c, out)
        if best is not None:
            rows.append((best[0], len(fam), best[1]))
    if not rows:
        return []
    pf = [min(1.0, g * o[0]) for _, g, o in rows]
    adj = holm(pf)
    res = [ComposedResult(c, g, float(o[0]), float(f), float(a), np.asarray(o[1]), float(o[2]), bool(a < alpha),
                          c.describe(o[1])) for (c, g, o), f, a in zip(rows, pf, adj)]
    res.sort(key=lambda r: (r.p_adjusted, -r.rss_drop))
    return _merge_aliases(res, sig)


def _plain_key(c: Composed) -> tuple:
    """What the plain effect's design of a test depends on: effect, joint, ripple order, Coulomb scale, and whether
    the modulation is time-like (the confounders, :meth:`Composed.confounder_columns`)."""
    return (c.effect, c.joint, c.order if c.effect == "ripple" else None, c.coulomb_v, c.signal in TIME_SIGNALS)


def _tests_by_plain(tester: _Tester, fams: Sequence[Sequence[Composed]], sig: RowSignals) -> dict:
    """``tester(c.columns(sig), c.joint, base)`` of every member ``i`` of every family ``f``, as ``{(f, i): out}``.

    The tests are run grouped by plain design (:func:`_plain_key`, in the order the designs first appear, each
    built from its first member as before), and each design is dropped once its group is done: a design holds
    the model's basis augmented by the plain columns, an (r, rank) array per design - keeping every design
    of the library alive made the memory of a round grow by dozens of times the decimated system. Within a
    group, the members with the same number of columns are tested together (:meth:`_Tester.batch`, at most
    :data:`BATCH_COLUMNS` stacked columns at a time): the same formulas as one test at a time, equal to
    rounding."""
    groups: dict[tuple, list[tuple[int, int]]] = {}
    for f, fam in enumerate(fams):
        for i, c in enumerate(fam):
            groups.setdefault(_plain_key(c), []).append((f, i))
    outs: dict = {}
    for members in groups.values():
        f0, i0 = members[0]
        c0 = fams[f0][i0]
        base = tester.with_plain(np.hstack([c0.plain_columns(sig), c0.confounder_columns(sig)]))
        by_width: dict[int, list] = {}
        for f, i in members:
            by_width.setdefault(len(fams[f][i].names()), []).append((f, i))
        # at most BATCH_COLUMNS stacked columns (and half the basis's) at a time: a batch's arrays
        # stay a fraction of the basis held beside them
        width = min(BATCH_COLUMNS, max(1, base[0].shape[1] // 2))
        for p, keys in by_width.items():
            size = max(1, width // p)
            for s in range(0, len(keys), size):
                chunk = keys[s:s + size]
                X = np.empty((sig.n_rows, p * len(chunk)))
                for n, (f, i) in enumerate(chunk):
                    X[:, n * p:(n + 1) * p] = fams[f][i].columns(sig)
                outs.update(zip(chunk, tester.batch(X, p, c0.joint, base)))
        del base
    return outs

def _merge_aliases(res: list[ComposedResult], sig: RowSignals) -> list[ComposedResult]:
    """Fold results whose modulating signals are indistinguishable on the data into the best-ranked one."""
    kept: list[tuple[ComposedResult, np.ndarray, list]] = []
    for r in res:
        c = r.candidate
        rows = np.flatnonzero(sig.joint == c.joint)
        m = c._signal(sig, rows)
        for _k, (r0, m0, al) in enumerate(kept):
            c0 = r0.candidate
            if (c0.effect, c0.joint, c0.order) != (c.effect, c.joint, c.order):
                continue
            den = float(np.linalg.norm(m) * np.linalg.norm(m0))
            if den > 0 and abs(float(m @ m0 - m.mean() * m0.sum())) / den > ALIAS_CORRELATION:
                al.append(c)
                break
        else:
            kept.append((r, m, []))
    out = []
    for r, _, al in kept:
        if al:
            words = ", ".join(a.describe().rsplit(" with ", 1)[-1] for a in al)
            r = replace(r, aliases=tuple(al), description=f"{r.description} (indistinguishable here from: {words})")
        out.append(r)
    return out



def load_friction_mu(c: Composed, value: float, std: float) -> tuple[float, float] | None:
    """``(mu, sigma_mu)`` of a composed ``coulomb`` by ``abs_tau`` candidate with its fitted coefficient
    ``value`` (standard deviation ``std``): ``mu = value / scale`` (module docstring; the standardisation fixed,
    :meth:`Composed.standardised_on`). None for any other composed candidate or without a fixed scale."""
    if c.effect != "coulomb" or c.signal != "abs_tau" or c.scale is None or not float(c.scale) > 0:
        return None
    s = float(c.scale)
    return float(value) / s, float(std) / s


def as_load_friction(effect, c: Composed | None):
    """A reported effect (:class:`.report.Effect`) of the composed ``coulomb`` by ``abs_tau`` candidate ``c``
    in the parametrization of the load-dependent friction (module docstring): kind ``load_friction``, first
    parameter ``mu`` (value, standard deviation, confidence interval divided by the signal's scale; the
    relative standard deviation unchanged), the
    composed coefficient's name and the change of ``FS<j>`` it implies in ``physical``. Any other effect
    unchanged. Its rating (verdict, alternatives) is the composed candidate's: the same law."""
    if c is None:
        return effect
    k = len(c.names())
    got = load_friction_mu(c, float(effect.values[0]), float(effect.std[0])) if len(effect.values) >= k else None
    if got is None or k != 1:
        return effect
    mu, sd = got
    s = float(c.scale or 1.0)
    values = np.r_[mu, np.asarray(effect.values, float)[1:]]
    std = np.r_[sd, np.asarray(effect.std, float)[1:]]
    name = effect.names[0]
    ci = {("mu" if nm == name else nm): ((lo / s, hi / s) if nm == name else (lo, hi))
          for nm, (lo, hi) in dict(effect.ci or {}).items()}
    phys = dict(effect.physical or {}) | {"mu": mu, "mu_std": sd, "composed_coefficient": float(effect.values[0]),
                                          "fs_change": -float(effect.values[0]) * float(c.center or 0.0) / s}
    desc = (f"load-dependent friction of joint {c.joint + 1}: mu |\u03c4\u0302{c.joint + 1}| sign(dq{c.joint + 1}), "
            f"mu = {mu:.3g} \u00b1 {sd:.2g} (found as the composed {effect.description or name})")
    return replace(effect, kind="load_friction", names=("mu",) + tuple(effect.names[1:]), values=values, std=std,
                   physical=phys, ci=ci, description=desc)
