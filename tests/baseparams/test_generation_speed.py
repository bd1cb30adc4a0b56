"""The shortcuts that make generation fast compute what the long way computes.

No timings here (bench/bench_generator.py measures them); each shortcut is checked against the
plain computation it replaces:

* the named-expression lookup finds ``-e`` among the named expressions without building ``-e``;
* the exact base-parameter solve builds only the columns it needs (``build_regressor(columns=...)``):
  those columns are the full model's, numerically, and no others are built;
* the closed-form regrouping expands each moved block on placeholders and substitutes the
  accumulated sums afterwards: once expanded, the same relation as expanding the block directly;
* the K matrix skips ``sympy.expand`` on relations that it would leave unchanged: whenever the
  test says "already expanded", ``expand`` is indeed the identity;
* the relations are computed as exact sparse polynomials (:class:`regroup._PolyAlgebra`) and built once
  as sympy sums, without flatten (:func:`regroup._canonical_sum`, sorted by ranks of their factors): the same expressions as sympy's arithmetic and ``expand`` (:class:`regroup._ExprAlgebra`),
  and the sympy path is taken for coefficients outside that form (``sqrt(3)`` from alpha = pi/3);
* the K matrix evaluates ``float(c * num)`` by sympy's evalf steps with cached factors: bit for bit the
  same floats;
* the relations are printed without sympy's printer: the same text as ``sympy.sstr(e, order="none")``;
* the shared-product pass builds its rewritten terms and sums as sympy's flatten orders them: the same
  expressions (and so the same printed code) as ``xreplace``;
* structure, not time: the Newton-Euler graph of a serial chain grows no faster than the n^2
  entries of the regressor ([KK1987]: one named variable per non-zero term, no expansion).
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from symoro_gen.baseparams import regroup
from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.dynamics.evaluate import evaluate_columns
from symoro_gen.dynamics.graph import GraphBuilder
from symoro_gen.dynamics.newton_euler import build_regressor


def chain_text(n: int, general: bool, seed: int = 0) -> str:
    """Serial revolute chain, 14 parameters per joint, random non-zero d and r; alpha arbitrary
    (``general``) or cycling through 0, -pi/2, pi/2."""
    rng = np.random.default_rng(seed)
    lines = [f'name = "chain{n}"', "gravity = [0, 0, -9.81]", 'drive = ["IA", "FV", "FS", "OFF"]', ""]
    for j in range(1, n + 1):
        d, r = (float(rng.integers(50, 500)) / 1000 * float(rng.choice([-1, 1])) for _ in range(2))
        alpha = repr(float(rng.integers(200, 1300)) / 1000) if general else ("0", '"-pi/2"', '"pi/2"')[j % 3]
        lines += ["[[frames]]", f"j = {j}", f"ant = {j - 1}", "sigma = 0", f"alpha = {alpha}", f"d = {d!r}",
                  'theta = "q"', f"r = {r!r}", ""]
    return "\n".join(lines)


def test_named_negation_found_without_building_it():
    x, y, z = sp.symbols("x y z", real=True)
    g = GraphBuilder()
    cases = [x * y + 0.25 * z, 2 * x - y * z + sp.Rational(1, 3), x * y * z, sp.sin(x) - 1.5 * y, -x * y + z]
    named = [g.name(e, "a") for e in cases]
    assert len(g.defs) == len(cases)
    for e, s in zip(cases, named):
        assert g.name(e, "b") == s  # the same expression: the same name
        assert g.name(-e, "b") == -s  # its negation: minus that name, nothing new defined
        assert g.name(sp.expand(-e), "b") == -s
    assert len(g.defs) == len(cases)
    assert g.name(x * y - 0.25 * z, "c") not in (named[0], -named[0])  # a sign flip of one term is new
    assert len(g.defs) == len(cases) + 1


@pytest.mark.parametrize("robot_text", ["rx90", "general4"])
def test_restricted_columns_equal_the_full_model(robot_text):
    robot = load_robot("rx90") if robot_text == "rx90" else parse_robot_text(chain_text(4, True), file="g.toml")
    full = build_regressor(robot, symbolic_gravity=True)
    names = [robot.standard_names[k] for k in (0, 5, 9, 12, 20, len(robot.standard_names) - 1)]
    part = build_regressor(robot, symbolic_gravity=True, columns=set(names))
    assert {n for _, n in part.graph.outputs} <= set(names)
    assert len(part.graph.defs) < len(full.graph.defs)
    rng = np.random.default_rng(3)
    n, N = robot.n_joints, 7
    values = {**robot.geometry_subs(), **{s: float(v) for s, v in regroup.gravity_symbols(robot).items()}}
    for syms, scale in ((robot.q, np.pi), (robot.dq, 2.0), (robot.ddq, 4.0)):
        for s in syms:
            values[s] = rng.uniform(-scale, scale, N)
    a = evaluate_columns(full.graph, n, names, values, N)
    b = evaluate_columns(part.graph, n, names, values, N)
    assert np.abs(a).max() > 0
    np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)


def test_linear_expansion_on_placeholders_equals_direct_expansion():
    a, b, c, d, e = sp.symbols("a b c d e", real=True)
    ca, sa = sp.cos(sp.Rational(7, 10)), sp.sin(sp.Rational(7, 10))
    R = sp.Matrix([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
    P = sp.Matrix([sp.Rational(3, 20), -sa / 4, ca / 4])
    values = (a + 2 * b - c * ca, c + sa * d, e - a / 3 + b * ca**2)  # accumulated sums, not expanded

    def moved(YY, MZ, M):
        s = R * sp.Matrix([0, 0, MZ])
        dJ = R * sp.diag(YY, YY, 0) * R.T + M * ((P.T * P)[0] * sp.eye(3) - P * P.T)
        dJ += 2 * (P.T * s)[0] * sp.eye(3) - P * s.T - s * P.T
        return dJ.row_join(s + M * P)

    fast = regroup._expand_linear(moved, values)
    direct = moved(*values).applyfunc(sp.expand)
    assert fast.applyfunc(sp.expand) == direct


def test_already_expanded_test_agrees_with_expand():
    x, y = sp.symbols("x y", real=True)
    c = sp.cos(sp.Rational(1, 5))
    expanded = [x * c**2 + 3 * y / 7, x * sp.sin(y / 5) * c - y, x**2 * y, sp.Integer(0), 2 * x]
    for e in expanded:
        assert regroup._is_expanded(e) and sp.expand(e) == e
    for e in (x * (y + c), (x + y) ** 2, c * (x - 2 * y) + y, sp.cos(x * (1 + y)) * y):
        assert not regroup._is_expanded(e), e
    bp = regroup.group_base_parameters(build_regressor(parse_robot_text(chain_text(3, True), file="g.toml")))
    for rel in bp.relations.values():
        e = rel.xreplace({**bp.gravity, **bp.geometry})
        if regroup._is_expanded(e):
            assert sp.expand(e) == e


def test_graph_size_grows_no_faster_than_the_regressor():
    """Named intermediate variables of the Newton-Euler graph: at most quadratic in the frame count
    (the regressor has ~n^2/2 x 14 non-zero entries); doubling n at most quadruples them (+10 %)."""
    sizes = {n: len(build_regressor(parse_robot_text(chain_text(n, False), file="c.toml")).graph.defs)
             for n in (3, 6)}
    assert sizes[6] <= 4.4 * sizes[3], sizes


def test_constant_split_equals_as_independent():
    """The K matrix splits each relation term into its constant factor and its parameter symbol: the
    shortcut gives what ``as_independent`` gives, term by term, on a general chain's relations."""
    bp = regroup.group_base_parameters(build_regressor(parse_robot_text(chain_text(3, True), file="g.toml")))
    n = 0
    memo: dict = {}  # shared by all the relations, as in BaseParameterMap.matrix
    plain: dict = {}
    for rel in bp.relations.values():
        e = rel.xreplace({**bp.gravity, **bp.geometry})
        fs = e.free_symbols
        assert set(regroup._LazyFreeSymbols(e)) == fs
        assert regroup._is_expanded(e, plain) == regroup._is_expanded(e)
        for term in e.as_coefficients_dict():
            want = term.as_independent(*fs, as_Add=False)
            assert regroup._split_constant(term, fs) == want
            assert regroup._split_constant(term, regroup._LazyFreeSymbols(e), memo) == want
            n += 1
    assert n > 50 and len(memo) < n  # factors recur across terms


