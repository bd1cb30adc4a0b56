"""Parse and validate TOML robot files into :class:`RobotDescription`.

Every problem found is collected and reported at once in a :class:`RobotFileError`
naming file, frame and field.
"""
from __future__ import annotations

import difflib
import hashlib
import math
import os
import re
import sys
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import sympy as sp

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

from ..errors import Problem, RobotFileError, RobotFileWarning
from ..params import DRIVE_KINDS, INERTIAL_KINDS
from ..paths import robots_dir
from .elastic import ElasticJoint, parse_elastic
from .expr import ExprError, parse_expression
from .friction_law import read_friction_laws
from .inertia import check_physical_consistency
from .loops import check_actuation, check_passive, parse_couplings, parse_loops
from .model import (
    FIXED,
    PRISMATIC,
    REVOLUTE,
    Coupling,
    DriveChain,
    JointLimits,
    LoopClosure,
    MdhRow,
    RobotDescription,
    q_symbol,
)

TOP_KEYS = {"name", "source", "gravity", "payload", "drive", "values", "frames", "nominal", "drive_chain", "limits",
            "loops", "loop_reference", "elastic", "base", "contacts"}
FRAME_REQUIRED = ("j", "ant", "sigma", "alpha", "d", "theta", "r")
FRAME_OPTIONAL = ("mu", "gamma", "b", "drive", "mimic", "name", "elastic", "friction_law")
CHAIN_KEYS = {"ratios", "coupling", "offsets", "directions"}
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_RESERVED = {"q", "pi", "sin", "cos", "tan", "sqrt", "atan2"}


def resolve_robot_path(name_or_path: str | os.PathLike) -> Path:
    """A robot name in ``robots/`` (``"lwr4"``) or the path of a ``.toml`` file."""
    p = Path(name_or_path)
    if p.suffix == ".toml" or p.exists():
        if not p.exists():
            raise RobotFileError([Problem(str(p), "", "", "file not found")])
        return p
    cand = robots_dir() / f"{name_or_path}.toml"
    if not cand.exists():
        known = sorted(x.stem for x in robots_dir().glob("*.toml"))
        near = difflib.get_close_matches(str(name_or_path).lower(), known, n=1, cutoff=0.6)
        mean = f"did you mean {near[0]}? " if near else ""
        raise RobotFileError(
            [Problem(str(name_or_path), "", "", f"no such robot; {mean}known robots: {', '.join(known) or 'none'}")]
        )
    return cand


def load_robot(name_or_path: str | os.PathLike) -> RobotDescription:
    """Parse a robot given by name (``robots/<name>.toml``) or path."""
    return parse_robot(resolve_robot_path(name_or_path))


def parse_robot(path: str | os.PathLike) -> RobotDescription:
    """Parse the TOML robot file at ``path``."""
    p = Path(path)
    try:
        text = p.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise RobotFileError([Problem(str(p), "", "", "file not found")]) from None
    except UnicodeDecodeError as exc:
        raise RobotFileError([Problem(str(p), f"byte {exc.start}", "", f"not UTF-8 text ({exc.reason}); "
                                      "a robot file is TOML text")]) from None
    except OSError as exc:  # a folder, no permission...
        raise RobotFileError([Problem(str(p), "", "", f"cannot read: {exc.strerror or exc}")]) from None
    _refuse_other_formats(p, text)
    return parse_robot_text(text, file=str(p))


def _refuse_other_formats(p: Path, text: str) -> None:
    """A URDF or a SYMORO ``.par`` file given where a robot file is expected: say what it is and which command
    turns it into a robot file (instead of a TOML syntax error)."""
    head = text.lstrip("\ufeff \t\r\n")[:4096]
    suffix = p.suffix.lower()
    if suffix in (".urdf", ".xacro") or (head.startswith("<") and "<robot" in head):
        raise RobotFileError([Problem(str(p), "", "", "a URDF (XML), not a robot file (TOML)")],
                             hint=f"convert it first: `symoro-gen import-urdf {p} -o {p.with_suffix('.toml')}` writes "
                                  "the robot file; then give that file")
    if suffix == ".par":
        raise RobotFileError([Problem(str(p), "", "", "a SYMORO+ .par file, not a robot file (TOML)")],
                             hint=f"convert it first: `symoro-gen import-par {p} -o {p.with_suffix('.toml')}` writes "
                                  "the robot file; then give that file")


