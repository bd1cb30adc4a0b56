"""description/inertia.py against bodies whose moments are summed directly (clouds of point masses)
and against Pinocchio's own conversion (``pin.Inertia``)."""
import re
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description.inertia import (
    check_physical_consistency,
    com_from_standard,
    matrix_from_six,
    parallel_axis,
    pseudo_inertia,
    six_from_matrix,
    standard_from_com,
)
from symoro_gen.params import INERTIAL_INDEX, INERTIAL_KINDS


def _cloud(rng, k=9):
    m = rng.uniform(0.1, 2.0, k)
    r = rng.normal(scale=0.2, size=(k, 3)) + rng.normal(scale=0.3, size=3)
    return m, r


def _moments(m, r, about=(0.0, 0.0, 0.0)):
    """Inertia about ``about``: sum of m (|x|^2 E - x x^T), x = r - about (the definition)."""
    x = r - np.asarray(about)
    return np.einsum("k,kij->ij", m, np.einsum("ka,ka->k", x, x)[:, None, None] * np.eye(3) - x[:, :, None] * x[:, None, :])


def test_point_mass_clouds():
    rng = np.random.default_rng(3)
    for _ in range(20):
        m, r = _cloud(rng)
        M, c = m.sum(), (m[:, None] * r).sum(0) / m.sum()
        J_O, I_c = _moments(m, r), _moments(m, r, c)
        p = standard_from_com(M, c, I_c)
        assert p[INERTIAL_INDEX["M"]] == pytest.approx(M)
        np.testing.assert_allclose(p[6:9], (m[:, None] * r).sum(0), rtol=1e-12, atol=1e-14)
        np.testing.assert_allclose(matrix_from_six(p), J_O, rtol=1e-10, atol=1e-13)
        np.testing.assert_allclose(parallel_axis(I_c, M, c), J_O, rtol=1e-10, atol=1e-13)
        M2, c2, I2 = com_from_standard(p)
        assert pytest.approx(M) == M2 and np.allclose(c2, c) and np.allclose(I2, I_c, atol=1e-12)
        # pseudo-inertia = sum m [x; 1][x; 1]^T (Wensing et al. 2017)
        xh = np.column_stack([r, np.ones(len(m))])
        np.testing.assert_allclose(pseudo_inertia(p), (m[:, None, None] * xh[:, :, None] * xh[:, None, :]).sum(0),
                                   rtol=1e-10, atol=1e-13)
        assert check_physical_consistency(p) == []


def test_six_entries_order_is_the_params_order():
    J = matrix_from_six(np.arange(1.0, 7.0))
    assert np.array_equal(J, J.T)
    for k, v in zip(INERTIAL_KINDS[:6], six_from_matrix(J)):
        i, j = "XYZ".index(k[0]), "XYZ".index(k[1])
        assert J[i, j] == v


def test_against_pinocchio():
    pin = pytest.importorskip("pinocchio")
    rng = np.random.default_rng(4)
    for _ in range(10):
        m, r = _cloud(rng)
        M, c = m.sum(), (m[:, None] * r).sum(0) / m.sum()
        I_c = _moments(m, r, c)
        v = pin.Inertia(M, c, I_c).toDynamicParameters()  # m, mc, Ixx Ixy Iyy Ixz Iyz Izz about the origin
        p = standard_from_com(M, c, I_c)
        np.testing.assert_allclose(p[[9, 6, 7, 8, 0, 1, 3, 2, 4, 5]], v, rtol=1e-10, atol=1e-13)


def test_inconsistent_bodies_are_named():
    good = standard_from_com(2.0, [0.1, 0.0, 0.2], np.diag([0.02, 0.03, 0.04]))
    assert check_physical_consistency(good) == []
    assert "mass" in check_physical_consistency(np.r_[good[:9], 0.0])[0]
    flat = standard_from_com(1.0, np.zeros(3), np.diag([0.01, 0.01, 0.1]))
    reasons = check_physical_consistency(flat)
    assert any("triangle" in x for x in reasons)
    assert np.linalg.eigvalsh(pseudo_inertia(flat)).min() < 0  # the LMI of Wensing et al. detects it too
    neg = standard_from_com(1.0, np.zeros(3), np.diag([-0.01, 0.05, 0.05]))
    assert any("positive definite" in x for x in check_physical_consistency(neg))
    with pytest.raises(ValueError, match="10 inertial parameters"):
        com_from_standard([1.0, 2.0])


#: patterns of the conventions that have one home: a second copy in the package fails here
_ONE_HOME = {
    "parallel-axis theorem": (re.compile(r"np\.eye\(3\)\s*-\s*np\.outer\("), "description/inertia.py"),
    "tuple of the ten inertial names": (re.compile(r'"XX",\s*"XY",\s*"XZ",\s*"YY",\s*"YZ",\s*"ZZ",\s*"MX"'),
                                        "params.py"),
    "elementary MDH rotation": (re.compile(r"def _?n?(rot_[xz]|r[xz])\("), "description/mdh.py"),
}


def test_conventions_have_one_home():
    pkg = Path(symoro_gen.__file__).parent
    for what, (pattern, home) in _ONE_HOME.items():
        where = [str(p.relative_to(pkg)) for p in sorted(pkg.rglob("*.py")) if pattern.search(p.read_text())]
        assert where == [home], f"{what}: expected only in {home}, found in {where}"
