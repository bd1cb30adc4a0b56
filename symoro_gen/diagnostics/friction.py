"""Friction-law selection per joint by time-blocked cross-validation (the loop's first stage).

The declared models carry the classical friction of the identification papers, ``FS_j sign(dq_j) +
FV_j dq_j`` (RX-90 paper eq. 2, Coulomb + viscous). At standstill and velocity reversals the
Coulomb column of a filtered velocity chatters; real drives often follow a smooth or a Stribeck law
instead. For each joint this module *replaces* the law rather than adding columns to it:

Coulomb laws (coefficients linear, shape parameter searched)
    * ``sign``      ``Fc sign(dq)`` (declared);
    * ``tanh``      ``Fc tanh(dq / v)``, ``v`` on a log grid then refined continuously (bounded
      scalar minimisation of the CV error in ``log v`` between the grid neighbours);
    * ``stribeck``  ``(Fc + (Fs - Fc) exp(-(dq/vs)^2)) sign(dq)``: linear in ``Fc`` and ``Fs - Fc``
      for a fixed ``vs`` (columns ``sign(dq)`` and ``exp(-(dq/vs)^2) sign(dq)``), ``vs`` on a grid
      (Armstrong-Helouvry, Dupont & Canudas de Wit 1994, eq. 5); when ``tanh`` is tried too, the
      ``sign(dq)`` is smoothed by ``tanh(dq/v)`` at the ``v`` the tanh search found (at the bottom of
      the grid this is ``sign``; otherwise the Stribeck law does not chatter at standstill either);
Pre-sliding (offered on data sampled at :data:`DAHL_MIN_RATE_HZ` or more only, ``LawSearch.rate_hz``)
    * ``dahl``      ``Fc phi(t)``, the Dahl state ([D1968]; docs/friction-dynamic.md) normalised to the
      sliding level: ``dphi/dx = (sign(dq) - phi) / x0`` along the displacement ``x``, ``x0 = Fc / sigma0`` the
      pre-sliding displacement; integrated exactly for the velocity held over each full-rate sample at the
      mean of its two ends (as :mod:`symoro_gen.simulate.friction_state`), so the column is a function of the
      ordered velocity series of one experiment and its rate ``fs``. Searched in ``vp = x0 fs`` (a velocity:
      one sample's displacement at ``vp`` is ``x0``) on a log grid of ``x0`` (:data:`DAHL_X0_GRID`); at small
      ``x0`` the law is ``sign(dq)``. Below 1 kHz the pre-sliding regime (milliseconds after each reversal)
      is not resolved and a fitted ``sigma0`` is not identifiable (docs/friction-dynamic.md, the study at
      reversals): the law is not offered there;
    * ``lugre``     the LuGre law ([COAL1995] eq. 1-4, bristle damping ``sigma1 = 0``), whose sliding part is the
      Stribeck law, linear in ``Fc`` and ``Fs - Fc`` (:func:`lugre_columns`): for fixed ``vs``, ``x0 = Fs / sigma0``
      and ``q = (Fs - Fc) / Fs`` the bristle state ``sigma0 z`` is ``Fc a + (Fs - Fc) b``, ``a`` and ``b`` two
      states relaxing to ``sign(dq)`` and ``exp(-(dq/vs)^2) sign(dq)`` over LuGre's relaxation length
      ``g(v) / sigma0``. Reported ``sigma0 = Fs / x0``. Searched by coordinate descent: ``vp = x0 fs`` as for
      Dahl, ``vs`` on the velocity grid at that ``vp``, then (:data:`LUGRE_PASSES` times) ``q`` from the fitted
      magnitudes, ``vs`` and ``vp`` again. Offered with Dahl, on the same rule (``LawSearch.rate_hz`` at :data:`DAHL_MIN_RATE_HZ` or more);
Viscous laws
    * ``linear``    ``Fv dq`` (declared);
    * ``power``     ``Fv |dq|^delta sign(dq)``, ``delta`` on a grid then refined.

Selection (coordinate descent): the Coulomb law is chosen first (with the linear viscous term), then
the viscous law (with the chosen Coulomb law), then, if the viscous law changed, the Coulomb law again
with it (a ``|dq|^delta`` knee can pass for a Stribeck dip and vice versa); each choice by the out-of-fold relative error norm of the joint's rows under
time-blocked K-fold cross-validation (:mod:`.stability`: ``K`` contiguous blocks per experiment, no
shuffling; fold ``k`` holds out block ``k`` of every experiment and the whole model - base parameters
of all joints and the candidate friction columns - is fitted on the other blocks). A law replaces the
simpler one (order ``sign < tanh < stribeck``, ``linear < power``) only if it lowers the CV error by
more than ``min_gain`` (relative) *and* by more than one standard error of the paired per-fold
difference of the squared errors (the one-standard-error rule over time blocks): ties, and gains inside
the fold-to-fold scatter, keep the simpler law.

Columns are evaluated on the rows by default (the decimated velocity); a caller that decimates columns
in parallel with ``W`` (RX-90 paper eq. 15) passes ``columns(f)``, which evaluates ``f`` on the
full-rate velocity of the joint and decimates it (``Frame.full_rate_columns`` style).

Static at rest
    Every law above describes *sliding* friction. At standstill friction is static: set-valued in
    ``[-Fs, Fs]``, balancing whatever the other torques leave, its value unknown from the velocity
    (Armstrong-Helouvry, Dupont & Canudas de Wit 1994, sec. 2.1: static friction and the pre-sliding
    regime; Gautier's practice leaves the samples of near-zero velocity out of the friction
    identification). :func:`rest_segments` finds the standstill *segments* of each joint in any data
    the model is evaluated on, from those data alone: ``|dq_j|`` below :data:`REST_NOISE_MULTIPLE`
    standard deviations of the velocity noise of the experiment (``Experiment.dq_noise``, estimated
    from the part of ``q`` above the filter cut-off) for at least :data:`REST_MIN_PERIODS` periods of the
    dynamics bandwidth ``1/f_dyn``. A velocity reversal of a moving trajectory crosses that band in
    ``2 K sigma / |ddq|`` (milliseconds on every recording here), far shorter than ``1/f_dyn``, so it is
    never a rest segment. Inside a segment the sliding columns of the joint (its Coulomb, Stribeck and
    viscous columns) are evaluated as 0 - the law is evaluated on the *sliding velocity*
    :func:`sliding_velocity`, ``dq`` with its rest segments set to 0 (every law here is 0 at ``dq = 0``) -
    in identification and validation alike: the model predicts no friction torque it cannot know, where
    ``sign(dq)`` would switch between ``+Fc`` and ``-Fc`` on the velocity's wander at standstill.

Standard deviations with the shape estimated
    A law's constants are linear for a fixed shape (``v``, ``vs``, ``vp``, ``delta``), and the shape is searched.
    The σ of a constant at the searched shape held fixed leaves out the shape's own uncertainty (on the SCARA
    LuGre case 3.2 times too narrow for ``Fs - Fc``, which falls with ``vs``). :func:`shape_uncertainty` gives
    the linearised covariance of the nonlinear least squares (Seber & Wild 1989, sec. 2.1) on the final fit's
    design with the derivatives of the law's torque in its shape, and :func:`shape_physical` the shape's σ
    (``vs_std``, ``x0_std``, ``sigma0_std``, ...); the report uses both (docs/friction-dynamic.md).

Declaring what the loop found
    A law the loop names as a cause (an effect of kind ``friction_law``, or the loop's ``stribeck``
    candidate: a dip ``exp(-(dq/vs)^2) sign(dq)`` beside the declared ``sign(dq)`` and ``dq``, the Stribeck
    law) is a property of the drive: :func:`law_declarations` gives the robot-file line that declares it
    (``friction_law = {kind = "stribeck", vs = 0.05}``, docs/robot-file.md "Friction laws"). Declared,
    ``diagnose`` starts from it (its scale refined on the identification data) and no longer offers it. A
    combination no single kind declares (a Stribeck or tanh Coulomb law *and* a power viscous law) gets
    no line.
"""
from __future__ import annotations

import math
import weakref
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import partial

import numpy as np
from scipy import optimize

from ..description.friction_law import (
    COULOMB_LAWS,
    PRESLIDING_BOUNDS,
    SCALE_BOUNDS,
    VISCOUS_LAWS,
    coulomb_columns,
    law_parameter,
    viscous_columns,
)
from ..errors import IdentificationError
from ..identification.friction_law import JointColumns, LawSplicedModel
from ..model import IdentificationModel
from .stability import N_FOLDS, BlockedLS, wls_basis