_SPECIAL = """name = "special"
gravity = [0, 0, -9.81]
drive = ["IA", "FV", "FS", "OFF"]

[[frames]]
j = 1
ant = 0
sigma = 0
alpha = 0
d = 0
theta = "q"
r = 0.3

[[frames]]
j = 2
ant = 1
sigma = 0
alpha = "pi/3"
d = 0.2
theta = "q"
r = 0.05

[[frames]]
j = 3
ant = 2
sigma = 1
alpha = 0.7
d = 0.1
theta = 0.4
r = "q"
"""


@pytest.mark.parametrize("case", ["general", "industrial", "rx90", "scara", "sda10f"])
def test_polynomial_relations_equal_sympy_arithmetic(case):
    robot = {"general": lambda: parse_robot_text(chain_text(5, True), file="g.toml"),
             "industrial": lambda: parse_robot_text(chain_text(5, False), file="i.toml"),
             }.get(case, lambda: load_robot(case))()
    reg = build_regressor(robot)
    args = (np.random.default_rng(0), 60, 1e-9, 1e-7, 1e-8)
    fast = regroup._group(reg, regroup._PolyAlgebra(), *args)
    slow = regroup._group(reg, regroup._ExprAlgebra(), *args)
    assert fast == slow  # same names, kept, eliminated, and relations (sympy's structural equality)
    assert [sp.srepr(fast.relations[k]) for k in fast.base_names] == [sp.srepr(slow.relations[k]) for k in slow.base_names]
    assert any(len(sp.Add.make_args(e)) > 3 for e in fast.relations.values())


