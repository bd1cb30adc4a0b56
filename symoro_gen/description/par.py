"""SYMORO+ / OpenSYMORO ``.par`` files: import into our TOML robot format, export back.

The ``.par`` syntax read and written here (learned from the files and the reader/writer of
OpenSYMORO, github.com/symoro/symoro: ``symoroutils/parfile.py``, ``Robots/*/*.par``, and from
iDynTree's SYMORO+ reader ``symoro_par_import.cpp``)::

    (* comments, possibly on a line of their own *)
    (* Robotname = 'RX90' *)                 robot name, inside a comment
    NF = 7                                   number of frames
    NL = 7                                   number of links
    NJ = 7                                   number of joints (NJ > NL: closed loops)
    Type = 0 (* Simple *)                    0 simple chain, 1 tree, 2 closed loops
    is_floating = 0                          OpenSYMORO only
    is_mobile = 0                            OpenSYMORO only
    Ant = {0,1,2,3,4,5,6}                    geometric lists, one entry per frame 1..NF:
    Sigma = {0,0,0,0,0,0,2}                    Ant Sigma B d R gamma Alpha Mu Theta (SYMORO+ spelling)
    B = {0,0,0,0,0,0,0}                        or ant sigma b d r gamma alpha mu theta (OpenSYMORO)
    d = {0,0,D3,0,0,0,0}                       the joint variable is a symbol of its own in Theta
    R = {0,0,0,RL4,0,0,0}                      (revolute, e.g. t3 or th3, with an offset: t2 - Pi/2)
    gamma = {0,0,0,0,0,0,0}                    or in R (prismatic, e.g. r3)
    Alpha = {0,-Pi/2,0,Pi/2,-Pi/2,Pi/2,0}
    Mu = {1,1,1,1,1,1,0}
    Theta = {t1,t2,t3,t4,t5,t6,0}
    XX = {XX1,XX2,...}                       dynamic lists, one entry per link 1..NL:
    ...                                        XX XY XZ YY YZ ZZ MX MY MZ M IA FV FS
    FX = {...}  CX = {...}                   external wrench on the links (ignored)
    QP = {...}  QDP = {...}  GAM = {...}     joint velocity/acceleration/torque names (ignored)
    W0 = {0,0,0} WP0 V0 VP0                  base velocity/acceleration (must be zero: fixed base)
    G = {0,0,G3}                             gravity acceleration in frame 0 (SYMORO: VP0 - G)
    Z = {1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1} base transform fT0 (must be the identity)

Lists may span several lines; ``Pi`` (or ``pi``) and ``^`` (power) are accepted in entries.
A dynamic entry is a number (a known value; ``0`` means the parameter is absent, which for
IA/FV/FS removes it from the model) or a symbol (a parameter to identify).

symoro_gen extensions, ignored by OpenSYMORO's reader (it skips lines without ``{`` and
lists with unknown keys):

* ``NAME = number`` lines give numeric values to symbols: geometric constants (``D3 = 0.45``)
  become ``[values]`` entries, a symbol used as a dynamic parameter gets it as nominal value.
* ``OFF = {OFF1,0,...}`` lists the joint offsets kept in the model (absent: all kept).
* A fixed frame (Sigma = 2) whose inertial entries are not all ``0`` is the payload.

Public functions: :func:`import_par`, :func:`import_par_text`, :func:`export_par`,
:func:`write_robot_toml`.
"""
from __future__ import annotations

import ast
import json
import math
import os
import re
from collections import Counter
from collections.abc import Mapping
from pathlib import Path

import sympy as sp
from sympy.printing.str import StrPrinter

from ..atomic import write_text_atomic
from ..errors import OutputError, Problem, RobotFileError
from ..params import DRIVE_KINDS, INERTIAL_KINDS
from .expr import ExprError, parse_expression
from .model import FIXED, PRISMATIC, REVOLUTE, RobotDescription, q_symbol
from .parse import load_robot, parse_robot_text

__all__ = ["import_par", "import_par_text", "export_par", "write_robot_toml", "OutputExistsError", "DEFAULT_GRAVITY_Z"]


class OutputExistsError(OutputError):
    """The output file exists and overwriting was not asked for (nothing written)."""

    def __init__(self, path: os.PathLike | str):
        super().__init__(f"{path} exists; not overwritten",
                         "pass overwrite=True (--force on the command line) to replace it")

#: gravity used for a symbolic ``G = {0,0,G3}`` without a numeric value (z axis pointing up)
DEFAULT_GRAVITY_Z = -9.81

# SYMORO+ spelling -> our field name (OpenSYMORO writes the lower-case names directly)
_GEOM_KEYS = {"Ant": "ant", "Sigma": "sigma", "B": "b", "d": "d", "R": "r", "gamma": "gamma",
              "Alpha": "alpha", "Mu": "mu", "Theta": "theta"}
_GEOM_ALIASES = {**_GEOM_KEYS, **{v: v for v in _GEOM_KEYS.values()}, "Gamma": "gamma", "D": "d"}
_PAR_SPELLING = {v: k for k, v in _GEOM_KEYS.items()}  # what export writes
_INT_FIELDS = ("ant", "sigma", "mu")
_REQUIRED_GEOM = ("ant", "sigma", "d", "r", "alpha", "theta")
_DYN_KEYS = INERTIAL_KINDS + DRIVE_KINDS  # OFF is our extension
_IGNORED_LISTS = {"FX", "FY", "FZ", "CX", "CY", "CZ", "QP", "QDP", "GAM", "k"}
_BASE_MOTION = ("W0", "WP0", "V0", "VP0")
_HEADER_INTS = ("NF", "NL", "NJ", "Type")
_HEADER_BOOLS = ("is_floating", "is_mobile")
_BOOL_WORDS = {"0": False, "1": True, "False": False, "True": True, "false": False, "true": True}
_TYPE_NAMES = {0: "Simple", 1: "Tree", 2: "Closed"}
_NAME_RE = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
_RESERVED = {"q", "pi", "sin", "cos", "tan", "sqrt", "atan2"}
_FUNCS = {"sin", "cos", "tan", "sqrt", "atan2"}