__all__ = [
    "COULOMB_LAWS",
    "DAHL_MIN_RATE_HZ",
    "DAHL_X0_GRID",
    "DELTA_GRID",
    "MIN_GAIN",
    "PRESLIDING_LAWS",
    "STRIBECK_LIKE",
    "REST_MIN_PERIODS",
    "REST_NOISE_MULTIPLE",
    "VISCOUS_LAWS",
    "FrictionChoice",
    "LawDeclaration",
    "LawFit",
    "LawSearch",
    "coulomb_columns",
    "clear_law_columns",
    "dahl_column",
    "lugre_columns",
    "friction_column_indices",
    "law_declarations",
    "law_errors",
    "shape_parameters",
    "shape_physical",
    "shape_uncertainty",
    "ShapeUncertainty",
    "replaced_friction_columns",
    "rest_mask",
    "rest_segments",
    "select_friction",
    "sliding_frame",
    "sliding_velocity",
    "velocity_grid",
    "viscous_columns",
]

#: the pre-sliding laws the stage can offer (at DAHL_MIN_RATE_HZ or more)
PRESLIDING_LAWS = ("dahl", "lugre")
#: passes of the LuGre search over its ratio q = (Fs - Fc) / Fs (:meth:`_LawSelection._lugre`)
LUGRE_PASSES = 3
#: Coulomb laws with the two columns of Stribeck's (``Fc``, ``Fs - Fc``)
STRIBECK_LIKE = ("stribeck", "lugre")
#: sampling rate from which the Dahl law is offered (``fit_presliding``'s rule, docs/friction-dynamic.md)
DAHL_MIN_RATE_HZ = 1000.0
#: pre-sliding displacements x0 = Fc / sigma0 searched [rad or m] (sigma0 from 1e2 to 1e6 times Fc)
DAHL_X0_GRID = tuple(float(x) for x in np.geomspace(1e-6, 1e-2, 13))
#: a more complex law must lower the CV relative error of its joint by this fraction
MIN_GAIN = 0.01
#: exponents of the non-linear viscous law searched
DELTA_GRID = (0.2, 0.35, 0.5, 0.65, 0.8, 1.25, 1.5, 2.0)
#: points of the log grid of the velocity scales (v of tanh, vs of Stribeck)
N_VELOCITY_GRID = 14
#: standstill: |dq_j| below this many standard deviations of the velocity noise (Gaussian noise alone
#: exceeds it with probability ~1e-23: a rest is not cut into pieces by the noise) ...
REST_NOISE_MULTIPLE = 10.0
#: ... for at least this many periods 1/f_dyn of the dynamics bandwidth (a reversal of a moving
#: trajectory spends 2 K sigma / |ddq| there: 5-40 ms on the TX40, LWR4 and Med 7 recordings)
REST_MIN_PERIODS = 1.0
#: floor of the standstill band, as a share of the 95th percentile of |dq_j| of the experiment (noise-free
#: simulated data, where the estimated noise is ~0)
REST_REL_FLOOR = 1e-4


def rest_segments(dq: np.ndarray, fs: float, noise, f_dyn: float, *, multiple: float = REST_NOISE_MULTIPLE,
                  min_periods: float = REST_MIN_PERIODS, source: str = "") -> np.ndarray:
    """Standstill segments of each joint: ``|dq_j| < max(multiple * noise_j, REST_REL_FLOOR * P95|dq_j|)``
    for at least ``min_periods / f_dyn`` seconds (see the module docstring, "Static at rest").

    Parameters
    ----------
    dq : ndarray, shape (M,) or (M, n)
        Band-pass velocity at full rate, one experiment.
    fs : float
        Sampling rate [Hz].
    noise : float or ndarray, shape (n,)
        Standard deviation of the velocity noise of each joint (``Experiment.dq_noise``).
    f_dyn : float
        Dynamics bandwidth [Hz] (``FilterSettings.dynamics_bandwidth_hz``).
    multiple, min_periods : float
        Band in noise standard deviations, shortest segment in periods ``1/f_dyn``.
    source : str
        Named in the error message.

    Returns
    -------
    ndarray of bool, same shape as ``dq``: True inside a rest segment.
    """
    dq = np.asarray(dq, float)
    one = dq.ndim == 1
    D = dq[:, None] if one else dq
    where = f"{source}: " if source else ""
    if D.ndim != 2:
        raise IdentificationError(f"{where}rest segments: velocity must be (samples,) or (samples, joints), "
                                  f"got shape {dq.shape}")
    if not (np.isfinite(fs) and fs > 0 and np.isfinite(f_dyn) and f_dyn > 0):
        raise IdentificationError(f"{where}rest segments: sampling rate {fs!r} Hz and dynamics bandwidth "
                                  f"{f_dyn!r} Hz must be finite and > 0")
    sig = np.broadcast_to(np.asarray(noise, float), (D.shape[1],))
    if not np.all(np.isfinite(sig) & (sig >= 0)):
        raise IdentificationError(f"{where}rest segments: velocity noise {sig.tolist()} must be finite and >= 0")
    min_len = max(2, int(math.ceil(min_periods * fs / f_dyn)))
    out = np.zeros(D.shape, bool)
    if D.shape[0] == 0:
        return out[:, 0] if one else out
    A = np.abs(D)
    p95 = np.quantile(A, 0.95, axis=0)
    for j in range(D.shape[1]):
        band = max(multiple * float(sig[j]), REST_REL_FLOOR * float(p95[j]))
        low = A[:, j] < band if band > 0 else A[:, j] == 0
        edges = np.diff(np.r_[0, low.astype(np.int8), 0])
        starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
        for a, b in zip(starts, ends):
            if b - a >= min_len:
                out[a:b, j] = True
    return out[:, 0] if one else out


_REST_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def rest_mask(ex) -> np.ndarray:
    """Rest segments (M, n) of one experiment of a diagnosis frame (``.frame.Experiment``), from its own
    band-pass velocity, velocity noise and filter settings (:func:`rest_segments`); cached per experiment."""
    try:
        return _REST_CACHE[ex]
    except (KeyError, TypeError):
        pass
    st = ex.settings
    m = rest_segments(ex.dq, st.fs, ex.dq_noise, st.dynamics_bandwidth_hz, source=getattr(ex, "source", ""))
    m.setflags(write=False)
    try:
        _REST_CACHE[ex] = m
    except TypeError:
        pass
    return m


def sliding_velocity(ex, j: int | None = None) -> np.ndarray:
    """``dq`` of an experiment with its rest segments set to 0 (:func:`rest_mask`): the velocity the
    sliding-friction laws are evaluated on (every law is 0 there). Joint ``j`` (M,), or all (M, n)."""
    m = rest_mask(ex)
    if j is None:
        return np.where(m, 0.0, ex.dq)
    return np.where(m[:, j], 0.0, ex.dq[:, j])


@dataclass(frozen=True)
class LawFit:
    """One law with its searched parameter and its cross-validated error.

    Attributes
    ----------
    law : str
        ``sign``, ``tanh``, ``stribeck``, ``linear`` or ``power``.
    param : float or None
        ``v`` (tanh), ``vs`` (Stribeck) [rad/s or m/s], ``delta`` (power); None for sign/linear.
    cv_rel_err : float
        Out-of-fold relative error norm of the joint's rows.
    smooth : float or None
        ``sign`` and Stribeck: velocity scale ``v`` of the ``tanh(dq/v)`` replacing ``sign(dq)``.
    vp : float or None
        LuGre: its pre-sliding scale ``vp = x0 fs`` (``param`` is its ``vs``); the Dahl law's is ``param``.
    q : float
        LuGre: ``(Fs - Fc) / Fs`` of its relaxation length (:func:`lugre_columns`).
    """

    law: str
    param: float | None
    cv_rel_err: float
    smooth: float | None = None
    vp: float | None = None
    q: float = 0.0

    @property
    def shape(self):
        """The law's shape parameter as :func:`_coulomb` takes it: ``(vs, vp, q)`` for LuGre, else ``param``."""
        return (self.param, self.vp, self.q) if self.law == "lugre" else self.param

    @property
    def label(self) -> str:
        if self.law == "tanh":
            return f"tanh(v={self.param:.3g})"
        if self.law == "stribeck":
            return f"stribeck(vs={self.param:.3g})"
        if self.law == "power":
            return f"power(delta={self.param:.3g})"
        if self.law == "dahl":
            return f"dahl(vp={self.param:.3g})"
        if self.law == "lugre":
            return f"lugre(vs={self.param:.3g},vp={self.vp:.3g})"
        return self.law