def test_canonical_sum_equals_sympy_add_of_muls():
    """The relations' sums built without flatten (ranks by ``Basic.compare``): the same class and args as
    ``Add(*[Mul(c, *factors)])`` on random terms (coefficients 1, -1, integers, fractions; symbols of
    several classes of names, sin/cos of rationals, integer powers incl. negative ones), and sympy's own
    result when something would combine (a repeated base, two terms with the same factors)."""
    rng = np.random.default_rng(5)
    params = [sp.Symbol(n, real=True) for n in ("XX2", "XY2", "MX10", "MX9", "M3", "ZZ1", "IA4", "FV2", "OFF7")]
    atoms = [sp.Symbol("G3", real=True), sp.Symbol("L1", real=True), sp.sin(sp.Rational(457, 500)),
             sp.cos(sp.Rational(457, 500)), sp.cos(sp.Rational(-3, 10)), sp.sin(sp.Rational(7, 1000))]
    coeffs = [sp.Integer(1), sp.Integer(-1), sp.Integer(2), sp.Rational(-3, 7), sp.Rational(1, 2), sp.Integer(-12)]
    for _trial in range(60):
        terms, seen = [], set()
        for _ in range(int(rng.integers(2, 25))):
            p = params[int(rng.integers(len(params)))]
            k = int(rng.integers(0, 4))
            chosen = rng.choice(len(atoms), size=k, replace=False)
            f = [p] + [atoms[int(a)] ** int(rng.choice([1, 1, 2, 3, -1])) for a in chosen]
            if frozenset(f) in seen:
                continue
            seen.add(frozenset(f))
            terms.append((coeffs[int(rng.integers(len(coeffs)))], f))
        fast, slow = regroup._canonical_sum(terms), sp.Add(*[sp.Mul(c, *f) for c, f in terms])
        assert (fast.func, fast.args) == (slow.func, slow.args), terms
        assert fast is not slow  # built directly (sympy's cached Add would be the same object)
        assert [(t.func, t.args) for t in sp.Add.make_args(fast)] == [(t.func, t.args) for t in sp.Add.make_args(slow)]
    x = params[0]
    for terms in ([(sp.Integer(1), [x, atoms[0]]), (sp.Integer(2), [atoms[0], x])],  # the same factors twice
                  [(sp.Integer(1), [x, atoms[2], atoms[2] ** 2]), (sp.Integer(3), [params[1]])],  # a repeated base
                  [(sp.Float(0.5), [x]), (sp.Integer(1), [params[1]])]):  # a float coefficient
        fast, slow = regroup._canonical_sum(terms), sp.Add(*[sp.Mul(c, *f) for c, f in terms])
        assert fast is slow  # sympy's own (cached) result