# ============================================================================ reading
class _Entry:
    """One list element or scalar value of a .par file, with its line number."""

    __slots__ = ("text", "line")

    def __init__(self, text: str, line: int):
        self.text = text
        self.line = line


class _Statement:
    """``KEY = {list}`` (``items``, ``scalar`` None) or ``KEY = value`` (``scalar``, no items)."""

    __slots__ = ("key", "line", "items", "scalar")

    def __init__(self, key: str, line: int, items: list[_Entry], scalar: _Entry | None):
        self.key, self.line, self.items, self.scalar = key, line, items, scalar


def _line_of(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


def _blank_comments(text: str, bad) -> str:
    """Replace every ``(* ... *)`` (nested as in Mathematica) by spaces, keeping newlines so that
    line numbers stay right."""
    out, i, n = [], 0, len(text)
    while True:
        k = text.find("(*", i)
        if k < 0:
            out.append(text[i:])
            break
        out.append(text[i:k])
        depth, e = 1, k + 2
        while depth and e < n:
            if text.startswith("(*", e):
                depth, e = depth + 1, e + 2
            elif text.startswith("*)", e):
                depth, e = depth - 1, e + 2
            else:
                e += 1
        if depth:
            bad(_line_of(text, k), "", "comment opened with '(*' is never closed with '*)'")
            break
        out.append(re.sub(r"[^\n]", " ", text[k:e]))
        i = e
    return "".join(out)


_STMT_RE = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)[ \t]*=[ \t]*")
_NEXT_STMT_RE = re.compile(r"\n[ \t]*[A-Za-z_][A-Za-z0-9_]*[ \t]*=")


def _split_items(body: str, body_start: int, text: str, line: int, key: str, bad) -> list[_Entry]:
    """Split a list body at the commas outside parentheses."""
    items: list[_Entry] = []
    depth, start = 0, 0
    if not body.strip():
        return []
    for i, ch in enumerate(body + ","):
        if ch in "([":
            depth += 1
        elif ch in ")]":
            depth -= 1
        elif ch == "," and depth <= 0:
            raw = body[start:i]
            lead = len(raw) - len(raw.lstrip())
            ln = _line_of(text, body_start + start + lead)
            if not raw.strip():
                bad(ln, key, f"empty entry number {len(items) + 1} in the list")
            items.append(_Entry(raw.strip(), ln))
            start, depth = i + 1, 0
    return items


def _statements(text: str, bad) -> list[_Statement]:
    """Cut comment-free .par text into ``KEY = {list}`` and ``KEY = value`` statements."""
    out: list[_Statement] = []
    pos, n = 0, len(text)
    while pos < n:
        while pos < n and text[pos] in " \t\r\n;":
            pos += 1
        if pos >= n:
            break
        m = _STMT_RE.match(text, pos)
        line = _line_of(text, pos)
        if not m:
            eol = text.find("\n", pos)
            eol = n if eol < 0 else eol
            bad(line, "", f"expected 'NAME = {{...}}' or 'NAME = value', got {text[pos:eol].strip()[:40]!r}")
            pos = eol
            continue
        key, pos = m.group(1), m.end()
        if pos < n and text[pos] == "{":
            close = text.find("}", pos)
            nxt = _NEXT_STMT_RE.search(text, pos + 1, close if close >= 0 else n)
            if close < 0 or nxt:
                bad(line, key, "list opened with '{' is never closed with '}'"
                    + (f" before the next statement (line {_line_of(text, nxt.start() + 1)})" if nxt else ""))
                if not nxt:
                    break
                pos = nxt.start() + 1
                continue
            items = _split_items(text[pos + 1:close], pos + 1, text, line, key, bad)
            pos = close + 1
            eol = text.find("\n", pos)
            eol = n if eol < 0 else eol
            if text[pos:eol].strip(" \t\r;"):
                bad(_line_of(text, pos), key, f"unexpected text after the list: {text[pos:eol].strip()[:40]!r}")
            pos = eol
            out.append(_Statement(key, line, items, None))
        else:
            eol = text.find("\n", pos)
            eol = n if eol < 0 else eol
            value = text[pos:eol].strip(" \t\r;")
            pos = eol
            if not value:
                bad(line, key, "missing value after '='")
                continue
            out.append(_Statement(key, line, [], _Entry(value, line)))
    return out


def _normalize(text: str) -> str:
    """SYMORO+ / Mathematica spellings -> our expression language."""
    text = re.sub(r"\bP[iI]\b", "pi", text)
    return text.replace("^", "**")


def _names_in(text: str) -> set[str]:
    try:
        tree = ast.parse(text, mode="eval")
    except (SyntaxError, ValueError, RecursionError):
        return set()
    return {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)} - _FUNCS - {"pi"}


def _expr(entry: _Entry) -> sp.Expr:
    """Parse one entry; raises ExprError."""
    text = _normalize(entry.text)
    syms = {n: sp.Symbol(n, real=True) for n in _names_in(text)}
    return parse_expression(text, syms)


# ============================================================================ import
def import_par(path: str | os.PathLike, *, values: Mapping[str, float] | None = None,
               payload: int | None = None, angle_tol: float = 1e-9) -> str:
    """Read a SYMORO+/OpenSYMORO ``.par`` file and return the text of our TOML robot file.

    Parameters
    ----------
    path : str or PathLike
        The ``.par`` file.
    values : mapping, optional
        Numeric values of symbols (geometric constants in m or rad, or dynamic parameters in SI
        units); they override ``NAME = number`` lines of the file.
    payload : int, optional
        The fixed frame to use as payload, when several fixed frames carry inertial parameters.
    angle_tol : float
        Numeric angles within this distance (rad) of a multiple of pi/12 are written exactly
        (``1.57079632679`` -> ``"pi/2"``), so that the base-parameter rules see exact axes.

    Returns
    -------
    str
        TOML text in the format of ``robots/*.toml`` (validated by :func:`parse_robot_text`),
        with a ``source`` line naming the ``.par`` file.

    Raises
    ------
    RobotFileError
        Listing every problem found, each naming the ``.par`` file, the line and the field.
    """
    p = Path(path)
    try:
        text = p.read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise RobotFileError([Problem(str(p), "", "", "file not found")]) from None
    except UnicodeDecodeError:
        text = p.read_bytes().decode("latin-1")  # SYMORO+ headers are Latin-1 ("Noë")
    return import_par_text(text, file=str(p), values=values, payload=payload, angle_tol=angle_tol)