#: the largest magnitude of a number of a robot file: no length, mass, inertia, friction, gain or limit of a robot
#: comes near it (1e300 was accepted, and its squares overflow in the regressor)
MAX_MAGNITUDE = 1e12
#: how a number of a robot file must be, in the messages
_FINITE = f"|x| <= {MAX_MAGNITUDE:g}"


def _is_number(v) -> bool:
    """A finite int or float of magnitude at most :data:`MAX_MAGNITUDE` (TOML booleans, inf and nan excluded)."""
    return (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
            and abs(v) <= MAX_MAGNITUDE)


class _Problems:
    """The problems found in one robot file, all reported at once in a :class:`RobotFileError`."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.found: list[Problem] = []

    def bad(self, where: str, fld: str, msg: str) -> None:
        self.found.append(Problem(self.file, where, fld, msg))

    def at(self, where: str, fld: str) -> bool:
        return any(p.where == where and p.field == fld for p in self.found)


@dataclass
class _Values:
    """The ``[values]`` table: the valid entries, the names already reported, ``all_reported`` when the
    table itself is (its symbols are not reported again one by one)."""

    raw: dict
    values: dict[str, float]
    reported: set[str]
    all_reported: bool


@dataclass
class _Frames:
    """The ``[[frames]]`` entries read: the rows, where each symbol is first used, the frames whose sigma is
    missing or bad (the checks that depend on it are skipped)."""

    entries: list
    rows: list[MdhRow]
    used_symbols: dict[str, str]
    bad_sigma: set[int]


def parse_robot_text(text: str, file: str = "<string>") -> RobotDescription:
    """Parse robot-file text; ``file`` is used in messages only."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"at line (\d+), column (\d+)", str(exc))
        where = f"line {m.group(1)}, column {m.group(2)}" if m else ""
        raise RobotFileError([Problem(file, where, "", f"malformed TOML: {exc}")]) from None
    probs = _Problems(file)
    bad = probs.bad
    for k in sorted(set(doc) - TOP_KEYS):
        bad("top level", k, f"unknown field (allowed: {', '.join(sorted(TOP_KEYS))})")
    name, source, gravity = _read_header(doc, file, bad)
    base = _read_base(doc, bad)
    default_drive = _check_drive(doc.get("drive", list(DRIVE_KINDS)), "top level", bad)
    if default_drive is None:  # reported; all four kinds, so that [nominal] drive terms are not reported again
        default_drive = DRIVE_KINDS
    vals = _read_values(doc, bad)
    fr = _read_frames(doc, default_drive, vals, probs)
    rows, bad_sigma = fr.rows, fr.bad_sigma
    for s, where in sorted(fr.used_symbols.items()):
        if s not in vals.values and s not in vals.reported and not vals.all_reported:
            bad(where, "values", f"symbol {s!r} has no numeric value (add it under [values])")
    if not probs.found:
        _check_finite_geometry(fr.entries, rows, vals.values, bad)
    _check_frame_order(rows, bad_sigma, bad)
    payload = _read_payload(doc.get("payload"), rows, bad_sigma, bad)
    nominal = _read_nominal(doc, rows, payload, bad_sigma, probs) if "nominal" in doc else None

    # per-joint tables of a closed-loop robot are per actuated joint (the passive ones are not logged)
    mimic_frames = frozenset(i for i, f in enumerate(fr.entries, start=1) if isinstance(f, dict) and "mimic" in f)
    coupled = bool(mimic_frames)
    model_rows = [r for r in rows if not (r.is_moving and r.mu == 0)] if ("loops" in doc or coupled) else rows
    passive_rows = [r for r in rows if r.is_moving and r.mu == 0] if ("loops" in doc or coupled) else []
    chain = None
    if "drive_chain" in doc:
        chain = _parse_chain(doc["drive_chain"], sum(r.is_moving for r in model_rows), bad)
    limits = _parse_limits(doc["limits"], model_rows, bad, passive_rows) if "limits" in doc else None
    loops: tuple[LoopClosure, ...] = ()
    loop_reference: dict[str, float] = {}
    if ("loops" in doc or "loop_reference" in doc) and not bad_sigma:
        loops, loop_reference = parse_loops(doc.get("loops"), doc.get("loop_reference"), rows, vals.values, bad)
    couplings: tuple[Coupling, ...] = ()
    if coupled and not bad_sigma:
        couplings = parse_couplings(fr.entries, rows, bad)
    if not bad_sigma:
        check_passive(rows, loops, couplings, bad, mimic_frames)
    if loops and not probs.found:
        check_actuation(rows, loops, vals.values, bad, reference=loop_reference)
    friction_laws = read_friction_laws(fr.entries, rows, bad) if not bad_sigma else {}
    elastic: tuple[ElasticJoint, ...] = ()
    if not bad_sigma:
        elastic = parse_elastic(doc.get("elastic"), fr.entries, rows, bad)

    contacts = _read_contacts(doc, rows, base, bad) if "contacts" in doc and not bad_sigma else ()

    if probs.found:
        raise RobotFileError(probs.found)
    return RobotDescription(
        name=name,
        rows=tuple(rows),
        gravity=gravity,
        values=vals.values,
        payload=payload,
        nominal=nominal,
        source=source,
        file=file,
        file_hash=hashlib.sha256(text.encode("utf-8")).hexdigest(),
        drive_chain=chain,
        limits=limits,
        loops=loops,
        loop_reference=loop_reference,
        couplings=couplings,
        friction_laws=friction_laws,
        elastic=elastic,
        base=base,
        contacts=contacts,
    )


