"""The generated derivative of the standard regressor w.r.t. the geometric constants (``_geometry.py``,
``geometry_<robot>.c``): against central finite differences of the numeric Newton-Euler model, against
Pinocchio at a perturbed geometry (first-order Taylor remainder of order delta^2), NumPy == C == CasADi,
identically zero derivatives dropped, deterministic output."""
from __future__ import annotations

import functools
import itertools
import json
import shutil
from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np
import pytest
import sympy as sp

from symoro_gen.description import load_robot
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.emit import geometry as emit_geometry
from symoro_gen.emit.geometry import geometry_files
from symoro_gen.emit.package import emit_robot
from symoro_gen.errors import ModelError
from symoro_gen.loader import import_package
from symoro_gen.runtime import ccompile
from symoro_gen.simulate import random_states

from ..oracles.pinocchio_model import pin_torque, random_parameters

ROOT = Path(__file__).resolve().parents[2]
HAVE_CC = ccompile.compiler() is not None


def _perturbed(robot, steps: dict[tuple[int, str], float]):
    """``robot`` with ``steps[(frame, field)]`` added to its MDH fields (a plain numeric offset)."""
    rows = list(robot.rows)
    for (j, fld), h in steps.items():
        k = j - 1
        rows[k] = dc_replace(rows[k], **{fld: sp.sympify(getattr(rows[k], fld)) + sp.Float(h)})
    return dc_replace(robot, rows=tuple(rows))


@functools.cache
def _package(name: str):
    return import_package(ROOT / "generated" / name)


def _numpy_model(name: str):
    return _package(name)._MODEL.numpy_only()


def _case(name: str, seed: int = 0, N: int = 6):
    robot = load_robot(name)
    rng = np.random.default_rng(seed)
    q, dq, ddq = random_states(rng, N, robot.n_joints)
    chi, _ = random_parameters(robot, rng)
    return robot, q, dq, ddq, chi


@pytest.mark.parametrize("name", ["scara", "rx90", "tx40", pytest.param("lwr4", marks=pytest.mark.slow),
                                  pytest.param("sda10f", marks=pytest.mark.slow)])
def test_columns_match_central_differences_of_numeric_newton_euler(name):
    """(dY_std/dg) chi == (tau(g + h) - tau(g - h)) / 2h of the numeric Newton-Euler model (no symbolic code),
    every kept constant to 1e-6 relative; every dropped constant has no effect on the torque."""
    robot, q, dq, ddq, chi = _case(name)
    m = _numpy_model(name)
    geo = m._geometry_module()
    G = m.geometry_columns(q, dq, ddq, chi)
    h = 1e-5
    scale = np.abs(inverse_dynamics(robot, q, dq, ddq, chi)).max()
    for k, g in enumerate(m.GEOMETRY_NAMES):
        jf = geo.GEOMETRY_FRAMES[k]
        fd = (inverse_dynamics(_perturbed(robot, {jf: h}), q, dq, ddq, chi)
              - inverse_dynamics(_perturbed(robot, {jf: -h}), q, dq, ddq, chi)) / (2 * h)
        assert np.abs(G[..., k] - fd).max() <= 1e-6 * max(np.abs(fd).max(), 1e-3 * scale), g
    for g in geo.GEOMETRY_DROPPED:
        fld = next(f for f in ("alpha", "theta", "d", "r") if g.startswith(f) and g[len(f):].isdigit())
        jf = (int(g[len(fld):]), fld)
        fd = (inverse_dynamics(_perturbed(robot, {jf: h}), q, dq, ddq, chi)
              - inverse_dynamics(_perturbed(robot, {jf: -h}), q, dq, ddq, chi)) / (2 * h)
        assert np.abs(fd).max() <= 1e-7 * scale, g


@pytest.mark.parametrize("name", ["scara", "rx90", "lwr4"])
def test_first_order_model_of_pinocchio_at_a_perturbed_geometry(name):
    """Pinocchio's RNEA at the geometry g + delta v (random direction v over every kept constant):
    tau_pin(g + delta v) - tau_pin(g) - delta (dY/dg chi) v is O(delta^2) (halving delta divides it by ~4),
    and much smaller than the first-order change itself."""
    robot, q, dq, ddq, chi = _case(name, seed=3)
    m = _numpy_model(name)
    geo = m._geometry_module()
    v = np.random.default_rng(7).normal(size=len(m.GEOMETRY_NAMES))
    v *= np.array([0.1 if f in ("d", "r") else 1.0 for _, f in geo.GEOMETRY_FRAMES])  # metres vs radians
    lin = m.geometry_columns(q, dq, ddq, chi) @ v
    tau0 = pin_torque(robot, q, dq, ddq, chi)
    errs = []
    for delta in (4e-3, 2e-3, 1e-3):
        moved = _perturbed(robot, {jf: delta * x for jf, x in zip(geo.GEOMETRY_FRAMES, v)})
        errs.append(np.abs(pin_torque(moved, q, dq, ddq, chi) - tau0 - delta * lin).max())
        assert errs[-1] < 0.05 * delta * np.abs(lin).max()
    for a, b in itertools.pairwise(errs):
        assert 3.0 < a / b < 5.0, errs


