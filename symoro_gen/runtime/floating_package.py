"""The floating-base contract (:class:`FloatingContract`) and the object behind a generated floating package.

Pinocchio's free-flyer conventions (Carpentier et al., "The Pinocchio C++ library", SII 2019;
:mod:`symoro_gen.dynamics.floating`): ``q`` of size ``7 + n`` (base position, unit quaternion ``x y z w``
at ``q[3:7]``, joints), ``dq`` and ``ddq`` of size ``6 + n`` (base linear and angular velocity in base
axes, then joints), ``6 + n`` rows per sample, the base wrench first. :class:`FloatingContract` holds the
evaluation both implementations share: :class:`symoro_gen.runtime.floating.FloatingModel` (kernels built
in memory from the robot description) and :class:`GeneratedFloatingModel` (the kernels of a generated
package, ``emit.floating``: C compiled on first use, NumPy otherwise, CasADi constructions). This module
needs no sympy: importing a generated package stays light.
"""
from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .batch import evaluate_kernel
from .ccompile import CBuildError
from .inputs import output_array
from .model import GeneratedModel

#: a unit quaternion's norm may differ from 1 by this much (rounding of logged values)
QUATERNION_TOL = 1e-6
#: the kernels of a generated floating package's regressors (the contact frames' come after them)
REGRESSOR_KINDS = ("base", "standard", "payload")


def floating_states(robot: str, n: int, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike
                    ) -> tuple[tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]], bool]:
    """``((q, dq, ddq) as (N, 7 + n), (N, 6 + n), (N, 6 + n) float arrays, one_sample)``.

    Raises
    ------
    ValueError
        A shape (naming the robot, the argument and the shape expected), or a quaternion ``q[:, 3:7]``
        that is not of unit norm (naming the first such sample).
    """
    arrs = []
    for name, x, size in (("q", q, 7 + n), ("dq", dq, 6 + n), ("ddq", ddq, 6 + n)):
        a = np.asarray(x, dtype=float)
        if a.ndim == 1 and a.shape[0] == size:
            a = a[None, :]
        elif not (a.ndim == 2 and a.shape[1] == size):
            raise ValueError(f"{robot}: {name} must have shape (N, {size}) or ({size},) for a floating base with "
                             f"{n} joints, got {a.shape}")
        arrs.append(a)
    if not arrs[0].shape[0] == arrs[1].shape[0] == arrs[2].shape[0]:
        raise ValueError(f"{robot}: q, dq, ddq have different sample counts {[a.shape[0] for a in arrs]}")
    norm = np.linalg.norm(arrs[0][:, 3:7], axis=1)
    off = np.flatnonzero(np.abs(norm - 1.0) > QUATERNION_TOL)
    if off.size:
        raise ValueError(f"{robot}: q[:, 3:7] must be a unit quaternion (x y z w); sample {off[0]} has norm "
                         f"{norm[off[0]]:.9g}")
    return (arrs[0], arrs[1], arrs[2]), np.ndim(q) == 1