@dataclass(frozen=True)
class FrictionChoice:
    """The friction law chosen for one joint.

    Attributes
    ----------
    joint : int
        0-based.
    coulomb, viscous : LawFit
        Chosen laws.
    candidates : tuple of LawFit
        Every law tried (best parameter of each), in the order tried; ``candidates[0]`` is the
        declared ``sign`` + ``linear``.
    coefficients : dict str -> float
        Coefficients of the chosen laws fitted on all rows: ``Fc`` (and ``Fs`` for Stribeck), ``Fv``.
    n_folds : int
    unit : str
        Velocity unit of ``v``/``vs``.
    """

    joint: int
    coulomb: LawFit
    viscous: LawFit
    candidates: tuple
    coefficients: Mapping[str, float] = field(default_factory=dict)
    n_folds: int = N_FOLDS
    unit: str = "rad/s"
    rate_hz: float | None = None

    @property
    def x0(self) -> float | None:
        """Dahl and LuGre laws: the pre-sliding displacement ``x0 = vp / fs`` [rad or m] (None otherwise)."""
        vp = {"dahl": self.coulomb.param, "lugre": self.coulomb.vp}.get(self.coulomb.law)
        if vp is None or not self.rate_hz:
            return None
        return float(vp) / float(self.rate_hz)

    @property
    def declared_cv_rel_err(self) -> float:
        return self.candidates[0].cv_rel_err

    @property
    def cv_rel_err(self) -> float:
        """Out-of-fold error of the chosen combination."""
        return self.viscous.cv_rel_err if self.viscous.law != "linear" else self.coulomb.cv_rel_err

    @property
    def replaced(self) -> bool:
        return self.coulomb.law != "sign" or self.viscous.law != "linear"

    def columns(self, dq: np.ndarray) -> np.ndarray:
        """Columns of the chosen laws at velocities ``dq``: Coulomb column(s) then the viscous one."""
        return np.hstack([_coulomb(self.coulomb.law, dq, self.coulomb.shape, self.coulomb.smooth),
                          viscous_columns(self.viscous.law, dq, self.viscous.param)])

    def names(self) -> tuple[str, ...]:
        """Parameter names of :meth:`columns` (``FS3``, ``FSS3``, ``FV3`` for joint 3)."""
        j = self.joint + 1
        c = (f"FS{j}", f"FSS{j}") if self.coulomb.law in STRIBECK_LIKE else (f"FS{j}",)
        return c + (f"FV{j}",)

    def describe(self) -> str:
        """The replacement in words: ``"joint 3: Coulomb -> tanh, v = 0.012 rad/s (CV error 0.081 -> 0.064)"``."""
        parts = []
        if self.coulomb.law == "tanh":
            parts.append(f"Coulomb \u2192 tanh, v = {self.coulomb.param:.3g} {self.unit}")
        elif self.coulomb.law == "stribeck":
            parts.append(f"Coulomb \u2192 Stribeck, vs = {self.coulomb.param:.3g} {self.unit}"
                         + (f" (sign smoothed by tanh, v = {self.coulomb.smooth:.3g} {self.unit})"
                            if self.coulomb.smooth is not None else ""))
        elif self.coulomb.law == "dahl" and self.x0 is not None:
            fc = self.coefficients.get("Fc")
            s0 = f", sigma0 = {abs(fc) / self.x0:.3g}" if fc is not None and self.x0 > 0 else ""
            parts.append(f"Coulomb \u2192 Dahl (pre-sliding), x0 = {self.x0:.3g}{s0}")
        elif self.coulomb.law == "lugre" and self.x0 is not None:
            fs = self.coefficients.get("Fs")
            s0 = f", sigma0 = {abs(fs) / self.x0:.3g}" if fs is not None and self.x0 > 0 else ""
            parts.append(f"Coulomb \u2192 LuGre (pre-sliding, Stribeck sliding part), vs = {self.coulomb.param:.3g} "
                         f"{self.unit}, x0 = {self.x0:.3g}{s0}")
        if self.viscous.law == "power":
            parts.append(f"viscous \u2192 |dq|^\u03b4, \u03b4 = {self.viscous.param:.3g}")
        if not parts:
            sm = (f", sign smoothed at v = {self.coulomb.smooth:.3g} {self.unit}"
                  if self.coulomb.smooth is not None else "")
            return (f"joint {self.joint + 1}: Coulomb sign(dq) + viscous dq kept{sm} "
                    f"(CV error {self.declared_cv_rel_err:.4g}, {self.n_folds} time-blocked folds)")
        return (f"joint {self.joint + 1}: " + "; ".join(parts)
                + f" (CV error {self.declared_cv_rel_err:.4g} \u2192 {self.cv_rel_err:.4g}, "
                  f"{self.n_folds} time-blocked folds)")


def friction_column_indices(names: Sequence[str], joint: int) -> tuple[list[int], list[int]]:
    """Indices of the declared Coulomb (``FS<j>``) and viscous (``FV<j>``) columns of ``joint`` (0-based)
    in the column names of a model, e.g. ``model.BASE_NAMES``."""
    j = joint + 1
    fs = [i for i, n in enumerate(names) if n == f"FS{j}"]
    fv = [i for i, n in enumerate(names) if n == f"FV{j}"]
    return fs, fv


def velocity_grid(dq: np.ndarray, n: int = N_VELOCITY_GRID) -> np.ndarray:
    """Log grid of velocity scales from ``1e-3`` to ``0.5`` times the 95th percentile of ``|dq|``."""
    s = float(np.quantile(np.abs(np.asarray(dq, float)), 0.95))
    if not s > 0:
        raise IdentificationError("friction: the joint does not move (95th percentile of |dq| is 0)")
    return s * np.geomspace(1e-3, 0.5, n)


def dahl_column(dq: np.ndarray, vp: float) -> np.ndarray:
    """The Dahl state ``phi`` (N,) normalised to the sliding level along the ordered full-rate velocity ``dq``
    of one experiment (module docstring): ``phi_{k+1} = s + (phi_k - s) exp(-|v| / vp)``, ``v`` the mean of
    ``dq_k`` and ``dq_{k+1}``, ``s = sign(v)``, ``vp = x0 fs``; ``phi_0 = 0`` (the state of
    :func:`symoro_gen.simulate.friction_state.dahl_friction` with ``z0 = 0``). At rest (``v = 0``) the state
    holds."""
    v = np.asarray(dq, float)
    if not vp > 0:
        raise ValueError(f"dahl_column: vp must be > 0, got {vp!r}")
    out = np.zeros(v.size)
    if v.size < 2:
        return out
    vm = 0.5 * (v[1:] + v[:-1])
    sg = np.sign(vm)
    # within a run of one sign s the recursion is phi_k = s + (phi_start - s) exp(-(X_k - X_start) / vp), X the
    # travelled distance |v| summed: one vectorised step per run (a reversal starts the next run)
    X = np.concatenate([[0.0], np.cumsum(np.abs(vm))])
    starts = np.flatnonzero(np.r_[True, sg[1:] != sg[:-1]])
    ends = np.r_[starts[1:], sg.size]
    w = 0.0
    for a, b in zip(starts.tolist(), ends.tolist()):
        sk = float(sg[a])
        out[a + 1:b + 1] = sk + (w - sk) * np.exp(-(X[a + 1:b + 1] - X[a]) / float(vp))
        w = float(out[b])
    return out


