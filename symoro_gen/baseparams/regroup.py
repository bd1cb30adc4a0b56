"""Base parameters by the closed-form rules of Gautier & Khalil, with a numeric QR check.

Rules, applied from the terminal links towards the base (geometry kept symbolic):

* revolute joint j (ant a): YYj, MZj, Mj are regrouped. Link j keeps XXjR = XXj - YYj;
  the rotationally symmetric remainder (inertia diag(YYj, YYj, 0), first moment
  (0, 0, MZj), mass Mj) moves rigidly onto link a through a_T_j (theta_j = 0): its
  inertia about O_a, first moment and mass are added to link a's parameters.
* prismatic joint j: the inertia matrix of link j (XXj..ZZj) moves onto link a,
  rotated by a_R_j (rotation inertia only; first moments and mass stay).
* contributions that reach the base (a = 0) have no effect and vanish.
* parameters whose regressor column is identically zero (links near the base whose
  motion is restricted) have no effect and are eliminated.

Whatever dependency remains after these rules (other special cases near the base)
is found by a seeded numerical QR-like sweep on random samples: a column in the span of
the columns kept before it is regrouped into them with numerical coefficients (exact
rationals when they are), and the relation is marked ``numeric``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from ..description.model import PRISMATIC, REVOLUTE
from ..dynamics.newton_euler import SymbolicRegressor
from ..description.mdh import constant_rotation, position, rot_z
from ..params import INERTIAL_KINDS, param_name

_J_KINDS = INERTIAL_KINDS[:6]
_J_INDEX = {"XX": (0, 0), "XY": (0, 1), "XZ": (0, 2), "YY": (1, 1), "YZ": (1, 2), "ZZ": (2, 2)}


@dataclass(frozen=True)
class BaseParameterMap:
    """How the standard parameters regroup into the base parameters.

    Attributes
    ----------
    standard_names : tuple of str
    base_names : tuple of str
        SYMORO names; regrouped ones carry ``R`` (``XX2R``).
    kept : tuple of str
        The standard parameter whose regressor column each base parameter uses.
    relations : dict
        ``base name -> sympy expression`` in the standard-parameter symbols (geometry symbolic).
    eliminated : tuple of str
        Standard parameters with no column of their own (regrouped or without effect).
    no_effect : tuple of str
        Standard parameters (or groups) without any effect on the model.
    numeric : tuple of str
        Base parameters whose relation came from the numerical sweep.
    """

    standard_names: tuple
    base_names: tuple
    kept: tuple
    relations: dict
    eliminated: tuple
    no_effect: tuple
    numeric: tuple = ()
    geometry: dict = field(default_factory=dict)

    def matrix(self, subs: dict | None = None) -> np.ndarray:
        """K (n_base x n_std) with chi_base = K chi_std, geometry substituted by ``subs``."""
        subs = self.geometry if subs is None else subs
        idx = {n: i for i, n in enumerate(self.standard_names)}
        K = np.zeros((len(self.base_names), len(self.standard_names)))
        for b, name in enumerate(self.base_names):
            e = sp.expand(self.relations[name].xreplace(subs))
            for s, c in e.as_coefficients_dict().items():
                if s == 1:
                    raise ValueError(f"relation of {name} has a constant term")
                K[b, idx[s.name]] = float(c)
        return K


def _sym(name: str) -> sp.Symbol:
    return sp.Symbol(name, real=True)


def _regroup_closed_form(reg: SymbolicRegressor):
    robot = reg.robot
    cur: dict[str, sp.Expr] = {n: _sym(n) for n in reg.standard_names}
    eliminated: list[str] = []
    no_effect: list[str] = []

    def add_J(a, dJ):
        for k, (r, c) in _J_INDEX.items():
            cur[param_name(k, a)] = cur[param_name(k, a)] + dJ[r, c]

    for row in reversed(robot.joints):
        j, a = row.j, row.ant
        R0 = constant_rotation(row)
        if row.sigma == REVOLUTE:
            YY, MZ, M = cur[f"YY{j}"], cur[f"MZ{j}"], cur[f"M{j}"]
            cur[f"XX{j}"] = cur[f"XX{j}"] - YY
            for k in ("YY", "MZ", "M"):
                eliminated.append(f"{k}{j}")
                del cur[f"{k}{j}"]
            if a == 0:
                no_effect.append(f"YY{j}, MZ{j}, M{j} (regrouped onto the base)")
                continue
            P = position(row)
            Js = sp.diag(YY, YY, 0)
            s = R0 * sp.Matrix([0, 0, MZ])
            dJ = R0 * Js * R0.T + M * ((P.T * P)[0] * sp.eye(3) - P * P.T)
            dJ += 2 * (P.T * s)[0] * sp.eye(3) - P * s.T - s * P.T
            add_J(a, dJ.applyfunc(sp.expand))
            dMS = (s + M * P).applyfunc(sp.expand)
            for i, k in enumerate(("MX", "MY", "MZ")):
                cur[f"{k}{a}"] = cur[f"{k}{a}"] + dMS[i]
            cur[f"M{a}"] = cur[f"M{a}"] + M
        elif row.sigma == PRISMATIC:
            Jj = sp.Matrix(3, 3, lambda r, c: cur[param_name(_kind_at(r, c), j)])
            for k in _J_KINDS:
                eliminated.append(f"{k}{j}")
                del cur[f"{k}{j}"]
            if a == 0:
                no_effect.append(f"XX{j}..ZZ{j} (rotation inertia of a link moving in translation from the base)")
                continue
            Rj = constant_rotation(row) * rot_z(row.theta)
            add_J(a, (Rj * Jj * Rj.T).applyfunc(sp.expand))
    return cur, eliminated, no_effect


def _kind_at(r, c):
    for k, (a, b) in _J_INDEX.items():
        if (a, b) == (r, c) or (b, a) == (r, c):
            return k
    raise KeyError((r, c))


def _sample_columns(reg: SymbolicRegressor, names, n_samples: int, rng: np.random.Generator) -> np.ndarray:
    """Numeric columns (n_samples*n, len(names)) of the standard regressor at random states."""
    from ..emit.numpy_backend import evaluate, kernel_source, load_kernel

    robot = reg.robot
    graph = reg.graph.substituted(robot.geometry_subs()).pruned({k for k in reg.graph.outputs if k[1] in set(names)})
    src = kernel_source(graph, robot.n_joints, names, "k", robot.q, robot.dq, robot.ddq)
    kern = load_kernel(src, "k")
    n = robot.n_joints
    q = rng.uniform(-np.pi, np.pi, (n_samples, n))
    dq = rng.normal(0, 2.0, (n_samples, n))
    ddq = rng.normal(0, 4.0, (n_samples, n))
    W = evaluate(kern, n, len(names), q, dq, ddq)
    return W.reshape(-1, len(names))


def _nice(c: float, tol: float) -> sp.Expr:
    r = sp.nsimplify(c, rational=True, tolerance=tol)
    if abs(float(r) - c) <= tol * max(1.0, abs(c)) and (r.q <= 1000):
        return r
    return sp.Float(float(f"{c:.12g}"))


def group_base_parameters(
    reg: SymbolicRegressor,
    *,
    rng: np.random.Generator | None = None,
    n_samples: int = 60,
    rank_tol: float = 1e-9,
    dependency_tol: float = 1e-7,
    coefficient_tol: float = 1e-8,
) -> BaseParameterMap:
    """Base parameters of the robot of ``reg`` (closed-form rules + numeric sweep).

    Parameters
    ----------
    reg : SymbolicRegressor
    rng : numpy.random.Generator, optional
        For the random samples of the numeric sweep (default: seeded with 0, deterministic).
    n_samples : int
        Random states used by the numeric sweep.
    rank_tol : float
        A column whose norm is below ``rank_tol`` times the largest one has no effect.
    dependency_tol : float
        A column whose distance to the span of the previously kept columns is below
        ``dependency_tol`` times its norm is dependent (regrouped into them).
    coefficient_tol : float
        Regrouping coefficients smaller than this are dropped; within it of a simple
        rational they are written exactly.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    robot = reg.robot
    cur, eliminated, no_effect = _regroup_closed_form(reg)

    # zero columns: no effect
    cols_present = {name for (_, name) in reg.graph.outputs}
    for name in list(cur):
        if name not in cols_present:
            no_effect.append(f"{name}R" if cur[name] != _sym(name) else name)
            eliminated.append(name)
            del cur[name]

    kept_order = [n for n in reg.standard_names if n in cur]
    # numeric sweep: columns in standard order, a dependent one regroups into earlier ones
    W = _sample_columns(reg, kept_order, n_samples, rng)
    norms = np.linalg.norm(W, axis=0)
    accepted: list[int] = []
    numeric: list[str] = []
    Q = np.zeros((W.shape[0], 0))
    for k, name in enumerate(kept_order):
        c = W[:, k]
        if norms[k] <= rank_tol * max(norms.max(), 1.0):
            no_effect.append(name)
            eliminated.append(name)
            del cur[name]
            continue
        resid = c - Q @ (Q.T @ c) if Q.shape[1] else c
        if np.linalg.norm(resid) > dependency_tol * norms[k]:
            accepted.append(k)
            qv = resid - Q @ (Q.T @ resid) if Q.shape[1] else resid
            Q = np.column_stack([Q, qv / np.linalg.norm(qv)])
            continue
        # dependent: c = W_acc beta
        Wa = W[:, accepted]
        beta, *_ = np.linalg.lstsq(Wa, c, rcond=None)
        for kk, b in zip(accepted, beta):
            if abs(b) > coefficient_tol:
                tgt = kept_order[kk]
                cur[tgt] = cur[tgt] + _nice(float(b), coefficient_tol) * cur[name]
                if tgt not in numeric:
                    numeric.append(tgt)
        eliminated.append(name)
        del cur[name]

    kept = tuple(n for n in reg.standard_names if n in cur)
    base_names, relations = [], {}
    for n in kept:
        e = sp.expand(cur[n])
        bn = n if e == _sym(n) else n + "R"
        base_names.append(bn)
        relations[bn] = e
    num_names = tuple(n + ("R" if (n + "R") in relations else "") for n in numeric if n in cur)
    return BaseParameterMap(
        standard_names=reg.standard_names,
        base_names=tuple(base_names),
        kept=kept,
        relations=relations,
        eliminated=tuple(eliminated),
        no_effect=tuple(no_effect),
        numeric=num_names,
        geometry=robot.geometry_subs(),
    )


def numeric_rank(W: np.ndarray, rtol: float = 1e-9) -> int:
    """Numeric rank of W by SVD with relative tolerance ``rtol``."""
    norms = np.linalg.norm(W, axis=0)
    keep = norms > rtol * max(norms.max(initial=0.0), 1e-300)
    s = np.linalg.svd(W[:, keep] / norms[keep], compute_uv=False)
    return int(np.sum(s > rtol * s[0])) if s.size else 0