def _read_header(doc: dict, file: str, bad: Callable[[str, str, str], None]
                 ) -> tuple[str, str, tuple[float, float, float]]:
    """``name`` (default: the file's stem), ``source`` and ``gravity`` of the top level."""
    name = doc.get("name", Path(file).stem if file != "<string>" else "")
    if not isinstance(name, str) or not _NAME_RE.match(name or ""):
        bad("top level", "name", f"robot name must be an identifier, got {name!r}")
        name = "robot"
    source = doc.get("source", "")
    if not isinstance(source, str):
        bad("top level", "source", "must be a string")
        source = ""
    gravity = doc.get("gravity", [0.0, 0.0, -9.81])
    if not (isinstance(gravity, list) and len(gravity) == 3 and all(_is_number(g) for g in gravity)):
        bad("top level", "gravity", f"must be a list of 3 numbers (finite, {_FINITE}), got {gravity!r}")
        gravity = [0.0, 0.0, -9.81]
    return name, source, (float(gravity[0]), float(gravity[1]), float(gravity[2]))


def _read_contacts(doc: dict, rows: list, base: str, bad: Callable[[str, str, str], None]) -> tuple[int, ...]:
    """The top-level ``contacts`` of a floating base: the frames (each a frame number ``j`` or a frame's
    ``name``) whose pose and Jacobian its generated package emits (docs/robot-file.md, "Floating base")."""
    raw = doc["contacts"]
    if base != "floating":
        bad("top level", "contacts", 'contact frames are for a floating base (base = "floating")')
        return ()
    if not isinstance(raw, list):
        bad("top level", "contacts", f"must be a list of frame numbers or frame names, got {raw!r}")
        return ()
    by_name = {r.name: r.j for r in rows if r.name is not None}
    out: list[int] = []
    for i, c in enumerate(raw):
        j = by_name.get(c) if isinstance(c, str) else (c if isinstance(c, int) and not isinstance(c, bool) else None)
        if j is None or not 1 <= j <= len(rows):
            bad("top level", f"contacts[{i}]", f"{c!r} is not a frame number (1..{len(rows)}) or a frame's name")
        elif j in out:
            bad("top level", f"contacts[{i}]", f"frame {j} is listed twice")
        else:
            out.append(j)
    return tuple(out)


#: the values of the top-level ``base`` field (docs/robot-file.md, "Floating base")
BASE_KINDS = ("fixed", "floating")


def _read_base(doc: dict, bad: Callable[[str, str, str], None]) -> str:
    """The top-level ``base``: ``"fixed"`` (default: frame 0 is the ground) or ``"floating"`` (frame 0 is a
    free body with 6 degrees of freedom whose velocity and acceleration are inputs of the Newton-Euler
    recursion, [KD2002] ch. 9). A floating base takes a tree: closed loops and coupled joints are refused."""
    base = doc.get("base", "fixed")
    if base not in BASE_KINDS:
        bad("top level", "base", f"must be one of {', '.join(repr(b) for b in BASE_KINDS)}, got {base!r}")
        return "fixed"
    frames = doc.get("frames")
    mimic = isinstance(frames, list) and any(isinstance(f, dict) and "mimic" in f for f in frames)
    unsupported = [k for k in ("loops", "loop_reference") if k in doc] + (["mimic"] if mimic else [])
    if base == "floating" and unsupported:
        bad("top level", "base", f"a floating base is not supported with {', '.join(unsupported)} "
                                 "(closed loops and coupled joints)")
    return str(base)


