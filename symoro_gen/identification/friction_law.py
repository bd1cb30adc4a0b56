"""``identify`` with declared friction laws (the robot file's ``friction_law``, :mod:`symoro_gen.description.friction_law`).

A declared law replaces the ``FS<j>``, ``FV<j>`` columns of its joint by the law's columns
(:class:`LawDeclaredModel`): the magnitudes (``FS<j>``, ``FSS<j>`` = Fs - Fc of a Stribeck law, ``FV<j>``)
stay linear parameters of the IDIM fit ([GB-gains] eq. 16-22). The law's scale (``vs``, ``v`` or ``delta``)
is the only non-linear parameter: :func:`refine_scales` refines all declared scales at once by a
Gauss-Newton iteration on the separable least-squares problem (variable projection, Golub & Pereyra 1973,
"The differentiation of pseudo-inverses and nonlinear least squares problems whose variables separate"):
at the current scales the magnitudes (and every base parameter) are the weighted LS solution; the
Jacobian of the prediction is ``[W, dW/ds theta]``, the derivative column obtained by assembling the data
again at ``s (1 + h)`` (the same filtering and parallel decimation as ``W``, [GB-gains] eq. 14-15). The
scales move in ``log s`` (they stay positive), inside the ranges of the robot file, from the declared value;
a step that does not lower the weighted residual is halved. Rows are weighted per joint by ``1/sigma_j`` of
the first fit (WLS, [GB-gains] eq. 22). The standard deviations of the scales and of the magnitudes are those
of the linearised problem at the solution, ``sigma^2 (J^T J)^-1`` ([GB-gains] eq. 19-20 with the scale
column added).

Only the identification data are used (never the validation data). A declared law whose joint does not
move in them (its law columns are 0), or whose scale the data cannot see (the magnitude that carries it,
:data:`SCALED_MAGNITUDE`, within :data:`MIN_T` standard deviations of 0, or the scale's relative standard
deviation above :data:`MAX_REL_STD`), is reported and keeps its declared scale: it is not fitted silently.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from ..description.friction_law import SCALE_BOUNDS, FrictionLaw
from ..errors import IdentificationError
from ..model import IdentificationModel
from ..observations.assembly import assemble
from ..observations.fused import model_column_map
from ..observations.options import AssemblyOptions

__all__ = ["MAX_REL_STD", "JointColumns", "LawDeclaredModel", "LawSplicedModel", "ScaleFit", "declared_laws",
           "refine_scales"]

#: a scale whose relative standard deviation exceeds this is "not determined by the data"
MAX_REL_STD = 0.5
#: the magnitude that carries each law's scale: its scale is seen only if this magnitude is significant
SCALED_MAGNITUDE = {"stribeck": "FSS", "tanh": "FS", "power": "FV", "lugre": "FSS"}
#: what a dynamic law's entry says: the rows cannot see its pre-sliding regime
SLIDING_NOTE = ("sliding part only: the pre-sliding regime (sigma0) lasts milliseconds after each reversal and "
                "the filtered, decimated rows (100-200 Hz) do not resolve it (docs/friction-dynamic.md)")
#: ... by this many standard deviations
MIN_T = 3.0
#: relative step of the finite-difference derivative in the scale
FD_STEP = 1e-4
#: Gauss-Newton iterations at most, and the relative change of the scales that stops them
MAX_ITER = 12
TOL = 1e-5


@dataclass(frozen=True)
class ScaleFit:
    """The identified (or kept) scale of one declared law.

    Attributes
    ----------
    law : FrictionLaw
        As declared (``law.scale`` is the declared value).
    joint : int
        0-based model joint.
    scale, std : float
        Identified scale and its standard deviation (``std`` is NaN when the scale was not fitted; both
        NaN for a law without scale, Dahl).
    fitted : bool
        False when the data cannot see the law (``note`` says why): ``scale`` is then the declared value.
    magnitudes, magnitude_std : mapping str -> float
        The law's magnitudes (``FS<j>``, ``FSS<j>``, ``FV<j>``) with the scale free (its uncertainty included).
    iterations : int
    note : str
    """

    law: FrictionLaw
    joint: int
    scale: float
    std: float
    fitted: bool
    magnitudes: Mapping[str, float]
    magnitude_std: Mapping[str, float]
    iterations: int = 0
    note: str = ""

    def to_dict(self) -> dict:
        def num(x: float):
            return float(x) if math.isfinite(x) else None
        return {"frame": self.law.frame, "joint": self.joint + 1, "kind": self.law.kind,
                "scale_name": self.law.scale_name, "declared": self.law.scale, "scale": num(self.scale),
                "presliding": dict(self.law.presliding), "sliding_part_only": self.law.dynamic,
                "std": num(self.std), "fitted": self.fitted, "iterations": self.iterations,
                "magnitudes": {k: num(v) for k, v in self.magnitudes.items()},
                "magnitude_std": {k: num(v) for k, v in self.magnitude_std.items()}, "note": self.note}

    def summary(self) -> str:
        nm = self.law.scale_name
        head = f"  joint {self.joint + 1} (frame {self.law.frame}): {self.law.kind}, "
        if nm is None:
            mags = ", ".join(f"{k} = {v:.4g} \u00b1 {self.magnitude_std.get(k, math.nan):.2g}"
                             for k, v in self.magnitudes.items())
            return head + f"{mags}; {self.note}"
        if not self.fitted:
            return head + f"{nm} = {self.scale:.4g} as declared, not fitted: {self.note}"
        mags = ", ".join(f"{k} = {v:.4g} \u00b1 {self.magnitude_std.get(k, math.nan):.2g}"
                         for k, v in self.magnitudes.items())
        return head + (f"{nm} = {self.scale:.4g} \u00b1 {self.std:.2g} (declared {self.law.scale:.4g}, "
                       f"{self.iterations} Gauss-Newton steps); {mags}")


@dataclass(frozen=True)
class JointColumns:
    """Columns spliced into one joint's rows of a regressor by :class:`LawSplicedModel`.

    Attributes
    ----------
    joint : int
        0-based model joint whose rows receive the columns (the other joints' rows get 0).
    names : tuple of str
        Names of the new columns, appended to ``BASE_NAMES`` in order.
    columns : callable
        ``columns(dq_j) -> (N, len(names))`` at the joint's velocities ``dq_j`` (N,).
    drop : tuple of str
        Columns of the wrapped model this law replaces (``FS<j>``, ``FV<j>``); absent names are ignored.
    """

    joint: int
    names: tuple[str, ...]
    columns: Callable[[np.ndarray], np.ndarray]
    drop: tuple[str, ...] = ()


class LawSplicedModel:
    """A model whose friction columns of some joints are replaced by a law's columns: the one regressor splice
    shared by ``identify``'s declared laws (:class:`LawDeclaredModel`) and the diagnosis loop's chosen laws
    (:class:`symoro_gen.diagnostics.friction.LawModel`).

    The columns named in the entries' ``drop`` are removed from the wrapped model's regressor; each entry's
    columns are appended (in order) on its joint's rows. The magnitudes of the new columns stay linear
    parameters of the IDIM fit ([GB-gains] eq. 16-22). It satisfies
    :class:`symoro_gen.model.IdentificationModel`: ``BASE_NAMES`` are the kept names then the entries'
    names; every other attribute (payload regressor included) is the wrapped model's.
    """

    def __init__(self, model: IdentificationModel, entries: Sequence[JointColumns]) -> None:
        self._model = model
        self.entries = tuple(entries)
        names = tuple(model.BASE_NAMES)
        drop = {nm for e in self.entries for nm in e.drop}
        self._keep = [i for i, nm in enumerate(names) if nm not in drop]
        # (position in the output, first, end) of each contiguous run of kept columns
        self._runs: list[tuple[int, int, int]] = []
        for pos, i in enumerate(self._keep):
            if self._runs and self._runs[-1][2] == i:
                self._runs[-1] = (self._runs[-1][0], self._runs[-1][1], i + 1)
            else:
                self._runs.append((pos, i, i + 1))
        self.BASE_NAMES = tuple(names[i] for i in self._keep) + tuple(nm for e in self.entries for nm in e.names)

    def __getattr__(self, name):
        if name.startswith("__") or name in ("_model", "entries", "_keep", "_runs"):
            raise AttributeError(name)
        return getattr(self._model, name)

    @property
    def wrapped(self) -> IdentificationModel:
        """The model whose columns are replaced."""
        return self._model

    def regressor(self, q, dq, ddq) -> np.ndarray:
        q, dq, ddq = (np.asarray(x, float) for x in (q, dq, ddq))
        single = q.ndim == 1
        if single:
            q, dq, ddq = q[None], dq[None], ddq[None]
        R = np.asarray(self._model.regressor(q, dq, ddq), float)
        # one output array: the kept columns copied by their contiguous runs, each entry's block zeroed and its
        # columns written on its joint's rows (the same numbers as concatenating the parts, without the copies)
        out = np.empty((R.shape[0], R.shape[1], len(self.BASE_NAMES)))
        for i, a, b in self._runs:
            out[:, :, i:i + b - a] = R[:, :, a:b]
        c = len(self._keep)
        for e in self.entries:
            k = len(e.names)
            out[:, :, c:c + k] = 0.0
            out[:, e.joint, c:c + k] = e.columns(dq[:, e.joint])
            c += k
        return out[0] if single else out


class LawDeclaredModel(LawSplicedModel):
    """The model with the declared friction laws in place of their joints' ``FS``/``FV`` columns.

    It satisfies :class:`symoro_gen.model.IdentificationModel`: ``BASE_NAMES`` are the declared model's
    without the replaced ``FS<j>``, ``FV<j>``, then each law's :meth:`FrictionLaw.names`; every other
    attribute (payload regressor included) is the declared model's (:class:`LawSplicedModel`).
    """

    def __init__(self, model: IdentificationModel, laws: Sequence[tuple[int, FrictionLaw]],
                 scales: Sequence[float] | None = None) -> None:
        self.laws = tuple(laws)
        given = scales if scales is not None else [lw.scale for _, lw in self.laws]
        self.scales = tuple(math.nan if x is None else float(x) for x in given)
        super().__init__(model, [JointColumns(j, lw.names(), partial(lw.columns, scale=s),
                                              (f"FS{lw.frame}", f"FV{lw.frame}"))
                                 for (j, lw), s in zip(self.laws, self.scales)])

    def with_scales(self, scales: Sequence[float]) -> LawDeclaredModel:
        return LawDeclaredModel(self._model, self.laws, scales)


def declared_laws(robot, model: IdentificationModel) -> list[tuple[int, FrictionLaw]]:
    """``(0-based model joint, law)`` of every ``friction_law`` of the robot file (empty without any)."""
    laws = dict(getattr(robot, "friction_laws", {}) or {})
    if not laws:
        return []
    frames = [r.j for r in robot.model_joints]
    out = []
    names = set(model.BASE_NAMES)
    for frame, lw in sorted(laws.items()):
        if frame not in frames or not {f"FS{frame}", f"FV{frame}"} <= names:
            raise IdentificationError(f"{robot.file}, frame {frame}, field 'friction_law': the model of "
                                      f"{robot.name} has no FS{frame}/FV{frame} columns on a joint to replace")
        out.append((frames.index(frame), lw))
    return out


def _check_structure(model: LawDeclaredModel) -> None:
    """The assembly evaluates only the entries of the regressor that are non-zero at random states
    (``observations.fused.column_map``): a law column that vanishes there (a Stribeck ``vs`` far below the
    states' velocities) would be dropped, so it is refused with its joint named."""
    cm = model_column_map(model)
    nb = len(model.BASE_NAMES)
    present = set((cm.entry % nb).tolist())
    for (_j, lw), s in zip(model.laws, model.scales):
        for nm in lw.names():
            if model.BASE_NAMES.index(nm) not in present:
                raise IdentificationError(f"frame {lw.frame}, field 'friction_law': the column {nm} of the "
                                          f"{lw.label(s)} law is 0 at the assembly's structure test (velocities "
                                          f"up to 2): declare a larger scale")


def _system(model: LawDeclaredModel, trajectories, options: AssemblyOptions):
    _check_structure(model)
    return assemble(model, trajectories, replace(options, keep_signals=False, payload_columns=False)).system


def refine_scales(model: IdentificationModel, laws: Sequence[tuple[int, FrictionLaw]], trajectories,
                  options: AssemblyOptions) -> tuple[ScaleFit, ...]:
    """The declared laws' scales refined on the identification recordings (module docstring): Gauss-Newton
    in ``log s`` from the declared values, bounded to the robot file's ranges; laws the data cannot see are
    reported (``fitted=False``) with their declared scale."""
    if not laws:
        return ()
    base = LawDeclaredModel(model, laws)
    s = np.array(base.scales)
    lo = np.array([SCALE_BOUNDS[lw.scale_name][0] if lw.scale_name else 0.0 for _, lw in laws])
    hi = np.array([SCALE_BOUNDS[lw.scale_name][1] if lw.scale_name else 1.0 for _, lw in laws])
    sys0 = _system(base, trajectories, options)
    W, Y, joint = sys0.W, sys0.Y, sys0.joint
    theta = _lstsq(W, Y)
    rho = Y - W @ theta
    n = int(joint.max()) + 1
    sig = np.sqrt(np.bincount(joint, rho ** 2, n) / np.maximum(np.bincount(joint, minlength=n), 1))
    w = 1.0 / np.where(sig > 0, sig, 1.0)[joint]
    cols = {nm: i for i, nm in enumerate(sys0.names)}
    moving = [bool(np.any(W[:, [cols[nm] for nm in lw.names()]] != 0.0)) for _, lw in laws]
    free = np.array(moving) & np.array([lw.scale_name is not None for _, lw in laws])

    def cost(W_, th):
        r = (Y - W_ @ th) * w
        return float(r @ r)

    def jacobian(sc, W_, th):
        D = np.zeros((W_.shape[0], len(laws)))
        for i in np.flatnonzero(free):
            s2 = sc.copy()
            s2[i] *= 1.0 + FD_STEP
            W2 = _system(base.with_scales(s2), trajectories, options).W
            D[:, i] = (W2 - W_) @ th / FD_STEP          # d prediction / d log s = s d/ds
        return D

    it = 0
    theta = _lstsq(W * w[:, None], Y * w)
    if free.any():
        cur = cost(W, theta)
        for _ in range(MAX_ITER):
            it += 1
            D = jacobian(s, W, theta)
            J = np.hstack([W, D[:, free]]) * w[:, None]
            step = _lstsq(J, (Y - W @ theta) * w)[W.shape[1]:]
            du = np.zeros(len(laws))
            du[free] = np.clip(step, -1.0, 1.0)                         # at most a factor e per step
            accepted = False
            for _halving in range(8):
                s_new = np.clip(s * np.exp(du), np.nextafter(lo, hi), hi)
                W_new = _system(base.with_scales(s_new), trajectories, options).W
                th_new = _lstsq(W_new * w[:, None], Y * w)
                c_new = cost(W_new, th_new)
                if c_new <= cur:
                    accepted = True
                    break
                du /= 2.0
            if not accepted:
                break
            change = float(np.max(np.abs(np.log(s_new[free] / s[free]))))
            s, W, theta, cur = s_new, W_new, th_new, c_new
            if change < TOL:
                break
        theta = _lstsq(W * w[:, None], Y * w)
    # linearised covariance at the solution, sigma^2 (J^T J)^-1 with J = [W, d/d log s]
    D = jacobian(s, W, theta)
    J = np.hstack([W, D[:, free]]) * w[:, None]
    r = (Y - W @ theta) * w
    dof = max(J.shape[0] - np.linalg.matrix_rank(J), 1)
    cov = float(r @ r) / dof * np.linalg.pinv(J.T @ J)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    out = []
    k = W.shape[1]
    for i, (j, lw) in enumerate(laws):
        names = lw.names()
        mags = {nm: float(theta[cols[nm]]) for nm in names}
        mstd = {nm: float(std[cols[nm]]) for nm in names}
        tail = f"; {SLIDING_NOTE}" if lw.dynamic else ""
        if not moving[i]:
            out.append(ScaleFit(lw, j, math.nan if lw.scale is None else lw.scale, math.nan, False, mags, mstd, 0,
                                "the joint does not move in the identification data (its law columns are 0)" + tail))
            continue
        if lw.scale_name is None:
            out.append(ScaleFit(lw, j, math.nan, math.nan, False, mags, mstd, 0,
                                "no scale: its sliding part is the Coulomb + viscous law" + tail))
            continue
        assert lw.scale is not None
        pos = k + int(np.count_nonzero(free[:i]))
        s_std = float(s[i] * std[pos])
        key = f"{SCALED_MAGNITUDE[lw.kind]}{lw.frame}"
        if not abs(mags[key]) > MIN_T * mstd[key]:
            out.append(ScaleFit(lw, j, lw.scale, math.nan, False, mags, mstd, it,
                                f"{key} = {mags[key]:.3g} \u00b1 {mstd[key]:.2g} is not significant ({MIN_T:g} "
                                f"sigma): the data do not determine {lw.scale_name}, the declared value is kept" + tail))
            continue
        if not s_std <= MAX_REL_STD * s[i]:
            out.append(ScaleFit(lw, j, lw.scale, math.nan, False, mags, mstd, it,
                                f"the data do not determine {lw.scale_name} (relative standard deviation "
                                f"{s_std / s[i]:.2g} > {MAX_REL_STD:g} at {s[i]:.4g}): the declared value is kept" + tail))
            continue
        out.append(ScaleFit(lw, j, float(s[i]), s_std, True, mags, mstd, it, tail.lstrip("; ")))
    return tuple(out)




def _lstsq(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.linalg.lstsq(A, b, rcond=None)[0]
