"""The one contract every identification model satisfies.

A *model* here is anything that evaluates the inverse dynamic identification model (IDM) of one
robot, linear in its parameters (Khalil & Dombre 2002, ch. 14; Gautier & Khalil 1990):

    tau = IDM_st(q, dq, ddq) chi_st = W_b(q, dq, ddq) chi_b  [+ IDM_payload chi_payload]

Three implementations exist and all satisfy :class:`IdentificationModel`:

* the generated package ``generated/<robot>/`` (``symoro_gen.load_model``), the real thing;
* :class:`symoro_gen.emit.package.InMemoryModel` (same kernels, built without files);
* :class:`symoro_gen.simulate.NumericModel` (numeric Newton–Euler, no regrouping; a reference).

Functions that take a ``model`` are typed with this Protocol, so a user's own model (for instance
a Pinocchio wrapper) works with the identification and diagnosis stages if it provides these names.
"""
from __future__ import annotations

from typing import Protocol, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import ModelError

__all__ = ["IdentificationModel", "check_model"]


@runtime_checkable
class IdentificationModel(Protocol):
    """Identification model of one robot (the generated-module contract).

    Attributes
    ----------
    ROBOT : str
        Robot name.
    N_JOINTS : int
        Number of actuated joints ``n``.
    STANDARD_NAMES, BASE_NAMES, PAYLOAD_NAMES : tuple of str
        Column names of the standard, base and payload regressors (SYMORO names, ``XX2``,
        regrouped ones ending in ``R``).

    Notes
    -----
    Inputs ``q, dq, ddq`` have shape ``(N, n)`` (or ``(n,)`` for one sample); regressors return
    ``(N, n, p)`` (or ``(n, p)``).
    """

    @property
    def ROBOT(self) -> str: ...  # noqa: N802 - module-constant names of the generated contract

    @property
    def N_JOINTS(self) -> int: ...  # noqa: N802

    @property
    def STANDARD_NAMES(self) -> tuple[str, ...]: ...  # noqa: N802

    @property
    def BASE_NAMES(self) -> tuple[str, ...]: ...  # noqa: N802

    @property
    def PAYLOAD_NAMES(self) -> tuple[str, ...]: ...  # noqa: N802

    def regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """Base regressor ``W_b``, shape ``(N, n, len(BASE_NAMES))``."""
        ...

    def standard_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """Standard regressor ``IDM_st``, shape ``(N, n, len(STANDARD_NAMES))``."""
        ...

    def payload_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """Payload regressor, shape ``(N, n, len(PAYLOAD_NAMES))`` (0 columns without payload)."""
        ...

    def base_parameters(self, chi_std: ArrayLike) -> NDArray[np.float64]:
        """Base parameters from standard ones, ``(..., len(STANDARD_NAMES)) -> (..., len(BASE_NAMES))``."""
        ...

    def torque(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike, chi_std: ArrayLike,
               chi_payload: ArrayLike | None = None) -> NDArray[np.float64]:
        """Joint torques ``(N, n)`` from standard (and payload) parameters."""
        ...


def check_model(model: object) -> IdentificationModel:
    """Return ``model`` if it satisfies :class:`IdentificationModel`, else raise a :class:`~symoro_gen.errors.ModelError`
    naming the missing attributes."""
    need = ("ROBOT", "N_JOINTS", "STANDARD_NAMES", "BASE_NAMES", "PAYLOAD_NAMES", "regressor",
            "standard_regressor", "payload_regressor", "base_parameters", "torque")
    missing = [a for a in need if not hasattr(model, a)]
    if missing:
        raise ModelError(f"{type(model).__name__} is not an identification model: missing {', '.join(missing)}")
    return model  # type: ignore[return-value]