def _read_values(doc: dict, bad: Callable[[str, str, str], None]) -> _Values:
    """The geometric constants of ``[values]``."""
    raw = doc.get("values", {})
    values: dict[str, float] = {}
    reported: set[str] = set()
    if not isinstance(raw, dict):
        bad("top level", "values", "must be a table of NAME = number")
        return _Values({}, values, reported, True)
    for k, v in raw.items():
        if k in _RESERVED or not _NAME_RE.match(k):
            bad("[values]", k, "reserved or invalid symbol name")
            reported.add(k)
        elif not _is_number(v):
            bad("[values]", k, f"value must be a finite number ({_FINITE}), got {v!r}")
            reported.add(k)
        else:
            values[k] = float(v)
    return _Values(raw, values, reported, False)


def _read_frames(doc: dict, default_drive: tuple[str, ...], vals: _Values, probs: _Problems) -> _Frames:
    """The MDH table. Fields are checked in dependency order (sigma before mu, drive and the joint
    variable); a field already reported stops the checks that depend on it, so one bad field gives one
    line."""
    frames = doc.get("frames")
    out = _Frames([], [], {}, set())
    if not isinstance(frames, list) or not frames:
        probs.bad("top level", "frames", "missing: the MDH table must be given as [[frames]] entries")
        return out
    out.entries = frames
    for idx, fr in enumerate(frames, start=1):
        where = f"frame {fr.get('j', idx) if isinstance(fr, dict) else idx}"
        if not isinstance(fr, dict):
            probs.bad(where, "", "each [[frames]] entry must be a table")
            continue
        out.rows.append(_read_frame(idx, fr, where, default_drive, vals, out, probs))
    return out


def _read_frame(idx: int, fr: dict, where: str, default_drive: tuple[str, ...], vals: _Values, out: _Frames,
                probs: _Problems) -> MdhRow:
    """One ``[[frames]]`` entry (``out``: the symbols used and the frames whose sigma is bad, updated)."""
    bad = probs.bad
    for k in sorted(set(fr) - set(FRAME_REQUIRED) - set(FRAME_OPTIONAL)):
        bad(where, k, f"unknown field (allowed: {', '.join(FRAME_REQUIRED + FRAME_OPTIONAL)})")
    missing = [k for k in FRAME_REQUIRED if k not in fr]
    for k in missing:
        bad(where, k, "missing field")
    j = fr.get("j")
    if not (isinstance(j, int) and not isinstance(j, bool)) or j != idx:
        bad(where, "j", f"frames must be numbered 1, 2, ... in order; entry {idx} has j = {j!r}")
        j = idx
    sigma = fr.get("sigma", 0)
    sigma_ok = "sigma" in fr and sigma in (0, 1, 2) and not isinstance(sigma, bool)
    if "sigma" in fr and not sigma_ok:
        bad(where, "sigma", f"must be 0 (revolute), 1 (prismatic) or 2 (fixed), got {sigma!r}")
    if not sigma_ok:
        sigma = 0
        out.bad_sigma.add(j)
    ant, mu, drive = _frame_joint(fr, where, j, sigma, default_drive, bad)
    q = q_symbol(j)
    ex = _frame_geometry(fr, where, q, vals, out.used_symbols, bad)
    if sigma_ok:
        _check_joint_variable(fr, where, sigma, q, ex, missing, probs)
    return MdhRow(j=j, ant=ant, sigma=sigma, mu=mu, drive=tuple(drive), **ex, name=_frame_name(fr, where, out, bad))


def _frame_name(fr: dict, where: str, out: _Frames, bad: Callable[[str, str, str], None]) -> str | None:
    """The frame's optional ``name`` (the joint's name in the robot's logs and URDF: ROS bags are matched
    by it): a non-empty string without spaces, unique in the file."""
    name = fr.get("name")
    if name is None:
        return None
    if not isinstance(name, str) or not name or any(ch.isspace() for ch in name):
        bad(where, "name", f"must be a non-empty string without spaces (the joint's name in its logs), got {name!r}")
        return None
    other = next((r.j for r in out.rows if r.name == name), None)
    if other is not None:
        bad(where, "name", f"{name!r} is already the name of frame {other}")
        return None
    return name