class FloatingContract:
    """The evaluation of a floating-base model (module docstring), on kernels a subclass provides.

    A subclass sets ``ROBOT``, ``N_JOINTS``, ``N_ROWS`` (``6 + n``), ``STANDARD_NAMES``, ``BASE_NAMES``,
    ``PAYLOAD_NAMES``, ``CONTACT_FRAMES`` (the contact frames' names), ``_K`` (base parameters
    ``= _K @ chi_std``) and implements :meth:`_fill`.
    """

    FLOATING = True
    ROBOT: str
    N_JOINTS: int
    N_ROWS: int
    STANDARD_NAMES: tuple[str, ...]
    BASE_NAMES: tuple[str, ...]
    PAYLOAD_NAMES: tuple[str, ...]
    CONTACT_FRAMES: tuple[str, ...] = ()
    _K: NDArray[np.float64]

    def _fill(self, kind: str, q: NDArray[np.float64], dq: NDArray[np.float64], ddq: NDArray[np.float64],
              res: NDArray[np.float64]) -> None:
        """Fill ``res`` (N, rows, cols) with the kernel ``kind`` (``base``, ``standard``, ``payload``,
        ``contact<k>_transform``, ``contact<k>_jacobian``) on (N, size) inputs."""
        raise NotImplementedError

    def _run(self, kind: str, shape: tuple[int, int], q: ArrayLike, dq: ArrayLike, ddq: ArrayLike,
             out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        (Q, DQ, DDQ), one = floating_states(self.ROBOT, self.N_JOINTS, q, dq, ddq)
        res = np.zeros((Q.shape[0],) + shape) if out is None else output_array(self.ROBOT, (Q.shape[0],) + shape, out)
        self._fill(kind, Q, DQ, DDQ, res)
        return res[0] if one else res

    def standard_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike,
                           out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Standard regressor ``(N, 6 + n, n_st)`` (``(6 + n, n_st)`` for 1-D inputs); ``out``: a
        preallocated C-contiguous float64 array of that shape (N, ...), as for every regressor."""
        return self._run("standard", (self.N_ROWS, len(self.STANDARD_NAMES)), q, dq, ddq, out)

    def payload_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike,
                          out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Payload regressor ``(N, 6 + n, 10)`` (0 columns without payload)."""
        return self._run("payload", (self.N_ROWS, len(self.PAYLOAD_NAMES)), q, dq, ddq, out)

    def regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike,
                  out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Base regressor ``(N, 6 + n, nb)``: the kept standard columns."""
        return self._run("base", (self.N_ROWS, len(self.BASE_NAMES)), q, dq, ddq, out)

    def base_parameters(self, chi_std: ArrayLike) -> NDArray[np.float64]:
        """Base parameters of standard ones, ``K @ chi_std`` (the closed-form relations); ``chi_std`` of
        shape ``(..., n_st)``."""
        chi = np.asarray(chi_std, float)
        if chi.shape[-1:] != (len(self.STANDARD_NAMES),):
            raise ValueError(f"{self.ROBOT}: chi_std must end with {len(self.STANDARD_NAMES)} entries "
                             f"(STANDARD_NAMES), got {chi.shape}")
        out: NDArray[np.float64] = chi @ self._K.T
        return out

    def torque(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike, chi_std: ArrayLike,
               chi_payload: ArrayLike | None = None) -> NDArray[np.float64]:
        """Base wrench and joint torques ``(N, 6 + n)`` (``(6 + n,)`` for 1-D inputs)."""
        y: NDArray[np.float64] = self.regressor(q, dq, ddq) @ self.base_parameters(chi_std)
        if chi_payload is not None:
            y = y + self.payload_regressor(q, dq, ddq) @ np.asarray(chi_payload, float)
        return y

    def contact_index(self, frame: str | int) -> int:
        """The position of a contact frame (its name, or its position) in ``CONTACT_FRAMES``.

        Raises
        ------
        KeyError
            Not a contact frame of this robot (the known ones named).
        """
        if isinstance(frame, (int, np.integer)) and 0 <= int(frame) < len(self.CONTACT_FRAMES):
            return int(frame)
        if frame in self.CONTACT_FRAMES:
            return self.CONTACT_FRAMES.index(str(frame))
        raise KeyError(f"{self.ROBOT}: {frame!r} is not a contact frame (the robot file's `contacts`: "
                       f"{', '.join(self.CONTACT_FRAMES) or 'none'})")

    def _frame(self, what: str, frame: str | int, q: ArrayLike, shape: tuple[int, int]) -> NDArray[np.float64]:
        k = self.contact_index(frame)
        qa = np.asarray(q, float)
        zeros = np.zeros(qa.shape[:-1] + (6 + self.N_JOINTS,))
        return self._run(f"contact{k}_{what}", shape, qa, zeros, zeros)

    def frame_transform(self, frame: str | int, q: ArrayLike) -> NDArray[np.float64]:
        """Pose of a contact frame in the world, ``(N, 4, 4)`` (``(4, 4)`` for 1-D ``q``): Pinocchio's
        ``data.oMf`` after ``updateFramePlacements``. The pose in base axes is that of ``q`` with the
        base at the origin (``q[:7] = 0 0 0 0 0 0 1``)."""
        return self._frame("transform", frame, q, (4, 4))

    def frame_jacobian(self, frame: str | int, q: ArrayLike) -> NDArray[np.float64]:
        """Jacobian of a contact frame in its own axes, ``(N, 6, 6 + n)``: linear then angular velocity
        of the frame from ``dq`` (Pinocchio's ``getFrameJacobian(..., LOCAL)``; the ``jacobian`` of
        :class:`symoro_gen.identification.floating.ContactWrench`)."""
        return self._frame("jacobian", frame, q, (6, 6 + self.N_JOINTS))


def casadi_floating_function(construct: Any, name: str, n: int, shape: tuple[int, int], q_only: bool = False) -> Any:
    """``casadi.Function name(q, dq, ddq) -> Y`` (``name(q) -> Y`` when ``q_only``) from a generated
    construction ``construct(ca, q, dq, ddq, out)`` (q: 7 + n, dq and ddq: 6 + n)."""
    import casadi as ca  # heavy; only needed when a CasADi function is asked for

    q, dq, ddq = ca.SX.sym("q", 7 + n), ca.SX.sym("dq", 6 + n), ca.SX.sym("ddq", 6 + n)
    out = ca.SX.zeros(*shape)
    construct(ca, q, dq, ddq, out)
    if q_only:
        return ca.Function(name, [q], [out], ["q"], ["Y"])
    return ca.Function(name, [q, dq, ddq], [out], ["q", "dq", "ddq"], ["Y"])


class GeneratedFloatingModel(FloatingContract, GeneratedModel):
    """The model of a generated floating package (``emit.floating``): :class:`FloatingContract` on the
    package's kernels, the C library found or compiled on first use as for a fixed-base package
    (:class:`~symoro_gen.runtime.model.GeneratedModel`: one warning and the NumPy kernels when it
    cannot be had).

    Parameters
    ----------
    package_dir, robot, n_joints, standard_names, base_names, payload_names, relations
        As for :class:`~symoro_gen.runtime.model.GeneratedModel`.
    kernels : module
        The package's ``_kernels.py``: ``<kind>_kernel`` for every kind.
    casadi_module : module
        The package's ``_casadi.py``: ``<kind>_casadi`` for every kind.
    contact_frames : tuple of str
        The contact frames' names (``contact<k>_*`` kernels, in this order).
    """

    def __init__(self, package_dir: str | os.PathLike[str], robot: str, n_joints: int, standard_names: Sequence[str],
                 base_names: Sequence[str], payload_names: Sequence[str], relations: Sequence[Any], kernels: ModuleType,
                 casadi_module: ModuleType, contact_frames: Sequence[str] = ()) -> None:
        GeneratedModel.__init__(self, Path(package_dir), robot, n_joints, standard_names, base_names, payload_names,
                                relations, kernels, casadi_module.base_casadi)
        self.N_ROWS = 6 + self.N_JOINTS
        self.CONTACT_FRAMES = tuple(contact_frames)
        self._K = self.K
        self._casadi_module = casadi_module
        for k in range(len(self.CONTACT_FRAMES)):
            for what in ("transform", "jacobian"):
                self._kernels[f"contact{k}_{what}"] = getattr(kernels, f"contact{k}_{what}_kernel")

    def _kinds(self) -> list[str]:
        return list(REGRESSOR_KINDS) + [f"contact{k}_{w}" for k in range(len(self.CONTACT_FRAMES))
                                        for w in ("transform", "jacobian")]

    def _c_name(self, kind: str) -> str:
        return f"{self.ROBOT}_{kind}_regressor" if kind in REGRESSOR_KINDS else f"{self.ROBOT}_{kind}"

    def _c_names(self) -> list[str]:
        return [self._c_name(k) for k in self._kinds()]

    def _fill(self, kind: str, q: NDArray[np.float64], dq: NDArray[np.float64], ddq: NDArray[np.float64],
              res: NDArray[np.float64]) -> None:
        c = self._c_functions()
        if c is not None:
            c[self._c_name(kind)](q.shape[0], np.ascontiguousarray(q), np.ascontiguousarray(dq),
                                  np.ascontiguousarray(ddq), res)
        else:
            evaluate_kernel(self._kernels[kind], res.shape[1], res.shape[2], q, dq, ddq, res)

    def numpy_only(self) -> GeneratedFloatingModel:
        """The same model evaluated with the NumPy kernels only (for comparisons)."""
        m = object.__new__(GeneratedFloatingModel)
        m.__dict__.update(self.__dict__)
        m._numpy_only, m._c, m._resolved, m._lock = True, None, False, threading.Lock()
        return m

    def casadi_regressor(self) -> Any:
        """``casadi.Function regressor_<robot>(q, dq, ddq) -> Y``: the base regressor ``(6 + n) x nb`` of one
        sample (``q`` of size ``7 + n``, ``dq`` and ``ddq`` of size ``6 + n``)."""
        return casadi_floating_function(self._casadi_module.base_casadi, f"regressor_{self.ROBOT}", self.N_JOINTS,
                                        (self.N_ROWS, len(self.BASE_NAMES)))

    def _casadi_frame(self, what: str, frame: str | int, shape: tuple[int, int]) -> Any:
        k = self.contact_index(frame)
        construct = getattr(self._casadi_module, f"contact{k}_{what}_casadi", None)
        if construct is None:
            raise CBuildError(f"{self.ROBOT}: this package has no CasADi construction of contact {frame!r}")
        return casadi_floating_function(construct, f"{what}_{self.ROBOT}_contact{k}", self.N_JOINTS, shape,
                                        q_only=True)

    def casadi_frame_transform(self, frame: str | int) -> Any:
        """``casadi.Function transform_<robot>_contact<k>(q) -> T`` (4 x 4): :meth:`frame_transform`."""
        return self._casadi_frame("transform", frame, (4, 4))

    def casadi_frame_jacobian(self, frame: str | int) -> Any:
        """``casadi.Function jacobian_<robot>_contact<k>(q) -> J`` (6 x (6 + n)): :meth:`frame_jacobian`."""
        return self._casadi_frame("jacobian", frame, (6, 6 + self.N_JOINTS))
