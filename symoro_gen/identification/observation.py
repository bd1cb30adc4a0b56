"""The over-determined system Y = W chi + rho, rows grouped per joint (eq. 16 of the RX-90 paper)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


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
    names: tuple
    joint: np.ndarray
    weights: np.ndarray | None = None

    def __post_init__(self) -> None:
        W = np.asarray(self.W, float)
        Y = np.asarray(self.Y, float).reshape(-1)
        if W.ndim != 2 or W.shape[0] != Y.shape[0]:
            raise ValueError(f"W {W.shape} and Y {Y.shape} do not match")
        if len(self.names) != W.shape[1]:
            raise ValueError(f"{len(self.names)} names for {W.shape[1]} columns")
        object.__setattr__(self, "W", W)
        object.__setattr__(self, "Y", Y)
        object.__setattr__(self, "names", tuple(self.names))
        object.__setattr__(self, "joint", np.asarray(self.joint, int).reshape(-1))

    @property
    def n_joints(self) -> int:
        return int(self.joint.max()) + 1 if self.joint.size else 0
