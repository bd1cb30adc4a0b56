"""Plausibility of identified bodies: is the estimate that of the robot the file describes?

Physical consistency (every pseudo-inertia positive definite, [WKS2017]) admits bodies no real arm has:
a 34 kg forearm link, a centre of mass half a metre outside its link. This module checks an estimate
against three independent references and returns findings that name the body, the quantity, its value
and the bound; it never changes the estimate.

(a) **The robot file's nominal values** (when it declares them): the mass outside
    ``[m0 / MASS_FACTOR, MASS_FACTOR m0]``; the centre of mass further than ``COM_SHIFT_FRACTION`` of the
    link's extent (the longest side of its box, below) from the nominal one; a rotor inertia outside
    ``[IA0 / IA_FACTOR, IA_FACTOR IA0]``. These thresholds are engineering choices (a nominal value from a
    CAD or a URDF is rarely off by a factor 3), not values of a paper.

(b) **The link's geometry**. Without meshes (the robot file carries none; ``import-urdf`` keeps the
    joints and the inertials, not the ``<visual>``/``<collision>`` shapes), link j is bounded by the box, in
    frame j, of the points its MDH rows give: its origin, the foot ``(0, 0, -r_j)`` on z_j of the common
    normal from its antecedent, and for each child k the origin of frame k with the two corners of the
    path ``Rot(z, gamma_k) Trans(z, b_k) Rot(x, alpha_k) Trans(x, d_k)`` ([KK1986]); prismatic offsets
    are taken at q = 0 and at the joint limits when the file has them. The box is widened on every side
    by ``margin = max(MARGIN_MIN, MARGIN_FRACTION L)``, ``L`` the longest distance between two such points
    of any link of the robot (the links' housings and motors around their axes). Checks:

    * the centre of mass lies in the box;
    * the second moments are those of a mass distribution inside the box. The box is the intersection
      of three slabs ``lo_i <= x_i <= hi_i``; on a slab ``(x_i - lo_i)(hi_i - x_i) >= 0``, so a density
      supported in it satisfies ``int (x_i - lo_i)(hi_i - x_i) dm = tr(Q_i P) >= 0``, with ``P`` the
      pseudo-inertia ``[[Sigma, h], [h^T, m]]`` and ``Q_i`` the (degenerate) ellipsoid matrix of the slab:
      the bounding-ellipsoid condition ``tr(Q P) >= 0`` of [WKS2017] (density realisability on an ellipsoid)
      applied to each slab, the cuboid bound of [SC2019] in pseudo-inertia form. Linear in the ten
      standard parameters (:func:`slab_rows`); with ``P >= 0`` it implies the centre of mass in the box.
      ``identify --physical --bounded-bodies`` imposes exactly these rows
      (:func:`symoro_gen.identification.physical.identify_physical`).

(c) **Sign rules** of the unconstrained fit, which identifies base parameters. A base parameter is a
    linear combination of standard ones (``chi_b = K chi_st``, [GK1990]); only when every standard
    parameter in it is non-negative for any physical robot (the diagonal ``XX, YY, ZZ`` of the inertia
    at the frame origin, the mass ``M``, the rotor inertia ``IA``, the viscous and Coulomb friction
    ``FV, FS``) and every coefficient is positive must the base parameter be >= 0: ``IA2`` alone,
    ``ZZ1R = ZZ1 + IA1 + ZZ2 + ...``. Differences (``XX2R = XX2 - YY2``), first moments and offsets carry
    no sign. A negative value is reported with its 2 sigma. The bodies of the unconstrained fit are not
    checked against (a) and (b): base parameters do not give them (``--physical`` does).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..description.inertia import com_from_standard
from ..description.mdh import row_values
from ..description.model import RobotDescription
from ..params import INERTIAL_KINDS, split_name

__all__ = [
    "BOX_TOLERANCE",
    "COM_SHIFT_FRACTION",
    "IA_FACTOR",
    "MARGIN_FRACTION",
    "MARGIN_MIN",
    "MASS_FACTOR",
    "NONNEGATIVE_KINDS",
    "BodyBox",
    "Finding",
    "Plausibility",
    "body_boxes",
    "check_base",
    "check_standard",
    "slab_rows",
    "thresholds",
]

#: mass outside [m0 / MASS_FACTOR, MASS_FACTOR m0] of the nominal mass m0 is reported
MASS_FACTOR = 3.0
#: rotor inertia outside [IA0 / IA_FACTOR, IA_FACTOR IA0] of the nominal IA0 is reported
IA_FACTOR = 3.0
#: centre of mass further from the nominal one than this fraction of the link's extent is reported
COM_SHIFT_FRACTION = 0.5
#: the links' boxes are widened by max(MARGIN_MIN, MARGIN_FRACTION L) on every side [m]
MARGIN_MIN = 0.15
MARGIN_FRACTION = 0.5
#: a centre of mass or a slab integral outside the box by less than this share of the box (solver tolerances
#: of a bounded fit) is not reported
BOX_TOLERANCE = 1e-4
#: standard parameters non-negative for any physical body or drive
NONNEGATIVE_KINDS = ("XX", "YY", "ZZ", "M", "IA", "FV", "FS")

_UNITS = {"XX": "kg m^2", "YY": "kg m^2", "ZZ": "kg m^2", "M": "kg", "IA": "kg m^2", "FV": "N m s/rad",
          "FS": "N m"}
_WHAT = {"IA": "rotor inertia", "FV": "viscous friction", "FS": "Coulomb friction", "M": "mass"}


def thresholds() -> dict[str, float]:
    """The thresholds in force (also in the JSON ``plausibility`` block)."""
    return {"mass_factor": MASS_FACTOR, "ia_factor": IA_FACTOR, "com_shift_fraction": COM_SHIFT_FRACTION,
            "margin_min_m": MARGIN_MIN, "margin_fraction": MARGIN_FRACTION}


@dataclass(frozen=True)
class Finding:
    """One implausible quantity: ``body`` (``link 2``, ``joint 3``, ``payload (frame 8)``), ``quantity``
    (``mass``, ``com``, ``second moments``, ``IA``, a base parameter's name...), its ``value``, the
    ``bound`` it breaks, which ``fit`` (``unconstrained`` or ``physical``) and the sentence."""

    fit: str
    body: str
    quantity: str
    value: float
    bound: float
    message: str

    def to_dict(self) -> dict:
        return {"fit": self.fit, "body": self.body, "quantity": self.quantity, "value": _finite(self.value),
                "bound": _finite(self.bound), "message": self.message}


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


@dataclass(frozen=True, eq=False)
class BodyBox:
    """The box bounding link ``frame`` in its own frame: ``lo``, ``hi`` (margin included) and ``margin``."""

    frame: int
    lo: np.ndarray
    hi: np.ndarray
    margin: float

    @property
    def extent(self) -> float:
        """The longest side of the box [m]."""
        return float(np.max(self.hi - self.lo))

    def outside(self, c: np.ndarray) -> float:
        """Distance of the point ``c`` from the box (0 inside) [m]."""
        return float(np.linalg.norm(np.maximum(0.0, np.maximum(self.lo - c, c - self.hi))))

    def to_dict(self) -> dict:
        return {"frame": self.frame, "lo": [float(v) for v in self.lo], "hi": [float(v) for v in self.hi],
                "margin": float(self.margin)}


@dataclass(frozen=True)
class Plausibility:
    """The findings of every check of one identification, and the boxes used."""

    findings: tuple[Finding, ...] = ()
    boxes: tuple[BodyBox, ...] = ()
    notes: tuple[str, ...] = field(default=())

    @property
    def warnings(self) -> tuple[str, ...]:
        """One sentence per finding, then the notes (e.g. a solver status other than optimal)."""
        return tuple(f"{f.fit} fit: {f.message}" for f in self.findings) + self.notes

    def summary(self) -> str:
        """``warning: ...`` lines (empty when nothing is implausible)."""
        return "\n".join(f"warning: {w}" for w in self.warnings)

    def to_dict(self) -> dict:
        return {"findings": [f.to_dict() for f in self.findings], "notes": list(self.notes),
                "thresholds": thresholds(), "boxes": [b.to_dict() for b in self.boxes]}


# ---- (b) geometry ---------------------------------------------------------------------------------------------
def _joint_values(robot: RobotDescription, j: int) -> list[float]:
    """q = 0 and the joint limits of joint ``j`` when the file gives them."""
    out = [0.0]
    lim = robot.limits
    js = [r.j for r in robot.joints]
    if lim is not None and j in js and lim.q_min is not None and lim.q_max is not None \
            and len(lim.q_min) == len(js) == len(lim.q_max):
        k = js.index(j)
        out += [float(lim.q_min[k]), float(lim.q_max[k])]
    return out


def _link_points(robot: RobotDescription, j: int, subs) -> list[np.ndarray]:
    """Origin of frame j, the foot of the antecedent's common normal on z_j, the children's origins and
    path corners, all in frame j."""
    row = robot.row(j)
    pts = [np.zeros(3)]
    for q in _joint_values(robot, j):
        pts.append(np.array([0.0, 0.0, -row_values(row, subs, q)[5]]))
    for k in robot.children(j):
        child = robot.row(k)
        for q in _joint_values(robot, k):
            gam, b, al, d, _, r = row_values(child, subs, q)
            cg, sg, ca, sa = math.cos(gam), math.sin(gam), math.cos(al), math.sin(al)
            rz = np.array([[cg, -sg, 0.0], [sg, cg, 0.0], [0.0, 0.0, 1.0]])
            pts += [rz @ np.array([0.0, 0.0, b]), rz @ np.array([d, 0.0, b]),
                    rz @ np.array([d, -r * sa, b + r * ca])]
    return pts


def body_boxes(robot: RobotDescription) -> dict[int, BodyBox]:
    """The box of every moving link (frame number -> :class:`BodyBox`), see (b) of the module docstring."""
    subs = robot.geometry_subs()
    points = {r.j: np.array(_link_points(robot, r.j, subs)) for r in robot.joints}
    span = max((float(np.max(np.linalg.norm(p[:, None, :] - p[None, :, :], axis=2))) for p in points.values()),
               default=0.0)
    margin = max(MARGIN_MIN, MARGIN_FRACTION * span)
    return {j: BodyBox(j, p.min(axis=0) - margin, p.max(axis=0) + margin, margin) for j, p in points.items()}


def slab_rows(box: BodyBox) -> tuple[np.ndarray, np.ndarray]:
    """``A`` (3, 10) with ``A p10 >= 0`` iff ``tr(Q_i P(p10)) >= 0`` for the three slabs of ``box``.

    ``int (x_i - lo_i)(hi_i - x_i) dm = -Sigma_ii + (lo_i + hi_i) h_i - lo_i hi_i m`` with
    ``Sigma = tr(J_O)/2 E - J_O`` and ``h = MS`` ([WKS2017], the pseudo-inertia and its bounding-ellipsoid
    condition ``tr(Q P) >= 0``). Returns ``(A, (lo, hi))`` stacked as ``A`` and ``np.stack([lo, hi])``.
    """
    A = np.zeros((3, 10))
    for i in range(3):
        # Sigma_ii = (XX + YY + ZZ)/2 - J_ii
        diag = [0, 3, 5]
        for k in diag:
            A[i, k] -= 0.5
        A[i, diag[i]] += 1.0
        A[i, 6 + i] = box.lo[i] + box.hi[i]
        A[i, 9] = -box.lo[i] * box.hi[i]
    return A, np.stack([box.lo, box.hi])


# ---- (a) + (b) on a standard set -----------------------------------------------------------------------------
def _body_findings(fit: str, label: str, p: np.ndarray, p0: np.ndarray | None, box: BodyBox | None) -> list[Finding]:
    out: list[Finding] = []
    m, c, _ = com_from_standard(p)
    if not m > 0:
        return [Finding(fit, label, "mass", float(m), 0.0, f"{label}: mass {m:.3g} kg <= 0")]
    if p0 is not None and p0[9] > 0:
        m0 = float(p0[9])
        ratio = m / m0
        if ratio > MASS_FACTOR:
            out.append(Finding(fit, label, "mass", float(m), MASS_FACTOR * m0,
                               f"{label}: mass {m:.3g} kg, {ratio:.3g} x its nominal {m0:.3g} kg "
                               f"(plausible: up to {MASS_FACTOR:g} x)"))
        elif ratio < 1.0 / MASS_FACTOR:
            out.append(Finding(fit, label, "mass", float(m), m0 / MASS_FACTOR,
                               f"{label}: mass {m:.3g} kg, {ratio:.3g} x its nominal {m0:.3g} kg "
                               f"(plausible: down to 1/{MASS_FACTOR:g})"))
        if box is not None:
            c0 = np.asarray(p0[6:9], float) / m0
            shift, lim = float(np.linalg.norm(c - c0)), COM_SHIFT_FRACTION * box.extent
            if shift > lim:
                out.append(Finding(fit, label, "com_shift", shift, lim,
                                   f"{label}: centre of mass {_vec(c)} m, {shift:.3g} m from its nominal {_vec(c0)} m "
                                   f"(plausible: up to {lim:.3g} m, {COM_SHIFT_FRACTION:g} of the link's extent "
                                   f"{box.extent:.3g} m)"))
    if box is not None:
        d = box.outside(c)
        if d > BOX_TOLERANCE * box.extent:
            out.append(Finding(fit, label, "com", d, 0.0,
                               f"{label}: centre of mass {_vec(c)} m lies {d:.3g} m outside the link's box "
                               f"{_vec(box.lo)}..{_vec(box.hi)} m (frame origins of the link and its children "
                               f"+ {box.margin:.3g} m)"))
        else:
            A, _ = slab_rows(box)
            slack = A @ p
            i = int(np.argmin(slack))
            if slack[i] < -BOX_TOLERANCE * m * box.extent ** 2:
                half = float(box.hi[i] - box.lo[i]) / 2
                same = p0 is not None and float((A @ p0)[i]) < 0
                out.append(Finding(fit, label, "second_moments", float(slack[i]), 0.0,
                                   f"{label}: inertia too large for its mass {m:.3g} kg within the link's box "
                                   f"(along {'xyz'[i]}: int (x-lo)(hi-x) dm = {slack[i]:.3g} kg m^2 < 0, "
                                   f"half-width {half:.3g} m)"
                                   + ("; so is the robot file's nominal body" if same else "")))
    return out


def _vec(v) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in np.asarray(v, float)) + ")"


def check_standard(robot: RobotDescription, standard: Mapping[str, float], *, nominal: Mapping[str, float] | None = None,
                   boxes: Mapping[int, BodyBox] | None = None, fit: str = "physical") -> list[Finding]:
    """Checks (a) and (b) of a standard set (``name -> value``: the links, the payload when present,
    the drive terms).

    Parameters
    ----------
    robot : RobotDescription
        Gives the links (and their boxes when ``boxes`` is None).
    standard : mapping
        Standard parameters (e.g. :meth:`PhysicalResult.standard_map`).
    nominal : mapping, optional
        Nominal values; default the robot file's (links, payload).
    """
    nominal = dict(robot.nominal or {}) if nominal is None else dict(nominal)
    boxes = body_boxes(robot) if boxes is None else boxes
    out: list[Finding] = []
    frames = [r.j for r in robot.joints] + ([robot.payload] if robot.payload is not None else [])
    for j in frames:
        names = [f"{k}{j}" for k in INERTIAL_KINDS]
        if f"M{j}" not in standard:
            continue
        p = np.array([float(standard.get(n, 0.0)) for n in names])
        p0 = np.array([float(nominal.get(n, 0.0)) for n in names])
        payload = j == robot.payload
        label = f"payload (frame {j})" if payload else f"link {j}"
        out += _body_findings(fit, label, p, p0 if np.any(p0) else None, None if payload else boxes.get(j))
    for r in robot.joints:
        ia, ia0 = standard.get(f"IA{r.j}"), float(nominal.get(f"IA{r.j}", 0.0))
        if ia is not None and ia0 > 0 and not (ia0 / IA_FACTOR <= ia <= IA_FACTOR * ia0):
            bound = IA_FACTOR * ia0 if ia > ia0 else ia0 / IA_FACTOR
            out.append(Finding(fit, f"joint {r.j}", f"IA{r.j}", float(ia), bound,
                               f"joint {r.j}: rotor inertia IA{r.j} = {ia:.3g} kg m^2, {ia / ia0:.3g} x its nominal "
                               f"{ia0:.3g} (plausible: {1 / IA_FACTOR:.3g} to {IA_FACTOR:g} x)"))
    return out


# ---- (c) sign rules on base parameters -----------------------------------------------------------------------
def _kind(name: str) -> tuple[str, int] | None:
    try:
        kind, j, _ = split_name(name)
    except ValueError:
        return None
    return kind, j


def _who(kind: str, j: int, payload: int | None) -> str:
    if kind in ("IA", "FV", "FS", "OFF"):
        return f"joint {j}"
    return f"payload (frame {j})" if j == payload else f"link {j}"


def _relation(row: np.ndarray, standard: Sequence[str]) -> str:
    terms = [(c, n) for c, n in zip(row, standard) if abs(c) > 1e-12]
    parts = [(n if abs(c - 1) < 1e-12 else f"{c:.3g} {n}") for c, n in terms[:4]]
    return " + ".join(parts) + (" + ..." if len(terms) > 4 else "")


def check_base(model, names: Sequence[str], values: Sequence[float], std: Sequence[float] | None = None, *,
               payload: int | None = None, nominal: Mapping[str, float] | None = None,
               fit: str = "unconstrained") -> list[Finding]:
    """Check (c) of base parameters ``names -> values`` (an unconstrained fit), and (a) for a rotor inertia
    or a mass that is a standard parameter alone (``IA2``, not ``IA3R``).

    ``model`` gives the regrouping ``K`` (``model.base_parameters`` is linear); names that are not base
    parameters (payload or other columns) stand for themselves.
    """
    st = tuple(model.STANDARD_NAMES)
    K = np.asarray(model.base_parameters(np.eye(len(st))), float).T  # (n_base, n_standard)
    if K.shape != (len(model.BASE_NAMES), len(st)):  # not a plain regrouping: the names alone are checked
        K = np.zeros((0, len(st)))
    bidx = {n: i for i, n in enumerate(model.BASE_NAMES)} if K.size else {}
    nominal = dict(nominal or {})
    sd = list(std) if std is not None else [math.nan] * len(names)
    out: list[Finding] = []
    for n, v, s in zip(names, values, sd):
        v = float(v)
        row = K[bidx[n]] if n in bidx else None
        if row is not None:
            used = [(c, st[k]) for k, c in enumerate(row) if abs(c) > 1e-12 * max(1.0, np.abs(row).max())]
        else:
            used = [(1.0, n)]
        kinds = [_kind(m) for _, m in used]
        if not used or any(k is None or k[0] not in NONNEGATIVE_KINDS for k in kinds) or any(c < 0 for c, _ in used):
            continue
        kj = _kind(n)
        if kj is None:
            continue
        who = _who(kj[0], kj[1], payload)
        alone = len(used) == 1 and abs(used[0][0] - 1.0) < 1e-12
        unit = _UNITS.get(kj[0], "")
        if v < 0:
            sig = f"2 sigma {2 * s:.3g}: " + ("within 2 sigma of 0" if 2 * s >= -v else "beyond 2 sigma") \
                if math.isfinite(s) else "no statistics"
            what = f"{_WHAT[kj[0]]} {n}" if alone and kj[0] in _WHAT else n
            why = "" if alone or row is None else \
                f", but {n} = {_relation(row, st)} is a sum of terms >= 0 for any physical robot"
            out.append(Finding(fit, who, n, v, 0.0, f"{who}: {what} = {v:.3g} {unit} < 0{why} ({sig})"))
        elif alone and kj[0] in ("IA", "M"):
            v0 = float(nominal.get(used[0][1], 0.0))
            f = IA_FACTOR if kj[0] == "IA" else MASS_FACTOR
            if v0 > 0 and not (v0 / f <= v <= f * v0):
                out.append(Finding(fit, who, n, v, f * v0 if v > v0 else v0 / f,
                                   f"{who}: {_WHAT[kj[0]]} {n} = {v:.3g} {unit}, {v / v0:.3g} x its nominal {v0:.3g} "
                                   f"(plausible: {1 / f:.3g} to {f:g} x)"))
    return out