def import_par_text(text: str, file: str = "<string>", *, values: Mapping[str, float] | None = None,
                    payload: int | None = None, angle_tol: float = 1e-9) -> str:
    """Same as :func:`import_par` on the text of a ``.par`` file (``file`` used in messages)."""
    imp = _ParImport(file)
    m = re.search(r"\(\*\s*Robotname\s*=\s*'([^']*)'\s*\*\)", text)
    robot_name = _identifier(m.group(1) if m else (Path(file).stem if file != "<string>" else "robot"))
    imp.sort_statements(_statements(_blank_comments(text, imp.bad), imp.bad))
    imp.take_values(values)
    imp.check_header()
    imp.count_frames()
    if imp.probs and not imp.geom:
        raise RobotFileError(imp.probs)
    imp.read_geometric_cells()
    imp.find_joint_variables()
    imp.check_geometric_symbols()
    imp.read_gravity()
    imp.check_fixed_base()
    imp.read_links_and_loops()
    imp.read_dynamic_lists()
    imp.choose_payload(payload)
    imp.check_value_names()
    if imp.probs:
        raise RobotFileError(imp.probs)
    toml = imp.toml_text(robot_name, angle_tol)
    imp.validate(toml)
    return toml


class _ParImport:
    """One import of a ``.par`` text, step by step: each step reads what the earlier ones stored and
    reports its problems through :meth:`bad` (all of them raised at once in a :class:`RobotFileError`)."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.probs: list[Problem] = []
        # the statements sorted by role (header: NF NL NJ Type is_floating is_mobile -> (line, value);
        # given: the ``NAME = number`` lines -> (value, line))
        self.header: dict[str, tuple[int, int]] = {}
        self.geom: dict[str, _Statement] = {}
        self.dyn: dict[str, _Statement] = {}
        self.other: dict[str, _Statement] = {}
        self.given: dict[str, tuple[float, int]] = {}
        self.numeric: dict[str, float] = {}
        # the geometric table: frames, cells (field, frame) -> (expression, entry), joint types and variables
        self.nf = 0
        self.cells: dict[tuple[str, int], tuple[sp.Expr, _Entry]] = {}
        self.sigmas: dict[int, int] = {}
        self.joint_var: dict[int, sp.Symbol] = {}
        self.reported: set[tuple[str, int]] = set()  # cells whose symbols are already reported (no cascade)
        # gravity and the notes written into the robot file
        self.notes: list[str] = []
        self.g_symbols: set[str] = set()
        self.gravity = [0.0, 0.0, DEFAULT_GRAVITY_Z]
        # links, joints and closed loops (links 1..NL, cut joints NL+1..NJ, closing frames NJ+1..NF)
        self.nl = self.nj = self.nb = self.nlinks = 0
        self.closed = False
        # the dynamic lists
        self.nominal: dict[str, float] = {}
        self.drive: dict[int, list[str]] = {}
        self.inertia_given: dict[int, bool] = {}
        self.dyn_symbol_at: dict[str, str] = {}  # a symbol names one parameter only
        self.payload: int | None = None

    def bad(self, line: int | None, fld: str, msg: str, frame: int | None = None) -> None:
        where = ", ".join(x for x in (f"line {line}" if line else "", f"frame {frame}" if frame else "") if x)
        self.probs.append(Problem(self.file, where, fld, msg))

    def cell(self, k: str, j: int, default: int = 0) -> sp.Expr:
        c = self.cells.get((k, j))
        return c[0] if c else sp.Integer(default)

    # ------------------------------------------------------------------ statements and header
    def sort_statements(self, stmts: list[_Statement]) -> None:
        """Header integers and flags, geometric, dynamic and other lists, ``NAME = number`` values."""
        seen: dict[str, int] = {}
        for st in stmts:
            key = _GEOM_ALIASES.get(st.key, st.key) if st.scalar is None else st.key
            if key in seen:
                self.bad(st.line, st.key, f"given twice (first on line {seen[key]})")
                continue
            seen[key] = st.line
            if st.scalar is not None:
                self._sort_scalar(key, st, st.scalar)
            elif key in _GEOM_KEYS.values():
                self.geom[key] = st
            elif key in _DYN_KEYS:
                self.dyn[key] = st
            elif key in _IGNORED_LISTS or key in _BASE_MOTION or key in ("G", "Z", "eta"):
                self.other[key] = st
            else:
                self.bad(st.line, st.key, "unknown list (expected the SYMORO keys Ant Sigma B d R gamma Alpha Mu "
                                          "Theta, XX..M IA FV FS, FX..CZ, QP QDP GAM, W0 WP0 V0 VP0, G, Z, or OFF)")

    def _sort_scalar(self, key: str, st: _Statement, scalar: _Entry) -> None:
        raw = scalar.text
        if key in _HEADER_INTS:
            if not re.fullmatch(r"\d+", raw):
                self.bad(st.line, key, f"must be a non-negative integer, got {raw!r}")
            else:
                self.header[key] = (st.line, int(raw))
        elif key in _HEADER_BOOLS:
            if raw not in _BOOL_WORDS:
                self.bad(st.line, key, f"must be 0/1 or True/False, got {raw!r}")
            else:
                self.header[key] = (st.line, _BOOL_WORDS[raw])
        else:
            try:
                e = _expr(scalar)
            except ExprError as exc:
                self.bad(st.line, key, str(exc))
                return
            if e.free_symbols or not e.is_real:
                self.bad(st.line, key, f"a numeric value must be a number, got {raw!r}")
                return
            self.given[key] = (float(e), st.line)

    def take_values(self, values: Mapping[str, float] | None) -> None:
        """The numeric values of symbols: the file's ``NAME = number`` lines overridden by ``values``."""
        self.numeric = {k: v for k, (v, _) in self.given.items()}
        for k, v in (values or {}).items():
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)):
                self.bad(None, k, f"value passed for {k!r} must be a finite number, got {v!r}")
            else:
                self.numeric[k] = float(v)

    def check_header(self) -> None:
        header = self.header
        if "Type" in header and header["Type"][1] not in (0, 1, 2):
            self.bad(header["Type"][0], "Type",
                     f"must be 0 (simple), 1 (tree) or 2 (closed), got {header['Type'][1]}")
        for k in _HEADER_BOOLS:
            if header.get(k, (0, False))[1]:
                self.bad(header[k][0], k, f"{k} = 1 is not supported: symoro_gen models fixed-base robots")
        if ("NJ" in header and "NL" in header and header["NJ"][1] != header["NL"][1]
                and header.get("Type", (0, 0))[1] != 2):
            self.bad(header["NJ"][0], "NJ", f"NJ = {header['NJ'][1]} differs from NL = {header['NL'][1]}: a "
                                            "structure with closed loops must say Type = 2")

    def count_frames(self) -> None:
        """NF (the header's, else the most common length of the geometric lists); every list must have NF
        entries."""
        for k in _REQUIRED_GEOM:
            if k not in self.geom:
                self.bad(None, _PAR_SPELLING[k],
                         "missing list (the geometric table needs Ant, Sigma, d, R, Alpha, Theta)")
        lengths = {k: len(st.items) for k, st in self.geom.items()}
        self.nf = self.header["NF"][1] if "NF" in self.header else (
            Counter(lengths.values()).most_common(1)[0][0] if lengths else 0)
        for st in self.geom.values():
            if len(st.items) != self.nf:
                self.bad(st.line, st.key,
                         f"has {len(st.items)} entries, expected {self.nf} (one per frame, NF = {self.nf})")

    # ------------------------------------------------------------------ geometric table
    def read_geometric_cells(self) -> None:
        for k, st in self.geom.items():
            for j, entry in enumerate(st.items[:self.nf], start=1):
                if not entry.text:
                    continue
                try:
                    e = _expr(entry)
                except ExprError as exc:
                    self.bad(entry.line, st.key, str(exc), j)
                    continue
                if k in _INT_FIELDS and not (e.is_Integer or (e.is_Float and float(e).is_integer())):
                    self.bad(entry.line, st.key, f"must be an integer, got {entry.text!r}", j)
                    continue
                self.cells[(k, j)] = (e, entry)

    def find_joint_variables(self) -> None:
        """The joint type of every frame and the joint variable of every moving one (the only symbol
        without a numeric value in Theta, revolute, or R, prismatic)."""
        self.sigmas = {j: int(self.cell("sigma", j)) for j in range(1, self.nf + 1)}
        for j in range(1, self.nf + 1):
            s = self.sigmas[j]
            if s not in (REVOLUTE, PRISMATIC, FIXED):
                self.reported |= {("theta", j), ("r", j)}
                if ("sigma", j) in self.cells:
                    self.bad(self.cells[("sigma", j)][1].line, _spelled(self.geom, "sigma"),
                             f"must be 0 (revolute), 1 (prismatic) or 2 (fixed), got {s}", j)
                continue
            if s == FIXED:
                continue
            fld = "theta" if s == REVOLUTE else "r"
            if (fld, j) not in self.cells:
                continue
            self.reported.add((fld, j))  # cleared once the joint variable is found
            v = self._joint_variable(j, s, fld)
            if v is not None:
                self.joint_var[j] = v
                self.reported.discard((fld, j))

    def _joint_variable(self, j: int, s: int, fld: str) -> sp.Symbol | None:
        e, entry = self.cells[(fld, j)]
        spelled = _spelled(self.geom, fld)
        cand = sorted((x for x in e.free_symbols if x.name not in self.numeric), key=lambda x: x.name)
        kind = "revolute" if s == REVOLUTE else "prismatic"
        if not cand:
            self.bad(entry.line, spelled, f"a {kind} frame needs its joint variable in {spelled} "
                                          f"(e.g. {'t' if s == REVOLUTE else 'r'}{j}), got {entry.text!r}", j)
            return None
        if len(cand) > 1:
            self.bad(entry.line, spelled,
                     f"several symbols without numeric value ({', '.join(c.name for c in cand)}): the joint "
                     f"variable must be the only one; give the others a value with a line 'NAME = number'", j)
            return None
        v = cand[0]
        if sp.diff(e, v) not in (1, -1) or sp.diff(e, v, 2) != 0:
            self.bad(entry.line, spelled, f"must be {v} + constant or -{v} + constant, got {entry.text!r}", j)
            return None
        return v

    def check_geometric_symbols(self) -> None:
        """Every other symbol of the table has a numeric value, an allowed name, and is no joint variable."""
        owners = {v: j for j, v in self.joint_var.items()}
        for (k, j), (e, entry) in sorted(self.cells.items(), key=lambda kv: (kv[0][1], kv[1][1].line)):
            if (k, j) in self.reported:
                continue
            spelled = _spelled(self.geom, k)
            for x in sorted(e.free_symbols, key=lambda x: x.name):
                if self.joint_var.get(j) == x and k == ("theta" if self.sigmas[j] == REVOLUTE else "r"):
                    continue
                if x in owners:
                    self.bad(entry.line, spelled, f"{x} is the joint variable of frame {owners[x]}; "
                                                  f"it cannot appear elsewhere", j)
                elif x.name not in self.numeric:
                    self.bad(entry.line, spelled,
                             f"symbol {x.name!r} has no numeric value: add a line '{x.name} = <number>' to the .par "
                             f"file (symoro_gen extension, ignored by SYMORO) or pass values={{'{x.name}': ...}}", j)
                elif x.name in _RESERVED or not _NAME_RE.match(x.name):
                    self.bad(entry.line, spelled, f"symbol name {x.name!r} is reserved in symoro_gen robot files; "
                                                  f"rename it", j)

    # ------------------------------------------------------------------ gravity, base, flexible joints
    def read_gravity(self) -> None:
        if "G" not in self.other:
            self.notes.append(f"gravity: the .par file has no G list; taken as [0, 0, {DEFAULT_GRAVITY_Z}] "
                              "(z axis up)")
            return
        st = self.other["G"]
        if len(st.items) != 3:
            self.bad(st.line, "G", f"must have 3 entries, got {len(st.items)}")
            return
        exprs: list[sp.Expr | None] = []
        for entry in st.items:
            try:
                exprs.append(_expr(entry))
            except ExprError as exc:
                self.bad(entry.line, "G", str(exc))
                exprs.append(None)
        parsed = [e for e in exprs if e is not None]
        if len(parsed) < len(exprs):
            return
        self.g_symbols |= {x.name for e in parsed for x in e.free_symbols}
        subs = {sp.Symbol(k, real=True): v for k, v in self.numeric.items()}
        vals = [e.subs(subs) for e in parsed]
        if all(v.is_number for v in vals):
            self.gravity = [float(v) for v in vals]
        elif vals[0] == 0 and vals[1] == 0 and vals[2].is_Symbol:
            self.notes.append(f"gravity: {vals[2]} in the .par file has no numeric value; taken as "
                              f"{DEFAULT_GRAVITY_Z} m/s^2 (z axis up). Edit if the base frame differs.")
        else:
            names = sorted({x.name for v in vals for x in v.free_symbols})
            self.bad(st.line, "G", f"gravity symbols {', '.join(names)} have no numeric value: add lines "
                                   f"'NAME = <m/s^2>' to the .par file or pass values=")

    def check_fixed_base(self) -> None:
        """The base transform is the identity, the base does not move, no joint is flexible."""
        other = self.other
        if "Z" in other:
            st = other["Z"]
            ident = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
            ok = len(st.items) == 16
            if ok:
                for entry, ref in zip(st.items, ident):
                    try:
                        e = _expr(entry)
                    except ExprError:
                        ok = False
                        break
                    if not e.is_number or abs(float(e) - ref) > 1e-12:
                        ok = False
                        break
            if not ok:
                self.bad(st.line, "Z", "the base transformation Z (fT0) must be the identity: symoro_gen has no "
                                       "base transform; fold it into frame 1 (gamma, b, alpha, d, theta, r)")
        for k in _BASE_MOTION:
            if k in other and not all(_is_zero(e) for e in other[k].items):
                self.bad(other[k].line, k, f"{k} must be zero: symoro_gen models fixed-base robots")
        if "eta" in other and not all(_is_zero(e) for e in other["eta"].items):
            self.bad(other["eta"].line, "eta", "flexible joints (eta = 1) are not supported")

    # ------------------------------------------------------------------ links, loops, dynamic lists, payload
    def read_links_and_loops(self) -> None:
        """NL, NJ and the closed loops (KK1986: links 1..NL, cut joints NL+1..NJ, closing frames NJ+1..NF)."""
        header, nf = self.header, self.nf
        nl = self.nl = header["NL"][1] if "NL" in header else nf
        closed = self.closed = header.get("Type", (0, 0))[1] == 2 or header.get("NJ", (0, nl))[1] != nl
        if nl != nf and not closed:
            self.bad(header["NL"][0], "NL", f"NL = {nl} differs from the number of frames {nf}: every frame of a "
                                            f"simple or tree structure is a link")
        nj = self.nj = header["NJ"][1] if "NJ" in header else nl
        nb = self.nb = nj - nl
        self.nlinks = nl if closed else nf  # frames carrying a body
        if not closed:
            return
        if "NL" not in header or "NJ" not in header:
            self.bad(header.get("Type", (None, 0))[0], "Type", "a closed-loop structure needs NL and NJ")
        elif nb <= 0:
            self.bad(header["Type"][0] if "Type" in header else header["NJ"][0], "Type" if "Type" in header else "NJ",
                     f"Type = 2 is a closed-loop structure: it needs more joints than links (NJ > NL), got "
                     f"NJ = {nj}, NL = {nl}")
        elif nf != nj + nb:
            self.bad(header["NF"][0] if "NF" in header else None, "NF",
                     f"a closed-loop structure has NF = NJ + (NJ - NL) = {nj + nb} frames (one closing frame per "
                     f"cut joint), got {nf}")
        else:
            for j in range(nl + 1, nf + 1):
                if (self.sigmas[j] == FIXED) != (j > nj):
                    what = "a cut joint (revolute or prismatic)" if j <= nj else "a closing frame (Sigma = 2)"
                    self.bad(self.cells[("sigma", j)][1].line if ("sigma", j) in self.cells else None,
                             _spelled(self.geom, "sigma"), f"frame {j} must be {what}", j)

    def read_dynamic_lists(self) -> None:
        """Nominal values, drive terms (IA FV FS OFF of the moving joints) and which links carry inertia."""
        for k, st in self.dyn.items():
            if len(st.items) != self.nl:
                self.bad(st.line, k, f"has {len(st.items)} entries, expected {self.nl} (one per link, NL = {self.nl})")
        self.drive = {j: [] for j in range(1, self.nf + 1)}
        for j in range(1, self.nlinks + 1):
            moving = self.sigmas[j] in (REVOLUTE, PRISMATIC)
            any_inertia = False
            for k in _DYN_KEYS:
                read = self._dynamic_entry(k, j)
                if read is None:
                    continue
                state, value = read
                if k in INERTIAL_KINDS:
                    any_inertia |= state != "zero"
                    if value is not None or state == "zero":
                        self.nominal[f"{k}{j}"] = 0.0 if value is None else value
                elif moving and state != "zero":
                    self.drive[j].append(k)
                    if value is not None:
                        self.nominal[f"{k}{j}"] = value
            self.inertia_given[j] = any_inertia

    def _dynamic_entry(self, k: str, j: int) -> tuple[str, float | None] | None:
        """``(state, nominal value)`` of parameter ``k`` of link ``j``: state ``zero`` (absent), ``number``
        (known) or ``symbol`` (to identify, nominal value from the given values); None when reported."""
        st = self.dyn.get(k)
        if st is None or j > len(st.items):
            return "symbol", None  # not given: a parameter to identify
        entry = st.items[j - 1]
        try:
            e = _expr(entry)
        except ExprError as exc:
            self.bad(entry.line, k, str(exc), j)
            return None
        if e.is_number:
            return ("zero", 0.0) if e == 0 else ("number", float(e))
        if not e.is_Symbol:
            self.bad(entry.line, k, f"must be a number or a single parameter symbol, got {entry.text!r}", j)
            return None
        here = f"{k}{j}"
        named = self.sigmas[j] != FIXED or k in INERTIAL_KINDS
        if e.name in self.dyn_symbol_at and named:
            self.bad(entry.line, k, f"symbol {e.name} already stands for {self.dyn_symbol_at[e.name]}: symoro_gen "
                                    f"parameters are independent; write {here} (or a number)", j)
            return None
        if named:
            self.dyn_symbol_at[e.name] = here
        return "symbol", self.numeric.get(e.name)

    def choose_payload(self, payload: int | None) -> None:
        """The one fixed frame carrying inertial parameters (or the one given); the nominal inertial values
        of the other fixed frames are dropped."""
        fixed_with_inertia = [j for j in range(1, self.nlinks + 1)
                              if self.sigmas[j] == FIXED and self.inertia_given[j]]
        xx_line = self.dyn["XX"].line if "XX" in self.dyn else None
        if payload is None:
            if len(fixed_with_inertia) > 1:
                self.bad(xx_line, "XX", f"fixed frames {fixed_with_inertia} all carry inertial parameters; symoro_gen "
                                        f"supports one payload: choose it with payload=<frame> and set the others' "
                                        f"inertial entries to 0")
            payload = fixed_with_inertia[0] if len(fixed_with_inertia) == 1 else None
        else:
            others = [j for j in fixed_with_inertia if j != payload]
            if others:
                self.bad(xx_line, "XX", f"fixed frames {others} carry inertial parameters but the payload is frame "
                                        f"{payload}")
        self.payload = payload
        for j in range(1, self.nlinks + 1):  # keep nominal values of moving links and of the payload only
            if self.sigmas[j] == FIXED and j != payload:
                for k in INERTIAL_KINDS:
                    self.nominal.pop(f"{k}{j}", None)

    def check_value_names(self) -> None:
        for k in sorted(set(self.numeric) - set(self.dyn_symbol_at) - self.g_symbols):
            if k in _RESERVED or not _NAME_RE.match(k):
                line = self.given[k][1] if k in self.given else None
                self.bad(line, k, f"{k!r} is a reserved name in symoro_gen robot files; rename the symbol")

    # ------------------------------------------------------------------ the robot file
    def toml_text(self, robot_name: str, angle_tol: float) -> str:
        geometric = ({x.name for e, _ in self.cells.values() for x in e.free_symbols}
                     - {v.name for v in self.joint_var.values()})
        unused = set(self.numeric) - geometric - set(self.dyn_symbol_at) - self.g_symbols
        used = sorted(geometric | unused)
        lines = [f"# Imported from the SYMORO .par file {Path(self.file).name} by "
                 "symoro_gen.description.par.import_par."]
        lines += [f"# Note: {n}" for n in self.notes]
        lines += [f"name = {_toml_str(robot_name)}",
                  f"source = {_toml_str(f'SYMORO .par file {self.file}')}",
                  f"gravity = [{', '.join(_toml_float(g) for g in self.gravity)}]"]
        if self.payload is not None:
            lines.append(f"payload = {self.payload}")
        actuated = [j for j in range(1, self.nlinks + 1)
                    if self.sigmas[j] != FIXED and int(self.cell("mu", j, 1)) == 1]
        top_drive = Counter(tuple(self.drive[j]) for j in actuated).most_common(1)[0][0] if actuated else None
        if top_drive is not None:
            lines.append(f"drive = [{', '.join(_toml_str(d) for d in top_drive)}]")
        if used:
            lines += ["", "[values]"] + [f"{n} = {_toml_float(self.numeric[n])}" for n in used]
        if self.closed:
            lines.append("# Note: closed loops; the loop is assembled from the zero configuration unless a "
                         "[loop_reference] table gives a closed, non-singular one")
        for j in range(1, self.nlinks + 1):
            lines += self._frame_lines(j, top_drive, angle_tol)
        for ell in range(1, self.nb + 1 if self.closed else 1):
            lines += ["", "[[loops]]"]
            for part, j in (("cut", self.nl + ell), ("close", self.nj + ell)):
                fields = [f"ant = {int(self.cell('ant', j))}", f"sigma = {self.sigmas[j]}"]
                fields += self._geometry_fields(j, angle_tol)
                lines.append(f"{part} = {{ {', '.join(fields)} }}")
        if self.nominal:
            order = {f"{k}{j}": (j, i) for j in range(1, self.nf + 1) for i, k in enumerate(_DYN_KEYS)}
            lines += ["", "[nominal]"] + [f"{k} = {_toml_float(self.nominal[k])}"
                                          for k in sorted(self.nominal, key=lambda k: order[k])]
        return "\n".join(lines) + "\n"

    def _frame_lines(self, j: int, top_drive: tuple[str, ...] | None, angle_tol: float) -> list[str]:
        s = self.sigmas[j]
        mu = int(self.cell("mu", j, 0 if s == FIXED else 1))
        lines = ["", "[[frames]]", f"j = {j}", f"ant = {int(self.cell('ant', j))}", f"sigma = {s}"]
        if mu != (0 if s == FIXED else 1):
            lines.append(f"mu = {mu}")
        lines += self._geometry_fields(j, angle_tol)
        if s != FIXED and (tuple(self.drive[j]) != top_drive if mu == 1 else bool(self.drive[j])):
            lines.append(f"drive = [{', '.join(_toml_str(d) for d in self.drive[j])}]")
        return lines

    def _geometry_fields(self, j: int, angle_tol: float) -> list[str]:
        """``gamma b alpha d theta r`` of frame ``j`` (gamma and b only when not zero), the joint variable
        written ``q``."""
        subs = {self.joint_var[j]: q_symbol(j)} if j in self.joint_var else {}
        fields = []
        for k in ("gamma", "b", "alpha", "d", "theta", "r"):
            e = self.cell(k, j).subs(subs)
            if k in ("gamma", "alpha", "theta"):
                e = _snap_angle(e, angle_tol, q_symbol(j) if self.sigmas[j] == REVOLUTE else None)
            if k in ("gamma", "b") and e == 0:
                continue
            fields.append(f"{k} = {_toml_expr(e, q_symbol(j))}")
        return fields

    def validate(self, toml: str) -> None:
        """The robot-file parser's findings on the TOML text, reported against the ``.par`` lines."""
        try:
            parse_robot_text(toml, file=self.file)
        except RobotFileError as err:
            raise RobotFileError([self._par_problem(p) for p in err.problems]) from None

    def _par_problem(self, p: Problem) -> Problem:
        mm = re.fullmatch(r"frame (\d+)", p.where)
        if mm and p.field in self.geom:
            j = int(mm.group(1))
            st = self.geom[p.field]
            line = st.items[j - 1].line if j <= len(st.items) else st.line
            return Problem(self.file, f"line {line}, frame {j}", st.key, p.message)
        if p.where == "[nominal]" and (mk := re.fullmatch(r"([A-Z]+)\d+", p.field)) and mk.group(1) in self.dyn:
            kind = mk.group(1)
            return Problem(self.file, f"line {self.dyn[kind].line}", kind, p.message)
        return Problem(self.file, p.where, p.field, p.message)


