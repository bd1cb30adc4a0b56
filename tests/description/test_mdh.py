"""description/mdh.py: the numeric transform is the product of the six elementary transforms of
Khalil-Kleinfinger, the symbolic one agrees with it, the joint variable enters with its sign."""
import numpy as np
import pytest
import sympy as sp

from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.description.mdh import (
    joint_sign,
    row_transform,
    row_values,
    symbolic_transform,
    transform,
)
from symoro_gen.description.model import q_symbol


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    return T


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    T = np.eye(4)
    T[1:3, 1:3] = [[c, -s], [s, c]]
    return T


def _tz(x):
    T = np.eye(4)
    T[2, 3] = x
    return T


def _tx(x):
    T = np.eye(4)
    T[0, 3] = x
    return T


def test_transform_is_the_product_of_elementary_ones():
    rng = np.random.default_rng(0)
    for _ in range(50):
        g, b, a, d, th, r = rng.uniform(-3, 3, 6)
        ref = _rz(g) @ _tz(b) @ _rx(a) @ _tx(d) @ _rz(th) @ _tz(r)
        np.testing.assert_allclose(transform(g, b, a, d, th, r), ref, atol=1e-14)
    th = rng.uniform(-3, 3, 7)
    batch = transform(0.3, 0.1, -1.2, 0.4, th, 0.25)
    assert batch.shape == (7, 4, 4)
    for k in range(7):
        np.testing.assert_allclose(batch[k], transform(0.3, 0.1, -1.2, 0.4, th[k], 0.25), atol=1e-15)


@pytest.mark.parametrize("name", ["rx90", "lwr4", "scara"])
def test_symbolic_and_numeric_rows_agree(name):
    robot = load_robot(name)
    subs = robot.geometry_subs()
    rng = np.random.default_rng(1)
    for row in robot.rows:
        q = float(rng.uniform(-2, 2))
        sym = symbolic_transform(row).subs(subs).subs(q_symbol(row.j), q)
        np.testing.assert_allclose(np.array(sym, float), row_transform(row, subs, q), atol=1e-12)


def test_minus_q_joint_and_array_q():
    robot = parse_robot_text(
        'name = "two"\n'
        '[[frames]]\nj = 1\nant = 0\nsigma = 0\nalpha = 0\nd = 0\ntheta = "-q + pi/2"\nr = 0\n'
        '[[frames]]\nj = 2\nant = 1\nsigma = 1\nalpha = "pi/2"\nd = 0.2\ntheta = 0\nr = "-q + 0.1"\n'
    )
    r1, r2 = robot.rows
    assert joint_sign(r1) == joint_sign(r2) == -1
    q = np.array([0.0, 0.5, -1.0])
    th = row_values(r1, {}, q)[4]
    np.testing.assert_allclose(th, np.pi / 2 - q)
    _, _, al, _, th2, r = row_values(r2, {}, q)
    np.testing.assert_allclose(r, 0.1 - q)
    assert np.shape(th2) == (3,) and float(al) == pytest.approx(np.pi / 2)
    assert isinstance(row_values(r2, {}, 0.3)[5], float)
    assert sp.diff(r2.r, q_symbol(2)) == -1