def test_polynomial_relations_fall_back_to_sympy_for_irrational_constants():
    robot = parse_robot_text(_SPECIAL, file="special.toml")
    reg = build_regressor(robot)
    with pytest.raises(regroup._NotPolynomial):
        regroup._group(reg, regroup._PolyAlgebra(), np.random.default_rng(0), 60, 1e-9, 1e-7, 1e-8)
    bp = regroup.group_base_parameters(reg)  # the public entry takes the sympy path
    slow = regroup._group(reg, regroup._ExprAlgebra(), np.random.default_rng(0), 60, 1e-9, 1e-7, 1e-8)
    assert bp == slow
    assert bp.relations["ZZ1R"].has(sp.Rational(3, 4) * sp.Symbol("YY2", real=True))  # sin(pi/3)**2, exact


def test_polynomial_algebra_products_and_laurent_terms():
    """Products of sums of atoms, exponents cancelling (``G3 * (1/G3)``), terms cancelling to zero."""
    alg = regroup._PolyAlgebra()
    G3, L = sp.Symbol("G3", real=True), sp.Symbol("L", real=True)
    c, s = sp.cos(sp.Rational(7, 10)), sp.sin(sp.Rational(7, 10))
    x = alg.add_scaled(alg.symbol("M2"), c * L + s**2 / 3, alg.symbol("MZ2"))
    y = alg.add_scaled(alg.symbol("M3"), G3 - c, x)
    z = alg.add_scaled(y, 1 / G3, alg.add_scaled(alg.symbol("OFF3"), -L * c, x))
    M2, MZ2, M3, OFF3 = (sp.Symbol(n, real=True) for n in ("M2", "MZ2", "M3", "OFF3"))
    xe = M2 + (c * L + s**2 / 3) * MZ2
    ze = sp.expand(M3 + (G3 - c) * xe + (OFF3 - L * c * xe) / G3)
    assert alg.to_expr(z) == ze
    assert alg.is_symbol(alg.sub(alg.add(alg.symbol("M2"), alg.symbol("M3")), alg.symbol("M3")), "M2")
    assert alg.sub(x, x) == {}
    with pytest.raises(regroup._NotPolynomial):
        alg.add_scaled(x, sp.Float(0.5), x)
    with pytest.raises(regroup._NotPolynomial):
        alg.add_scaled(x, 1 / (G3 + L), x)


@pytest.mark.parametrize("n_frames", [3, 6])
def test_product_float_equals_sympy_float_bit_for_bit(n_frames):
    bp = regroup.group_base_parameters(build_regressor(parse_robot_text(chain_text(n_frames, True, seed=n_frames),
                                                                        file="g.toml")))
    to_float = regroup._ProductFloat()
    n_fast = 0
    for rel in bp.relations.values():
        e = rel.xreplace({**bp.gravity, **bp.geometry})
        fs = e.free_symbols
        for term, c in e.as_coefficients_dict().items():
            num, _ = regroup._split_constant(term, fs)
            assert to_float(c, num).hex() == float(c * num).hex(), (c, num)
            n_fast += num is not sp.S.One
    assert n_fast >= 20
    for c, num in ((sp.Rational(-3, 7), sp.cos(sp.Rational(1, 3))), (sp.Integer(1), sp.sin(sp.Rational(2, 7)) ** 3),
                   (sp.Rational(5, 2), sp.sqrt(3) * sp.cos(sp.Rational(1, 9))), (sp.Float(0.3), sp.sin(sp.Rational(1, 2)))):
        assert to_float(c, num).hex() == float(c * num).hex()
    K = bp.matrix()
    assert K.shape == (len(bp.base_names), len(bp.standard_names)) and np.abs(K).max() > 0