def _spelled(geom: dict[str, _Statement], k: str) -> str:
    """The key as the file spells it (``Theta`` or ``theta``)."""
    return geom[k].key if k in geom else _PAR_SPELLING[k]


def _is_zero(entry: _Entry) -> bool:
    try:
        e = _expr(entry)
    except ExprError:
        return False
    return e.is_number and e == 0


def _identifier(name: str) -> str:
    s = re.sub(r"[^A-Za-z0-9_]", "_", name.strip()) or "robot"
    return s if _NAME_RE.match(s) else f"r_{s}"


def _snap_angle(e: sp.Expr, tol: float, q: sp.Symbol | None) -> sp.Expr:
    """Replace a float angle (or the float offset of ``q + c``) within ``tol`` of k*pi/12 by the exact value."""
    rest = e - q if q is not None and q in e.free_symbols and sp.diff(e, q) == 1 else (
        e + q if q is not None and q in e.free_symbols and sp.diff(e, q) == -1 else e)
    head = e - rest
    if not (rest.is_number and rest.has(sp.Float)):
        return e
    v = float(rest)
    if not math.isfinite(v / (math.pi / 12)):
        return e  # far outside any multiple of pi/12 that could be meant (and round() would overflow)
    k = round(v / (math.pi / 12))
    if abs(v - k * math.pi / 12) <= tol:
        return head + sp.pi * sp.Rational(k, 12)
    return e