def lugre_columns(dq: np.ndarray, vs: float, vp: float, q: float = 0.0) -> np.ndarray:
    """The two Coulomb columns (N, 2) of the loop's LuGre law (module docstring) along the ordered full-rate
    velocity ``dq`` of one experiment, coefficients ``Fc`` and ``Fs - Fc``: the states ``a`` and ``b`` of
    ``da/dx = (sign(v) - a) / (x0 h(v))`` and ``db/dx = (e(v) sign(v) - b) / (x0 h(v))``, ``e(v) = exp(-(v/vs)^2)``,
    ``h(v) = 1 - q (1 - e(v))`` with ``q = (Fs - Fc) / Fs``, ``x0 = vp / fs = Fs / sigma0``. Then
    ``Fc a + (Fs - Fc) b = sigma0 z``, LuGre's friction with ``sigma1 = 0`` (relaxation length ``g(v) / sigma0 =
    x0 h(v)``), integrated like :func:`symoro_gen.simulate.friction_state.lugre_state`: the velocity held over
    each interval at the mean of its two samples, ``e`` and ``h`` at the mean of their two ends, ``a = b = 0`` at
    the start. ``q = 0`` is the Dahl state :func:`dahl_column` in both (``phi`` and ``e phi`` at sliding)."""
    v = np.asarray(dq, float)
    if not vs > 0 or not vp > 0 or not 0.0 <= q < 1.0:
        raise ValueError(f"lugre_columns: vs ({vs!r}) and vp ({vp!r}) must be > 0 and q ({q!r}) in [0, 1)")
    out = np.zeros((v.size, 2))
    if v.size < 2:
        return out
    e = np.exp(-(v / float(vs)) ** 2)
    vm = 0.5 * (v[1:] + v[:-1])
    em = 0.5 * (e[1:] + e[:-1])
    hm = 1.0 - q * (1.0 - em)
    sg = np.sign(vm)
    decay = np.exp(-np.abs(vm) / (float(vp) * hm))
    gain = -np.expm1(-np.abs(vm) / (float(vp) * hm))     # 1 - decay
    out[1:, 0] = _affine_scan(decay, sg * gain)
    out[1:, 1] = _affine_scan(decay, em * sg * gain)
    return out


def _affine_scan(d: np.ndarray, u: np.ndarray) -> np.ndarray:
    """``x_k = d_k x_{k-1} + u_k`` from ``x_0 = 0`` for every ``k`` (the state recursion of :func:`lugre_columns`,
    ``a_k = s + (a_{k-1} - s) d_k``), by the parallel prefix scan of the affine maps ``x -> d x + u`` (Hillis &
    Steele 1986; Blelloch 1990, sec. 1.4: first-order linear recurrences): ``log2 N`` vectorised passes, each
    composing a map with the one ``2^i`` steps before it. The products of ``d`` only fall (``0 <= d <= 1``), so
    nothing overflows."""
    D = np.array(d, float, copy=True)
    U = np.array(u, float, copy=True)
    s = 1
    while s < U.size:
        U[s:] = D[s:] * U[:-s] + U[s:]
        D[s:] = D[s:] * D[:-s]
        s *= 2
    return U


def _coulomb(law: str, dq: np.ndarray, param, smooth: float | None) -> np.ndarray:
    """:func:`coulomb_columns`, and the pre-sliding ``dahl`` (:func:`dahl_column`, ``param = vp``) and ``lugre``
    (:func:`lugre_columns`, ``param = (vs, vp, q)``) laws."""
    if law == "dahl":
        if param is None:
            raise TypeError("the 'dahl' friction law needs its scale vp")
        return dahl_column(dq, float(param))[:, None]
    if law == "lugre":
        if not isinstance(param, tuple) or None in param:
            raise TypeError("the 'lugre' friction law needs its scales (vs, vp, q)")
        return lugre_columns(dq, float(param[0]), float(param[1]), float(param[2]))
    return coulomb_columns(law, dq, param, smooth)


def _search(err: Callable[[float], float], grid: np.ndarray, refine: bool, log: bool = True):
    """Best grid point of ``err``, then a bounded continuous refinement between its neighbours."""
    vals = np.array([err(float(g)) for g in grid])
    i = int(np.nanargmin(vals))
    best, best_err = float(grid[i]), float(vals[i])
    if refine and grid.size > 2:
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
        tr = (np.log, np.exp) if log else ((lambda x: x), (lambda x: x))
        res = optimize.minimize_scalar(lambda x: err(float(tr[1](x))), bounds=(tr[0](lo), tr[0](hi)),
                                       method="bounded", options={"xatol": 0.01})
        if res.success and res.fun < best_err:
            best, best_err = float(tr[1](res.x)), float(res.fun)
    return best, best_err


@dataclass(frozen=True, eq=False)
class LawSearch:
    """What :func:`select_friction` tries and how.

    Attributes
    ----------
    laws : sequence of str
        Laws allowed (``sign`` and ``linear`` are always tried: the declared reference).
    min_gain : float
        Relative decrease of the CV error a more complex law needs to replace a simpler one.
    v_grid : ndarray, optional
        Velocity scales searched (default :func:`velocity_grid` of ``dq`` on joint ``j``'s rows).
    delta_grid : sequence of float
        Exponents of the ``power`` viscous law.
    refine : bool
        Refine ``v`` and ``delta`` continuously between grid points.
    v_floor : float, optional
        Smallest velocity scale of any ``sign`` in the laws, e.g. 3 times the standard deviation of the
        velocity noise: ``sign(dq)`` becomes ``tanh(dq / v_floor)`` (so the declared law does not chatter
        on noise at standstill, where identification data without rest phases give no evidence either
        way), and the tanh search starts there. Default: none (a true ``sign``).
    rate_hz : float, optional
        The full rate ``fs`` of every experiment (one value): the ``dahl`` law is tried only when ``laws``
        names it and ``rate_hz >= DAHL_MIN_RATE_HZ``.
    """

    laws: Sequence[str] = COULOMB_LAWS + VISCOUS_LAWS
    min_gain: float = MIN_GAIN
    v_grid: np.ndarray | None = None
    delta_grid: Sequence[float] = DELTA_GRID
    refine: bool = True
    v_floor: float | None = None
    rate_hz: float | None = None

    @property
    def fast(self) -> bool:
        """Sampled at :data:`DAHL_MIN_RATE_HZ` or more (a rate from time stamps is within rounding of 1000 Hz)."""
        return self.rate_hz is not None and self.rate_hz >= DAHL_MIN_RATE_HZ * (1 - 1e-6)

    @property
    def dahl(self) -> bool:
        return "dahl" in self.laws and self.fast

    @property
    def lugre(self) -> bool:
        return "lugre" in self.laws and self.fast


def select_friction(A: np.ndarray, y: np.ndarray, joint: np.ndarray, j: int, dq: np.ndarray, blocks: np.ndarray, *,
                    weights: np.ndarray | None = None,
                    columns: Callable[[Callable[[np.ndarray], np.ndarray], int], np.ndarray] | None = None,
                    search: LawSearch | None = None, unit: str = "rad/s",
                    coefficients: bool = True) -> FrictionChoice:
    """Choose the Coulomb and viscous laws of joint ``j`` by time-blocked cross-validation.

    Parameters
    ----------
    A : ndarray, shape (r, k)
        The declared model's design *without* joint ``j``'s friction columns (FS, FV; drop them with
        :func:`friction_column_indices`), with every other column (base parameters of all joints,
        offsets, other joints' friction, already accepted effects).
    y : ndarray, shape (r,)
        Measured torques of the rows.
    joint : ndarray of int, shape (r,)
        0-based joint of each row.
    j : int
        The joint (0-based).
    dq : ndarray, shape (r,)
        Velocity of joint ``j`` at each row (used on the rows of joint ``j`` unless ``columns`` is given).
    blocks : ndarray of int, shape (r,)
        Time blocks of the rows (:func:`.stability.time_blocks`); one fold per block.
    weights : ndarray, shape (r,), optional
        Row weights of the fits (WLS: ``1/sigma_joint``); default 1 (OLS).
    columns : callable, optional
        ``columns(f, p) -> (r, p)``: the (decimated) columns of ``f(dq_j_full_rate) -> (M, p)`` on the
        rows of joint ``j`` (zeros elsewhere). Default: ``f`` applied to ``dq`` on joint ``j``'s rows.
    search : LawSearch, optional
        The laws tried, the gain a law needs, the grids of its shape parameter, the velocity floor of
        ``sign`` (default :class:`LawSearch`: every law, :data:`MIN_GAIN`, no floor).
    unit : str
        Velocity unit in the description.
    coefficients : bool
        Fit the chosen laws' coefficients on all rows (``FrictionChoice.coefficients``); False leaves them
        empty (a simulated-noise placebo replicate needs the choice and its CV errors only).

    Returns
    -------
    FrictionChoice
    """
    search = LawSearch() if search is None else search
    A = np.asarray(A, float)
    y = np.asarray(y, float)
    joint = np.asarray(joint)
    dq = np.asarray(dq, float)
    r = y.size
    if A.shape[0] != r or joint.shape != (r,) or dq.shape != (r,) or np.shape(blocks) != (r,):
        raise ValueError(f"select_friction: A {A.shape}, y {y.shape}, joint {joint.shape}, dq {dq.shape} and "
                         f"blocks {np.shape(blocks)} must have one entry per row")
    rows = joint == j
    if not rows.any():
        raise IdentificationError(f"friction: joint {j + 1} has no rows")
    bad = [x for x in search.laws if x not in COULOMB_LAWS + VISCOUS_LAWS + PRESLIDING_LAWS]
    if bad:
        raise ValueError(f"select_friction: unknown laws {bad}; use {COULOMB_LAWS + VISCOUS_LAWS + PRESLIDING_LAWS}")
    cols = _row_columns(dq, rows) if columns is None else columns
    grid = _velocity_search_grid(dq[rows], search)
    sel = _LawSelection(BlockedLS(A, y, blocks, weights), y, rows, np.asarray(blocks)[rows], cols, search, grid)
    best_c, best_v = sel.coordinate_descent()
    n_folds = len(sel.cv.folds)
    choice = FrictionChoice(j, best_c, best_v, tuple(sel.tried), {}, n_folds, unit, search.rate_hz)
    if not coefficients:
        return choice
    coef = _law_coefficients(A, y, weights, cols, choice)
    return FrictionChoice(j, best_c, best_v, tuple(sel.tried), coef, n_folds, unit, search.rate_hz)