def test_derivative_tensor_contracts_to_the_columns():
    """geometry_derivative (N, n, n_st, n_g) contracted with chi is geometry_columns; 1-D inputs drop N."""
    robot, q, dq, ddq, chi = _case("rx90", N=4)
    m = _numpy_model("rx90")
    D = m.geometry_derivative(q, dq, ddq)
    assert D.shape == (4, robot.n_joints, len(robot.standard_names), len(m.GEOMETRY_NAMES))
    np.testing.assert_allclose(np.einsum("sikg,k->sig", D, chi), m.geometry_columns(q, dq, ddq, chi),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(m.geometry_derivative(q[1], dq[1], ddq[1]), D[1], rtol=0, atol=0)


def test_drive_columns_have_no_geometry_derivative():
    """IA, FV, FS, OFF columns do not depend on the geometry: their derivative is zero."""
    robot, q, dq, ddq, _ = _case("tx40", N=3)
    m = _numpy_model("tx40")
    D = m.geometry_derivative(q, dq, ddq)
    drive = [k for k, n in enumerate(robot.standard_names) if n.startswith(("IA", "FV", "FS", "OFF"))]
    assert drive and not np.any(D[:, :, drive, :])


@pytest.mark.skipif(not HAVE_CC, reason="no C compiler")
@pytest.mark.parametrize("name", ["scara", pytest.param("rx90", marks=pytest.mark.slow)])
def test_numpy_c_and_casadi_agree(name, tmp_path, monkeypatch):
    """The three printed forms of one graph: C (compiled in a private copy) == NumPy == CasADi to 1e-10."""
    dst = tmp_path / "pkgs" / name
    shutil.copytree(ROOT / "generated" / name, dst, ignore=shutil.ignore_patterns("_build", "__pycache__"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv("SYMORO_BACKEND", raising=False)
    robot, q, dq, ddq, chi = _case(name, seed=5, N=9)  # 9: the C loop over samples, not a multiple of anything
    pkg = import_package(dst)
    Gc = pkg.geometry_columns(q, dq, ddq, chi)
    assert pkg._MODEL._geometry_c_function() is not None
    Gn = pkg._MODEL.numpy_only().geometry_columns(q, dq, ddq, chi)
    f = pkg.casadi_geometry_columns()
    Gx = np.array([np.array(f(q[s], dq[s], ddq[s], chi)) for s in range(len(q))])
    scale = np.abs(Gn).max()
    assert np.abs(Gc - Gn).max() <= 1e-10 * scale
    assert np.abs(Gx - Gn).max() <= 1e-10 * scale


def test_dropped_constants_and_manifest(monkeypatch, tmp_path):
    """The base frame's own offsets (d1, r1 and theta1, with gravity along z0) move the whole robot without
    changing its dynamics: dropped, and listed in the manifest; every shipped robot has the derivative (the
    SDA10F's 15 frames are within the limit); a robot with more frames than the limit has none, and says why."""
    man = json.loads((ROOT / "generated" / "rx90" / "manifest.json").read_text())["geometry_derivative"]
    assert {"d1", "r1", "theta1"} <= set(man["dropped"])
    assert "alpha1" not in man["dropped"]  # tilting joint 1's axis changes the gravity torque
    assert set(man["names"]).isdisjoint(man["dropped"])
    for pkg in sorted((ROOT / "generated").iterdir()):
        if (pkg / "manifest.json").exists():
            geo = json.loads((pkg / "manifest.json").read_text())["geometry_derivative"]
            assert "omitted" not in geo and (pkg / geo["c_file"]).exists(), pkg.name
    monkeypatch.setattr(emit_geometry, "MAX_FRAMES", 3)
    emit_robot(load_robot("scara"), tmp_path)
    small = json.loads((tmp_path / "scara" / "manifest.json").read_text())["geometry_derivative"]
    assert "more than 3" in small["omitted"] and not (tmp_path / "scara" / "geometry_scara.c").exists()
    with pytest.raises(ModelError, match="no geometry derivative"):
        import_package(tmp_path / "scara").geometry_derivative(np.zeros(4), np.zeros(4), np.zeros(4))


def test_generation_is_deterministic():
    """Two generations of the derivative's files in one process are byte-identical (the shipped files,
    generated in another process, are compared by `make check-generated`)."""
    robot = load_robot("scara")
    a, ma = geometry_files(robot, "# header\n")
    b, mb = geometry_files(robot, "# header\n")
    assert a == b and ma == mb
