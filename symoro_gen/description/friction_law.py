"""Friction laws: their columns (one definition, shared by the diagnosis loop and ``identify``) and the
per-frame ``friction_law`` field of a robot file.

The declared models carry ``FS_j sign(dq_j) + FV_j dq_j`` (Coulomb + viscous, RX-90 paper eq. 2). A robot
file may replace that law on a joint by one of the laws the diagnosis loop selects
(:mod:`symoro_gen.diagnostics.friction`), with the same definitions and parameter names:

* ``{kind = "stribeck", vs = 0.05}``: ``(Fc + (Fs - Fc) exp(-(dq/vs)^2)) sign(dq) + Fv dq``
  (Armstrong-Helouvry, Dupont & Canudas de Wit 1994, eq. 5); columns ``sign(dq)`` (``FS<j>``),
  ``exp(-(dq/vs)^2) sign(dq)`` (``FSS<j>`` = ``Fs - Fc``), ``dq`` (``FV<j>``);
* ``{kind = "tanh", v = 0.02}``: ``Fc tanh(dq/v) + Fv dq`` (a smoothed Coulomb law, e.g. Makkar, Dixon,
  Sawyer & Hu 2005, eq. 2 without its Stribeck terms);
* ``{kind = "power", delta = 0.5}``: ``Fc sign(dq) + Fv |dq|^delta sign(dq)`` (a power law of the
  speed for the lubricated viscous part, Olsson, Astrom, Canudas de Wit, Gafvert & Lischinsky 1998,
  "Friction models and friction compensation", eq. 5).

The magnitudes (``FS``, ``FSS``, ``FV``) stay linear parameters; the scale (``vs``, ``v`` or ``delta``)
is the only non-linear one (``identify`` refines it, :mod:`symoro_gen.identification.friction_law`).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace

import numpy as np

__all__ = [
    "COULOMB_LAWS",
    "DECLARED_KINDS",
    "DYNAMIC_KINDS",
    "SCALE_BOUNDS",
    "SCALE_NAME",
    "VISCOUS_LAWS",
    "FrictionLaw",
    "coulomb_columns",
    "law_parameter",
    "read_friction_laws",
    "viscous_columns",
    "with_identified_laws",
]

COULOMB_LAWS = ("sign", "tanh", "stribeck")
VISCOUS_LAWS = ("linear", "power")

#: the kinds of a robot file's ``friction_law`` and the name of their scale (the loop's names); the
#: dynamic laws (Dahl, LuGre) are identified by their sliding part: Dahl's is Coulomb + viscous (no
#: scale), LuGre's the Stribeck law
SCALE_NAME: dict[str, str | None] = {"stribeck": "vs", "tanh": "v", "power": "delta", "lugre": "vs", "dahl": None}
DECLARED_KINDS = tuple(SCALE_NAME)
#: the dynamic laws and their optional pre-sliding constants (bristle stiffness sigma0 [N m/rad or N/m],
#: LuGre's bristle damping sigma1 [N m s/rad]): carried, not identified by ``identify`` (docs/friction-dynamic.md)
DYNAMIC_KINDS = {"lugre": ("sigma0", "sigma1"), "dahl": ("sigma0",)}
#: range of the pre-sliding constants
PRESLIDING_BOUNDS = {"sigma0": (0.0, 1e9), "sigma1": (0.0, 1e6)}
#: the open-closed range of each scale: velocity scales [rad/s or m/s] up to 100 (no drive has a
#: Stribeck or smoothing velocity near it); exponents of the power law in (0, 3] (the loop searches 0.2-2)
SCALE_BOUNDS = {"vs": (0.0, 100.0), "v": (0.0, 100.0), "delta": (0.0, 3.0)}


def law_parameter(law: str, param: float | None) -> float:
    """The shape parameter a ``tanh``, ``stribeck`` or ``power`` law needs (a TypeError without it)."""
    if param is None:
        raise TypeError(f"the {law!r} friction law needs its shape parameter")
    return float(param)


def coulomb_columns(law: str, dq: np.ndarray, param: float | None = None, smooth: float | None = None) -> np.ndarray:
    """Columns of a Coulomb law at velocities ``dq`` (N,): (N, 1) for ``sign``/``tanh``, (N, 2) for
    ``stribeck`` (coefficients ``Fc`` and ``Fs - Fc``; its ``sign(dq)`` replaced by ``tanh(dq/smooth)``
    when ``smooth`` is given)."""
    dq = np.asarray(dq, float)
    if law == "sign":
        return (np.sign(dq) if smooth is None else np.tanh(dq / float(smooth)))[:, None]
    if law == "tanh":
        return np.tanh(dq / law_parameter(law, param))[:, None]
    if law == "stribeck":
        s = np.sign(dq) if smooth is None else np.tanh(dq / float(smooth))
        return np.column_stack([s, np.exp(-(dq / law_parameter(law, param)) ** 2) * s])
    raise ValueError(f"unknown Coulomb law {law!r}; use one of {COULOMB_LAWS}")


def viscous_columns(law: str, dq: np.ndarray, param: float | None = None) -> np.ndarray:
    """Column of a viscous law: ``dq`` (``linear``) or ``|dq|^delta sign(dq)`` (``power``), shape (N, 1)."""
    dq = np.asarray(dq, float)
    if law == "linear":
        return dq[:, None]
    if law == "power":
        return (np.abs(dq) ** law_parameter(law, param) * np.sign(dq))[:, None]
    raise ValueError(f"unknown viscous law {law!r}; use one of {VISCOUS_LAWS}")


@dataclass(frozen=True)
class FrictionLaw:
    """The friction law declared on one frame of a robot file.

    Attributes
    ----------
    frame : int
        Frame number ``j`` of the ``[[frames]]`` entry.
    kind : {"stribeck", "tanh", "power", "lugre", "dahl"}
    scale : float or None
        ``vs`` (Stribeck, LuGre), ``v`` (tanh) [rad/s or m/s] or ``delta`` (power); None for Dahl.
    presliding : mapping str -> float
        ``sigma0`` (and LuGre's ``sigma1``) when declared (dynamic laws only).
    """

    frame: int
    kind: str
    scale: float | None
    presliding: tuple[tuple[str, float], ...] = ()

    @property
    def scale_name(self) -> str | None:
        return SCALE_NAME[self.kind]

    @property
    def dynamic(self) -> bool:
        """Dahl or LuGre: a state law, identified by its sliding part."""
        return self.kind in DYNAMIC_KINDS

    @property
    def coulomb(self) -> str:
        """The Coulomb law of :func:`coulomb_columns` (``sign`` for the power and Dahl laws; the sliding
        part of LuGre is the Stribeck law)."""
        return {"stribeck": "stribeck", "tanh": "tanh", "lugre": "stribeck"}.get(self.kind, "sign")

    @property
    def viscous(self) -> str:
        return "power" if self.kind == "power" else "linear"

    def names(self) -> tuple[str, ...]:
        """Names of the magnitudes of :meth:`columns`: ``FS<j>`` (and ``FSS<j>`` = Fs - Fc), ``FV<j>``."""
        j = self.frame
        return (f"FS{j}", f"FSS{j}", f"FV{j}") if self.coulomb == "stribeck" else (f"FS{j}", f"FV{j}")

    def columns(self, dq: np.ndarray, scale: float | None = None) -> np.ndarray:
        """Columns (N, 2 or 3) of the law (of its sliding part for Dahl and LuGre) at velocities ``dq`` (N,),
        at ``scale`` (default: the declared one)."""
        s = self.scale if scale is None else float(scale)
        return np.hstack([coulomb_columns(self.coulomb, dq, s if self.coulomb != "sign" else None),
                          viscous_columns(self.viscous, dq, s if self.viscous == "power" else None)])

    def label(self, scale: float | None = None) -> str:
        s = self.scale if scale is None else scale
        return self.kind if self.scale_name is None or s is None else f"{self.kind}({self.scale_name}={s:.4g})"


def with_identified_laws(robot, doc: Mapping):
    """``robot`` with the scales of its declared friction laws replaced by those an identify result (its JSON
    ``doc``) fitted (``friction_laws`` entries with ``fitted`` true), for the exports; unchanged without any."""
    laws = dict(getattr(robot, "friction_laws", {}) or {})
    new = dict(laws)
    for e in doc.get("friction_laws", ()) or ():
        lw = laws.get(e.get("frame"))
        if lw is not None and e.get("fitted") and e.get("kind") == lw.kind and e.get("scale") is not None:
            new[lw.frame] = replace(lw, scale=float(e["scale"]))
    return robot if new == laws else replace(robot, friction_laws=new)


def read_friction_laws(frames: list, rows: list, bad: Callable[[str, str, str], None]) -> dict[int, FrictionLaw]:
    """The ``friction_law`` field of each ``[[frames]]`` entry: ``{kind = "stribeck", vs = ...}``,
    ``{kind = "tanh", v = ...}`` or ``{kind = "power", delta = ...}`` on an actuated moving joint whose
    drive terms include ``FS`` and ``FV`` (the law replaces them). Problems are reported through ``bad``
    (where, field, message); the valid laws by frame number."""
    out: dict[int, FrictionLaw] = {}
    if len(frames) != len(rows):   # an entry that is not a table is reported already
        return out
    for fr, r in zip(frames, rows):
        if not isinstance(fr, dict) or "friction_law" not in fr:
            continue
        law = _read_one(fr["friction_law"], r, f"frame {r.j}", bad)
        if law is not None:
            out[r.j] = law
    return out


def _read_one(raw, row, where: str, bad: Callable[[str, str, str], None]) -> FrictionLaw | None:
    fld = "friction_law"
    kinds = ", ".join(f'{{kind = "{k}"' + (f", {v} = ...}}" if v else "}") for k, v in SCALE_NAME.items())
    if not isinstance(raw, dict):
        bad(where, fld, f"must be an inline table, one of {kinds}; got {raw!r}")
        return None
    kind = raw.get("kind")
    if kind not in SCALE_NAME:
        bad(where, f"{fld}.kind", f"must be one of {', '.join(map(repr, DECLARED_KINDS))}, got {kind!r}")
        return None
    name = SCALE_NAME[kind]
    extra = DYNAMIC_KINDS.get(kind, ())
    allowed = ("kind",) + ((name,) if name else ()) + extra
    ok = True
    for k in sorted(set(raw) - set(allowed)):
        bad(where, f"{fld}.{k}", f"unknown field of a {kind!r} law (its fields: {', '.join(allowed)})")
        ok = False
    pres = _presliding(raw, extra, where, bad)
    if pres is None:
        ok = False
    if name is None:
        return _on_joint(FrictionLaw(row.j, kind, None, pres or ()), row, where, bad) if ok else None
    lo, hi = SCALE_BOUNDS[name]
    x = raw.get(name)
    if x is None:
        bad(where, f"{fld}.{name}", f"missing: a {kind!r} law needs its scale {name}")
        return None
    if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or not lo < x <= hi:
        bad(where, f"{fld}.{name}", f"must be a number in ({lo:g}, {hi:g}], got {x!r}")
        return None
    return _on_joint(FrictionLaw(row.j, kind, float(x), pres or ()), row, where, bad) if ok else None


def _presliding(raw: dict, keys: tuple[str, ...], where: str, bad: Callable[[str, str, str], None]
                ) -> tuple[tuple[str, float], ...] | None:
    """The optional pre-sliding constants of a dynamic law; None after a reported problem."""
    out = []
    for k in keys:
        if k not in raw:
            continue
        x = raw[k]
        lo, hi = PRESLIDING_BOUNDS[k]
        if isinstance(x, bool) or not isinstance(x, (int, float)) or not math.isfinite(x) or not lo < x <= hi:
            bad(where, f"friction_law.{k}", f"must be a number in ({lo:g}, {hi:g}], got {x!r}")
            return None
        out.append((k, float(x)))
    return tuple(out)


def _on_joint(law: FrictionLaw, row, where: str, bad: Callable[[str, str, str], None]) -> FrictionLaw | None:
    """``law`` if frame ``row`` can carry it: an actuated moving joint with FS and FV drive terms."""
    fld = "friction_law"
    if not row.is_moving or row.mu == 0:
        bad(where, fld, "only an actuated moving joint carries a friction law")
        return None
    missing = [k for k in ("FS", "FV") if k not in row.drive]
    if missing:
        bad(where, fld, f"the law replaces the joint's FS and FV terms: add {' and '.join(missing)} to its drive")
        return None
    return law