def _row_columns(dq: np.ndarray, rows: np.ndarray) -> Callable[[Callable[[np.ndarray], np.ndarray], int], np.ndarray]:
    """The default ``columns`` hook of :func:`select_friction`: ``f`` of the rows' velocity, on joint j's rows."""
    def columns(f: Callable[[np.ndarray], np.ndarray], p: int) -> np.ndarray:
        X = np.zeros((dq.size, p))
        X[rows] = np.asarray(f(dq[rows]), float).reshape(-1, p)
        return X
    return columns


def _velocity_search_grid(dq_rows: np.ndarray, search: LawSearch) -> np.ndarray:
    """The velocity scales tried for ``tanh`` and ``stribeck``: the search's grid (default
    :func:`velocity_grid`), from ``v_floor`` up when there is one."""
    grid = velocity_grid(dq_rows) if search.v_grid is None else np.asarray(search.v_grid, float)
    v_floor = search.v_floor
    if v_floor is not None:
        if not v_floor > 0:
            raise ValueError(f"select_friction: v_floor must be > 0, got {v_floor!r}")
        grid = np.unique(np.r_[v_floor, grid[grid > v_floor]])
        if grid.size < 3:
            grid = v_floor * np.geomspace(1.0, 10.0, 4)
    return grid


#: law columns of the last ``columns`` hook (:func:`_law_columns`): hook, {law arguments: (rows, values)}
_LAW_COLUMNS: dict = {}
#: bytes of law columns kept
LAW_COLUMNS_BYTES = 32 * 2 ** 20
#: bytes of full-rate pieces of the law columns kept (:class:`_FullRatePieces`): 48 pieces of a 7-joint
#: 1 kHz recording of 100 s (the Stribeck grid's ``exp`` pieces of every replicate stay)
FULL_RATE_PIECES_BYTES = 32 * 2 ** 20


class _FullRatePieces:
    """Full-rate factors of the law columns (``sign(v)``, ``|v|``, ``tanh(v / s)``, ``exp(-(v / vs)^2)``) kept per
    velocity array, so that a law evaluated again on the same velocities computes only what is new: the
    searches of :func:`select_friction` evaluate ``tanh(v / s)`` at one ``s`` as the ``tanh`` law and again as the
    smoothed ``sign`` of every Stribeck law, and ``exp(-(v / vs)^2)`` at every ``vs`` of the grid on each
    replicate of the simulated-noise placebo. A piece is the very array the column's definition
    (:func:`coulomb_columns`, :func:`viscous_columns`) computes, so the columns are the same numbers.

    Keyed by the identity of the velocity array, which is kept (its id stays unique while it is held), and
    only for a read-only array (the friction stage's hook passes its sliding velocities so): a writeable one
    could change between two calls, its pieces are computed afresh. The least recently used pieces are
    dropped beyond :data:`FULL_RATE_PIECES_BYTES`."""

    def __init__(self) -> None:
        self._d: dict = {}
        self._bytes = 0

    def clear(self) -> None:
        self._d.clear()
        self._bytes = 0

    def get(self, v: np.ndarray, key: tuple, make: Callable[[], np.ndarray]) -> np.ndarray:
        if v.flags.writeable:
            return make()
        k = (id(v), key)
        hit = self._d.pop(k, None)
        if hit is not None and hit[0] is v:
            self._d[k] = hit              # the most recently used last
            return hit[1]
        if hit is not None:
            self._bytes -= hit[2]
        x = make()
        size = x.nbytes
        if size <= FULL_RATE_PIECES_BYTES:
            while self._d and self._bytes + size > FULL_RATE_PIECES_BYTES:
                old = self._d.pop(next(iter(self._d)))
                self._bytes -= old[2]
            self._d[k] = (v, x, size)
            self._bytes += size
        return x


_PIECES = _FullRatePieces()


def clear_law_columns() -> None:
    """Drop the law columns and full-rate pieces kept by the friction-law searches (:func:`_law_columns`); the
    friction-law stage calls it when it is done."""
    _LAW_COLUMNS.clear()
    _PIECES.clear()


def _smooth_sign(v: np.ndarray, smooth: float | None) -> np.ndarray:
    """``sign(v)``, or ``tanh(v / smooth)``, as :func:`coulomb_columns` computes it."""
    if smooth is None:
        return _PIECES.get(v, ("sign",), lambda: np.sign(v))
    s = float(smooth)
    return _PIECES.get(v, ("tanh", s), lambda: np.tanh(v / s))


def _law_values(args: tuple, v: np.ndarray, p: int) -> np.ndarray:
    """``np.hstack([_coulomb(claw, v, cpar, smooth), viscous_columns(vlaw, v, vpar)])`` for ``args = (claw, cpar,
    vlaw, vpar, smooth)``, the same numbers (the definitions' expressions, term by term), from the pieces kept
    for ``v`` (:class:`_FullRatePieces`)."""
    claw, cpar, vlaw, vpar, smooth = args
    v = np.asarray(v, float)
    if claw in ("dahl", "lugre") or v.ndim != 1 or vlaw not in VISCOUS_LAWS:
        return np.hstack([_coulomb(claw, v, cpar, smooth), viscous_columns(vlaw, v, vpar)])
    out = np.empty((v.size, p))
    if claw == "sign":
        out[:, 0] = _smooth_sign(v, smooth)
    elif claw == "tanh":
        out[:, 0] = _smooth_sign(v, law_parameter(claw, cpar))
    elif claw == "stribeck":
        s = _smooth_sign(v, smooth)
        vs = law_parameter(claw, cpar)
        out[:, 0] = s
        out[:, 1] = _PIECES.get(v, ("exp", vs), lambda: np.exp(-(v / vs) ** 2)) * s
    else:
        return np.hstack([_coulomb(claw, v, cpar, smooth), viscous_columns(vlaw, v, vpar)])
    if vlaw == "linear":
        out[:, p - 1] = v
    else:
        out[:, p - 1] = (_PIECES.get(v, ("abs",), lambda: np.abs(v)) ** law_parameter(vlaw, vpar)
                         * _PIECES.get(v, ("sign",), lambda: np.sign(v)))
    return out


def _law_columns(columns: Callable[[Callable[[np.ndarray], np.ndarray], int], np.ndarray], args: tuple,
                 p: int) -> np.ndarray:
    """``columns`` of the law ``args = (claw, cpar, vlaw, vpar, smooth)``, kept for the same hook: the
    columns depend on the law and the velocities only, not on ``y``, and the simulated-noise placebo
    re-runs the same selection (the same grid) on many ``y``; the hook builds them at full rate and
    decimates them, which costs more than the fit. Only the non-zero rows are kept (one joint's).
    The full-rate values come from the pieces kept per velocity array (:func:`_law_values`)."""
    memo = _LAW_COLUMNS.get("memo") if _LAW_COLUMNS.get("hook") is columns else None
    if memo is None:
        _LAW_COLUMNS.clear()
        _PIECES.clear()
        memo = _LAW_COLUMNS["memo"] = {}
        _LAW_COLUMNS["hook"] = columns
    hit = memo.get(args)
    if hit is not None:
        X = np.zeros((hit[2], p))
        X[hit[0]] = hit[1]
        return X
    X = columns(partial(_law_values, args, p=p), p)
    rows = np.flatnonzero(np.any(X != 0.0, axis=1))
    size = rows.nbytes + rows.size * p * 8
    if _LAW_COLUMNS.get("bytes", 0) + size <= LAW_COLUMNS_BYTES:     # the first selection's grid stays
        memo[args] = (rows, X[rows].copy(), X.shape[0])
        _LAW_COLUMNS["bytes"] = _LAW_COLUMNS.get("bytes", 0) + size
    return X


