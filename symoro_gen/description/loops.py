"""The ``[[loops]]`` and ``[loop_reference]`` tables of a robot file (closed-loop robots).

Khalil & Kleinfinger's notation for closed loops ([KK1986]; [KD2002] sec. 7.3, the SR400 example; the
SYMORO+ ``.par`` layout ``NL < NJ < NF``): the loops are cut at passive joints, which leaves a tree of
``NL`` links (the ``[[frames]]`` table, passive joints with ``mu = 0``). Each cut joint ``k`` gets two
frames:

* the **cut frame** ``k = NR + l`` (``NR`` = number of ``[[frames]]`` rows, ``l`` = 1, 2, ... the loop),
  placed on its antecedent link like any MDH frame, with the cut joint's variable ``q<k>``;
* the **closing frame** ``k + B`` (``B`` loops), fixed (``sigma = 2``) on the link at the other side
  of the cut, which coincides with frame ``k`` when the loop is closed: ``T(0, k) = T(0, k + B)``.

Syntax (every field of ``cut``/``close`` as in ``[[frames]]``; ``j`` may be omitted)::

    [[loops]]
    cut   = { ant = 6, sigma = 0, alpha = 0, d = "D3", theta = "q + pi/2", r = 0 }
    close = { ant = 3, gamma = "pi/2", alpha = 0, d = "-L5", theta = 0, r = 0 }

    [loop_reference]          # optional: a closed, non-singular assembly (rad or m; missing = 0)
    q3 = 0.0

The assembly mode (a parallelogram or its crossed twin) is the one of the reference configuration,
followed continuously (:mod:`symoro_gen.closedloop.kinematics`).

Coupled (mimic) joints: a passive frame whose variable follows an actuated joint linearly,
``q<j> = multiplier * q<joint> + offset`` (URDF's ``<mimic>`` semantics; a gear pair, the second finger
of a gripper), written on its own ``[[frames]]`` row::

    [[frames]]
    j = 6
    ant = 4
    sigma = 1
    mimic = { joint = 5, multiplier = 1, offset = 0 }   # q6 = q5; mu = 0 is implied
    ...

``joint`` is an earlier, actuated moving frame; ``multiplier`` (non-zero) and ``offset`` (rad or m, default
0) are constant numbers or expressions (``"pi/2"``, ``"-1/3"``; no ``[values]`` symbols: the closure must be
a known constant). The model projects the tree on the actuated joints exactly as for a loop
(:mod:`symoro_gen.closedloop`, ``G`` constant); loops and couplings may be combined.
"""
from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import sympy as sp

from .expr import ExprError, parse_expression
from .mdh import row_transform
from .model import FIXED, PRISMATIC, REVOLUTE, Coupling, LoopClosure, MdhRow, q_symbol

__all__ = ["parse_loops", "parse_couplings", "check_passive", "check_actuation"]

_CUT_KEYS = ("j", "ant", "sigma", "mu", "gamma", "b", "alpha", "d", "theta", "r")
_GEOM = ("gamma", "b", "alpha", "d", "theta", "r")
LOOP_KEYS = {"cut", "close"}


