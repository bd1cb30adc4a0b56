"""Loop-closure kinematics of a closed-loop robot: passive joints from the actuated ones.

The robot is the tree of its ``[[frames]]`` plus, per loop, a cut frame ``k`` (with the cut joint's
variable) and a closing frame ``k + B`` ([KK1986]; [KD2002] sec. 7.3; see
:mod:`symoro_gen.description.loops`). With ``x = (q_a, q_p)`` all joint variables (the actuated tree
joints ``q_a``; the passive tree joints and the cut joints ``q_p``), the loops are closed when

    Phi(x) = [p_k - p_{k+B} ;  1/2 sum_i (u_i(k+B) x u_i(k))]  = 0   for each loop      (geometric)

(positions of the frame origins in frame 0, and the orientation error of the two frames' axes
``u_i``). Its velocity form is the constraint Jacobian ``A(x) = [A_a A_p]`` (the relative twist of the
two frames, ``A xdot = [v_k - v_{k+B}; w_k - w_{k+B}] = 0``), and its time derivative the acceleration
constraint ``A xddot + b(x, xdot) = 0`` with ``b`` the relative acceleration at ``xddot = 0``
([KD2002] sec. 7.3 and 10.x: kinematic constraint equations of closed loops). Hence

    q_p    : Newton's method on Phi(q_a, q_p) = 0 (Gauss-Newton steps  dq_p = -A_p^+ Phi)
    qd_p   = -A_p^+ A_a qd_a                  (= G_p qd_a)
    qdd_p  = -A_p^+ (A_a qdd_a + b)

with ``A_p^+`` the least-squares inverse (a planar loop gives only 3 independent equations of the 6;
the others vanish identically): the solution is exact whenever the passive joints are determined
(``A_p`` of full column rank, checked at the reference configuration; the residual is checked at
every sample).

The assembly mode (for a parallelogram: parallel or crossed) is the one of the reference
configuration (``[loop_reference]`` of the robot file, zeros by default): the actuated joints are
moved along a straight line from the reference to each requested configuration (a homotopy, in steps
of at most ``0.1`` rad or m) and Newton's method follows the solution. A configuration that this
path cannot reach without crossing a singular configuration raises :class:`ClosureError`.

Coupled (mimic) joints (``q_m = k q_s + c``, :class:`~symoro_gen.description.model.Coupling`) add one
linear row per coupling to ``Phi`` (``x_m - k x_s - c``), to ``A`` (constant: ``+1`` at ``m``, ``-k`` at
``s``) and nothing to ``b``. A robot with couplings and no loop needs no Newton solve: its closure is
``q_tree = A q_a + b`` with constant ``A`` (``G = A``), evaluated directly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..description.mdh import joint_sign, row_values, transform
from ..description.model import FIXED, PRISMATIC, REVOLUTE, MdhRow, RobotDescription
from ..errors import ModelError

__all__ = ["ClosureError", "LoopKinematics", "ClosedState", "independent_columns", "sample_states"]


class ClosureError(ModelError):
    """The loops cannot be closed (out of reach, or a singular configuration on the way)."""


@dataclass(frozen=True, eq=False)
class ClosedState:
    """Closed-loop state of N samples.

    Attributes
    ----------
    q, dq, ddq : (N, n_tree)
        Every tree joint (actuated and passive), tree joint order.
    q_cut : (N, B)
        The cut joints' variables.
    G : (N, n_tree, n_a)
        ``d q_tree / d q_a`` (actuated rows are the identity).
    residual : (N,)
        Largest constraint residual ``|Phi|`` (m and rad) after the solve.
    """

    q: NDArray[np.float64]
    dq: NDArray[np.float64]
    ddq: NDArray[np.float64]
    q_cut: NDArray[np.float64]
    G: NDArray[np.float64]
    residual: NDArray[np.float64]


class LoopKinematics:
    """Constraint solve of a robot description with ``[[loops]]``.

    Parameters
    ----------
    robot : RobotDescription
        With at least one loop.
    tol : float
        Target of the constraint residual (m, rad) of Newton's method.
    """

    def __init__(self, robot: RobotDescription, *, tol: float = 1e-13, step: float = 0.1):
        if not robot.constrained:
            raise ModelError(f"{robot.name}: no [[loops]] and no coupled (mimic) joint: not a closed-loop robot")
        self.robot = robot
        self.tol, self.step = tol, step
        subs = robot.geometry_subs()
        tree = [r for r in robot.rows]
        cuts = [lp.cut for lp in robot.loops]
        closes = [lp.close for lp in robot.loops]
        self.frames: list[MdhRow] = tree + cuts + closes
        self.tree_joints = [r.j for r in robot.joints]
        self.actuated = [r.j for r in robot.actuated]
        self.passive = [r.j for r in robot.joints if r.mu == 0] + [c.j for c in cuts]
        self.variables = self.tree_joints + [c.j for c in cuts]  # x order
        self._col = {j: i for i, j in enumerate(self.variables)}
        self._ia = np.array([self._col[j] for j in self.actuated], int)
        self._ip = np.array([self._col[j] for j in self.passive], int)
        self._sign = {r.j: joint_sign(r) for r in self.frames if r.sigma != FIXED}
        self._subs = subs
        self._fixed = {r.j: transform(*row_values(r, subs)) for r in self.frames if r.sigma == FIXED}
        # per frame, once (no sympy below): T(ant, j) = [C Rot(z, theta) | p0 + r C e_z] with
        # C = Rot(z, gamma) Rot(x, alpha) and p0 = Rot(z, gamma) [d, 0, b] (the MDH transform of mdh.py)
        self._local: dict[int, tuple[NDArray[np.float64], NDArray[np.float64], float, float]] = {}
        for r in self.frames:
            if r.sigma != FIXED:
                g, b, al, d, th, rr = row_values(r, subs, 0.0)
                T0 = transform(g, b, al, d, 0.0, 0.0)
                self._local[r.j] = (T0[:3, :3], T0[:3, 3], float(th), float(rr))
        self.pairs = [(lp.cut.j, lp.close.j) for lp in robot.loops]
        # couplings x_m = k x_s + c: (column of m, column of s, k, c)
        self.couplings = [(self._col[c.joint], self._col[c.source], float(c.multiplier), float(c.offset))
                          for c in robot.couplings]
        self._nrows = 6 * len(self.pairs) + len(self.couplings)
        # frames on the path of each frame down to the base (for the Jacobian)
        ant = {r.j: r.ant for r in self.frames}
        self._ant = ant
        self._reference = self._reference_state()

    # ---------------------------------------------------------------------------------------------
    @property
    def n_a(self) -> int:
        return len(self.actuated)

    def _poses(self, x: NDArray[np.float64]) -> dict[int, tuple[NDArray[np.float64], NDArray[np.float64]]]:
        """Rotation (N,3,3) and origin (N,3) in frame 0 of every frame, for variables x (N, nx).

        ``R(0, j) = R(0, a) C Rot(z, theta)`` and ``p(0, j) = p(0, a) + R(0, a) (p0 + r C e_z)``, written with
        products by the constant ``C`` (matrix products of (3N, 3) blocks) and elementwise terms."""
        N = x.shape[0]
        out = {0: (np.broadcast_to(np.eye(3), (N, 3, 3)), np.zeros((N, 3)))}
        for r in self.frames:
            Ra, pa = out[r.ant]
            if r.sigma == FIXED:
                T = self._fixed[r.j]
                out[r.j] = ((Ra.reshape(-1, 3) @ T[:3, :3]).reshape(N, 3, 3), pa + (Ra.reshape(-1, 3) @ T[:3, 3]).reshape(N, 3))
                continue
            C, p0, th, rr = self._local[r.j]
            v = self._sign[r.j] * x[:, self._col[r.j]]
            M = (Ra.reshape(-1, 3) @ C).reshape(N, 3, 3)  # R(0, a) C
            if r.sigma == PRISMATIC:
                R = (Ra.reshape(-1, 3) @ (C @ np.array([[np.cos(th), -np.sin(th), 0.0],
                                                        [np.sin(th), np.cos(th), 0.0], [0.0, 0.0, 1.0]]))
                     ).reshape(N, 3, 3)
                p = pa + (Ra.reshape(-1, 3) @ p0).reshape(N, 3) + M[:, :, 2] * (rr + v)[:, None]
            else:
                ct, st = np.cos(th + v)[:, None], np.sin(th + v)[:, None]
                R = np.empty((N, 3, 3))
                R[:, :, 0] = M[:, :, 0] * ct + M[:, :, 1] * st
                R[:, :, 1] = M[:, :, 1] * ct - M[:, :, 0] * st
                R[:, :, 2] = M[:, :, 2]
                p = pa + (Ra.reshape(-1, 3) @ p0).reshape(N, 3) + M[:, :, 2] * rr
            out[r.j] = (R, p)
        return out

    def _path(self, f: int) -> list[int]:
        out = []
        while f:
            out.append(f)
            f = self._ant[f]
        return out

    def residual(self, x: NDArray[np.float64]) -> NDArray[np.float64]:
        """``Phi(x)``, shape (N, 6 B)."""
        P = self._poses(x)
        return self._residual(P, x)

    def _residual(self, P, x: NDArray[np.float64]) -> NDArray[np.float64]:
        parts = []
        for k, c in self.pairs:
            (Rk, pk), (Rc, pc) = P[k], P[c]
            parts.append(pk - pc)
            parts.append(0.5 * np.cross(Rc, Rk, axis=1).sum(axis=2))  # sum over the three axes (d/dt: w_k - w_c)
        for im, i_s, k_, c_ in self.couplings:
            parts.append((x[:, im] - k_ * x[:, i_s] - c_)[:, None])
        return np.concatenate(parts, axis=1)

    def _jacobian(self, P) -> NDArray[np.float64]:
        """Constraint Jacobian ``A`` (N, 6B, nx): the relative twist of the two frames per unit xdot."""
        N = next(iter(P.values()))[1].shape[0]
        A = np.zeros((N, self._nrows, len(self.variables)))
        for r, (im, i_s, k_, _) in enumerate(self.couplings, start=6 * len(self.pairs)):
            A[:, r, im] = 1.0
            A[:, r, i_s] -= k_
        for li, (k, c) in enumerate(self.pairs):
            for f, s in ((k, 1.0), (c, -1.0)):
                pf = P[f][1]
                for m in self._path(f):
                    row = self._frame(m)
                    if row.sigma == FIXED:
                        continue
                    z = P[m][0][:, :, 2] * self._sign[m]
                    i = self._col[m]
                    if row.sigma == REVOLUTE:
                        A[:, 6 * li:6 * li + 3, i] += s * np.cross(z, pf - P[m][1])
                        A[:, 6 * li + 3:6 * li + 6, i] += s * z
                    else:
                        A[:, 6 * li:6 * li + 3, i] += s * z
        return A

    def _frame(self, j: int) -> MdhRow:
        return self.frames[j - 1]

    def _bias(self, x, xd, P) -> NDArray[np.float64]:
        """Relative acceleration of the loop frames at ``xddot = 0``: ``b`` of ``A xddot + b = 0``, (N, 6B)."""
        N = x.shape[0]
        w = {0: np.zeros((N, 3))}
        v = {0: np.zeros((N, 3))}
        wd = {0: np.zeros((N, 3))}
        a = {0: np.zeros((N, 3))}
        for r in self.frames:
            j, p = r.j, r.ant
            rr = P[j][1] - P[p][1]
            w[j], v[j], wd[j] = w[p].copy(), v[p] + np.cross(w[p], rr), wd[p].copy()
            a[j] = a[p] + np.cross(wd[p], rr) + np.cross(w[p], np.cross(w[p], rr))
            if r.sigma == FIXED:
                continue
            u = P[j][0][:, :, 2] * (self._sign[j] * xd[:, self._col[j]])[:, None]  # axis * joint rate
            if r.sigma == REVOLUTE:
                w[j] = w[j] + u
                wd[j] = wd[j] + np.cross(w[p], u)
            elif r.sigma == PRISMATIC:
                v[j] = v[j] + u
                a[j] = a[j] + 2 * np.cross(w[p], u)
        parts = []
        for k, c in self.pairs:
            parts += [a[k] - a[c], wd[k] - wd[c]]
        parts.append(np.zeros((N, len(self.couplings))))  # linear couplings: no velocity-product term
        return np.concatenate(parts, axis=1)

    @staticmethod
    def _lsq(Ap: NDArray[np.float64], rhs: NDArray[np.float64]) -> NDArray[np.float64]:
        """Least-squares solution of ``Ap y = rhs`` per sample (``Ap`` (N, m, p) of full column rank; ``rhs``
        (N, m) or (N, m, k)), by the normal equations (a batched p x p solve, much faster than a batched
        SVD) with one step of iterative refinement; a singular sample is caught by the residual check."""
        vec = rhs.ndim == 2
        b = rhs[..., None] if vec else rhs
        AtA = np.einsum("nmi,nmj->nij", Ap, Ap)
        try:
            y = np.linalg.solve(AtA, np.einsum("nmi,nmk->nik", Ap, b))
            y += np.linalg.solve(AtA, np.einsum("nmi,nmk->nik", Ap, b - Ap @ y))  # one refinement step
        except np.linalg.LinAlgError:  # an exactly singular sample: minimum-norm solution
            y = np.linalg.pinv(Ap, rcond=1e-12) @ b
        return y[..., 0] if vec else y

    # ---------------------------------------------------------------------------------------------
    def _newton(self, x: NDArray[np.float64], iters: int = 30) -> NDArray[np.float64]:
        for _ in range(iters):
            P = self._poses(x)
            e = self._residual(P, x)
            if np.max(np.abs(e), initial=0.0) < self.tol:
                break
            dx = self._lsq(self._jacobian(P)[:, :, self._ip], e)
            x = x.copy()
            x[:, self._ip] -= dx
        return x

    def _reference_state(self) -> NDArray[np.float64]:
        x0 = np.array([[self.robot.loop_reference.get(f"q{j}", 0.0) for j in self.variables]])
        x = self._newton(x0, iters=60)
        P = self._poses(x)
        e = float(np.max(np.abs(self._residual(P, x))))
        sv = np.linalg.svd(self._jacobian(P)[0][:, self._ip], compute_uv=False)
        if e > 1e-9 or sv[len(self._ip) - 1] < 1e-6 * max(1.0, sv[0]):
            what = (f"the loops do not close from it (residual {e:.2g})" if e > 1e-9 else
                    "the passive joints are not determined there (singular constraint Jacobian)")
            raise ClosureError(f"{self.robot.file}, [loop_reference]: the reference configuration is not usable: "
                               f"{what}; give a closed, non-singular assembly (q<j> = value of each joint, "
                               f"passive and cut joints included)")
        return x[0]

    @property
    def linear(self) -> bool:
        """True when the closure is linear by construction (couplings only, no loop): ``x = A q_a + b``."""
        return not self.pairs

    def _linear_map(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """``(A, b)`` of ``x = A q_a + b`` for a robot with couplings and no loop (x order, actuated columns)."""
        A = np.zeros((len(self.variables), self.n_a))
        b = np.zeros(len(self.variables))
        A[self._ia, np.arange(self.n_a)] = 1.0
        for im, i_s, k_, c_ in self.couplings:
            A[im], b[im] = k_ * A[i_s], k_ * b[i_s] + c_
        return A, b

    def solve_positions(self, q_a) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """All variables ``x`` (N, nx) and the residual (N,) for actuated positions ``q_a`` (N, n_a)."""
        q_a = np.atleast_2d(np.asarray(q_a, float))
        N = q_a.shape[0]
        if self.linear:
            A, b = self._linear_map()
            x = q_a @ A.T + b
            return x, np.max(np.abs(self._residual({}, x)), axis=1, initial=0.0) if N else np.zeros(0)
        ref = self._reference
        x = np.tile(ref, (N, 1))
        d = q_a - ref[self._ia]
        nsteps = max(1, int(np.ceil(np.max(np.abs(d), initial=0.0) / self.step)))
        for s in range(1, nsteps + 1):
            # first-order predictor along the path (x_p += G_p dq_a), then Newton's corrector
            A = self._jacobian(self._poses(x))
            x[:, self._ip] -= self._lsq(A[:, :, self._ip], A[:, :, self._ia] @ (d / nsteps)[..., None])[..., 0]
            x[:, self._ia] = ref[self._ia] + d * (s / nsteps)
            x = self._newton(x, iters=30 if s == nsteps else 8)
        res = np.max(np.abs(self.residual(x)), axis=1) if N else np.zeros(0)
        return x, res

    def solve(self, q_a, dq_a, ddq_a, *, check: bool = True) -> ClosedState:
        """Positions, velocities, accelerations of every tree joint for actuated ``q_a, dq_a, ddq_a`` (N, n_a)."""
        q_a, dq_a, ddq_a = (np.atleast_2d(np.asarray(v, float)) for v in (q_a, dq_a, ddq_a))
        if self.linear:  # couplings only: G constant, no bias term
            A, _ = self._linear_map()
            x, res = self.solve_positions(q_a)
            nt, N = len(self.tree_joints), q_a.shape[0]
            return ClosedState(q=x[:, :nt], dq=dq_a @ A[:nt].T, ddq=ddq_a @ A[:nt].T, q_cut=x[:, nt:],
                               G=np.broadcast_to(A[:nt], (N, nt, self.n_a)).copy(), residual=res)
        x, res = self.solve_positions(q_a)
        P = self._poses(x)
        A = self._jacobian(P)
        Ap = A[:, :, self._ip]
        Gp = -self._lsq(Ap, A[:, :, self._ia])  # (N, np, na)
        N, nx = x.shape
        xd = np.zeros((N, nx))
        xd[:, self._ia] = dq_a
        xd[:, self._ip] = np.einsum("npa,na->np", Gp, dq_a)
        b = self._bias(x, xd, P)
        xdd = np.zeros((N, nx))
        xdd[:, self._ia] = ddq_a
        xdd[:, self._ip] = -self._lsq(Ap, np.einsum("nka,na->nk", A[:, :, self._ia], ddq_a) + b)
        if check:
            bad = np.flatnonzero(~(res < 1e-8))
            if bad.size:
                i = int(bad[0])
                raise ClosureError(f"{self.robot.name}: the loops do not close at sample {i} "
                                   f"(q_a = {np.array2string(q_a[i], precision=4)}, residual {res[i]:.2g}; "
                                   f"{bad.size} sample(s)): out of reach or past a singular configuration "
                                   "from the reference assembly")
        G = np.zeros((N, nx, self.n_a))
        G[:, self._ia, np.arange(self.n_a)] = 1.0
        G[:, self._ip, :] = Gp
        nt = len(self.tree_joints)
        return ClosedState(q=x[:, :nt], dq=xd[:, :nt], ddq=xdd[:, :nt], q_cut=x[:, nt:], G=G[:, :nt, :],
                           residual=res)


def independent_columns(M: NDArray[np.float64], tol: float) -> NDArray[np.float64]:
    """Distance of each column of ``M`` (columns scaled to unit norm, zero columns excluded by the caller)
    from the span of the **independent** columns before it, in order: a column at distance ``<= tol``
    depends on earlier ones (the regrouping order of [G1991]).

    Gram-Schmidt with re-orthogonalisation against the independent columns only: a QR factorisation
    without pivoting would let a dependent column consume a row direction (its Householder reflector is
    built from rounding noise), after which a later independent column can look dependent when the
    matrix has few rows (a coupled joint's energy matrix)."""
    basis: list[NDArray[np.float64]] = []
    out = np.zeros(M.shape[1])
    for i in range(M.shape[1]):
        v = np.array(M[:, i], float)
        for _ in range(2):
            for b in basis:
                v -= (b @ v) * b
        d = float(np.linalg.norm(v))
        out[i] = d
        if d > tol:
            basis.append(v / d)
    return out


def sample_states(kin: LoopKinematics, n: int, seed: int = 0, scale: float = 1.0) -> tuple[NDArray[np.float64], ...]:
    """``n`` random actuated states around the reference assembly: positions within ``0.5 scale`` rad
    (``0.05 scale`` m for prismatic joints) of it, velocities and accelerations standard normal.
    Deterministic."""
    rng = np.random.default_rng(seed)
    ref = kin._reference[kin._ia]
    span = scale * np.array([0.05 if r.sigma == PRISMATIC else 0.5 for r in kin.robot.actuated])
    q = ref + rng.uniform(-1, 1, (n, kin.n_a)) * span
    return q, rng.standard_normal((n, kin.n_a)), rng.standard_normal((n, kin.n_a))
