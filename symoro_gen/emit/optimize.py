"""Graph optimisations applied before printing.

``rotation_pairs``: a plane rotation by theta_j needs 4 multiplications when written
``u = C a - S b; v = S a + C b``. When both outputs are used, the 3-multiplication form
``k1 = C (a + b); u = k1 - b (C + S); v = k1 + a (S - C)`` (Gauss) is used instead, with
``C + S`` and ``S - C`` computed once per joint.
"""
from __future__ import annotations

from typing import Any

import sympy as sp
from sympy.core.add import _addsort
from sympy.core.mul import _mulsort

from ..dynamics.graph import ExprGraph


def _term(t: sp.Expr) -> tuple[int, tuple[sp.Expr, ...]] | None:
    """Split a product ``sign * X * Y`` into (sign, frozenset{X, Y}) when it has that shape."""
    coeff, rest = t.as_coeff_Mul()
    if coeff not in (1, -1):
        return None
    f = sp.Mul.make_args(rest)
    if len(f) != 2 or not all(x.is_Symbol for x in f):
        return None
    return int(coeff), f


def _match(e: sp.Expr, trig: dict[sp.Symbol, tuple[str, str]]) -> tuple[Any, ...] | None:
    """e == s1 * C * a + s2 * S * b with C, S the cos/sin of the same joint -> (j, s1, a, s2, b)."""
    if not e.is_Add or len(e.args) != 2:
        return None
    parts = [_term(t) for t in e.args]
    info = []
    for part in parts:
        if part is None:
            return None
        s, f = part
        k = [x for x in f if x in trig]
        if len(k) != 1:
            return None
        other = f[0] if f[1] is k[0] else f[1]
        info.append((trig[k[0]], s, other))
    (ja, kind_a, sa, xa), (jb, kind_b, sb, xb) = [(t[0][0], t[0][1], t[1], t[2]) for t in info]
    if ja != jb or kind_a == kind_b:
        return None
    if kind_a == "C":
        return ja, "C", sa, xa, sb, xb  # sa*C*xa + sb*S*xb
    return ja, "C", sb, xb, sa, xa


def _signed(s: int, e: sp.Expr) -> sp.Expr:
    """``s * e`` for ``s = +-1``: ``e`` or ``-e`` (the same expressions as sympy's ``s * e``, without the
    multiplication by 1 and its sympify)."""
    return e if s == 1 else -e


