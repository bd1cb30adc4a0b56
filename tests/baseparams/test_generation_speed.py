"""The shortcuts that make generation fast (issue 13) compute what the long way computes.

No timings here (bench/bench_generator.py measures them); each shortcut is checked against the
plain computation it replaces:

* the named-expression lookup finds ``-e`` among the named expressions without building ``-e``;
* the exact base-parameter solve builds only the columns it needs (``build_regressor(columns=...)``):
  those columns are the full model's, numerically, and no others are built;
* the closed-form regrouping expands each moved block on placeholders and substitutes the
  accumulated sums afterwards: once expanded, the same relation as expanding the block directly;
* the K matrix skips ``sympy.expand`` on relations that it would leave unchanged: whenever the
  test says "already expanded", ``expand`` is indeed the identity;
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
    for rel in bp.relations.values():
        e = rel.xreplace({**bp.gravity, **bp.geometry})
        fs = e.free_symbols
        for term in e.as_coefficients_dict():
            assert regroup._split_constant(term, fs) == term.as_independent(*fs, as_Add=False)
            n += 1
    assert n > 50