class _LawSelection:
    """The coordinate descent of :func:`select_friction` on one joint: out-of-fold errors of law
    combinations, the one-standard-error rule between two laws, every law tried (``tried``)."""

    def __init__(self, cv: BlockedLS, y: np.ndarray, rows: np.ndarray, fold_of: np.ndarray,
                 columns: Callable[[Callable[[np.ndarray], np.ndarray], int], np.ndarray], search: LawSearch,
                 grid: np.ndarray) -> None:
        self.cv, self.rows, self.columns, self.search, self.grid = cv, rows, columns, search, grid
        self.den = float(np.sum(y[rows] ** 2))
        self.fold_of = fold_of
        self.fold_ids = np.unique(fold_of)
        self.tried: list[LawFit] = []
        self._oof: dict = {}

    def oof(self, claw, cpar, vlaw="linear", vpar=None, smooth=None) -> np.ndarray:
        """Out-of-fold residual of the joint's rows with the law's columns, kept per law (the one-standard-error
        rule and the viscous search ask again for laws already scored)."""
        args = (claw, cpar, vlaw, vpar, smooth)
        hit = self._oof.get(args)
        if hit is not None:
            return hit
        pc = 2 if claw in STRIBECK_LIKE else 1
        X = _law_columns(self.columns, args, pc + 1)
        e = self._oof[args] = self.cv.oof_residual(X, self.rows)
        e.setflags(write=False)
        return e

    def err(self, *a, **k) -> float:
        e = self.oof(*a, **k)
        return math.sqrt(float(e @ e) / self.den) if self.den > 0 else math.inf

    def better(self, new: LawFit, new_args: tuple, old: LawFit, old_args: tuple) -> bool:
        """``new`` (the more complex law) replaces ``old``: its CV error is lower by more than ``min_gain``
        *and* by more than one standard error of the paired difference over the time-blocked folds (the
        one-standard-error rule, Hastie, Tibshirani & Friedman 2009, sec. 7.10; Breiman et al. 1984): a
        gain inside the fold-to-fold scatter keeps the simpler law."""
        if not new.cv_rel_err < old.cv_rel_err * (1.0 - self.search.min_gain):
            return False
        e_new, e_old = self.oof(*new_args), self.oof(*old_args)
        fold_of = self.fold_of
        d = np.array([float(np.sum(e_old[fold_of == b] ** 2) - np.sum(e_new[fold_of == b] ** 2))
                      for b in self.fold_ids])
        if d.size < 2:
            return True
        return bool(np.mean(d) > np.std(d, ddof=1) / math.sqrt(d.size))

    def choose_coulomb(self, vlaw: str, vpar: float | None) -> LawFit:
        v_floor = self.search.v_floor
        best = LawFit("sign", None, self.err("sign", None, vlaw, vpar, v_floor), v_floor)
        best_args: tuple = ("sign", None, vlaw, vpar, v_floor)
        self.tried.append(best)
        smooth = v_floor
        for law in ("tanh", "dahl", "stribeck"):
            if law not in self.search.laws or (law == "dahl" and not self.search.dahl):
                continue
            grid = self.grid if law != "dahl" else float(self.search.rate_hz or 0.0) * np.asarray(DAHL_X0_GRID)
            p, e = _search(partial(self._coulomb_error, law, vlaw=vlaw, vpar=vpar, smooth=smooth), grid,
                           self.search.refine)
            fit = LawFit(law, p, e, smooth if law == "stribeck" else None)
            args = (law, p, vlaw, vpar, smooth if law == "stribeck" else None)
            if law == "tanh":
                smooth = p
            self.tried.append(fit)
            if self.better(fit, args, best, best_args):
                best, best_args = fit, args
        if "lugre" in self.search.laws and self.search.lugre:
            fit = self._lugre(vlaw, vpar)
            args = ("lugre", fit.shape, vlaw, vpar, None)
            self.tried.append(fit)
            if self.better(fit, args, best, best_args):
                best, best_args = fit, args
        return best

    def _lugre(self, vlaw: str, vpar: float | None) -> LawFit:
        """The LuGre law's scales by coordinate descent (module docstring): ``vp`` of the Dahl state, ``vs`` on
        the velocity grid at it, then :data:`LUGRE_PASSES` times ``q = (Fs - Fc) / Fs`` from the fitted
        magnitudes, ``vs`` again at ``(vp, q)`` and ``vp`` again at ``(vs, q)``."""
        vp_grid = float(self.search.rate_hz or 0.0) * np.asarray(DAHL_X0_GRID)
        vp, _ = _search(partial(self._coulomb_error, "dahl", vlaw=vlaw, vpar=vpar, smooth=None), vp_grid,
                        self.search.refine)
        vs, e = _search(lambda v: self.err("lugre", (v, vp, 0.0), vlaw, vpar), self.grid, self.search.refine)
        q = 0.0
        for _ in range(LUGRE_PASSES):
            q = self.lugre_ratio((vs, vp, q), vlaw, vpar)
            vs, e = _search(partial(self._lugre_vs_error, vp=vp, q=q, vlaw=vlaw, vpar=vpar), self.grid,
                            self.search.refine)
            vp, e = _search(partial(self._lugre_vp_error, vs, q=q, vlaw=vlaw, vpar=vpar), vp_grid, self.search.refine)
        return LawFit("lugre", vs, e, None, vp, q)

    def _lugre_vp_error(self, vs: float, vp: float, *, q: float, vlaw: str, vpar: float | None) -> float:
        return self.err("lugre", (vs, vp, q), vlaw, vpar)

    def _lugre_vs_error(self, vs: float, *, vp: float, q: float, vlaw: str, vpar: float | None) -> float:
        return self.err("lugre", (vs, vp, q), vlaw, vpar)

    def lugre_ratio(self, shape: tuple, vlaw: str, vpar: float | None) -> float:
        """``(Fs - Fc) / Fs`` of the LuGre law at ``shape`` fitted on all rows (with the whole model), in [0, 0.95]."""
        X = _law_columns(self.columns, ("lugre", shape, vlaw, vpar, None), 3)
        M = np.hstack([self.cv.A, X]) * self.cv.w[:, None]
        theta = np.linalg.lstsq(M, self.cv.y * self.cv.w, rcond=None)[0][-3:]
        fs = float(theta[0] + theta[1])
        return float(np.clip(theta[1] / fs, 0.0, 0.95)) if fs != 0 else 0.0

    def _coulomb_error(self, law: str, v: float, *, vlaw: str, vpar: float | None, smooth: float | None) -> float:
        return self.err(law, v, vlaw, vpar, smooth)

    def choose_viscous(self, c: LawFit) -> LawFit:
        best = LawFit("linear", None, self.err(c.law, c.shape, smooth=c.smooth))
        delta_grid = self.search.delta_grid
        if "power" in self.search.laws and len(delta_grid):
            d, e = _search(lambda d: self.err(c.law, c.shape, "power", d, c.smooth), np.asarray(delta_grid, float),
                           self.search.refine)
            fit = LawFit("power", d, e)
            self.tried.append(fit)
            if self.better(fit, (c.law, c.shape, "power", d, c.smooth), best,
                           (c.law, c.shape, "linear", None, c.smooth)):
                best = fit
        return best

    def coordinate_descent(self) -> tuple[LawFit, LawFit]:
        """Coulomb law (linear viscous), viscous law (chosen Coulomb), and once more the Coulomb law with a
        non-linear viscous term (|dq|^delta with delta < 1 mimics a Stribeck/tanh knee)."""
        best_c = self.choose_coulomb("linear", None)
        best_v = self.choose_viscous(best_c)
        if best_v.law != "linear":
            c2 = self.choose_coulomb(best_v.law, best_v.param)
            if c2.law != best_c.law:
                best_c = c2
                best_v = self.choose_viscous(c2)
                if best_v.law == "linear":
                    best_c = LawFit(c2.law, c2.param, best_v.cv_rel_err, c2.smooth, c2.vp, c2.q)
        return best_c, best_v