def test_relation_text_equals_sympy_sstr():
    from symoro_gen.emit.printing import relation_text

    texts = 0
    for robot in (parse_robot_text(chain_text(4, True), file="g.toml"), load_robot("scara"), load_robot("sda10f"),
                  parse_robot_text(_SPECIAL, file="special.toml")):
        bp = regroup.group_base_parameters(build_regressor(robot))
        memo: dict = {}  # shared by the relations of a robot, as in package_files
        for e in bp.relations.values():
            assert relation_text(e) == sp.sstr(e, order="none")
            assert relation_text(e, memo) == sp.sstr(e, order="none")
            texts += 1
    G3, x, y = sp.symbols("G3 x y", real=True)
    c = sp.cos(sp.Rational(3, 4))
    for e in (-x, -x / 3 + 2 * y * c**2, x / G3 - y / (3 * G3), x + sp.Float(0.25) * y, -2 * x * c / 7 - y,
              x * sp.sin(y) ** 2 - sp.sqrt(2) * y, sp.Integer(3) * x):
        assert relation_text(e) == sp.sstr(e, order="none"), e
        assert relation_text(e, memo) == sp.sstr(e, order="none"), e  # a memo filled by other relations
    assert texts > 50


def test_shared_products_equal_the_xreplace_rewrite(monkeypatch):
    """The optimiser's direct construction of rewritten terms and sums against plain ``xreplace``: the same
    expressions, argument order included (which the printers follow), on a general chain (float constants)."""
    from symoro_gen.emit import optimize
    from symoro_gen.emit.package import model_graphs

    robot = parse_robot_text(chain_text(4, True), file="g.toml")
    reg = build_regressor(robot)
    bp = regroup.group_base_parameters(reg)
    fast, _ = model_graphs(reg, bp)
    monkeypatch.setattr(optimize, "_times", lambda coeff, factors: coeff * sp.Mul(*factors))
    monkeypatch.setattr(optimize, "_replace_terms", lambda e, rep: e.xreplace(rep))
    slow, _ = model_graphs(reg, bp)
    for k in fast:
        assert [(s, e.args) for s, e in fast[k].defs] == [(s, e.args) for s, e in slow[k].defs]
        assert {o: e.args for o, e in fast[k].outputs.items()} == {o: e.args for o, e in slow[k].outputs.items()}
    assert any(s.name.startswith("pr") for s, _ in fast["base"].defs)


@pytest.mark.parametrize("which", ["general", "rx90"])
def test_newton_euler_direct_products_equal_sympy_flatten(monkeypatch, which):
    """Newton-Euler's float-times-symbol products and sums built without flatten: the same graph, argument
    order included, as with sympy's ``Mul``/``Add`` (float constants of a general chain; rx90's lengths)."""
    from symoro_gen.dynamics import newton_euler as ne

    robot = parse_robot_text(chain_text(4, True), file="g.toml") if which == "general" else load_robot("rx90")
    fast = build_regressor(robot).graph
    monkeypatch.setattr(ne, "_mul", lambda a, b: sp.Mul(a, b))
    monkeypatch.setattr(ne, "_add", lambda terms: sp.Add(*terms))
    monkeypatch.setattr(ne, "_plus", lambda x, y: x + y)
    slow = build_regressor(robot).graph
    assert [(s, e.func, e.args) for s, e in fast.defs] == [(s, e.func, e.args) for s, e in slow.defs]
    assert {k: (e.func, e.args) for k, e in fast.outputs.items()} == {k: (e.func, e.args) for k, e in slow.outputs.items()}
    n_direct = sum(1 for _, e in fast.defs for t in sp.Add.make_args(e)
                   if t.is_Mul and len(t.args) == 2 and t.args[0].is_Float and t.args[1].is_Symbol)
    assert n_direct >= (20 if which == "general" else 1)