def rotation_pairs(graph: ExprGraph, memo: dict[Any, Any] | None = None) -> ExprGraph:
    """Rewrite paired rotations with 3 multiplications (see module docstring).

    ``memo``: a dict kept by the caller across the graphs of one model; the products that do not depend
    on the numbering of the new variables are built once (results do not depend on it).
    """
    memo = {} if memo is None else memo

    def once(key: tuple[Any, ...], build: Any) -> Any:
        got = memo.get(key)
        if got is None:
            got = memo[key] = build()
        return got

    trig: dict[sp.Symbol, tuple[str, str]] = {}
    for s, e in graph.defs:
        if isinstance(e, sp.cos):
            trig[s] = (s.name[1:], "C")
        elif isinstance(e, sp.sin):
            trig[s] = (s.name[1:], "S")
    csym = {v: k for k, v in trig.items()}
    # candidate "C-led" (u = s1 C a + s2 S b) and "S-led" (v = s3 S a + s4 C b) expressions
    items = list(graph.defs) + [(("out",) + k, e) for k, e in sorted(graph.outputs.items(), key=lambda kv: str(kv[0]))]
    by_pair: dict[Any, list[Any]] = {}
    for key, e in items:
        m = _match(e, trig)
        if m is None:
            continue
        j, _, sc, xc, ss, xs = m
        # C multiplies xc, S multiplies xs: u-type if we call a = xc, b = xs; v-type if a = xs, b = xc.
        by_pair.setdefault((j, frozenset((xc, xs))), []).append((key, sc, xc, ss, xs))
    replace: dict[Any, sp.Expr] = {}
    new_defs_for: dict[Any, Any] = {}
    used_joints: set[str] = set()
    for (j, pair), lst in by_pair.items():
        if len(pair) != 2 or len(lst) < 2:
            continue
        done = False
        for i1 in range(len(lst)):
            if done:
                break
            for i2 in range(len(lst)):
                if i1 == i2:
                    continue
                k1, s1, a, s2, b = lst[i1]  # u = s1 C a + s2 S b
                k2, s4, b2, s3, a2 = lst[i2]  # v = s4 C b2 + s3 S a2  -> need a2 == a, b2 == b
                if a2 != a or b2 != b or s1 * s2 * s3 * s4 != -1:
                    continue
                C = csym[(j, "C")]
                S = csym[(j, "S")]
                bp = _signed(-s1 * s2, b)  # b' = -s1 s2 b
                new_defs_for[(k1, k2)] = (j, C, a, bp, s1, s3)
                used_joints.add(j)
                done = True
                break
    if not new_defs_for:
        return graph
    # build new defs
    extra_at: dict[Any, list[tuple[sp.Symbol, sp.Expr]]] = {}
    jdefs = {}
    for j in sorted(used_joints):
        C, S = csym[(j, "C")], csym[(j, "S")]
        jdefs[j] = (sp.Symbol(f"CpS{j}", real=True), C + S, sp.Symbol(f"SmC{j}", real=True), S - C)
    order = {k: i for i, (k, _) in enumerate(items)}
    joint_at: dict[Any, str] = {}
    for n, ((k1, k2), (j, C, a, bp, s1, s3)) in enumerate(new_defs_for.items()):
        K = sp.Symbol(f"rot{n}", real=True)
        CpS, _, SmC, _ = jdefs[j]
        replace[k1] = _signed(s1, K - once(("rot*", bp, CpS), lambda bp=bp, CpS=CpS: bp * CpS))
        replace[k2] = _signed(s3, K + once(("rot*", a, SmC), lambda a=a, SmC=SmC: a * SmC))
        first = k1 if order[k1] < order[k2] else k2
        extra_at[first] = [(K, once(("rotK", C, a, bp), lambda C=C, a=a, bp=bp: C * (a + bp)))]
        joint_at[first] = j
    placed_joint: set[str] = set()

    def emit_extra(key: Any, sink: list[tuple[sp.Symbol, sp.Expr]]) -> None:
        j = joint_at[key]
        if j not in placed_joint:  # the joint's C+S and S-C before their first use
            CpS, ce, SmC, se = jdefs[j]
            sink += [(CpS, ce), (SmC, se)]
            placed_joint.add(j)
        sink += extra_at[key]

    defs: list[tuple[sp.Symbol, sp.Expr]] = []
    for s, e in graph.defs:
        if s in extra_at:
            emit_extra(s, defs)
        defs.append((s, replace.get(s, e)))
    outs = {}
    tail: list[tuple[sp.Symbol, sp.Expr]] = []
    for k, e in graph.outputs.items():
        key = ("out",) + k
        if key in extra_at:
            emit_extra(key, tail)
        outs[k] = replace.get(key, e)
    return ExprGraph(graph.inputs, tuple(defs) + tuple(tail), outs)


def _products_in(e: sp.Expr) -> tuple[frozenset[sp.Symbol] | tuple[sp.Symbol], ...]:
    """Two-symbol products (up to sign) appearing as terms or factors of e."""
    out: list[frozenset[sp.Symbol] | tuple[sp.Symbol]] = []
    for m in e.atoms(sp.Mul):
        _coeff, rest = m.as_coeff_Mul()
        f = sp.Mul.make_args(rest)
        syms = [x for x in f if x.is_Symbol]
        if len(syms) == 2 and len(f) == 2:
            out.append(frozenset(syms) if syms[0] != syms[1] else (syms[0],))
        for x in f:
            if x.is_Pow and x.exp == 2 and x.base.is_Symbol:
                out.append((x.base,))
    return tuple(out)


def _times(coeff: sp.Expr, factors: list[sp.Expr]) -> sp.Expr:
    """``coeff * Mul(*factors)``: for factors that are not numbers nor sums and have distinct bases, the Mul that
    sympy's ``Mul.flatten`` builds (the number first, then the factors in ``_mulsort`` order), built directly.

    Flatten multiplies the number by 1 and asks the new Float whether it is zero: sympy's assumption system
    deduces all the facts of each new Float (~0.2 ms), which was most of this pass on general chains
    (float constants from sin/cos of arbitrary alpha).
    """
    if (len(factors) < 1 or not coeff.is_Number
            or any(f.is_Number or f.is_Add or f.is_Mul or not f.is_commutative for f in factors)
            or len({f.as_base_exp()[0] for f in factors}) != len(factors)):
        return coeff * sp.Mul(*factors)
    fs = list(factors)
    _mulsort(fs)
    if coeff is sp.S.One:
        return fs[0] if len(fs) == 1 else sp.Mul._from_args(fs)
    return sp.Mul._from_args([coeff] + fs)