# ---------------------------------------------------------------------------- printing
class _Printer(StrPrinter):
    """sympy -> text of our expression language, floats in shortest round-trip form."""

    def _print_Float(self, expr):
        return repr(float(expr))


def _expr_text(e: sp.Expr) -> str:
    return _Printer().doprint(e)


def _toml_str(s: str) -> str:
    return json.dumps(s)  # a JSON string is a valid TOML basic string


def _toml_float(v: float) -> str:
    v = float(v)
    if v == int(v) and abs(v) < 1e15:
        return repr(float(int(v)))  # 2.0
    return repr(v)


def _toml_expr(e: sp.Expr, q: sp.Symbol) -> str:
    e = sp.sympify(e)
    if e.is_Integer:
        return str(int(e))
    if e.is_Float:
        return repr(float(e))
    return _toml_str(_expr_text(e.subs(q, sp.Symbol("q", real=True))))


# ============================================================================ export
def export_par(robot: RobotDescription | str | os.PathLike) -> str:
    """The robot as a ``.par`` file in SYMORO+ syntax (plus the symoro_gen extensions above).

    Parameters
    ----------
    robot : RobotDescription, or a robot name / path of a TOML robot file

    Returns
    -------
    str
        ``.par`` text. Joint variables are ``t<j>`` in Theta (revolute) and ``r<j>`` in R
        (prismatic) unless those names are taken by geometric constants; numeric values of the
        geometric constants and nominal values equal to zero are written as ``NAME = number``
        lines; other nominal values are written in the dynamic lists. The drive chain (gear
        ratios, coupling) has no SYMORO equivalent and is not written. A robot with coupled (mimic)
        joints is an error naming them (``.par`` has no coupled joints).
    """
    if not isinstance(robot, RobotDescription):
        robot = load_robot(robot)
    if robot.couplings:  # SYMORO+ has no coupled joints: writing them as independent ones would be wrong
        raise RobotFileError([Problem(robot.file, f"frame {c.joint}", "mimic", (
            f"a coupled joint (q{c.joint} = {c.multiplier} q{c.source} + {c.offset}) has no SYMORO .par spelling; "
            "export it with export-urdf (<mimic>) or export-mjcf (joint equality)")) for c in robot.couplings])
    links = robot.rows
    rows = links + tuple(lp.cut for lp in robot.loops) + tuple(lp.close for lp in robot.loops)
    nf, nl, nj = len(rows), len(links), len(links) + len(robot.loops)
    taken = set(robot.values)
    prefix = {}
    for sigma, cands in ((REVOLUTE, ("t", "th", "qj")), (PRISMATIC, ("r", "rj", "qr"))):
        for c in cands:
            if not any(f"{c}{r.j}" in taken for r in rows if r.sigma == sigma):
                prefix[sigma] = c
                break
        else:  # pragma: no cover - every candidate taken
            raise ValueError(f"cannot name the joint variables of {robot.name}: t<j>, th<j>, qj<j> all taken")

    def geo(r, k: str) -> str:
        e = getattr(r, k)
        if r.is_moving:
            e = e.subs(q_symbol(r.j), sp.Symbol(f"{prefix[r.sigma]}{r.j}", real=True))
        return _par_expr(e)

    simple = all(r.ant == r.j - 1 for r in rows)
    kind = 2 if robot.loops else (0 if simple else 1)
    out = [
        "(* SYMORO+ : parameters of a robot, written by symoro_gen *)",
        f"(* Robotname = '{robot.name}' *)",
    ]
    if robot.source:
        src = re.sub(r"\s+", " ", robot.source).replace("*)", "* )")
        out.append(f"(* Source: {src} *)")
    out += [f"NF = {nf}", f"NL = {nl}", f"NJ = {nj}", f"Type = {kind} (* {_TYPE_NAMES[kind]} *)",
            "is_floating = 0", "is_mobile = 0", "", "(* Geometric parameters *)"]
    for k in ("ant", "sigma", "b", "d", "r", "gamma", "alpha", "mu", "theta"):
        if k in _INT_FIELDS:
            vals = [str(getattr(r, k)) for r in rows]
        else:
            vals = [geo(r, k) for r in rows]
        out.append(f"{_PAR_SPELLING[k]} = {{{','.join(vals)}}}")

    nominal = dict(robot.nominal or {})
    extra: dict[str, float] = {}

    def dyn(k: str, r) -> str:
        name = f"{k}{r.j}"
        if k in INERTIAL_KINDS:
            present = r.is_moving or r.j == robot.payload
        else:
            present = r.is_moving and k in r.drive
        if not present:
            return "0"
        if name in nominal:
            v = nominal[name]
            if v != 0.0:
                return _par_number(v)
            extra[name] = 0.0  # a literal 0 would mean "absent" in SYMORO
        return name

    out += ["", "(* Dynamic parameters and external forces *)"]
    for k in INERTIAL_KINDS + ("IA", "FV", "FS"):
        out.append(f"{k} = {{{','.join(dyn(k, r) for r in links)}}}")
    for k in ("FX", "FY", "FZ", "CX", "CY", "CZ"):
        out.append(f"{k} = {{{','.join('0' for _ in links)}}}")
    out += ["(* Joint offsets kept in the model: symoro_gen extension, ignored by SYMORO *)",
            f"OFF = {{{','.join(dyn('OFF', r) for r in links)}}}"]
    out += ["", "(* Joint parameters *)"]
    for k in ("QP", "QDP", "GAM"):
        out.append(f"{k} = {{{','.join(f'{k}{r.j}' for r in rows[:nj])}}}")
    out += ["", "(* Speed and acceleration of the base *)"]
    out += [f"{k} = {{0,0,0}}" for k in _BASE_MOTION]
    out += ["", "(* Acceleration of gravity *)", f"G = {{{','.join(_par_number(g) for g in robot.gravity)}}}",
            "", "(* Transformation of 0 frame position fT0 *)", "Z = {1,0,0,0,0,1,0,0,0,0,1,0,0,0,0,1}"]
    numbers = {**{k: float(v) for k, v in sorted(robot.values.items())}, **extra}
    if numbers:
        out += ["", "(* Numerical values: symoro_gen extension, one NAME = number per line, ignored by SYMORO *)"]
        out += [f"{k} = {_par_number(v)}" for k, v in numbers.items()]
    out += ["", "(* End of definition *)"]
    return "\n".join(out) + "\n"