def _law_coefficients(A: np.ndarray, y: np.ndarray, weights: np.ndarray | None,
                      columns: Callable[[Callable[[np.ndarray], np.ndarray], int], np.ndarray],
                      choice: FrictionChoice) -> dict[str, float]:
    """Coefficients of the chosen laws on all rows (weighted LS of the whole model): ``Fc`` (and ``Fs``
    for Stribeck), ``Fv``."""
    X = columns(choice.columns, 2 + (choice.coulomb.law in STRIBECK_LIKE))
    w = np.ones(y.size) if weights is None else np.asarray(weights, float)
    M = np.hstack([A, X]) * w[:, None]
    _, pinv, _ = wls_basis(M)
    theta = pinv @ (y * w)
    bx = theta[A.shape[1]:]
    coef = {"Fc": float(bx[0]), "Fv": float(bx[-1])}
    if choice.coulomb.law in STRIBECK_LIKE:
        coef["Fs"] = float(bx[0] + bx[1])
    return coef


#: relative step of the central differences of a law's columns in its shape parameters (:func:`shape_uncertainty`)
SHAPE_STEP = 1e-3


def shape_parameters(choice: FrictionChoice) -> tuple[str, ...]:
    """The searched shape parameters of the chosen laws: ``v`` (tanh), ``vs`` (Stribeck), ``vp`` (Dahl), ``vs`` and
    ``vp`` (LuGre: its ``q = (Fs - Fc) / Fs`` follows the magnitudes, :func:`lugre_columns`), ``delta`` (power).
    The ``tanh`` smoothing of a Stribeck law's ``sign`` is not one (a floor, not fitted to the law)."""
    out = {"tanh": ("v",), "stribeck": ("vs",), "dahl": ("vp",), "lugre": ("vs", "vp")}.get(choice.coulomb.law, ())
    return out + (("delta",) if choice.viscous.law == "power" else ())


def _shape_value(choice: FrictionChoice, name: str) -> float:
    if name == "delta":
        return float(choice.viscous.param or math.nan)
    if name == "q":
        return float(choice.coulomb.q)
    if name == "vp" and choice.coulomb.law == "lugre":
        return float(choice.coulomb.vp or math.nan)
    return float(choice.coulomb.param or math.nan)


def _with_shape(choice: FrictionChoice, name: str, value: float) -> FrictionChoice:
    """``choice`` with one shape parameter (:func:`shape_parameters`, or LuGre's ``q``) set to ``value``."""
    c, v = choice.coulomb, choice.viscous
    if name == "delta":
        v = replace(v, param=value)
    elif name == "q":
        c = replace(c, q=value)
    elif name == "vp" and c.law == "lugre":
        c = replace(c, vp=value)
    else:
        c = replace(c, param=value)
    return replace(choice, coulomb=c, viscous=v)


def _shape_derivative(choice: FrictionChoice, columns: Callable[[FrictionChoice], np.ndarray], coef: np.ndarray,
                      name: str) -> np.ndarray:
    """``d(columns(choice) @ coef) / d name`` by central differences (relative step :data:`SHAPE_STEP`; additive for
    ``delta`` and ``q``, one-sided at ``q = 0``)."""
    x = _shape_value(choice, name)
    h = SHAPE_STEP if name in ("delta", "q") else SHAPE_STEP * abs(x)
    lo, hi = x - h, x + h
    if name == "q" and lo < 0.0:
        lo = x
    return (columns(_with_shape(choice, name, hi)) - columns(_with_shape(choice, name, lo))) @ coef / (hi - lo)


@dataclass(frozen=True)
class ShapeUncertainty:
    """The law's constants and searched shape estimated together: the linearised covariance of the nonlinear least
    squares (Seber & Wild 1989, *Nonlinear Regression*, sec. 2.1; Bates & Watts 1988, sec. 2.3), ``s^2 (J^T J)^-1``
    with ``J`` the fit's design and the derivatives of the law's torque in its shape parameters.

    Attributes
    ----------
    names : tuple of str
        The shape parameters (:func:`shape_parameters`).
    values, std : ndarray
        Their values and standard deviations.
    law_std : ndarray
        Standard deviations of the constants asked for (the law's columns, in the order given), the shape
        estimated too.
    cov : ndarray
        Covariance of the constants asked for then the shape parameters.
    """

    names: tuple[str, ...]
    values: np.ndarray
    std: np.ndarray
    law_std: np.ndarray
    cov: np.ndarray


def shape_uncertainty(choice: FrictionChoice, columns: Callable[[FrictionChoice], np.ndarray], A: np.ndarray,
                      idx: Sequence[int], values: np.ndarray, std: np.ndarray, weights: np.ndarray | None = None
                      ) -> ShapeUncertainty | None:
    """The standard deviations of a fitted law's constants with its shape estimated too (:class:`ShapeUncertainty`).

    ``A`` (r, c) is the design of the fit, ``idx`` the columns whose standard deviation is asked for (the law's,
    :meth:`FrictionChoice.names` first in that order), ``values`` and ``std`` (len(idx)) their estimates and
    standard deviations from the fit at the shape held, ``weights`` (r) the fit's row weights (WLS).
    ``columns(choice) -> (r, p)`` evaluates the law's columns on the rows. The fit's ``s^2`` is read from ``std``
    (``std_i^2 / [(A^T A)^-1]_ii``), so the estimator's own scale is kept: only the design gains the derivative
    columns. For LuGre, ``q = (Fs - Fc) / Fs`` of the relaxation length follows the magnitudes (the chain rule adds
    ``d/dq`` times ``dq/dFc`` and ``dq/d(Fs - Fc)`` to their two columns) unless the search clipped it. None when
    the law has no searched shape or a design is singular."""
    names = shape_parameters(choice)
    p = len(choice.names())
    idx = [int(i) for i in idx]
    std = np.asarray(std, float)
    if not names or len(idx) < p or not np.all(np.isfinite(std)) or not np.all(std > 0):
        return None
    coef = np.asarray(values, float)[:p]
    D = np.column_stack([_shape_derivative(choice, columns, coef, nm) for nm in names])
    Af = np.array(A, float, copy=True)
    q = float(choice.coulomb.q)
    if choice.coulomb.law == "lugre" and 0.0 < q < 0.95:
        fc, d = float(coef[0]), float(coef[1])
        fs = fc + d
        if fs != 0.0:
            dX = _shape_derivative(choice, columns, coef, "q")
            Af[:, idx[0]] += dX * (-d / fs ** 2)
            Af[:, idx[1]] += dX * (fc / fs ** 2)
    w = np.ones(A.shape[0]) if weights is None else np.asarray(weights, float)
    held = _scaled_inverse(A * w[:, None])
    free = _scaled_inverse(np.hstack([Af, D]) * w[:, None])
    if held is None or free is None:
        return None
    s2 = float(np.median(std ** 2 / np.diag(held)[idx]))
    sel = idx + list(range(A.shape[1], A.shape[1] + len(names)))
    cov = s2 * free[np.ix_(sel, sel)]
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return ShapeUncertainty(names, np.array([_shape_value(choice, nm) for nm in names]), sd[len(idx):],
                            sd[:len(idx)], cov)


def _scaled_inverse(M: np.ndarray) -> np.ndarray | None:
    """``(M^T M)^-1`` computed on the columns scaled to unit norm (None when singular)."""
    n = np.linalg.norm(M, axis=0)
    if not np.all(n > 0):
        return None
    G = (M / n).T @ (M / n)
    try:
        Gi = np.linalg.inv(G)
    except np.linalg.LinAlgError:
        return None
    if not np.all(np.isfinite(Gi)) or np.linalg.cond(G) > 1e14:
        return None
    return Gi / np.outer(n, n)


def shape_physical(choice: FrictionChoice, unc: ShapeUncertainty, values: np.ndarray) -> dict[str, float]:
    """The standard deviations of the law's reported shape (``physical`` of its effect): ``v_std``, ``vs_std``,
    ``delta_std``; for the pre-sliding laws ``x0_std`` (``x0 = vp / fs``) and ``sigma0_std`` (``sigma0 = |F| / x0``,
    ``F`` = ``Fc`` for Dahl, ``Fs = Fc + (Fs - Fc)`` for LuGre; first-order propagation of :attr:`ShapeUncertainty.cov`).
    ``values`` are the law's constants (:meth:`FrictionChoice.names` order)."""
    out = {f"{nm}_std": float(s) for nm, s in zip(unc.names, unc.std) if nm != "vp"}
    if "vp" not in unc.names or not choice.rate_hz:
        return out
    k = len(unc.law_std) + unc.names.index("vp")
    fs = float(choice.rate_hz)
    x0 = float(unc.values[unc.names.index("vp")]) / fs
    out["x0_std"] = float(unc.std[unc.names.index("vp")]) / fs
    g = np.zeros(unc.cov.shape[0])
    force = float(values[0]) + (float(values[1]) if choice.coulomb.law == "lugre" else 0.0)
    sgn = 1.0 if force >= 0 else -1.0
    g[0] = sgn / x0
    if choice.coulomb.law == "lugre":
        g[1] = sgn / x0
    g[k] = -abs(force) / x0 ** 2 / fs
    out["sigma0_std"] = float(np.sqrt(max(float(g @ unc.cov @ g), 0.0)))
    return out


