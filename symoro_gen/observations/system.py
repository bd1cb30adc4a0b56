"""The over-determined system Y = W chi + rho, rows grouped per joint ([GB-gains] eq. 16; IDIM eq. 12)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import IdentificationError


@dataclass(frozen=True)
class ObservationSystem:
    """Sampled, filtered and decimated identification model.

    Attributes
    ----------
    W : ndarray, shape (r, c)
        Observation matrix; rows grouped per joint: all rows of joint 1, then joint 2...
    Y : ndarray, shape (r,)
        Sampled torques (or sensor/drive signals).
    names : tuple of str, length c
        Column labels (base parameter names, payload names, extra effect parameters...).
    joint : ndarray of int, shape (r,)
        0-based joint index of each row.
    weights : ndarray, shape (r,), optional
        Row weights (1/sigma_j for WLS); None means unweighted.
    """

    W: np.ndarray
    Y: np.ndarray
    names: tuple[str, ...]
    joint: np.ndarray
    weights: np.ndarray | None = None

    def __post_init__(self) -> None:
        # IdentificationError derives from ValueError (what this constructor always raised)
        W = np.asarray(self.W, float)
        Y = np.asarray(self.Y, float).reshape(-1)
        if W.ndim != 2 or W.shape[0] != Y.shape[0]:
            raise IdentificationError(
                f"ObservationSystem: W {W.shape} and Y {Y.shape} do not match (W must be (r, c), Y (r,))")
        if len(self.names) != W.shape[1]:
            raise IdentificationError(f"ObservationSystem: {len(self.names)} names for {W.shape[1]} columns of W")
        names = tuple(self.names)
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise IdentificationError(f"ObservationSystem: duplicate column names {dup}")
        joint = np.asarray(self.joint, int).reshape(-1)
        if joint.shape[0] != Y.shape[0]:
            raise IdentificationError(
                f"ObservationSystem: joint has {joint.shape[0]} entries for {Y.shape[0]} rows")
        if joint.size and joint.min() < 0:
            raise IdentificationError("ObservationSystem: joint indices must be >= 0 (0-based)")
        object.__setattr__(self, "W", W)
        object.__setattr__(self, "Y", Y)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "joint", joint)
        if self.weights is not None:
            w = np.asarray(self.weights, float).reshape(-1)
            if w.shape[0] != Y.shape[0]:
                raise IdentificationError(
                    f"ObservationSystem: weights has {w.shape[0]} entries for {Y.shape[0]} rows")
            object.__setattr__(self, "weights", w)

    @property
    def n_joints(self) -> int:
        return int(self.joint.max()) + 1 if self.joint.size else 0