def parse_loops(raw: Any, raw_ref: Any, rows: tuple[MdhRow, ...] | list[MdhRow], values: Mapping[str, float],
                bad: Callable[[str, str, str], None]) -> tuple[tuple[LoopClosure, ...], dict[str, float]]:
    """Validate ``[[loops]]`` (``raw``) and ``[loop_reference]`` (``raw_ref``) against the tree ``rows``.

    Every problem is reported through ``bad(where, field, message)`` (``where`` is ``"loop 1, cut"``,
    ``"[loop_reference]"``...). Returns the loops and the reference values.
    """
    loops: list[LoopClosure] = []
    if raw is None:
        raw = []
    if not isinstance(raw, list) or not all(isinstance(x, dict) for x in raw):
        bad("top level", "loops", "must be [[loops]] entries, each with a `cut` and a `close` table")
        return (), {}
    nr, nb = len(rows), len(raw)
    syms = {k: sp.Symbol(k, real=True) for k in values}
    link_frames = {r.j for r in rows if r.is_moving}
    for idx, entry in enumerate(raw, start=1):
        where0 = f"loop {idx}"
        for k in sorted(set(entry) - LOOP_KEYS):
            bad(where0, k, "unknown field (allowed: cut, close)")
        made: dict[str, MdhRow] = {}
        for part, j in (("cut", nr + idx), ("close", nr + nb + idx)):
            fr = entry.get(part)
            where = f"{where0}, {part}"
            if not isinstance(fr, dict):
                bad(where0, part, "missing: a table of MDH fields (ant, sigma, alpha, d, theta, r, ...)")
                continue
            ok = True
            for k in sorted(set(fr) - set(_CUT_KEYS)):
                bad(where, k, f"unknown field (allowed: {', '.join(_CUT_KEYS)})")
                ok = False
            if "j" in fr and fr["j"] != j:
                bad(where, "j", f"the {part} frame of loop {idx} is frame {j} (after the {nr} frames"
                                f"{' and the cut frames' if part == 'close' else ''}), got {fr['j']!r}")
                ok = False
            raw_ant = fr.get("ant")
            ant = raw_ant if isinstance(raw_ant, int) and not isinstance(raw_ant, bool) else -1
            if not (0 <= ant <= nr) or (ant and ant not in link_frames):
                bad(where, "ant", f"must be a link (a moving frame 1..{nr}) or 0 (the base), got {raw_ant!r}")
                ok = False
                ant = 0
            sigma = fr.get("sigma", REVOLUTE if part == "cut" else FIXED)
            if part == "cut" and sigma not in (REVOLUTE, PRISMATIC):
                bad(where, "sigma", f"a cut joint is 0 (revolute) or 1 (prismatic), got {sigma!r}")
                ok, sigma = False, REVOLUTE
            if part == "close" and sigma != FIXED:
                bad(where, "sigma", f"the closing frame is fixed on its link (sigma = 2), got {sigma!r}")
                ok, sigma = False, FIXED
            if fr.get("mu", 0) != 0:
                bad(where, "mu", "cut joints are passive (mu = 0)")
                ok = False
            q = q_symbol(j)
            ex: dict[str, sp.Expr] = {}
            for k in _GEOM:
                try:
                    e = parse_expression(fr.get(k, 0), {**syms, "q": q})
                except ExprError as exc:
                    bad(where, k, str(exc))
                    ok, e = False, sp.Integer(0)
                ex[k] = e
            var = {REVOLUTE: "theta", PRISMATIC: "r"}.get(sigma)
            for k, e in ex.items():
                if q in e.free_symbols and k != var:
                    bad(where, k, "the joint variable q may only appear in theta (cut revolute joint) or r "
                                  "(cut prismatic joint)")
                    ok = False
            if var is not None and ok:
                e = ex[var]
                if q not in e.free_symbols or sp.diff(e, q) not in (1, -1) or sp.diff(e, q, 2) != 0:
                    bad(where, var, f"must be q + constant (or -q + constant), got {fr.get(var)!r}")
                    ok = False
            if ok:
                made[part] = MdhRow(j=j, ant=ant, sigma=sigma, mu=0, drive=(), **ex)
        if len(made) == 2:
            if made["cut"].ant == made["close"].ant:
                bad(f"{where0}, close", "ant", "the cut and closing frames are on the same link: no loop")
            else:
                loops.append(LoopClosure(cut=made["cut"], close=made["close"]))

    ref: dict[str, float] = {}
    if raw_ref is not None:
        if not isinstance(raw_ref, dict):
            bad("top level", "loop_reference", "must be a table of q<j> = number")
        else:
            names = {f"q{r.j}" for r in rows if r.is_moving} | {f"q{lp.cut.j}" for lp in loops}
            for k, v in raw_ref.items():
                if k not in names:
                    bad("[loop_reference]", k, f"not a joint variable of this robot (known: {', '.join(sorted(names))})")
                elif not (isinstance(v, (int, float)) and not isinstance(v, bool) and v == v and abs(v) != float("inf")):
                    bad("[loop_reference]", k, f"must be a finite number, got {v!r}")
                else:
                    ref[k] = float(v)
        if not raw:
            bad("top level", "loop_reference", "given without [[loops]]")
    return tuple(loops), ref


MIMIC_KEYS = ("joint", "multiplier", "offset")


def _constant(value: Any, what: str) -> tuple[sp.Expr | None, str]:
    """A finite real constant (number or expression without symbols), or None and the reason."""
    try:
        e = parse_expression(value, {})
    except ExprError as exc:
        return None, str(exc)
    v = complex(sp.N(e))
    if not (v.imag == 0 and abs(v.real) != float("inf") and v.real == v.real):
        return None, f"{what} must be a finite real number, got {value!r}"
    return e, ""


