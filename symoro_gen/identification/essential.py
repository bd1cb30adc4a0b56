"""Essential parameters (LWR4 paper Sec. IV-B; Khalil, Gautier & Lemoine 2007).

Starting from the base-parameter estimate, the parameter with the largest relative standard
deviation %sigma is cancelled and the simplified model re-estimated, until
``max(%sigma) / min(%sigma) < r_sigma`` (r_sigma between 10 and 30; the paper uses 30).
"""
from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import IdentificationError
from .accumulate import Accumulator
from .estimators import (
    COND_WARN,
    RANK_TOL,
    REL_STD_WARN_PCT,
    ZERO_COL_TOL,
    Options,
    RawFit,
    as_accumulator,
    fit_raw,
    make_result,
)
from .observation import ObservationSystem
from .result import EliminationStep, IdentificationResult

#: default stop ratio of the papers
R_SIGMA = 30.0
#: relative growth of a joint's error norm (essential vs base model) above which a warning is given
ERR_GROWTH_WARN = 0.5


@dataclass(frozen=True, eq=False)
class EssentialResult:
    """Outcome of the essential-parameter procedure.

    Attributes
    ----------
    result : IdentificationResult
        Estimate of the essential parameters (cancelled ones listed in ``result.eliminated``).
    initial : IdentificationResult
        Estimate of all (base) parameters before any cancellation.
    history : tuple of EliminationStep
        One step per cancelled parameter, in order.
    r_sigma : float
        Stop ratio used.
    """

    result: IdentificationResult
    initial: IdentificationResult
    history: tuple[EliminationStep, ...]
    r_sigma: float

    @property
    def removed(self) -> tuple[str, ...]:
        return tuple(s.removed for s in self.history)

    def summary(self) -> str:
        lines = [f"Essential parameters (r_sigma = {self.r_sigma:g}): "
                 f"{self.initial.n_params} -> {self.result.n_params} parameters", "",
                 f"{'step':>4}  {'cancelled':<10}{'%sigma':>12}{'max/min':>12}{'n':>5}"]
        for i, s in enumerate(self.history, 1):
            lines.append(f"{i:>4}  {s.removed:<10}{s.rel_std_pct:>12.4g}{s.ratio:>12.4g}{s.n_params:>5}")
        lines += ["", self.result.summary()]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        out = self.result.to_dict()
        out["essential"] = {
            "r_sigma": self.r_sigma,
            "removed": [s.removed for s in self.history],
            "history": [{"removed": s.removed, "rel_std_pct": s.rel_std_pct if np.isfinite(s.rel_std_pct) else None,
                         "ratio": s.ratio if np.isfinite(s.ratio) else None, "n_params": s.n_params}
                        for s in self.history],
        }
        return out


def essential_raw(acc: Accumulator, method: str, r_sigma: float, keep: Sequence[str], opts: Options,
                  weighting=None, what: str = "essential parameters"
                  ) -> tuple[RawFit, RawFit, tuple[EliminationStep, ...]]:
    """The elimination loop on an accumulator; parameters named in ``keep`` are never cancelled
    and do not enter the stop ratio. Returns (final fit, initial fit, history)."""
    if not r_sigma > 1:
        raise IdentificationError(f"{what}: r_sigma must be > 1, got {r_sigma}")
    unknown = [k for k in keep if k not in acc.names]
    if unknown:
        raise IdentificationError(f"{what}: keep names {unknown} are not columns of W {acc.names}")
    kept = set(keep)
    active = list(range(acc.n_params))
    raw = fit_raw(acc, method, active, opts, weighting=weighting, what=what)
    initial = raw
    history = []
    while True:
        pct = raw.rel_std_pct
        cand = [i for i, a in enumerate(active) if acc.names[a] not in kept]
        if len(cand) <= 1:
            break
        p = pct[cand]
        pmin = p.min()
        ratio = float(p.max() / pmin) if pmin > 0 else np.inf
        if ratio < r_sigma:
            break
        i = cand[int(np.argmax(p))]
        history.append(EliminationStep(acc.names[active[i]], float(pct[i]), ratio, len(active)))
        del active[i]
        raw = fit_raw(acc, method, active, opts, weighting=weighting, what=what)
    return raw, initial, tuple(history)


def essential_parameters(data: ObservationSystem | Accumulator, r_sigma: float = R_SIGMA,
                         method: str = "ols", weighting: str | None = None, keep: Sequence[str] = (), *,
                         rank_tol: float = RANK_TOL, cond_warn: float = COND_WARN,
                         rel_std_warn_pct: float = REL_STD_WARN_PCT, zero_col_tol: float = ZERO_COL_TOL,
                         err_growth_warn: float = ERR_GROWTH_WARN) -> EssentialResult:
    """Iteratively cancel the parameter with the largest %sigma until max %sigma / min %sigma < r_sigma.

    Parameters
    ----------
    data : ObservationSystem or Accumulator
    r_sigma : float
        Stop ratio (10 to 30 in the papers; default 30).
    method : {"ols", "wls", "tls"}
        Estimator re-run at every step (WLS weights and TLS row weights are re-estimated each time).
    weighting : None or "joint"
        TLS row weighting.
    keep : sequence of str
        Parameters never cancelled (and left out of the stop ratio).
    err_growth_warn : float
        Warn when a joint's relative error norm grows by more than this fraction.

    Returns
    -------
    EssentialResult
        ``.result`` (reduced estimate), ``.initial`` (all parameters), ``.history``.
    """
    opts = Options(rank_tol=rank_tol, cond_warn=cond_warn, rel_std_warn_pct=rel_std_warn_pct,
                   zero_col_tol=zero_col_tol)
    m = method.lower()
    use_w = m == "ols" or (m == "tls" and weighting in (None, False, "none"))
    acc, system = as_accumulator(data, use_weights=use_w)
    raw, raw0, history = essential_raw(acc, m, r_sigma, keep, opts, weighting)
    eliminated = tuple(s.removed for s in history)
    result = make_result(raw, acc, system, opts, eliminated=eliminated, keep=keep)
    initial = make_result(raw0, acc, system, opts, keep=keep)
    w = growth_warning(initial.rel_err, result.rel_err, err_growth_warn)
    if w:
        result = dataclasses.replace(result, warnings=result.warnings + (w,))
    return EssentialResult(result, initial, history, float(r_sigma))


def growth_warning(before: np.ndarray, after: np.ndarray, growth: float) -> str | None:
    """Warning naming the joints whose error norm grew by more than ``growth`` (relative)."""
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(after > (1.0 + growth) * before)
    if bad.size == 0:
        return None
    listed = ", ".join(f"joint {j + 1} ({before[j]:.3g} -> {after[j]:.3g})" for j in bad)
    return (f"the essential model fits {listed} much worse than the base model (rel. error norms): "
            f"parameters that matter there were cancelled; consider a larger r_sigma")