def _replace_terms(e: sp.Expr, rep: dict[sp.Expr, sp.Expr]) -> sp.Expr:
    """``e.xreplace(rep)`` when ``rep`` replaces terms of the sum ``e`` by products with a new symbol: the sum is
    rebuilt as sympy's ``Add.flatten`` would (the number first, the other terms in ``_addsort`` order; no two
    terms become alike, the new symbol standing for one product), without flatten re-multiplying every
    ``float * symbol`` term (a new Float whose facts sympy deduces each time). Other shapes: ``xreplace``."""
    if e in rep:
        return rep[e]
    if not e.is_Add:
        return e.xreplace(rep)
    args = e.args
    if not all(m in args for m in rep):  # a product nested deeper than a term
        return e.xreplace(rep)
    new = [rep.get(t, t) for t in args]
    if any(t.is_Add or t.is_Number for t in rep.values()):
        return e.xreplace(rep)
    num = [t for t in new if t.is_Number]
    terms = [t for t in new if not t.is_Number]
    _addsort(terms)
    return sp.Add._from_args(num + terms)


def share_products(graph: ExprGraph, memo: dict[Any, Any] | None = None) -> ExprGraph:
    """Name every product of two symbols (or square) used more than once, and reuse it.

    ``memo``: a dict kept by the caller across the graphs of one model (they share most definitions),
    expression -> its products; results do not depend on it.
    """
    memo = {} if memo is None else memo

    def products(e: sp.Expr) -> tuple[frozenset[sp.Symbol] | tuple[sp.Symbol], ...]:
        got = memo.get(e)
        if got is None:
            got = memo[e] = _products_in(e)
        return got

    count: dict[frozenset[sp.Symbol] | tuple[sp.Symbol], int] = {}
    for _, e in graph.defs:
        for p in products(e):
            count[p] = count.get(p, 0) + 1
    for e in graph.outputs.values():
        for p in products(e):
            count[p] = count.get(p, 0) + 1
    shared = sorted((p for p, c in count.items() if c > 1), key=lambda p: sorted(s.name for s in p))
    if not shared:
        return graph
    sym_of = {}
    for i, p in enumerate(shared):
        sym_of[p] = sp.Symbol(f"pr{i}", real=True)

    def expr_of(p: frozenset[sp.Symbol] | tuple[sp.Symbol]) -> sp.Expr:
        return p[0] * p[0] if isinstance(p, tuple) else sp.Mul(*sorted(p, key=lambda s: s.name))

    subs = {expr_of(p): sym_of[p] for p in shared}
    # place each product right after the last of its operands is defined
    pos = {s: i for i, (s, _) in enumerate(graph.defs)}
    place: dict[int, list[frozenset[sp.Symbol] | tuple[sp.Symbol]]] = {}
    for p in shared:
        ops = p if isinstance(p, tuple) else tuple(p)
        k = max((pos.get(s, -1) for s in ops), default=-1)
        place.setdefault(k, []).append(p)

    def rewrite(e: sp.Expr) -> sp.Expr:
        rep = {}
        for m in e.atoms(sp.Mul):
            coeff, rest = m.as_coeff_Mul()
            f = sp.Mul.make_args(rest)
            if rest in subs:
                rep[m] = _times(coeff, [subs[rest]])
            elif len(f) > 2:
                # a longer product containing a shared pair: factor it out
                for a in range(len(f)):
                    for b in range(a + 1, len(f)):
                        # f[a] * f[b] is a shared product only when both are symbols (the factors of a
                        # canonical Mul have distinct bases): look the pair up without building it
                        if not (f[a].is_Symbol and f[b].is_Symbol):
                            continue
                        pair = frozenset((f[a], f[b]))
                        if pair in sym_of:
                            others = [x for k, x in enumerate(f) if k not in (a, b)]
                            rep[m] = _times(coeff, [sym_of[pair], *others])
                            break
                    if m in rep:
                        break
            else:
                for x in f:
                    if x.is_Pow and x in subs:
                        rep[m] = _times(coeff, [subs[x], *[y for y in f if y is not x]])
        return _replace_terms(e, rep) if rep else e

    defs = [(sym_of[p], expr_of(p)) for p in place.get(-1, [])]
    for i, (s, e) in enumerate(graph.defs):
        defs.append((s, rewrite(e)))
        defs += [(sym_of[p], expr_of(p)) for p in place.get(i, [])]
    outs = {k: rewrite(e) for k, e in graph.outputs.items()}
    return ExprGraph(graph.inputs, tuple(defs), outs)


def optimize(graph: ExprGraph, memo: dict[Any, Any] | None = None) -> ExprGraph:
    """All passes, in order (``memo``: see :func:`share_products`)."""
    memo = {} if memo is None else memo
    return share_products(rotation_pairs(graph, memo), memo)