def _frame_joint(fr: dict, where: str, j: int, sigma: int, default_drive: tuple[str, ...],
                 bad: Callable[[str, str, str], None]) -> tuple[int, int, tuple[str, ...]]:
    """``ant``, ``mu`` and the drive terms of frame ``j``."""
    ant = fr.get("ant", j - 1)
    if not (isinstance(ant, int) and not isinstance(ant, bool)):
        bad(where, "ant", f"must be an integer frame number, got {ant!r}")
        ant = j - 1
    elif ant < 0 or ant >= j:
        what = "points forward (ant must be < j)" if ant >= j else "is out of range (ant >= 0)"
        bad(where, "ant", f"antecedent {ant} {what}")
        ant = j - 1
    mu = fr.get("mu", 0 if sigma == FIXED or "mimic" in fr else 1)  # a coupled joint is passive
    if mu not in (0, 1) or isinstance(mu, bool):
        bad(where, "mu", f"must be 0 (passive) or 1 (actuated), got {mu!r}")
        mu = 1
    if sigma == FIXED and mu == 1 and "mu" in fr:
        bad(where, "mu", "a fixed frame (sigma = 2) cannot be actuated")
    drive = fr.get("drive")
    if drive is None:
        drive = tuple(default_drive) if (sigma != FIXED and mu == 1) else ()
    else:
        checked = _check_drive(drive, where, bad)
        drive = checked if checked is not None else (tuple(default_drive) if sigma != FIXED else ())
        if sigma == FIXED and checked:
            bad(where, "drive", "a fixed frame has no drive chain")
    return ant, mu, drive


def _frame_geometry(fr: dict, where: str, q: sp.Symbol, vals: _Values, used_symbols: dict[str, str],
                    bad: Callable[[str, str, str], None]) -> dict[str, sp.Expr]:
    """The six geometric expressions of a frame (0 for a reported one); the first frame using each
    symbol is noted in ``used_symbols``."""
    syms = {k: sp.Symbol(k, real=True) for k in vals.raw if isinstance(k, str)}
    syms["q"] = q
    ex: dict[str, sp.Expr] = {}
    for k in ("gamma", "b", "alpha", "d", "theta", "r"):
        raw = fr.get(k, 0)
        try:
            e = parse_expression(raw, syms)
        except ExprError as exc:
            if not (vals.all_reported and str(exc).startswith("unknown name")):  # [values] already reported
                bad(where, k, str(exc))
            e = sp.Integer(0)
        for s in e.free_symbols:
            if s != q:
                used_symbols.setdefault(s.name, where)
        ex[k] = e
    return ex


def _check_joint_variable(fr: dict, where: str, sigma: int, q: sp.Symbol, ex: dict[str, sp.Expr],
                          missing: list[str], probs: _Problems) -> None:
    """The joint variable ``q`` appears in theta (revolute) or r (prismatic) only, as ``±q + constant``."""
    var_field = {REVOLUTE: "theta", PRISMATIC: "r"}.get(sigma)
    for k, e in ex.items():
        if q in e.free_symbols and k != var_field:
            if sigma == FIXED:
                probs.bad(where, k, "a fixed frame (sigma = 2) has no joint variable q")
            else:
                probs.bad(where, k, f"joint variable q may only appear in {var_field} for sigma = {sigma}")
    if var_field and var_field not in missing and not probs.at(where, var_field):
        e = ex[var_field]
        if q not in e.free_symbols:
            probs.bad(where, var_field, f"must contain the joint variable q (e.g. \"q\" or \"q - pi/2\"), "
                                        f"got {fr.get(var_field)!r}")
        elif sp.diff(e, q) not in (1, -1) or sp.diff(e, q, 2) != 0:
            probs.bad(where, var_field, f"must be q + constant (or -q + constant), got {fr.get(var_field)!r}")


def _check_finite_geometry(frames: list, rows: list[MdhRow], values: dict[str, float],
                           bad: Callable[[str, str, str], None]) -> None:
    """Every geometric field is finite with the ``[values]`` given (``d = "1/L3"`` with ``L3 = 0`` is not) and at
    most :data:`MAX_MAGNITUDE` at q = 0."""
    vsubs = {sp.Symbol(k, real=True): sp.Rational(v) for k, v in values.items()}
    for fr, r in zip(frames, rows):
        for k in ("gamma", "b", "alpha", "d", "theta", "r"):
            val = getattr(r, k).xreplace({**vsubs, q_symbol(r.j): sp.Integer(0)})
            if val.is_finite is not True:
                what = "infinite (division by zero)" if val.has(sp.zoo, sp.oo) else "undefined"
                bad(f"frame {r.j}", k, f"{fr.get(k)!r} is {what} with the [values] given")
            elif val.is_number and val.is_real is True and abs(float(val)) > MAX_MAGNITUDE:
                bad(f"frame {r.j}", k, f"{fr.get(k)!r} is {float(val):g} with the [values] given: not a length or "
                                       f"angle of a robot (finite, {_FINITE})")


