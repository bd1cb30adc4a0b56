"""The object behind a generated package's functions (:class:`GeneratedModel`)."""
from __future__ import annotations

import ctypes
import importlib
import os
import threading
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .batch import evaluate_kernel
from .casadi import build_function, build_geometry_function
from .ccompile import (
    BuildResult,
    CBuildError,
    build_library,
    compiler,
    find_library,
    load_functions,
)
from .inputs import joint_states, output_array

#: optimisation level of the geometry derivative's C file (its one long function: minutes at -O1 with GCC)
GEOMETRY_OPT = "-O0"

#: (robot, C file) pairs already warned about in this process: one fallback warning per model
_WARNED: set[tuple[str, str]] = set()


class CBackendWarning(RuntimeWarning):
    """The C kernels of a generated package are not available; NumPy kernels are used."""


def _numpy_forced() -> bool:
    return os.environ.get("SYMORO_BACKEND", "").strip().lower() == "numpy"


class GeneratedModel:
    """Identification model of one generated package (satisfies
    :class:`symoro_gen.model.IdentificationModel`).

    Parameters
    ----------
    package_dir : path
        The package folder (holds ``regressor_<robot>.c``; ``_build/`` is created beside it).
    robot : str
    n_joints : int
    standard_names, base_names, payload_names : tuple of str
    relations : tuple
        One entry per base parameter: ``((standard index, coefficient), ...)``; the base vector is
        ``chi_b[b] = sum(coefficient * chi_std[index])`` (closed-form regrouping, geometry substituted).
    kernels : module
        ``base_kernel``, ``standard_kernel``, ``payload_kernel`` (NumPy, emitted).
    construct_casadi : callable, optional
        ``base_casadi(ca, q, dq, ddq, out)`` of the package's ``_casadi.py``.
    geometry : (module or str, tuple of str), optional
        The package's ``_geometry.py`` (derivative of the standard regressor w.r.t. the geometric
        constants, :mod:`symoro_gen.emit.geometry`), or its module name, imported on first use (it is
        large), and its constants ``GEOMETRY_NAMES``; None when the package has none.

    Notes
    -----
    The C library is looked for, or compiled, on the first evaluation (never at import). When it
    cannot be had (no compiler, compile error, timeout, ``SYMORO_BACKEND=numpy``), the NumPy kernels
    are used; except for ``SYMORO_BACKEND=numpy`` one :class:`CBackendWarning` says why.
    """

    def __init__(self, package_dir: str | os.PathLike[str], robot: str, n_joints: int, standard_names: Sequence[str],
                 base_names: Sequence[str], payload_names: Sequence[str], relations: Sequence[Any], kernels: ModuleType,
                 construct_casadi: Callable[..., Any] | None = None, *, c_file: str | None = None, numpy_only: bool = False,
                 geometry: tuple[ModuleType | str, Sequence[str]] | None = None):
        self.package_dir = Path(package_dir)
        self.ROBOT = robot
        self.N_JOINTS = int(n_joints)
        self.STANDARD_NAMES = tuple(standard_names)
        self.BASE_NAMES = tuple(base_names)
        self.PAYLOAD_NAMES = tuple(payload_names)
        self.relations = tuple(relations)
        K = np.zeros((len(self.BASE_NAMES), len(self.STANDARD_NAMES)))
        for b, terms in enumerate(self.relations):
            for k, c in terms:
                K[b, k] = c
        self.K = K
        self._kernels = {"base": kernels.base_kernel, "standard": kernels.standard_kernel,
                         "payload": kernels.payload_kernel}
        self._ncols = {"base": len(self.BASE_NAMES), "standard": len(self.STANDARD_NAMES),
                       "payload": len(self.PAYLOAD_NAMES)}
        self._construct_casadi = construct_casadi
        self.c_path = self.package_dir / (c_file or f"regressor_{robot}.c")
        self._numpy_only = numpy_only
        self._c: dict[str, Any] | None = None
        self._resolved = False
        self._reason = ""
        self._lock = threading.Lock()
        self._geometry: ModuleType | str | None = None if geometry is None else geometry[0]
        self.GEOMETRY_NAMES: tuple[str, ...] = () if geometry is None else tuple(geometry[1])
        self._geo_c: Any = None
        self._geo_resolved = False

    # -- backend ---------------------------------------------------------------------------------
    @property
    def backend(self) -> str:
        """``"c"`` or ``"numpy"``: after the first evaluation, the kernels in use; before it, the ones
        the first evaluation will try (``"c"`` when a built library or a C compiler is present and
        NumPy is not forced)."""
        if self._resolved:
            return "c" if self._c is not None else "numpy"
        if self._numpy_only or _numpy_forced() or not self.c_path.exists():
            return "numpy"
        return "c" if (find_library(self.c_path) is not None or compiler() is not None) else "numpy"

    def numpy_only(self) -> GeneratedModel:
        """The same model evaluated with the NumPy kernels only (for comparisons)."""
        m = object.__new__(GeneratedModel)
        m.__dict__.update(self.__dict__)
        m._numpy_only, m._c, m._resolved, m._lock = True, None, False, threading.Lock()
        m._geo_c, m._geo_resolved = None, False
        return m

    def build(self, *, force: bool = False, timeout: float | None = None) -> BuildResult:
        """Compile (or find) the C library now and use it; raises :class:`CBuildError` on failure."""
        with self._lock:
            res = build_library(self.c_path, force=force, timeout=timeout)
            self._c = load_functions(res.path, self._c_names())
            self._resolved = True
            return res

    def _c_names(self) -> list[str]:
        return [f"{self.ROBOT}_{kind}_regressor" for kind in ("base", "standard", "payload")]

    def _c_functions(self) -> dict[str, Any] | None:
        if self._resolved:
            return self._c
        with self._lock:
            if self._resolved:
                return self._c
            if self._numpy_only or _numpy_forced():
                self._c, self._reason = None, "SYMORO_BACKEND=numpy"
            else:
                try:
                    if not self.c_path.exists():
                        raise CBuildError(f"{self.c_path.name} is missing")
                    self._c = load_functions(build_library(self.c_path).path, self._c_names())
                except (CBuildError, OSError) as exc:
                    self._c, self._reason = None, str(exc)
                    key = (self.ROBOT, str(self.c_path))
                    if key not in _WARNED:
                        _WARNED.add(key)
                        retry = getattr(exc, "hint", None) or (f"`symoro-gen build {self.package_dir}` shows the "
                                                                   "compiler's error")
                        warnings.warn(
                            f"{self.ROBOT}: C kernels unavailable ({exc}); using the NumPy kernels (same results, "
                            f"slower). To fix: {retry}; set SYMORO_BACKEND=numpy to silence this.",
                            CBackendWarning, stacklevel=4)
            self._resolved = True
            return self._c

    # -- evaluation ------------------------------------------------------------------------------
    def _evaluate(self, kind: str, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike,
                  out: NDArray[np.float64] | None) -> NDArray[np.float64]:
        (Q, DQ, DDQ), one = joint_states(self.ROBOT, self.N_JOINTS, q, dq, ddq)
        N, nc = Q.shape[0], self._ncols[kind]
        res = output_array(self.ROBOT, (N, self.N_JOINTS, nc), out)
        c = self._c_functions()
        if c is not None:
            try:
                c[f"{self.ROBOT}_{kind}_regressor"](N, np.ascontiguousarray(Q), np.ascontiguousarray(DQ),
                                                    np.ascontiguousarray(DDQ), res)
            except ctypes.ArgumentError as exc:  # Ctrl-C during ctypes' argument conversion
                if "KeyboardInterrupt" in str(exc):
                    raise KeyboardInterrupt from None
                raise
        else:
            evaluate_kernel(self._kernels[kind], self.N_JOINTS, nc, Q, DQ, DDQ, res)
        return res[0] if one else res

    def regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike,
                  out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Base regressor ``W_b``, shape (N, n, nb) for (N, n) inputs, (n, nb) for (n,).

        q [rad or m], dq, ddq in joint space (MDH convention of the robot file); ``out`` may be a
        preallocated C-contiguous (N, n, nb) float64 array.
        """
        return self._evaluate("base", q, dq, ddq, out)

    def standard_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike,
                           out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Standard regressor ``IDM_st``, shape (N, n, len(STANDARD_NAMES))."""
        return self._evaluate("standard", q, dq, ddq, out)

    def payload_regressor(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike,
                          out: NDArray[np.float64] | None = None) -> NDArray[np.float64]:
        """Payload regressor, shape (N, n, len(PAYLOAD_NAMES)) (0 columns without payload)."""
        return self._evaluate("payload", q, dq, ddq, out)

    def base_parameters(self, chi_std: ArrayLike) -> NDArray[np.float64]:
        """Base parameters from standard ones (closed-form relations, geometry substituted).

        chi_std : (..., len(STANDARD_NAMES)). Returns (..., len(BASE_NAMES)).
        """
        chi = np.asarray(chi_std, dtype=float)
        if chi.shape[-1:] != (len(self.STANDARD_NAMES),):
            raise ValueError(f"{self.ROBOT}: chi_std must end with {len(self.STANDARD_NAMES)} entries "
                             f"(STANDARD_NAMES), got {chi.shape}")
        out = np.zeros(chi.shape[:-1] + (len(self.BASE_NAMES),))
        for b, terms in enumerate(self.relations):  # only the non-zero terms: NaN/inf stay where they are
            acc = None
            for k, c in terms:
                t = chi[..., k] if c == 1.0 else (-chi[..., k] if c == -1.0 else c * chi[..., k])
                acc = t if acc is None else acc + t
            if acc is not None:
                out[..., b] = acc
        return out

    def torque(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike, chi_std: ArrayLike,
               chi_payload: ArrayLike | None = None) -> NDArray[np.float64]:
        """Inverse dynamics: joint torques (N, n) ((n,) for 1-D inputs) for standard parameters."""
        Y = self.regressor(q, dq, ddq) @ self.base_parameters(chi_std)
        if chi_payload is not None:
            p = np.asarray(chi_payload, dtype=float)
            if p.shape != (len(self.PAYLOAD_NAMES),):
                raise ValueError(f"{self.ROBOT}: chi_payload must have shape ({len(self.PAYLOAD_NAMES)},), got {p.shape}")
            Y = Y + self.payload_regressor(q, dq, ddq) @ p
        return Y

    def casadi_regressor(self) -> Any:
        """``casadi.Function regressor_<robot>(q, dq, ddq) -> Y`` (n x nb base regressor)."""
        if self._construct_casadi is None:
            raise CBuildError(f"{self.ROBOT}: this package has no CasADi construction")
        return build_function(self._construct_casadi, f"regressor_{self.ROBOT}", self.N_JOINTS, len(self.BASE_NAMES))

    # -- geometry derivative ----------------------------------------------------------------------
    def _geometry_module(self) -> ModuleType:
        if self._geometry is None:
            raise CBuildError(f"{self.ROBOT}: this package has no geometry derivative (manifest.json, "
                              "geometry_derivative.omitted, says why)")
        if isinstance(self._geometry, str):
            self._geometry = importlib.import_module(self._geometry)
        return self._geometry

    def _geometry_c_function(self) -> Any:
        """The C function of ``geometry_<robot>.c`` (compiled on first use), or None (NumPy kernel)."""
        with self._lock:
            if not self._geo_resolved:
                self._geo_resolved = True
                path = self.package_dir / f"geometry_{self.ROBOT}.c"
                name = f"{self.ROBOT}_geometry_derivative"
                if not (self._numpy_only or _numpy_forced()) and path.exists():
                    try:
                        self._geo_c = load_functions(build_library(path, opt=GEOMETRY_OPT).path, [name])[name]
                    except (CBuildError, OSError) as exc:
                        warnings.warn(f"{self.ROBOT}: C geometry kernel unavailable ({exc}); using the NumPy "
                                      "kernel (same results, slower)", CBackendWarning, stacklevel=4)
            return self._geo_c

    def _geometry_compact(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike
                          ) -> tuple[NDArray[np.float64], NDArray[np.int_], bool]:
        """The kernel's output (N, n, n_pairs), the pairs (n_pairs, 2), and whether inputs were 1-D."""
        geo = self._geometry_module()
        (Q, DQ, DDQ), one = joint_states(self.ROBOT, self.N_JOINTS, q, dq, ddq)
        N, n = Q.shape[0], self.N_JOINTS
        pairs = np.asarray(geo.GEOMETRY_PAIRS, dtype=int).reshape(-1, 2)
        compact = np.zeros((N, n, len(pairs)))
        fn = self._geometry_c_function()
        if fn is not None:
            fn(N, np.ascontiguousarray(Q), np.ascontiguousarray(DQ), np.ascontiguousarray(DDQ), compact)
        else:
            evaluate_kernel(geo.geometry_kernel, n, len(pairs), Q, DQ, DDQ, compact)
        return compact, pairs, one

    def geometry_terms(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike
                       ) -> tuple[NDArray[np.float64], NDArray[np.int_]]:
        """The entries of ``dY_std/dg`` the emitted kernel evaluates, every other one being identically 0
        (:mod:`symoro_gen.emit.geometry` drops them): their values, shape (N, n, n_pairs) ((n, n_pairs) for 1-D
        inputs), and their ``(standard index, geometry index)`` pairs, shape (n_pairs, 2).

        :meth:`geometry_derivative` is these values scattered into the dense array, :meth:`geometry_columns`
        their product with ``chi_std``; a caller that needs the derivative for many parameter vectors (or
        linear maps of it, such as a decimation) keeps these few columns instead of either.
        """
        compact, pairs, one = self._geometry_compact(q, dq, ddq)
        return (compact[0] if one else compact), pairs

    def geometry_derivative(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike) -> NDArray[np.float64]:
        """``dY_std/dg`` at the nominal geometry: shape (N, n, len(STANDARD_NAMES), len(GEOMETRY_NAMES))
        ((n, n_st, n_g) for 1-D inputs).

        ``[s, i, k, m]`` is the derivative of the standard regressor's entry (row i, column k) with respect
        to the geometric constant ``GEOMETRY_NAMES[m]`` (MDH ``d<j>``, ``r<j>`` [m], ``alpha<j>``,
        ``theta<j>`` [rad]; ``theta<j>`` of a revolute joint, ``r<j>`` of a prismatic one is its joint zero).
        With ``tau = Y_std(q, dq, ddq; g) chi_std``, ``d tau / d g = (dY_std/dg) chi_std``
        (:meth:`geometry_columns`, cheaper).
        """
        compact, pairs, one = self._geometry_compact(q, dq, ddq)
        N, n = compact.shape[:2]
        res = np.zeros((N, n, len(self.STANDARD_NAMES), len(self.GEOMETRY_NAMES)))
        res[:, :, pairs[:, 0], pairs[:, 1]] = compact
        return res[0] if one else res

    def geometry_columns(self, q: ArrayLike, dq: ArrayLike, ddq: ArrayLike, chi_std: ArrayLike) -> NDArray[np.float64]:
        """``d tau / d g = (dY_std/dg) chi_std``: shape (N, n, len(GEOMETRY_NAMES)) ((n, n_g) for 1-D inputs),
        the sensitivity of the joint torques to each geometric constant at the parameters ``chi_std``."""
        chi = np.asarray(chi_std, dtype=float)
        if chi.shape != (len(self.STANDARD_NAMES),):
            raise ValueError(f"{self.ROBOT}: chi_std must have shape ({len(self.STANDARD_NAMES)},) "
                             f"(STANDARD_NAMES), got {chi.shape}")
        compact, pairs, one = self._geometry_compact(q, dq, ddq)
        M = np.zeros((len(pairs), len(self.GEOMETRY_NAMES)))
        M[np.arange(len(pairs)), pairs[:, 1]] = chi[pairs[:, 0]]
        out: NDArray[np.float64] = compact @ M
        return out[0] if one else out

    def casadi_geometry_columns(self) -> Any:
        """``casadi.Function geometry_<robot>(q, dq, ddq, chi_std) -> G`` (n x n_g): :meth:`geometry_columns`
        of one sample, from the package's CasADi construction of ``dY_std/dg``."""
        geo = self._geometry_module()
        return build_geometry_function(geo.geometry_casadi, f"geometry_{self.ROBOT}", self.N_JOINTS,
                                       len(self.STANDARD_NAMES), len(self.GEOMETRY_NAMES), geo.GEOMETRY_PAIRS)


def geometry_terms_of(model: Any) -> Callable[[ArrayLike, ArrayLike, ArrayLike],
                                             tuple[NDArray[np.float64], NDArray[np.int_]]] | None:
    """:meth:`GeneratedModel.geometry_terms` of ``model``: a :class:`GeneratedModel`, or a generated package
    (whose ``geometry_columns`` is the bound method of the :class:`GeneratedModel` behind it); None for any
    other model (built in memory, a wrapper) or a package without the emitted derivative."""
    owner = model if isinstance(model, GeneratedModel) else getattr(getattr(model, "geometry_columns", None),
                                                                     "__self__", None)
    if not isinstance(owner, GeneratedModel) or owner._geometry is None:
        return None
    return owner.geometry_terms