def parse_couplings(frames: list[Any], rows: tuple[MdhRow, ...] | list[MdhRow],
                    bad: Callable[[str, str, str], None]) -> tuple[Coupling, ...]:
    """The ``mimic`` tables of the ``[[frames]]`` entries (``frames``, as read from TOML) against the parsed
    ``rows``; every problem through ``bad(where, field, message)``, ``where`` = ``"frame j"``, field
    ``mimic.joint``, ``mimic.multiplier``..."""
    out: list[Coupling] = []
    by_j = {r.j: r for r in rows}
    mimic_of = {}
    for idx, fr in enumerate(frames, start=1):
        if isinstance(fr, dict) and "mimic" in fr:
            mimic_of[idx] = fr["mimic"]
    for j, raw in mimic_of.items():
        where = f"frame {j}"
        row = by_j.get(j)
        if row is None:
            continue
        if not isinstance(raw, dict):
            bad(where, "mimic", "must be a table { joint = J, multiplier = 1.0, offset = 0.0 }")
            continue
        ok = True
        for k in sorted(set(raw) - set(MIMIC_KEYS)):
            bad(where, f"mimic.{k}", f"unknown field (allowed: {', '.join(MIMIC_KEYS)})")
            ok = False
        if not row.is_moving:
            bad(where, "mimic", "a fixed frame (sigma = 2) has no joint variable to couple")
            continue
        if row.mu != 0:
            bad(where, "mu", "a coupled joint (mimic) is passive: mu = 0 (the default with mimic)")
            ok = False
        src = raw.get("joint")
        if "joint" not in raw:
            bad(where, "mimic.joint", "missing: the frame of the joint it follows")
            ok = False
        elif not (isinstance(src, int) and not isinstance(src, bool)) or src not in by_j:
            bad(where, "mimic.joint", f"not a frame of this robot (1..{len(rows)}), got {src!r}")
            ok = False
        elif src == j:
            bad(where, "mimic.joint", "a joint cannot follow itself")
            ok = False
        elif src > j:
            bad(where, "mimic.joint", f"joint {src} comes after frame {j}: a coupled joint follows an earlier "
                                      "joint (renumber the frames)")
            ok = False
        elif not by_j[src].is_moving:
            bad(where, "mimic.joint", f"frame {src} is fixed (sigma = 2): no joint variable to follow")
            ok = False
        elif src in mimic_of:
            bad(where, "mimic.joint", f"joint {src} is itself coupled (mimic): follow the joint it follows "
                                      "(compose the multipliers and offsets); chains and cycles are not allowed")
            ok = False
        elif by_j[src].mu != 1:
            bad(where, "mimic.joint", f"joint {src} is passive (mu = 0): a coupled joint follows an actuated one")
            ok = False
        mult, why = _constant(raw.get("multiplier", 1), "the multiplier")
        if mult is None:
            bad(where, "mimic.multiplier", why)
            ok = False
        elif mult == 0 or abs(float(sp.N(mult))) < 1e-12:
            bad(where, "mimic.multiplier", "must be non-zero (a joint that does not move is a fixed frame, sigma = 2)")
            ok = False
        off, why = _constant(raw.get("offset", 0), "the offset")
        if off is None:
            bad(where, "mimic.offset", why)
            ok = False
        if ok and isinstance(src, int) and mult is not None and off is not None:
            out.append(Coupling(joint=j, source=src, multiplier=mult, offset=off))
    return tuple(out)


def check_passive(rows: tuple[MdhRow, ...] | list[MdhRow], loops: tuple[LoopClosure, ...],
                  couplings: tuple[Coupling, ...], bad: Callable[[str, str, str], None],
                  mimic_frames: frozenset[int] = frozenset()) -> None:
    """Every passive tree joint (``mu = 0``) of a robot with loops or couplings must lie on a loop or be
    coupled (else it is a free, unactuated joint: the closure would not determine it). ``mimic_frames``: the
    frames with a ``mimic`` table (a bad one is reported already, not again here)."""
    if not (loops or couplings or mimic_frames):
        return
    antecedent = {r.j: r.ant for r in rows}

    def chain(f: int) -> set[int]:
        out = set()
        while f:
            out.add(f)
            f = antecedent[f]
        return out

    on_loop: set[int] = {c.joint for c in couplings} | set(mimic_frames)
    for lp in loops:
        on_loop |= chain(lp.cut.ant) ^ chain(lp.close.ant)
    for r in rows:
        if r.is_moving and r.mu == 0 and r.j not in on_loop:
            bad(f"frame {r.j}", "mu", "a passive joint (mu = 0) must lie on a closed loop ([[loops]]) or follow "
                                      "another joint (mimic)")