def _check_frame_order(rows: list[MdhRow], bad_sigma: set[int], bad: Callable[[str, str, str], None]) -> None:
    """Moving frames first, fixed ones after; at least one moving joint."""
    seen_fixed = None
    for r in rows:
        if r.j in bad_sigma:
            continue
        if r.sigma == FIXED:
            seen_fixed = seen_fixed or r.j
        elif seen_fixed is not None:
            bad(f"frame {r.j}", "sigma", f"moving frames must come before fixed ones (frame {seen_fixed} is fixed)")
    if rows and not bad_sigma and not any(r.is_moving for r in rows):
        bad("top level", "frames", "the robot has no moving joint")


def _read_payload(payload: object, rows: list[MdhRow], bad_sigma: set[int],
                  bad: Callable[[str, str, str], None]) -> int | None:
    """The payload frame (a fixed frame), None when absent or reported."""
    if payload is None:
        return None
    if not (isinstance(payload, int) and not isinstance(payload, bool)):
        bad("top level", "payload", f"must be the frame number of the payload, got {payload!r}")
        return None
    if not (1 <= payload <= len(rows)):
        bad("top level", "payload", f"payload frame {payload} does not exist (frames 1..{len(rows)})")
        return None
    if payload in bad_sigma:
        return None  # its sigma is already reported
    if rows[payload - 1].sigma != FIXED:
        bad(f"frame {payload}", "sigma", "the payload frame must be fixed (sigma = 2)")
        return None
    return payload


def _read_nominal(doc: dict, rows: list[MdhRow], payload: int | None, bad_sigma: set[int],
                  probs: _Problems) -> dict[str, float]:
    """The ``[nominal]`` values of the standard parameters of the moving links, their drive terms and the
    payload."""
    raw = doc["nominal"]
    nominal: dict[str, float] = {}
    if not isinstance(raw, dict):
        probs.bad("[nominal]", "", "must be a table of PARAM = number")
        return nominal
    allowed = set()
    for r in rows:
        if r.is_moving:
            allowed |= {f"{k}{r.j}" for k in INERTIAL_KINDS}
            allowed |= {f"{k}{r.j}" for k in r.drive}
    if payload is not None:
        allowed |= {f"{k}{payload}" for k in INERTIAL_KINDS}
    floating = doc.get("base") == "floating"  # a floating base link (frame 0) has its 10 inertial parameters
    if floating:
        allowed |= {f"{k}0" for k in INERTIAL_KINDS}
    rejected_payload = set()
    payload_given = doc.get("payload")  # a bad payload is reported once, not again in [nominal]
    if payload is None and payload_given is not None:
        # the payload is already reported: its nominal values (on the frame it names, or on any
        # fixed frame when it names none) are not reported again
        frames_ = {payload_given} if isinstance(payload_given, int) and not isinstance(payload_given, bool) \
            else {r.j for r in rows if r.sigma == FIXED or r.j in bad_sigma}
        rejected_payload = {f"{k}{f_}" for k in INERTIAL_KINDS for f_ in frames_}
    for k, v in raw.items():
        if k in rejected_payload:
            continue  # the payload entry is already reported
        if k not in allowed:
            probs.bad("[nominal]", k, "not a standard parameter of this robot")
        elif not _is_number(v):
            probs.bad("[nominal]", k, f"value must be a finite number ({_FINITE}), got {v!r}")
        elif v < 0 and k.rstrip("0123456789") in _NON_NEGATIVE:
            probs.bad("[nominal]", k, f"{_NON_NEGATIVE[k.rstrip('0123456789')]} cannot be negative, got {v!r}")
        else:
            nominal[k] = float(v)
    _warn_inconsistent_inertia(nominal, rows, payload, probs.file, floating)
    return nominal


_NON_NEGATIVE = {"M": "a mass", "IA": "a rotor inertia", "FV": "a viscous friction coefficient",
                 "FS": "a Coulomb friction coefficient"}


