"""One-call identification: the estimator by name, optionally reduced to the essential parameters.

Kept apart from :mod:`.estimators` (the OLS/WLS/TLS solvers) because the essential-parameter procedure
(:mod:`.essential`, LWR4 paper Sec. IV-B) is built on those solvers: this module sits above both.
"""
from __future__ import annotations

from collections.abc import Sequence

from ..errors import IdentificationError
from ..observations.system import ObservationSystem
from .accumulate import Accumulator
from .essential import essential_parameters
from .estimators import fit_ols, fit_tls, fit_wls
from .result import IdentificationResult

__all__ = ["identify"]


def identify(data: ObservationSystem | Accumulator, method: str = "ols", essential: bool = False,
             r_sigma: float = 30.0, weighting: str | None = None, keep: Sequence[str] = (),
             **tolerances) -> IdentificationResult:
    """One-call identification: ``method`` in {"ols", "wls", "tls"}, optionally reduced to the
    essential parameters (:func:`essential_parameters`, stop ratio ``r_sigma``).

    Parameters
    ----------
    data : ObservationSystem or Accumulator
    method : str
    essential : bool
    r_sigma : float
        Stop ratio max %sigma / min %sigma of the essential-parameter procedure.
    weighting : None or "joint"
        TLS row weighting (ignored by OLS/WLS).
    keep : sequence of str
        Parameters never cancelled by the essential procedure.
    **tolerances
        rank_tol, cond_warn, rel_std_warn_pct, zero_col_tol.
    """
    m = method.lower()
    if m not in ("ols", "wls", "tls"):
        raise IdentificationError(f"unknown identification method {method!r}; use 'ols', 'wls' or 'tls'")
    if essential:
        return essential_parameters(data, r_sigma=r_sigma, method=m, weighting=weighting, keep=keep,
                                    **tolerances).result
    if m == "ols":
        return fit_ols(data, **tolerances)
    if m == "wls":
        return fit_wls(data, **tolerances)
    return fit_tls(data, weighting=weighting, **tolerances)
