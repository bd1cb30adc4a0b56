"""Structure left in a residual, per joint, against the signals of the recording.

For joint j the residual ``rho_j`` is tested against its own velocity (binned), position, model torque,
acceleration, the time, the velocity and acceleration of every other joint (one-way ANOVA over
quantile bins, :func:`.stats.binned_anova`: explained variance ``eta2`` and a p-value robust to
serial correlation and heteroscedasticity), and in frequency (largest periodogram ordinate against the
local level of the spectrum, :func:`.stats.fisher_g_test`).
All p-values of one analysis are Bonferroni-corrected together; ``significant`` means corrected
p < ``significance``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .frame import Frame
from .stats import binned_anova, bonferroni, fisher_g_test

__all__ = ["StructureItem", "residual_structure", "SIGNAL_LABELS"]

#: the frequency test searches below this share of the decimation cut-off (above it the decimation
#: filter shapes the residual spectrum)
FREQUENCY_BAND = 0.8

SIGNAL_LABELS = {"dq": "velocity", "q": "position", "tau_hat": "torque", "ddq": "acceleration", "t": "time",
                 "dtau_hat": "torque rate", "frequency": "frequency"}


@dataclass(frozen=True)
class StructureItem:
    """One test of structure in the residual of one joint.

    Attributes
    ----------
    joint : int
        0-based joint of the residual.
    signal : str
        ``dq q tau_hat ddq t`` (binned) or ``frequency``.
    signal_joint : int or None
        Joint of the signal (None for time and frequency).
    eta2 : float
        Explained variance (share of the periodogram peak for ``frequency``).
    p_value : float
        Bonferroni-corrected p-value.
    significant : bool
    frequency_hz : float or None
        Peak frequency for the ``frequency`` test.
    """

    joint: int
    signal: str
    signal_joint: int | None
    eta2: float
    p_value: float
    significant: bool
    frequency_hz: float | None = None

    @property
    def label(self) -> str:
        name = SIGNAL_LABELS.get(self.signal, self.signal)
        if self.signal == "frequency":
            return f"frequency (peak {self.frequency_hz:.3g} Hz)"
        if self.signal_joint is None:
            return name
        return f"{name} {self.signal_joint + 1}" if self.signal_joint != self.joint else name

    def to_dict(self) -> dict:
        return {"joint": self.joint + 1, "signal": self.signal,
                "signal_joint": None if self.signal_joint is None else self.signal_joint + 1,
                "label": self.label, "explained_variance": self.eta2, "p_value": self.p_value,
                "significant": self.significant,
                **({"frequency_hz": self.frequency_hz} if self.frequency_hz is not None else {})}


def residual_structure(frame: Frame, residual: np.ndarray, *, significance: float = 0.01, n_bins: int = 16,
                       others: bool = True) -> tuple[StructureItem, ...]:
    """Test the residual of every joint for structure (see the module docstring).

    Parameters
    ----------
    frame : Frame
    residual : ndarray, shape (r,)
        ``Y - W chi`` on the frame's rows.
    significance : float
        Family-wise level (Bonferroni over all tests of this call).
    n_bins : int
        Quantile bins of the ANOVA.
    others : bool
        Also test against the other joints' velocities and accelerations.

    Returns
    -------
    tuple of StructureItem
        Sorted by joint, then by decreasing explained variance.
    """
    residual = np.asarray(residual, float)
    n = frame.n_joints
    raw: list[tuple[int, str, int | None, float, float, float | None]] = []
    for j in range(n):
        rows = frame.rows_of(j)
        if rows.size < 3 * n_bins:
            continue
        r = residual[rows]
        groups = frame.row_experiment[rows]
        tests = [("dq", j), ("q", j), ("tau_hat", j), ("ddq", j), ("t", None)]
        if others:
            tests += [(s, k) for k in range(n) if k != j for s in ("dq", "ddq")]
        for sig, k in tests:
            x = frame.sig["t"][rows] if sig == "t" else frame.sig[sig][rows, k]
            a = binned_anova(r, x, n_bins=n_bins, groups=groups)
            raw.append((j, sig, k, a.eta2, a.p_value, None))
        # frequency: per experiment (below the decimation filter's transition band), keep the strongest
        best = (0.0, 0.0, 1.0)
        exps = np.unique(groups)
        for e in exps:
            m = groups == e
            dt = float(np.median(np.diff(frame.sig["t"][rows][m]))) if m.sum() > 2 else 1.0
            fmax = FREQUENCY_BAND * frame.experiments[int(e)].settings.decimation_cutoff_hz
            f, g, p = fisher_g_test(r[m], dt, f_max=fmax if np.isfinite(fmax) else None)
            p = min(1.0, p * exps.size)
            if p < best[2] or (best[2] == 1.0 and g > best[1]):
                best = (f, g, p)
        raw.append((j, "frequency", None, best[1], best[2], best[0]))
    m = len(raw)
    out = []
    for j, sig, k, eta2, p, f_hz in raw:
        pc = bonferroni(p, m)
        out.append(StructureItem(j, sig, k, float(eta2), pc, pc < significance, f_hz))
    out.sort(key=lambda s: (s.joint, -s.eta2))
    return tuple(out)