def _warn_inconsistent_inertia(nominal: dict, rows, payload, file: str, floating: bool = False) -> None:
    """Warn (:class:`RobotFileWarning`) about nominal links that are not a rigid body.

    Checked for every link whose nominal values give its mass and the three moments ``XX``,
    ``YY``, ``ZZ`` (a partial prior, e.g. ``ZZ1`` alone, cannot be judged; missing products and
    first moments are 0), with a positive mass and some inertia (a point mass is accepted): the
    pseudo-inertia must be positive
    definite (Wensing, Kim & Slotine, IEEE RA-L 2017; :func:`~.inertia.check_physical_consistency`).
    A warning rather than an error: nominal values are priors and start values, and the
    identification itself does not need them to be consistent.
    """
    links = [0] * floating + [r.j for r in rows if r.is_moving] + ([payload] if payload is not None else [])
    for j in links:
        if not all(f"{k}{j}" in nominal for k in ("M", "XX", "YY", "ZZ")):
            continue
        p10 = np.array([nominal.get(f"{k}{j}", 0.0) for k in INERTIAL_KINDS])
        if not (p10[9] > 0 and np.any(p10[:6] != 0)):
            continue
        try:
            with np.errstate(all="ignore"):
                reasons = check_physical_consistency(p10, tol=1e-9)
        except np.linalg.LinAlgError:  # overflow of values near the float range
            reasons = ["values too large to check"]
        if reasons:
            warnings.warn(f"{file}, [nominal], fields 'XX{j}'..'M{j}': the nominal values of link {j} are not "
                          f"those of a rigid body: {'; '.join(reasons)}", RobotFileWarning, stacklevel=4)


def _check_drive(drive, where, bad):
    if not isinstance(drive, list) or not all(isinstance(x, str) for x in drive):
        bad(where, "drive", f"must be a list among {list(DRIVE_KINDS)}, got {drive!r}")
        return None
    unknown = [x for x in drive if x.upper() not in DRIVE_KINDS]
    if unknown:
        bad(where, "drive", f"unknown drive-chain parameter(s) {unknown}; allowed {list(DRIVE_KINDS)}")
        return None
    up = [x.upper() for x in drive]
    dup = sorted({x for x in up if up.count(x) > 1})
    if dup:
        bad(where, "drive", f"drive-chain parameter(s) listed twice: {dup}")
        return None
    return tuple(k for k in DRIVE_KINDS if k in up)


def _parse_chain(raw, n, bad) -> DriveChain | None:
    where = "[drive_chain]"
    if not isinstance(raw, dict):
        bad(where, "", "must be a table")
        return None
    for k in sorted(set(raw) - CHAIN_KEYS):
        bad(where, k, f"unknown field (allowed: {', '.join(sorted(CHAIN_KEYS))})")
    ok = True

    def vec(key, default):
        nonlocal ok
        v = raw.get(key, default)
        if not (isinstance(v, list) and len(v) == n and all(_is_number(x) for x in v)):
            bad(where, key, f"must be a list of {n} numbers (finite, {_FINITE}), got {v!r}")
            ok = False
            return default
        return [float(x) for x in v]

    ratios = vec("ratios", [1.0] * n)
    offsets = vec("offsets", [0.0] * n)
    directions = vec("directions", [1.0] * n)
    if any(x == 0 for x in ratios):
        bad(where, "ratios", "gear ratios must be non-zero")
        ok = False
    if any(x not in (1.0, -1.0) for x in directions):
        bad(where, "directions", "joint directions must be +1 or -1")
        ok = False
    eye = [[1.0 if i == k else 0.0 for k in range(n)] for i in range(n)]
    coupling = raw.get("coupling", eye)
    if not (isinstance(coupling, list) and len(coupling) == n and all(
        isinstance(row, list) and len(row) == n and all(_is_number(x) for x in row) for row in coupling
    )):
        bad(where, "coupling", f"must be a {n}x{n} matrix (list of {n} lists of {n} finite numbers, {_FINITE})")
        ok = False
        coupling = eye
    else:
        import numpy as np

        if abs(np.linalg.det(np.asarray(coupling, float))) < 1e-12:
            bad(where, "coupling", "coupling matrix is singular")
            ok = False
    if not ok:
        return None
    return DriveChain(
        ratios=tuple(ratios),
        coupling=tuple(tuple(float(x) for x in row) for row in coupling),
        offsets=tuple(offsets),
        directions=tuple(directions),
    )


PASSIVE_LIMIT_KEYS = ("passive_q_min", "passive_q_max")
LIMIT_KEYS = {"angles"} | set(JointLimits.FIELDS) | set(PASSIVE_LIMIT_KEYS)