def law_errors(choice: FrictionChoice) -> dict[str, float]:
    """``{law label: CV relative error}`` of every law tried (for JSON/report tables)."""
    return {c.label: float(c.cv_rel_err) for c in choice.candidates}



def replaced_friction_columns(model: IdentificationModel, choices: Sequence[FrictionChoice]
                              ) -> tuple[tuple[str, ...], Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]]:
    """The declared model with the friction laws of ``choices`` in place of its ``FS``/``FV`` columns.

    Returns
    -------
    names : tuple of str
        Column names: the declared base columns without the replaced joints' ``FS<j>``, ``FV<j>``, then
        :meth:`FrictionChoice.names` of each choice.
    columns : callable
        ``columns(q, dq, ddq) -> (N, n, len(names))`` per-sample regressor.
    """
    spliced = LawModel(model, choices)
    return tuple(spliced.BASE_NAMES), spliced.regressor


def _ones(dq: np.ndarray) -> np.ndarray:
    return np.ones((np.shape(dq)[0], 1))


class LawModel(LawSplicedModel):
    """The declared model with the friction laws of ``choices`` in place of its ``FS``/``FV`` columns, and
    an offset column ``OFF<j>`` for each joint of ``offsets`` (joints declared without friction or offset
    get the expert's terms: Coulomb law, viscous law, offset).

    The column splice is :class:`symoro_gen.identification.friction_law.LawSplicedModel` (shared with
    ``identify``'s declared laws); this adds the loop's choices, offsets and :meth:`sliding_torque`. It
    satisfies :class:`symoro_gen.model.IdentificationModel` (``BASE_NAMES`` are the new columns; every other
    attribute, the payload regressor included, is the declared model's), so the model torque of a fit
    (:func:`symoro_gen.observations.full_rate_torque`) is that of the chosen laws.
    """

    def __init__(self, model: IdentificationModel, choices: Sequence[FrictionChoice], offsets: Sequence[int] = ()):
        self.choices = tuple(choices)
        self.offsets = tuple(int(j) for j in offsets)
        entries = [JointColumns(ch.joint, ch.names(), ch.columns, (f"FS{ch.joint + 1}", f"FV{ch.joint + 1}"))
                   for ch in self.choices]
        entries += [JointColumns(j, (f"OFF{j + 1}",), _ones) for j in self.offsets]
        super().__init__(model, entries)

    def sliding_torque(self, theta: Mapping[str, float], dq: np.ndarray) -> np.ndarray:
        """Torque (N, n) of the chosen friction laws alone at velocities ``dq`` (N, n), parameters by name
        (missing ones count as 0): what :meth:`regressor` adds on each joint with a law. A caller with
        rest segments subtracts it there (static at rest, see the module docstring)."""
        dq = np.asarray(dq, float)
        out = np.zeros(dq.shape)
        for ch in self.choices:
            c = np.array([float(theta.get(nm, 0.0)) for nm in ch.names()])
            out[:, ch.joint] += ch.columns(dq[:, ch.joint]) @ c
        return out


def sliding_frame(frame):
    """A copy of a diagnosis frame (``.frame.Frame``) whose experiments carry the sliding velocity
    (:func:`sliding_velocity`) as ``dq``: candidate columns of sliding friction built on it are 0 in
    the rest segments (the rest segments of the copy are those of the original)."""
    exps = []
    for ex in frame.experiments:
        m = rest_mask(ex)
        if not m.any():
            exps.append(ex)
            continue
        new = replace(ex, dq=np.where(m, 0.0, ex.dq))
        _REST_CACHE[new] = m
        exps.append(new)
    return replace(frame, experiments=tuple(exps))


#: significant digits of a scale in a robot-file line
DECLARATION_DIGITS = 3


@dataclass(frozen=True)
class LawDeclaration:
    """The robot-file declaration of a friction law the loop found on one joint.

    Attributes
    ----------
    frame : int
        The joint's frame ``j`` in the robot file.
    joint : int
        0-based model column.
    law : str
        ``stribeck``, ``tanh`` or ``power`` (a kind of the robot file's ``friction_law``).
    scale_name : str
        ``vs``, ``v`` or ``delta``.
    scale : float
        The loop's value (rounded to :data:`DECLARATION_DIGITS` significant digits in ``line``).
    verdict, label : str
        The effect's verdict and label.
    line : str
        ``friction_law = {kind = "stribeck", vs = 0.05}``, to add to the frame.
    """

    frame: int
    joint: int
    law: str
    scale_name: str
    scale: float
    verdict: str
    label: str
    line: str

    def to_dict(self) -> dict:
        """One entry of ``robot_file`` in diagnose's JSON (docs/json-output.md); ``joint`` 1-based."""
        return {"kind": "friction_law", "frame": self.frame, "joint": self.joint + 1, "line": self.line,
                "law": self.law, "scale_name": self.scale_name, "scale": float(self.scale),
                "verdict": self.verdict or None, "effect": self.label}

    def text(self) -> str:
        """``frame 2 (joint 2): friction_law = {kind = "stribeck", vs = 0.1}   (vs = 0.1002 rad/s; ...)``."""
        v = f", {self.verdict}" if self.verdict else ""
        unit = {"delta": "", "sigma0": " (N m/rad or N/m)"}.get(self.scale_name, " (rad/s or m/s)")
        return (f"frame {self.frame} (joint {self.joint + 1}): {self.line}   ({self.scale_name} = {self.scale:.4g}"
                f"{unit}; effect {self.label}{v})")


def _declared_kind(kind: str, values: Mapping[str, float]) -> tuple[str, str] | None:
    """``(law, scale name)`` a friction effect declares as one robot-file ``friction_law``, or None."""
    has = {k for k in ("v", "vs", "delta", "sigma0") if k in values and math.isfinite(float(values[k]))}
    if kind == "stribeck":
        return ("stribeck", "vs") if "vs" in has else None
    if kind == "friction_law" and has == {"vs", "sigma0"}:
        return ("lugre", "vs")   # the LuGre law: its Stribeck scale, sigma0 added to the line
    if kind != "friction_law" or len(has) != 1:
        return None
    (name,) = has
    return {"vs": ("stribeck", "vs"), "v": ("tanh", "v"), "delta": ("power", "delta"), "sigma0": ("dahl", "sigma0")}[name]


def law_declarations(robot, effects: Sequence) -> list[LawDeclaration]:
    """The robot-file lines declaring the friction laws the loop named (``effects``:
    :class:`symoro_gen.diagnostics.report.Effect`; module docstring, "Declaring what the loop found"). An
    effect on a joint that already declares a law, a joint declared without friction (the law came with
    an offset ``OFF<j>``), a modulated effect and a scale outside the robot file's range get no line."""
    joints = robot.model_joints
    declared = set(dict(getattr(robot, "friction_laws", {}) or {}))
    out = []
    for e in effects:
        if e.joint is None or getattr(e, "modulation", None) is not None or not 0 <= e.joint < len(joints):
            continue
        values = {**dict(getattr(e, "search", {}) or {}), **dict(e.physical or {})}
        kind = _declared_kind(str(e.kind), values)
        if kind is None or any(str(nm).startswith("OFF") for nm in e.names):
            continue
        frame = joints[e.joint].j
        law, name = kind
        scale = float(values[name])
        lo, hi = SCALE_BOUNDS[name] if name in SCALE_BOUNDS else PRESLIDING_BOUNDS[name]
        if frame in declared or not lo < scale <= hi:
            continue
        shown = float(f"{scale:.{DECLARATION_DIGITS}g}")
        line = f'friction_law = {{kind = "{law}", {name} = {shown:g}}}'
        s0 = float(values.get("sigma0", math.nan))
        if law == "lugre" and PRESLIDING_BOUNDS["sigma0"][0] < s0 <= PRESLIDING_BOUNDS["sigma0"][1]:
            line = line[:-1] + f", sigma0 = {float(f'{s0:.{DECLARATION_DIGITS}g}'):g}}}"
        out.append(LawDeclaration(frame=frame, joint=int(e.joint), law=law, scale_name=name, scale=scale,
                                  verdict=str(getattr(e, "verdict", "") or ""), label=str(e.label), line=line))
    return out
