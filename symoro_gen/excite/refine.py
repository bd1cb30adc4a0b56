"""The SDP refinement of a design on the TRUE condition number (sequential semidefinite programming, cvxpy +
Clarabel): :func:`refine_excitation`, its settings (:class:`RefineSettings`) and the information matrix linearised
in the design (:class:`Linearisation`)."""
from __future__ import annotations

import dataclasses
import importlib.util
import math
import warnings
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..model import IdentificationModel
from .bases import basis_eval, dense_times
from .criterion import COND_DEGENERATE, casadi_regressor, stacked_cond
from .designs import inside_limits
from .limits import ExcitationError, Limits, check_limits, floor_linearisation, load_casadi

__all__ = ["REFINE_ITERATIONS", "REFINE_RATE", "Linearisation", "RefineSettings", "has_cvxpy", "refine_excitation"]

#: SDP iterations of ``excite --effort thorough`` (and of the command's default before the efforts: on the LWR4 spline
#: bench, 20 iterations took the IPOPT optimum from 29.9 to 25.1, 40 to 24.9; docs/excitation.md)
REFINE_ITERATIONS = 20
#: the SDP refinement's grid: at most this many samples per second of the output (every 10th of a 1-kHz output)
REFINE_RATE = 100.0


def has_cvxpy() -> bool:
    """cvxpy and Clarabel are installed (the ``physical`` extra): the SDP refinement can run."""
    return importlib.util.find_spec("cvxpy") is not None and importlib.util.find_spec("clarabel") is not None


@dataclass(frozen=True)
class RefineSettings:
    """Settings of :func:`refine_excitation`, checked when made.

    Attributes
    ----------
    iterations : int
        SDPs at most (>= 0).
    margin : float
        Fraction by which the limits are tightened (``0 <= margin < 1``).
    delta, delta_min, delta_max : float
        The trust region's initial radius, the radius below which the refinement stops, and its largest radius
        (fractions of the change of a coefficient that spans a full limit).
    block : int
        Eigenvectors of each extreme cluster the SDP sees at most (>= 1).
    """

    iterations: int = 30
    margin: float = 0.01
    delta: float = 0.05
    delta_min: float = 1e-4
    delta_max: float = 0.5
    block: int = 16

    def __post_init__(self) -> None:
        if self.iterations < 0:
            raise ExcitationError(f"--refine {self.iterations}: must be a number of iterations >= 0")
        if not 0.0 <= self.margin < 1.0:
            raise ExcitationError(f"refinement margin {self.margin:g}: must be in [0, 1)")
        if not (self.delta > 0 and self.delta_min > 0 and self.delta_max >= self.delta_min):
            raise ExcitationError(f"refinement trust region delta {self.delta:g}, delta_min {self.delta_min:g}, "
                                  f"delta_max {self.delta_max:g}: must be positive, delta_max >= delta_min")
        if self.block < 1:
            raise ExcitationError(f"refinement block {self.block}: must be >= 1")


