"""Small algebra on observation systems: stacking experiments, moving known parameters to the
left-hand side, scaling measurements by gains. Pure functions; inputs are never modified."""
from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..errors import IdentificationError
from .observation import ObservationSystem
from .result import Gains


def stack_systems(*systems: ObservationSystem) -> ObservationSystem:
    """Stack experiments row-wise; columns are matched by name, missing ones are zero.

    With an unloaded system (columns ``chi``) and a loaded one (columns ``chi`` + payload) this
    builds ``[[W_a, 0], [W_b, W_L]]`` of eq. 7 (LWR4 paper) / eq. 27 (RX-90 paper).

    Returns
    -------
    ObservationSystem
        Columns: those of the first system, then new names in order of appearance. Row weights
        are kept when any system has them (1 for the others).
    """
    if not systems:
        raise IdentificationError("stack_systems: no system given")
    for s in systems:
        if not isinstance(s, ObservationSystem):
            raise IdentificationError(f"stack_systems expects ObservationSystem values, got {type(s).__name__}")
    names: list[str] = []
    for s in systems:
        names += [n for n in s.names if n not in names]
    col = {n: i for i, n in enumerate(names)}
    blocks = []
    for s in systems:
        B = np.zeros((s.W.shape[0], len(names)))
        B[:, [col[n] for n in s.names]] = s.W
        blocks.append(B)
    weights = None
    if any(s.weights is not None for s in systems):
        weights = np.concatenate([s.weights if s.weights is not None else np.ones(s.Y.size) for s in systems])
    return ObservationSystem(np.vstack(blocks), np.concatenate([s.Y for s in systems]), tuple(names),
                             np.concatenate([s.joint for s in systems]), weights)


def fix_parameters(system: ObservationSystem, known: Mapping[str, float]) -> ObservationSystem:
    """Move known parameters to the left-hand side: ``Y - W_k chi_k = W_u chi_u + rho``.

    Parameters
    ----------
    system : ObservationSystem
    known : mapping name -> value
        Every name must be a column of ``system``.

    Returns
    -------
    ObservationSystem
        Without the known columns.
    """
    missing = [k for k in known if k not in system.names]
    if missing:
        raise IdentificationError(
            f"known parameter(s) {missing} are not columns of the observation system {system.names}")
    kidx = [system.names.index(k) for k in known]
    kval = np.array([float(known[k]) for k in known])
    if not np.isfinite(kval).all():
        raise IdentificationError(f"known parameter values must be finite: {dict(known)}")
    uidx = [i for i in range(len(system.names)) if i not in set(kidx)]
    Y = system.Y - system.W[:, kidx] @ kval if kidx else system.Y
    return ObservationSystem(system.W[:, uidx], Y, tuple(system.names[i] for i in uidx), system.joint,
                             system.weights)


def gain_vector(gains, n_joints: int) -> np.ndarray:
    """Gains per joint as an array from a :class:`Gains` or an array-like.

    Parameters
    ----------
    gains : Gains or array_like
        An array must have at least ``n_joints`` entries (one per joint, 0-based order).
    n_joints : int
        Number of joints the gains must cover.

    Returns
    -------
    ndarray, shape (max(n_joints, len(gains)),)
    """
    if isinstance(gains, Gains):
        return gains.as_vector(max(n_joints, max(gains.joints, default=-1) + 1))
    g = np.asarray(gains, float).reshape(-1)
    if g.size < n_joints:
        raise IdentificationError(f"{g.size} gains given for {n_joints} joints")
    if not np.isfinite(g).all() or (g == 0).any():
        raise IdentificationError(f"gains must be finite and non-zero, got {g}")
    return g


def apply_gains(system: ObservationSystem, gains) -> ObservationSystem:
    """Scale the measurements by the gains, ``tau_j = g_j v_j`` (eq. 4 / eq. 13).

    Parameters
    ----------
    gains : Gains or array_like, shape (n_joints,)
        Joints without an identified gain (in a :class:`Gains`) keep gain 1.
    """
    g = gain_vector(gains, system.n_joints)
    return ObservationSystem(system.W, system.Y * g[system.joint], system.names, system.joint, system.weights)


def select_rows(system: ObservationSystem, mask) -> ObservationSystem:
    """Rows where ``mask`` is True."""
    mask = np.asarray(mask, bool)
    return ObservationSystem(system.W[mask], system.Y[mask], system.names, system.joint[mask],
                             None if system.weights is None else system.weights[mask])
