"""The settings of the assembly stage, validated once (:class:`AssemblyOptions`).

The filter rules are Gautier's (M. Gautier, "Dynamic identification of robots with power model",
ICRA 1997; RX-90 paper, Gautier & Briot, eq. 14-16: band-pass ``q, dq, ddq`` by a zero-phase
Butterworth low-pass and central differences, then parallel decimation of ``Y`` and of every column
of ``W``), applied per experiment by
:func:`~symoro_gen.preprocessing.filtering.choose_filter_settings` for every value left unset.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

import numpy as np

from ..preprocessing.filtering import (
    FilterRule,
)

__all__ = ["RULE_FIELDS", "RULE_CONSTANTS", "AssemblyOptions"]

#: fields passed to :func:`~symoro_gen.preprocessing.filtering.choose_filter_settings` as they are
RULE_FIELDS = ("dynamics_bandwidth_hz", "cutoff_hz", "n_d", "order", "ftype", "edge_samples")
#: fields passed to it as its ``rule`` (:class:`~symoro_gen.preprocessing.filtering.FilterRule`)
RULE_CONSTANTS = ("cutoff_factor", "decimation_margin", "cutoff_ratio", "energy_fraction", "min_bandwidth_hz",
                  "max_cutoff_fraction")


def _positive(name: str, x: object, *, allow_none: bool = True, integer: bool = False, zero: bool = False) -> None:
    if x is None:
        if allow_none:
            return
        raise ValueError(f"AssemblyOptions.{name} must be given")
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise ValueError(f"AssemblyOptions.{name} must be a number, got {x!r}")
    if integer and int(x) != x:
        raise ValueError(f"AssemblyOptions.{name} must be an integer, got {x!r}")
    if not math.isfinite(float(x)) or (x < 0 if zero else x <= 0):
        raise ValueError(f"AssemblyOptions.{name} must be {'>= 0' if zero else '> 0'} and finite, got {x!r}")


@dataclass(frozen=True)
class AssemblyOptions:
    """How trajectories become the observation system ``Y = W chi`` (RX-90 paper eq. 14-16).

    Every value left ``None`` is chosen per experiment by Gautier's rules
    (:func:`~symoro_gen.preprocessing.filtering.choose_filter_settings`). Values are checked when the
    options are built: a bad one fails here, before any data are read.

    >>> AssemblyOptions(cutoff_hz=20.0, n_d=5).n_d
    5
    >>> AssemblyOptions(min_velocity=-1.0)
    Traceback (most recent call last):
    ...
    ValueError: AssemblyOptions.min_velocity must be >= 0, got -1.0
    """

    #: Cut-off of the zero-phase Butterworth low-pass of ``q`` [Hz]; default ``cutoff_factor * f_dyn``.
    cutoff_hz: float | None = None
    #: Decimation factor (one sample kept in ``n_d``, after the decimation low-pass); default from
    #: ``f_dyn`` and ``decimation_margin``; 1 means no decimation.
    n_d: int | None = None
    #: Dynamics bandwidth ``f_dyn`` [Hz] the rules start from; default: estimated per experiment from ``q``.
    dynamics_bandwidth_hz: float | None = None
    #: Butterworth order (applied forward and backward: zero phase).
    order: int = 4
    #: Decimation low-pass: ``"fir"`` (zero-phase FIR, streamable) or ``"iir"`` (Chebyshev, SciPy's
    #: ``decimate`` default; needs each experiment in memory at once).
    ftype: str = "fir"
    #: Samples dropped at both ends of each experiment (filter edge effects); default from the filters.
    edge_samples: int | None = None
    #: Gautier's rule: Butterworth cut-off = ``cutoff_factor * f_dyn`` (>= 10). These six default to
    #: :class:`~symoro_gen.preprocessing.filtering.FilterRule`'s (passed to the filters as one, ``rule_keywords``).
    cutoff_factor: float = FilterRule.cutoff_factor
    #: Decimated Nyquist frequency >= ``decimation_margin * f_dyn``.
    decimation_margin: float = FilterRule.decimation_margin
    #: Decimation cut-off relative to the decimated Nyquist frequency (0.8 as Matlab's ``decimate``).
    cutoff_ratio: float = FilterRule.cutoff_ratio
    #: Share of the position energy below ``f_dyn`` when ``f_dyn`` is estimated.
    energy_fraction: float = FilterRule.energy_fraction
    #: Floor of the estimated ``f_dyn`` [Hz].
    min_bandwidth_hz: float = FilterRule.min_bandwidth_hz
    #: The cut-off never exceeds this share of the Nyquist frequency.
    max_cutoff_fraction: float = FilterRule.max_cutoff_fraction
    #: Append the payload regressor's columns (zeros for experiments without the payload, LWR4 paper eq. 7).
    payload_columns: bool = False
    #: Remove the rows of joint j that depend on samples with ``|dq_j| < min_velocity[j]`` [rad/s or m/s]
    #: (a float for every joint or one per joint); None keeps every row. Row selection: it applies to
    #: the identification rows only (validation errors are computed on every sample).
    min_velocity: float | tuple[float, ...] | None = None
    #: A row is removed when more than this share of its decimation filter's absolute weights fall on
    #: slow samples (see ``min_velocity``).
    slow_weight_tol: float = 0.01
    #: Remove the rows of joint j that depend on saturated samples of ``tau_j``
    #: (:func:`~symoro_gen.preprocessing.motion.saturation_mask`: at ``tau_limits`` or in plateaus at the
    #: column's extreme), with the weight rule of ``min_velocity`` (``slow_weight_tol``); :func:`assemble` only.
    drop_saturated: bool = False
    #: With ``drop_saturated``: remove the rows of every joint at such samples (the diagnosis needs every joint
    #: on every sample), not only those of the saturated joint.
    saturated_all_joints: bool = False
    #: Torque limit per joint [N m or N] (the robot file's ``[limits] tau_max``) for ``drop_saturated``.
    tau_limits: tuple[float, ...] | None = None
    #: Use the trajectory's recorded ``dq``/``ddq`` (and the raw ``q``) instead of filtering ``q``.
    use_recorded_derivatives: bool = False
    #: Keep, per experiment, the full-rate filtered ``q, dq, ddq``, the raw torque and the decimated
    #: torques of all joints (:class:`~symoro_gen.observations.assembly.ExperimentSignals`): what the
    #: diagnosis and the raw-torque error need. Costs ``~4 n`` floats per sample.
    keep_signals: bool = True
    #: Approximate size of the full-rate buffer of one block [MB] (bounds memory when streaming).
    max_chunk_mb: float = 64.0
    #: Full-rate samples per block (overrides ``max_chunk_mb``).
    chunk_samples: int | None = None
    #: Samples per call of the model's regressor.
    regressor_batch: int = 8192
    #: OpenBLAS threads during the decimation products (1: fastest on a loaded machine); None: unchanged.
    blas_threads: int | None = 1

    def __post_init__(self) -> None:
        for name in ("cutoff_hz", "dynamics_bandwidth_hz"):
            _positive(name, getattr(self, name))
        for name in ("cutoff_factor", "decimation_margin", "cutoff_ratio", "energy_fraction", "min_bandwidth_hz",
                     "max_cutoff_fraction", "max_chunk_mb"):
            _positive(name, getattr(self, name), allow_none=False)
        for name in ("n_d", "chunk_samples", "blas_threads"):
            _positive(name, getattr(self, name), integer=True)
        _positive("order", self.order, allow_none=False, integer=True)
        _positive("regressor_batch", self.regressor_batch, allow_none=False, integer=True)
        _positive("edge_samples", self.edge_samples, integer=True, zero=True)
        _positive("slow_weight_tol", self.slow_weight_tol, allow_none=False, zero=True)
        if self.ftype not in ("fir", "iir"):
            raise ValueError(f"AssemblyOptions.ftype must be 'fir' or 'iir', got {self.ftype!r}")
        if self.min_velocity is not None:
            v = np.asarray(self.min_velocity, float).reshape(-1)
            if not np.all(np.isfinite(v)):
                raise ValueError(f"AssemblyOptions.min_velocity must be finite, got {self.min_velocity!r}")
            if (v < 0).any():
                raise ValueError(f"AssemblyOptions.min_velocity must be >= 0, got {self.min_velocity!r}")
            object.__setattr__(self, "min_velocity", float(v[0]) if np.ndim(self.min_velocity) == 0
                               else tuple(float(x) for x in v))
        for name in ("n_d", "chunk_samples", "blas_threads", "edge_samples"):
            if getattr(self, name) is not None:
                object.__setattr__(self, name, int(getattr(self, name)))
        if self.tau_limits is not None:
            lim = tuple(float(x) for x in np.asarray(self.tau_limits, float).reshape(-1))
            if not all(math.isfinite(x) and x > 0 for x in lim):
                raise ValueError(f"AssemblyOptions.tau_limits must be positive and finite, got {self.tau_limits!r}")
            object.__setattr__(self, "tau_limits", lim)
        object.__setattr__(self, "order", int(self.order))
        object.__setattr__(self, "regressor_batch", int(self.regressor_batch))
        object.__setattr__(self, "slow_weight_tol", float(self.slow_weight_tol))

    @classmethod
    def from_keywords(cls, **kw: Any) -> AssemblyOptions:
        """Options from the keywords of the former functions (``build_observation(..., cutoff_hz=...)``).

        An unknown keyword raises ``TypeError`` naming it, as a function call would."""
        known = {f.name for f in fields(cls)}
        bad = sorted(set(kw) - known)
        if bad:
            raise TypeError(f"unknown assembly option(s) {', '.join(bad)}; known: {', '.join(sorted(known))}")
        return cls(**kw)

    def rule_keywords(self) -> dict[str, Any]:
        """The keywords of :func:`~symoro_gen.preprocessing.filtering.choose_filter_settings`."""
        rule = FilterRule(**{k: getattr(self, k) for k in RULE_CONSTANTS})
        return {**{k: getattr(self, k) for k in RULE_FIELDS}, "rule": rule}

    def velocity_threshold(self, n_joints: int) -> np.ndarray | None:
        """``min_velocity`` per joint, shape (n_joints,), or None."""
        if self.min_velocity is None:
            return None
        v = np.asarray(self.min_velocity, float)
        if v.ndim and v.size != n_joints:
            raise ValueError(f"AssemblyOptions.min_velocity has {v.size} values for {n_joints} joints")
        out: np.ndarray = np.broadcast_to(v, (n_joints,)).copy()
        return out

    def summary(self) -> str:
        """The options that differ from the defaults, one per line (``"defaults (the papers' rules)"``
        when none does)."""
        default = AssemblyOptions()
        lines = [f"{f.name} = {getattr(self, f.name)!r}" for f in fields(self)
                 if getattr(self, f.name) != getattr(default, f.name)]
        return "\n".join(lines) if lines else "defaults (the papers' rules)"