class Linearisation:
    """``M(X) = W^T W / N`` of the base regressor stacked over the samples ``t`` and its derivative
    ``dM/dX`` (the design enters ``q, dq, ddq`` linearly through the basis matrices), from the generated
    CasADi regressor and its Jacobian with respect to ``(q, dq, ddq)`` (one sample at a time, mapped
    over chunks of samples); with ``chi_b``, the torques ``W chi_b`` and their derivative too."""

    def __init__(self, model: IdentificationModel, basis, t: np.ndarray, chi_b: np.ndarray | None = None,
                 chunk: int = 100):
        ca = load_casadi()
        self.n, self.nb, self.m = int(model.N_JOINTS), len(model.BASE_NAMES), int(basis.m)
        n = self.n
        qs, dqs, ddqs = ca.MX.sym("q", n), ca.MX.sym("dq", n), ca.MX.sym("ddq", n)
        Y = casadi_regressor(model)(qs, dqs, ddqs)
        J = ca.jacobian(ca.vec(Y), ca.vertcat(qs, dqs, ddqs))  # (n nb, 3n), vec column-major
        self.P, self.D, self.A = basis.matrices(t)
        self.N = len(t)
        self.chunk = int(min(chunk, self.N))
        # dense outputs evaluated straight into NumPy arrays (a FunctionBuffer): converting the CasADi matrices
        # element by element (DM.full) cost half of every linearisation
        self.f = ca.Function("YJ", [qs, dqs, ddqs], [ca.densify(Y), ca.densify(J)]).map(self.chunk)
        c, nb = self.chunk, self.nb
        self._args = [np.zeros(n * c) for _ in range(3)]
        self._Y, self._J = np.zeros(n * nb * c), np.zeros(n * nb * 3 * n * c)
        self._buf, self._eval = self.f.buffer()
        for i, a in enumerate(self._args):
            self._buf.set_arg(i, a.data)
        self._buf.set_res(0, self._Y.data)
        self._buf.set_res(1, self._J.data)
        self.chi_b = None if chi_b is None else np.asarray(chi_b, float)

    def _evaluate(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """At the ``c`` samples ``q, dq, ddq`` (c, n): ``Yt[s, a, r] = Y_s[r, a]`` (c, nb, n) and
        ``Jt[s, v, b, r] = dY_s[r, b] / dz_v`` (c, 3n, nb, n), ``z = (q, dq, ddq)`` (views of the output buffers)."""
        n, nb, c = self.n, self.nb, self.chunk
        for a, z in zip(self._args, (q, dq, ddq)):
            a[:] = z.reshape(-1)  # the mapped inputs are (n, c), column-major: sample after sample
        self._eval()
        # column-major outputs: Y (n, nb c), column s nb + b; J (n nb, 3n c), row b n + r, column s 3n + v
        return self._Y.reshape(c, nb, n), self._J.reshape(c, 3 * n, nb, n)

    def __call__(self, X: np.ndarray):
        """``M`` (nb, nb), ``dM`` (m, n, nb, nb) (``dM[k, j] = dM/dX[k, j]``) and, with ``chi_b``, the
        torques (N, n) and their derivative (N, n, m, n)."""
        n, nb, m, N, c = self.n, self.nb, self.m, self.N, self.chunk
        q, dq, ddq = self.P @ X, self.D @ X, self.A @ X
        M = np.zeros((nb, nb))
        G = np.zeros((m, n, nb, nb))
        with_tau = self.chi_b is not None
        tau, dtau = (np.zeros((N, n)), np.zeros((N, n, m, n))) if with_tau else (np.zeros((0, n)), np.zeros((0, n, m, n)))
        for s0 in range(0, N, c):
            idx = np.arange(s0, s0 + c)
            valid = idx < N
            idx = np.minimum(idx, N - 1)  # the last chunk is padded by repeating the last sample
            Yc, Jc = self._evaluate(q[idx], dq[idx], ddq[idx])
            Yt, Jt = Yc[valid], Jc[valid]  # (S, nb, n), (S, 3n, nb, n)
            M += np.einsum("sar,sbr->ab", Yt, Yt)
            H = np.matmul(Yt[:, None], Jt.transpose(0, 1, 3, 2))  # (S, 3n, nb, nb): Y_s^T dY_s/dz_v
            rows = idx[valid]
            for w, B in enumerate((self.P, self.D, self.A)):
                Hw = H[:, w * n:(w + 1) * n].reshape(len(rows), n * nb * nb)
                G += (B[rows].T @ Hw).reshape(m, n, nb, nb)
            if with_tau:
                tau[rows] = Yt.transpose(0, 2, 1) @ self.chi_b
                dT = Jt.transpose(0, 1, 3, 2) @ self.chi_b  # (S, 3n, n): d tau_s / d z_v
                for w, B in enumerate((self.P, self.D, self.A)):
                    # dtau[s, r, k, j] += B[s, k] dT[s, w n + j, r]
                    dtau[rows] += np.einsum("sk,sjr->srkj", B[rows], dT[:, w * n:(w + 1) * n])
        dM = (G + G.transpose(0, 1, 3, 2)) / N
        return M / N, dM, (tau if with_tau else None), (dtau if with_tau else None)


def _cond2(M: np.ndarray) -> float:
    ev = np.linalg.eigvalsh(M)
    return float(ev[-1] / ev[0]) if ev[0] > 0 else math.inf


def _reachable(reach: np.ndarray, room: np.ndarray) -> np.ndarray:
    """The rows a step can break: those whose largest change within the trust region (``reach``) is not
    safely below their room to the bound (``room >= 0``; a relative 1e-9 kept for rounding)."""
    return ~(reach * (1.0 + 1e-9) < room)


class _SdpStep:
    """The pieces of :func:`refine_excitation` that stay fixed over its iterations: the linearisation, the
    constraint grids (``t_con`` and a spline's knots), the scale of the trust region per coefficient, and the
    checks of a candidate design (its true cond and its limits on the output and on ``check_times``)."""

    def __init__(self, model: IdentificationModel, basis, limits: Limits, t_out: np.ndarray, t_con: np.ndarray,
                 margin: float, cb: np.ndarray | None, check_times: np.ndarray):
        self.model, self.basis, self.limits, self.t_out, self.cb = model, basis, limits, t_out, cb
        self.n, self.nb, self.m = limits.n, len(model.BASE_NAMES), basis.m
        self.lin = Linearisation(model, basis, t_out, cb)
        self.check_times = check_times
        self.lim = limits.shrunk(margin)
        knots = getattr(basis, "knots", None)
        self.Pc, self.Dc, self.Ac = basis.matrices(t_con if knots is None else
                                                   np.union1d(t_con, np.clip(knots, 0.0, t_out[-1])))
        self.Do = basis.matrices(t_out)[1]
        with np.errstate(divide="ignore"):
            h = (limits.q_max - limits.q_min) / 2
            scale = np.minimum.reduce([h[None] / np.abs(self.Pc).max(0)[:, None],
                                       limits.dq_max[None] / np.abs(self.Dc).max(0)[:, None],
                                       limits.ddq_max[None] / np.abs(self.Ac).max(0)[:, None]])  # (m, n)
        self.scale = np.where(np.isfinite(scale), scale, 0.0)
        self.heights_jac = None if self.lim.workspace is None else floor_linearisation(self.lim.workspace)

    def feasible(self, Xc: np.ndarray) -> bool:
        q, dq, ddq = basis_eval(self.basis, Xc, self.t_out)
        tau = None if self.cb is None else np.asarray(self.model.regressor(q, dq, ddq)) @ self.cb
        return bool(check_limits(self.limits, q, dq, ddq, tau)["ok"]
                    and inside_limits(self.basis, self.limits, Xc, self.check_times))

    def cond2(self, Xc: np.ndarray) -> float:
        return stacked_cond(self.model, *basis_eval(self.basis, Xc, self.t_out)) ** 2

    def compress(self, dM: np.ndarray, U: np.ndarray) -> np.ndarray:
        """``U^T dM_i U`` of every design variable i, as the columns of a (k^2, m n) matrix."""
        m, n, nb, k = self.m, self.n, self.nb, U.shape[1]
        R = (dM.reshape(m * n * nb, nb) @ U).reshape(m * n, nb, k)
        return np.einsum("ax,iay->ixy", U, R).reshape(m * n, k * k).T

    def constraints(self, cp: Any, d: Any, Dm: Any, X: np.ndarray, lin_at_X: tuple, delta: float) -> list:
        """The SDP's linear constraints on the step ``d`` (``Dm``: the same as an (m, n) matrix) from ``X``.

        A row that no step within the trust region can break is left out (:func:`_reachable`: the largest change
        of the row over the box ``|d| <= delta scale`` is below its room): the feasible set is the same, the SDP
        smaller (most rows of a design far from its limits)."""
        lim, limits, Pc = self.lim, self.limits, self.Pc
        _, _, tau0, dtau = lin_at_X
        box = delta * self.scale  # (m, n): the trust region
        cons = [cp.abs(d) <= box.reshape(-1)]
        for Bm, lo, hi in ((Pc, lim.q_min, lim.q_max), (self.Dc, -lim.dq_max, lim.dq_max),
                           (self.Ac, -lim.ddq_max, lim.ddq_max)):
            cur = Bm @ X
            up, down = np.maximum(hi - cur, 0.0), np.minimum(lo - cur, 0.0)
            reach = np.abs(Bm) @ box  # (t, n): the largest |Bm D| of each row within the box
            for j in range(self.n):
                ku, kd = _reachable(reach[:, j], up[:, j]), _reachable(reach[:, j], -down[:, j])
                if ku.any():
                    cons.append(Bm[ku] @ Dm[:, j] <= up[ku, j])
                if kd.any():
                    cons.append(Bm[kd] @ Dm[:, j] >= down[kd, j])
        if lim.passive:
            Cp, _, lo, hi = lim.passive_rows()
            cur = lim.passive_positions(Pc @ X)
            cons += [Pc @ Dm @ Cp.T <= np.maximum(hi - cur, 0.0), Pc @ Dm @ Cp.T >= np.minimum(lo - cur, 0.0)]
        if self.heights_jac is not None and lim.workspace is not None:  # the frame heights linearised: h + J (Pc D) >= z_min
            hz, Jz = self.heights_jac(Pc @ X)
            E = Pc @ Dm
            cons += [cp.sum(cp.multiply(Jz[:, f, :], E), axis=1) >= np.minimum(lim.workspace.z_min - hz[:, f], 0.0)
                     for f in range(hz.shape[1])]
        # the Coulomb columns sign(dq) are piecewise constant: the sign of every moving output sample is kept,
        # so that the linearisation holds (a velocity may halve towards zero, not cross it)
        dq_out = self.Do @ X
        for j in range(self.n):
            sg = np.sign(dq_out[:, j])
            room = np.abs(dq_out[:, j]) - 0.5 * np.minimum(np.abs(dq_out[:, j]), 0.01 * limits.dq_max[j])
            mv = (sg != 0) & _reachable(np.abs(self.Do) @ box[:, j], room)
            if mv.any():
                cons.append(cp.multiply(sg[mv], self.Do[mv] @ Dm[:, j]) >= -room[mv])
        if self.cb is not None and dtau is not None and tau0 is not None and lim.tau_max is not None:
            T = dtau.reshape(-1, self.m * self.n)
            cur = tau0.reshape(-1)
            tm = np.tile(lim.tau_max, len(self.t_out))
            up, down = np.maximum(tm - cur, 0.0), np.minimum(-tm - cur, 0.0)
            reach = np.abs(T) @ box.reshape(-1)
            ku, kd = _reachable(reach, up), _reachable(reach, -down)
            if ku.any():
                cons.append(T[ku] @ d <= up[ku])
            if kd.any():
                cons.append(T[kd] @ d >= down[kd])
        return cons

    def solve(self, X: np.ndarray, lin_at_X: tuple, c2: float, delta: float, block: int,
              rec: dict) -> tuple[np.ndarray | None, float]:
        """One Dinkelbach SDP from ``X``: the step (None when the SDP failed) and the decrease of ``cond^2`` it
        predicts; ``rec`` receives the SDP's status and the sizes of the two eigenvalue blocks."""
        import cvxpy as cp

        m, n = self.m, self.n
        M0, dM = lin_at_X[0], lin_at_X[1]
        # the eigenspaces of the two clusters (Overton 1992): the SDP sees M_lin compressed to the eigenvectors of
        # M(X) within a factor of 2 of lambda_max and of lambda_min (at most `block` each)
        w, Q = np.linalg.eigh(M0)
        top = np.flatnonzero(w >= 0.5 * w[-1])[-block:]
        bot = np.flatnonzero(w <= 2.0 * w[0])[:block]
        ku, kv = len(top), len(bot)
        rec["block"] = [ku, kv]
        if not (ku and kv and w[0] > 0):  # a singular M(X): no lambda_min block, nothing the SDP can scale by
            rec["status"] = "singular information matrix"
            return None, 0.0
        BU, BV = self.compress(dM, Q[:, top]) / w[-1], self.compress(dM, Q[:, bot]) / w[0]
        d = cp.Variable(m * n)
        smax, smin = cp.Variable(), cp.Variable()
        Dm = cp.reshape(d, (m, n), order="C")
        MU = np.diag(w[top] / w[-1]) + cp.reshape(BU @ d, (ku, ku), order="C")
        MV = np.diag(w[bot] / w[0]) + cp.reshape(BV @ d, (kv, kv), order="C")
        cons = [smax * np.eye(ku) - MU >> 0, MV - smin * np.eye(kv) >> 0]
        cons += self.constraints(cp, d, Dm, X, lin_at_X, delta)
        # Dinkelbach: lambda_max - rho lambda_min with rho = lambda_max / lambda_min at X, divided by lambda_max
        # (each block scaled by its own extreme eigenvalue, so the SDP's data are O(1)); 0 at D = 0
        prob = cp.Problem(cp.Minimize(smax - smin), cons)
        try:
            with warnings.catch_warnings():  # "solution may be inaccurate": the status is recorded, the step checked
                warnings.simplefilter("ignore", UserWarning)
                prob.solve(solver="CLARABEL")
            status = prob.status
        except cp.error.SolverError as e:  # pragma: no cover - numerical failure of the solver
            status = f"solver error: {e}"
        rec["status"] = status
        if d.value is None or status not in ("optimal", "optimal_inaccurate"):
            return None, 0.0
        lu = np.linalg.eigvalsh(np.diag(w[top]) + (BU @ d.value).reshape(ku, ku) * w[-1])[-1]
        lv = np.linalg.eigvalsh(np.diag(w[bot]) + (BV @ d.value).reshape(kv, kv) * w[0])[0]
        return np.asarray(d.value).reshape(m, n), float(c2 - (lu / lv if lv > 0 else math.inf))


def refine_excitation(model: IdentificationModel, basis, limits: Limits, X: np.ndarray, t_out: np.ndarray,
                      t_con: np.ndarray, settings: RefineSettings | None = None, *, chi_b=None, check_times=None,
                      progress=None, **options: Any) -> tuple[np.ndarray, list[dict]]:
    """Lower the TRUE condition number of a design by sequential semidefinite programming.

    The smooth power-mean criterion of the IPOPT stage is loose at the optimum of an eigenvalue problem,
    where the extreme eigenvalues of ``M = W^T W / N`` coalesce into clusters and ``cond`` is not
    differentiable (Overton 1992, "Large-scale optimization of eigenvalues", SIAM J. Optim. 2(1); Lewis
    & Overton 1996, "Eigenvalue optimization", Acta Numerica 5). Each iteration linearises the
    *matrix* ``M(X + D) ~ M(X) + sum_kj D_kj dM/dX_kj`` (not its eigenvalues, so that clusters are
    handled; :class:`Linearisation`, from the generated CasADi regressor) and minimises the ratio
    ``lambda_max / lambda_min`` of the linearised matrix by Dinkelbach's parametric form (Dinkelbach
    1967, "On nonlinear fractional programming", Management Science 13(7)): the convex SDP

        minimise  lambda_max(M_lin(D)) - rho lambda_min(M_lin(D)),   rho = cond(W)^2 at X

    with ``M_lin`` compressed to the invariant subspaces of the two clusters (the eigenvectors of ``M(X)``
    whose eigenvalues are within a factor of 2 of ``lambda_max``, resp. ``lambda_min``, at most ``block``
    each: Overton's active eigenspaces, which keep the SDP small for any number of base parameters),
    subject to the position, velocity and acceleration limits of ``X + D`` on the grid ``t_con`` (and the
    knots of a spline basis) (tightened by ``margin``; a bound the current design already exceeds is relaxed to its current
    value), the sign of every moving output velocity kept (the Coulomb columns ``sign(dq)`` are piecewise
    constant: a velocity may fall to half its value, not cross zero, so that the linearisation holds), with
    ``chi_b`` and ``limits.tau_max`` the linearised torque limits at the output samples, and the
    trust region ``|D_kj| <= delta s_kj`` (``s_kj``: the change of coefficient ``k`` alone that spans a
    full limit of joint ``j``). Solved by cvxpy with Clarabel. The step is accepted when the true cond
    on ``t_out`` decreases and every limit holds on ``t_out`` and on ``check_times`` (default: 10x denser
    than ``t_out``, and the knots: :func:`dense_times`); the radius follows the usual trust-region rule on the ratio of actual to predicted
    decrease (Conn, Gould & Toint 2000, "Trust-region methods", alg. 6.1.1). Stops after ``iterations``
    SDPs, when ``delta < delta_min`` or when the SDP predicts no decrease; not started on a degenerate design
    (cond above :data:`COND_DEGENERATE`: its smallest eigenvalues are rounding noise, their eigenspace undefined),
    whose final record says ``skipped``. ``progress(record)`` is called
    after each SDP (with the iteration's record).

    ``settings`` (:class:`RefineSettings`: ``iterations``, ``margin``, ``delta``, ``delta_min``, ``delta_max``,
    ``block``); any of its fields may be given as a keyword instead, e.g. ``iterations=5``.

    Returns the refined design (never of larger cond than ``X``) and the history of the iterations
    (``cond`` at the start of each, ``delta``, ``predicted`` and ``actual`` decrease of ``cond^2``,
    ``accepted``, ``status`` of the SDP).
    """
    cfg = dataclasses.replace(settings or RefineSettings(), **options)
    if not has_cvxpy():
        raise ExcitationError("the SDP refinement needs cvxpy and clarabel: pip install 'symoro-gen[physical]'")
    X = np.asarray(X, float).copy()
    cb = None if chi_b is None or limits.tau_max is None else np.asarray(chi_b, float)
    check_times = dense_times(t_out, float(t_out[-1]), basis) if check_times is None else check_times
    sdp = _SdpStep(model, basis, limits, t_out, t_con, cfg.margin, cb, check_times)
    history: list[dict] = []

    def record(rec: dict) -> None:
        history.append(rec)
        if progress is not None:
            progress(rec)

    delta = cfg.delta
    lin_at_X = sdp.lin(X)
    c2 = _cond2(lin_at_X[0])
    if int(cfg.iterations) > 0 and not c2 <= COND_DEGENERATE ** 2:
        # a numerically rank-deficient information matrix (e.g. limits that leave the joints no motion): its
        # smallest eigenvalues are rounding noise, so neither their eigenspace (the SDP's lambda_min block) nor the
        # ratio is defined; the design is returned as it is and reported degenerate by the caller
        history.append({"iteration": 0, "cond": math.sqrt(c2), "delta": delta, "final": True,
                        "skipped": f"degenerate design: cond above {COND_DEGENERATE:g}"})
        return X, history
    for it in range(int(cfg.iterations)):
        if delta < cfg.delta_min:
            break
        rec: dict = {"iteration": it, "cond": math.sqrt(c2), "delta": delta}
        D, pred = sdp.solve(X, lin_at_X, c2, delta, cfg.block, rec)
        if D is None:
            rec.update(accepted=False, predicted=0.0, actual=0.0)
            record(rec)
            delta /= 4
            continue
        rec["predicted"] = pred
        if not pred > 1e-8 * c2:
            rec.update(accepted=False, actual=0.0)
            record(rec)
            break  # the linearised problem sees no descent: a stationary point of the ratio
        Xn = X + D
        c2n = sdp.cond2(Xn)
        ok = sdp.feasible(Xn)
        actual = c2 - c2n
        rec["actual"] = actual
        rho = actual / pred
        accepted = bool(ok and actual > 0)
        rec["accepted"] = accepted
        record(rec)
        step = float(np.max(np.abs(D) / np.where(sdp.scale > 0, sdp.scale, 1.0)))
        if accepted:
            X = Xn
            lin_at_X = sdp.lin(X)
            c2 = _cond2(lin_at_X[0])
        if not ok or rho < 0.25:
            delta = 0.5 * min(delta, step)
        elif rho > 0.75 and step >= 0.99 * delta:
            delta = min(2 * delta, cfg.delta_max)
    history.append({"iteration": len(history), "cond": math.sqrt(c2), "delta": delta, "final": True})
    return X, history