def _par_number(v: float) -> str:
    v = float(v)
    return str(int(v)) if v == int(v) and abs(v) < 1e15 else repr(v)


def _par_expr(e: sp.Expr) -> str:
    e = sp.sympify(e)
    if e.is_Integer:
        return str(int(e))
    if e.is_Float:
        return _par_number(float(e))
    text = _expr_text(e).replace("**", "^").replace(" ", "")
    return re.sub(r"\bpi\b", "Pi", text)


# ============================================================================ writing
def write_robot_toml(text: str, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Validate robot-file text and write it atomically (:func:`symoro_gen.atomic.write_text_atomic`).

    Parameters
    ----------
    text : str
        TOML robot file (e.g. from :func:`import_par`); it is parsed first and nothing is
        written if it is invalid.
    path : str or PathLike
        Destination (its folder must exist).
    overwrite : bool
        Replace an existing file; without it an existing ``path`` is left untouched.

    Returns
    -------
    Path
        The written path.

    Raises
    ------
    RobotFileError
        ``text`` is not a valid robot file (nothing written).
    OutputExistsError
        ``path`` exists and ``overwrite`` is false (a ``SymoroError`` and a ``FileExistsError``).
    """
    dest = Path(path)
    parse_robot_text(text, file=str(dest))
    if dest.exists() and not overwrite:
        raise OutputExistsError(dest)
    try:
        write_text_atomic(dest, text, overwrite=overwrite)  # never clobbers a file appearing meanwhile
    except FileExistsError:
        if dest.exists() and not overwrite:
            raise OutputExistsError(dest) from None
        raise
    return dest