@pytest.mark.slow
def test_direct_monomial_products_equal_sympy_mul():
    """Every product of two monomials (numbers incl. 0, 1, -1, 1.0 and floats; symbols with and without
    assumptions; products of up to three factors; non-monomials for the fallback) built by ``_mul`` is
    ``sympy.Mul``'s, class and argument order included."""
    import itertools

    from symoro_gen.dynamics.newton_euler import _mul

    x, y, c3, f = sp.symbols("x y C3 FMX2_1x", real=True)
    atoms = [x, y, c3, f, sp.Symbol("w"), sp.Float(0.7), sp.Float(-1.0), sp.Float(1.0), sp.Integer(-1),
             sp.Integer(2), sp.Rational(-1, 3), sp.Integer(1), sp.Integer(0), sp.Float(0.0), sp.pi, sp.sin(x)]
    exprs = atoms + [sp.Mul(a, b) for a, b in itertools.product(atoms, repeat=2)]
    exprs += [sp.Mul(*t) for t in itertools.product(atoms[:6], repeat=3)]
    exprs = list(dict.fromkeys(exprs))
    n_direct = 0
    for a, b in itertools.product(exprs, repeat=2):
        fast, slow = _mul(a, b), sp.Mul(a, b)
        assert (fast.func, fast.args) == (slow.func, slow.args), (a, b)
        n_direct += fast is not slow and not fast.is_Atom
    assert n_direct > 1000  # the direct construction, not the fallback, produced most of them


def test_printing_and_counting_memos_shared_by_the_three_graphs():
    """The NumPy/C texts and operation counts memoised across the base, standard and payload graphs of one
    model: the same text and counts, expression by expression and graph by graph, as without the memo;
    the memo does save work (definitions recur across the graphs)."""
    from symoro_gen.emit import printing
    from symoro_gen.emit.package import model_graphs

    robot = parse_robot_text(chain_text(4, True), file="g.toml")
    reg = build_regressor(robot)
    graphs, _ = model_graphs(reg, regroup.group_base_parameters(reg))
    printed: dict = {}
    counted: dict = {}
    calls = 0
    for g in graphs.values():
        exprs = [e for _, e in g.defs] + list(g.outputs.values())
        calls += len(exprs)
        for d in (printing.NUMPY, printing.C_SCALAR, printing.C_VECTOR):
            for e in exprs:
                assert printing.print_expr(e, d, printed) == printing.print_expr(e, d)
        assert printing.graph_ops(g, counted) == printing.graph_ops(g)
    assert len(counted) < calls and len(printed) < 3 * calls


def test_number_printing_equals_the_code_printer():
    """Numbers and signed coefficients printed without the code printer's set-up: the same text in every
    dialect as ``doprint`` (and the same sign test as sympy's ``coeff < 0``)."""
    from symoro_gen.emit import printing

    x, y = sp.symbols("x y", real=True)
    numbers = [sp.Float(0.7919524001197934), sp.Float(-5.026835757662715), sp.Float(1e-300), sp.Integer(3),
               sp.Integer(-1), sp.Integer(2**60), sp.Rational(-3, 7), sp.Rational(1, 2), sp.Float(-0.0)]
    for d in (printing.NUMPY, printing.C_SCALAR, printing.C_VECTOR, printing.CASADI):
        for c in numbers:
            assert printing._number(c, d) == printing._printer(d).doprint(c), (c, d)
            e = sp.Mul(c, x, y)
            if e.is_Mul and e.as_coeff_Mul()[0] not in (1, -1):
                coeff = e.as_coeff_Mul()[0]
                s = printing.print_expr(e, d)
                assert s.startswith("(") == bool(coeff < 0), s
