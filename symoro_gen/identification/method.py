"""One-call identification: the estimator by name, optionally reduced to the essential parameters.

Kept apart from :mod:`.estimators` (the OLS/WLS/TLS solvers) because the essential-parameter procedure
(:mod:`.essential`, LWR4 paper Sec. IV-B) is built on those solvers: this module sits above both.
"""
from __future__ import annotations

from collections.abc import Sequence

from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.options import AssemblyOptions
from ..observations.system import ObservationSystem
from ..preprocessing.trajectory import Trajectory
from .accumulate import Accumulator
from .didim import identify_didim
from .essential import essential_parameters
from .estimators import fit_ols, fit_tls, fit_wls
from .iv import identify_iv
from .result import IdentificationResult

__all__ = ["METHODS", "identify"]

#: the estimators by name: the IDIM least-squares family on an observation system, and the iterated
#: closed-loop estimators (IDIM-IV [JVG2014], DIDIM [GJV2013]) on the trajectories
METHODS = ("ols", "wls", "tls", "iv", "didim")


def identify(data: ObservationSystem | Accumulator | Trajectory | Sequence[Trajectory], method: str = "ols",
             essential: bool = False, r_sigma: float = 30.0, weighting: str | None = None, keep: Sequence[str] = (),
             *, model: IdentificationModel | None = None, options: AssemblyOptions | None = None,
             closed_loop: dict | None = None, **tolerances) -> IdentificationResult:
    """One-call identification: ``method`` in :data:`METHODS`, optionally reduced to the
    essential parameters (:func:`essential_parameters`, stop ratio ``r_sigma``; OLS/WLS/TLS only).

    Parameters
    ----------
    data : ObservationSystem, Accumulator, Trajectory or sequence of Trajectory
        An observation system for "ols", "wls", "tls"; the measured trajectories for "iv" and "didim"
        (they simulate the robot and assemble the simulated states with ``options``).
    method : str
    essential : bool
    r_sigma : float
        Stop ratio max %sigma / min %sigma of the essential-parameter procedure.
    weighting : None or "joint"
        TLS row weighting (ignored by OLS/WLS).
    keep : sequence of str
        Parameters never cancelled by the essential procedure.
    model : IdentificationModel
        Needed by "iv" and "didim".
    options : AssemblyOptions
        Assembly options of "iv" and "didim".
    closed_loop : dict, optional
        Keywords of :func:`~.iv.identify_iv` / :func:`~.didim.identify_didim` (``references``,
        ``gains``, ``bandwidth_hz``, ``max_iter``, ``tol``, ``start``...).
    **tolerances
        rank_tol, cond_warn, rel_std_warn_pct, zero_col_tol.

    Returns
    -------
    IdentificationResult
        For "iv"/"didim" the final estimate (the iterations are in the functions' own result,
        :class:`~.iv.IterativeIdentification`).
    """
    m = method.lower()
    if m not in METHODS:
        raise IdentificationError(f"unknown identification method {method!r}; use one of {', '.join(METHODS)}")
    if m in ("iv", "didim"):
        if essential:
            raise IdentificationError(f"--essential is not available with the {m} method")
        if model is None:
            raise IdentificationError(f"the {m} method simulates the robot: pass model=...")
        if isinstance(data, (ObservationSystem, Accumulator)):
            raise IdentificationError(f"the {m} method needs the measured trajectories, not an observation system")
        fn = identify_iv if m == "iv" else identify_didim
        return fn(model, data, options, **(closed_loop or {})).result
    if not isinstance(data, (ObservationSystem, Accumulator)):  # what the estimators say of anything else
        raise IdentificationError(f"expected an ObservationSystem or an Accumulator, got {type(data).__name__}")
    if essential:
        return essential_parameters(data, r_sigma=r_sigma, method=m, weighting=weighting, keep=keep,
                                    **tolerances).result
    if m == "ols":
        return fit_ols(data, **tolerances)
    if m == "wls":
        return fit_wls(data, **tolerances)
    return fit_tls(data, weighting=weighting, **tolerances)