def check_actuation(rows: tuple[MdhRow, ...] | list[MdhRow], loops: tuple[LoopClosure, ...],
                    values: Mapping[str, float], bad: Callable[[str, str, str], None], tol: float = 1e-9,
                    reference: Mapping[str, float] | None = None) -> None:
    """Refuse an over-actuated loop, naming the loop, its joints and the actuated ones (``load_model`` would only
    fail to close it). A loop of ``k`` joint variables (its moving tree joints and its cut joint) with ``c``
    independent closure equations has ``k - c`` degrees of freedom (the mobility of a single loop, [KD2002]
    sec. 7.3): more actuated joints than that cannot all move freely.

    * A planar loop (at q = 0 its revolute axes parallel, its prismatic axes orthogonal to them: a property of
      the geometry, kept by every joint motion) has ``c = 3`` (the planar case of [KD2002] sec. 7.3).
    * Any other loop: ``c`` is the rank of its joints' twists (screws, in one frame) at its reference assembly
      (``[loop_reference]``, missing values 0: a closed, non-singular configuration), the rank of the closure
      equations' Jacobian there (3 for a spherical loop, 6 for a general spatial one). When the loop does not
      close at that configuration (not an assembly: the rank of an open chain says nothing of the closed loop's)
      it is left to the model's closure check."""
    if not loops:
        return
    ref = dict(reference or {})
    subs = {sp.Symbol(k, real=True): v for k, v in values.items()}
    by_j = {r.j: r for r in rows}
    poses: dict[int, np.ndarray] = {0: np.eye(4)}
    at_ref: dict[int, np.ndarray] = {0: np.eye(4)}

    def pose(j: int, cache: dict[int, np.ndarray], q: Callable[[int], float]) -> np.ndarray:
        if j not in cache:
            r = by_j[j]
            cache[j] = pose(r.ant, cache, q) @ row_transform(r, subs, q(r.j) if r.is_moving else 0.0)
        return cache[j]

    def zero(j: int) -> float:
        return 0.0

    def reference_q(j: int) -> float:
        return float(ref.get(f"q{j}", 0.0))

    def chain(f: int) -> set[int]:
        out = set()
        while f:
            out.add(f)
            f = by_j[f].ant
        return out

    for k, lp in enumerate(loops, start=1):
        try:
            moving = [by_j[j] for j in sorted(chain(lp.cut.ant) ^ chain(lp.close.ant)) if by_j[j].is_moving]
            axes = [(pose(r.j, poses, zero)[:3, 2], r.sigma) for r in moving]
            axes.append(((pose(lp.cut.ant, poses, zero) @ row_transform(lp.cut, subs, 0.0))[:3, 2], lp.cut.sigma))
        except (KeyError, TypeError, ValueError):  # a geometry reported elsewhere
            continue
        revolute = [z for z, sg in axes if sg == REVOLUTE]
        if not revolute:
            continue
        n0 = revolute[0]
        planar = (all(np.linalg.norm(np.cross(n0, z)) < tol for z in revolute)
                  and all(abs(float(n0 @ z)) < tol for z, sg in axes if sg == PRISMATIC))
        actuated = [r.j for r in moving if r.mu != 0]
        joints = ", ".join(map(str, [r.j for r in moving]))
        if planar:
            equations, kind = 3, "is planar (3 closure equations)"
        else:
            try:
                rank = _closure_rank(moving, lp, subs, lambda j: pose(j, at_ref, reference_q), reference_q)
            except (KeyError, TypeError, ValueError):
                continue
            if rank is None:
                continue
            equations, kind = rank, f"is not planar ({rank} independent closure equations at its reference assembly)"
        dof = len(moving) + 1 - equations
        if len(actuated) <= max(dof, 0):
            continue
        bad(f"loop {k}", "mu", (
            f"over-actuated: the loop through joints {joints} and its cut joint {lp.cut.j} {kind} and has {dof} "
            f"degree(s) of freedom, but its actuated joints are {', '.join(map(str, actuated))}: make all but "
            f"{max(dof, 0)} of them passive (mu = 0)"))


def _closure_rank(moving: list[MdhRow], lp: LoopClosure, subs: Mapping[Any, Any],
                  pose: Callable[[int], np.ndarray], q: Callable[[int], float]) -> int | None:
    """The number of independent closure equations of a loop at its reference assembly: the rank of the twists
    ``(z, p x z)`` (revolute) or ``(0, z)`` (prismatic) of its joints, axis ``z`` and a point ``p`` of it (the
    origin of the joint's MDH frame) in the base frame ([KD2002] sec. 7.3; Murray, Li & Sastry 1994, ch. 3); None
    when the loop does not close there (cut frame and closing frame apart by more than 1e-6)."""
    cut = pose(lp.cut.ant) @ row_transform(lp.cut, subs, q(lp.cut.j))
    close = pose(lp.close.ant) @ row_transform(lp.close, subs, 0.0)
    if not np.allclose(cut, close, atol=1e-6):
        return None
    frames = [(pose(r.j), r.sigma) for r in moving] + [(cut, lp.cut.sigma)]
    twists = np.array([np.r_[T[:3, 2], np.cross(T[:3, 3], T[:3, 2])] if sg == REVOLUTE else np.r_[np.zeros(3), T[:3, 2]]
                       for T, sg in frames]).T
    sv = np.linalg.svd(twists, compute_uv=False)
    return int(np.sum(sv > 1e-8 * max(sv[0], 1.0)))