def _parse_limits(raw, rows, bad, passive=()) -> JointLimits | None:
    """The ``[limits]`` table: per-joint lists ``q_min, q_max, dq_max, ddq_max, tau_max`` (each
    optional, one number per moving joint of ``rows``), ``passive_q_min, passive_q_max`` (one number
    per ``passive`` joint, :func:`_parse_passive_limits`) and ``angles = "rad" | "deg"`` (unit of the
    revolute joints' position, velocity and acceleration entries; default rad). Returned in SI units."""
    where = "[limits]"
    if not isinstance(raw, dict):
        bad(where, "", "must be a table of per-joint lists (q_min, q_max, dq_max, ddq_max, tau_max)")
        return None
    for k in sorted(set(raw) - LIMIT_KEYS):
        bad(where, k, f"unknown field (allowed: {', '.join(sorted(LIMIT_KEYS))})")
    unit = raw.get("angles", "rad")
    if unit not in ("rad", "deg"):
        bad(where, "angles", f'must be "rad" or "deg", got {unit!r}')
        unit = "rad"
    moving = [r for r in rows if r.is_moving]
    n = len(moving)
    out: dict[str, Any] = {}  # JointLimits fields: a tuple per joint or None
    ok = True
    for key in JointLimits.FIELDS:
        v = raw.get(key)
        if v is None:
            out[key] = None
            continue
        if not (isinstance(v, list) and len(v) == n):
            bad(where, key, f"must be a list of {n} numbers (one per moving joint), got {v!r}")
            ok = False
            continue
        vals = []
        for i, (x, r) in enumerate(zip(v, moving), start=1):
            if not _is_number(x):
                bad(f"{where} joint {i}", key, f"must be a finite number ({_FINITE}), got {x!r}")
                ok = False
                x = 0.0
            elif key != "q_min" and key != "q_max" and x <= 0:
                bad(f"{where} joint {i}", key, f"must be positive, got {x!r}")
                ok = False
            scale = math.pi / 180.0 if (unit == "deg" and r.sigma == REVOLUTE and key != "tau_max") else 1.0
            vals.append(float(x) * scale)
        out[key] = tuple(vals)
    lo, hi = out.get("q_min"), out.get("q_max")
    if lo is not None and hi is not None:
        for i, (a, b) in enumerate(zip(lo, hi), start=1):
            if a >= b:
                bad(f"{where} joint {i}", "q_min", f"q_min {raw['q_min'][i - 1]!r} must be below q_max {raw['q_max'][i - 1]!r}")
                ok = False
    if ("q_min" in raw) != ("q_max" in raw):
        bad(where, "q_max" if "q_min" in raw else "q_min", "missing: q_min and q_max must be given together")
        ok = False
    pas = _parse_passive_limits(raw, list(passive), unit, bad)
    return JointLimits(**out, **pas) if ok and pas is not None else None


def _parse_passive_limits(raw, passive: list[MdhRow], unit: str, bad) -> dict | None:
    """``passive_q_min, passive_q_max`` of ``[limits]``: the position range of each passive joint (``mu = 0``
    of a closed-loop or coupled robot, joint order ``passive``), in the unit of ``q_min, q_max``. The
    :class:`JointLimits` fields (SI units, with ``passive_joints``; empty when not given), or None after a
    reported problem."""
    where = "[limits]"
    given = [k for k in PASSIVE_LIMIT_KEYS if k in raw]
    if not given:
        return {}
    if not passive:
        for k in given:
            bad(where, k, "this robot has no passive joints (mu = 0 joints of a closed-loop or coupled robot)")
        return None
    ok = True
    if len(given) == 1:
        bad(where, "passive_q_max" if given[0] == "passive_q_min" else "passive_q_min",
            "missing: passive_q_min and passive_q_max must be given together")
        ok = False
    n, joints = len(passive), ", ".join(str(r.j) for r in passive)
    out: dict[str, tuple] = {"passive_joints": tuple(r.j for r in passive)}
    for key in given:
        v = raw[key]
        if not (isinstance(v, list) and len(v) == n):
            bad(where, key, f"must be a list of {n} numbers (one per passive joint: joints {joints}), got {v!r}")
            ok = False
            continue
        vals = []
        for x, r in zip(v, passive):
            if not _is_number(x):
                bad(f"{where} passive joint {r.j}", key, f"must be a finite number ({_FINITE}), got {x!r}")
                ok = False
                continue
            vals.append(float(x) * (math.pi / 180.0 if (unit == "deg" and r.sigma == REVOLUTE) else 1.0))
        out[key] = tuple(vals)
    if not ok:
        return None
    for r, a, b, xa, xb in zip(passive, out["passive_q_min"], out["passive_q_max"], raw["passive_q_min"],
                               raw["passive_q_max"]):
        if a >= b:
            bad(f"{where} passive joint {r.j}", "passive_q_min", f"passive_q_min {xa!r} must be below passive_q_max {xb!r}")
            ok = False
    return out if ok else None
