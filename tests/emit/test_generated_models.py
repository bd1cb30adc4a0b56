"""The committed generated models against independent references.

Identities: emitted NumPy regressor == numeric Newton-Euler == CasADi function; base
regressor x base parameters == standard regressor x standard parameters; number of base
parameters == numeric rank of the standard regressor; committed files == generator.
"""
import json
from pathlib import Path

import numpy as np
import pytest

from symoro_gen import load_model
from symoro_gen.baseparams.regroup import numeric_rank
from symoro_gen.description import load_robot
from symoro_gen.dynamics.numeric import inverse_dynamics, numeric_regressor
from symoro_gen.simulate import random_states

ROOT = Path(__file__).resolve().parents[2]
ROBOTS = sorted(p.stem for p in (ROOT / "robots").glob("*.toml"))
REL = 1e-9


def _states(rng, N, n):
    return random_states(rng, N, n)


@pytest.fixture(params=ROBOTS)
def robot_and_model(request):
    # a closed-loop robot's package is its tree model; load_model wraps it (tests/closedloop test the wrapper)
    m = load_model(request.param)
    return load_robot(request.param), getattr(m, "tree", m)


def test_every_robot_file_has_a_generated_model():
    for name in ROBOTS:
        assert (ROOT / "generated" / name / "__init__.py").exists(), f"run `make robot ROBOT={name}`"


def test_contract_names_and_shapes(robot_and_model):
    robot, m = robot_and_model
    assert robot.name == m.ROBOT and robot.n_joints == m.N_JOINTS
    assert robot.standard_names == m.STANDARD_NAMES
    assert robot.payload_names == m.PAYLOAD_NAMES
    assert all(isinstance(n, str) for n in m.BASE_NAMES)
    n, nb, ns = m.N_JOINTS, len(m.BASE_NAMES), len(m.STANDARD_NAMES)
    rng = np.random.default_rng(1)
    q, dq, ddq = _states(rng, 5, n)
    assert m.regressor(q, dq, ddq).shape == (5, n, nb)
    assert m.regressor(q[0], dq[0], ddq[0]).shape == (n, nb)
    assert m.standard_regressor(q, dq, ddq).shape == (5, n, ns)
    assert m.payload_regressor(q, dq, ddq).shape == (5, n, len(m.PAYLOAD_NAMES))
    assert m.base_parameters(np.zeros(ns)).shape == (nb,)
    assert m.torque(q, dq, ddq, np.zeros(ns)).shape == (5, n)
    with pytest.raises(ValueError, match="q must have shape"):
        m.regressor(np.zeros((5, n + 1)), dq, ddq)


def test_emitted_equals_numeric_newton_euler(robot_and_model):
    robot, m = robot_and_model
    rng = np.random.default_rng(2)
    q, dq, ddq = _states(rng, 40, m.N_JOINTS)
    chi = rng.normal(size=len(m.STANDARD_NAMES))
    pay = rng.normal(size=len(m.PAYLOAD_NAMES)) if m.PAYLOAD_NAMES else None
    tau_ref = inverse_dynamics(robot, q, dq, ddq, chi, pay)
    tau = m.torque(q, dq, ddq, chi, pay)
    assert np.max(np.abs(tau - tau_ref)) <= REL * np.max(np.abs(tau_ref))
    Ws_ref, Wp_ref = numeric_regressor(robot, q, dq, ddq)
    scale = max(1.0, np.abs(Ws_ref).max())
    assert np.max(np.abs(m.standard_regressor(q, dq, ddq) - Ws_ref)) <= REL * scale
    if m.PAYLOAD_NAMES:
        assert np.max(np.abs(m.payload_regressor(q, dq, ddq) - Wp_ref)) <= REL * scale


def test_base_identity_and_rank(robot_and_model):
    _robot, m = robot_and_model
    rng = np.random.default_rng(3)
    q, dq, ddq = _states(rng, 60, m.N_JOINTS)
    Ws = m.standard_regressor(q, dq, ddq)
    Wb = m.regressor(q, dq, ddq)
    chi = rng.normal(size=len(m.STANDARD_NAMES))
    lhs = Wb @ m.base_parameters(chi)
    rhs = Ws @ chi
    assert np.max(np.abs(lhs - rhs)) <= REL * max(1.0, np.abs(rhs).max())
    Wflat = Ws.reshape(-1, Ws.shape[-1])
    assert numeric_rank(Wflat) == len(m.BASE_NAMES)
    assert numeric_rank(Wb.reshape(-1, Wb.shape[-1])) == len(m.BASE_NAMES)


def test_casadi_function_equals_numpy(robot_and_model):
    _, m = robot_and_model
    f = m.casadi_regressor()
    assert f.name_in() == ["q", "dq", "ddq"]
    rng = np.random.default_rng(4)
    q, dq, ddq = _states(rng, 5, m.N_JOINTS)
    for k in range(5):
        Yc = np.array(f(q[k], dq[k], ddq[k]))
        Yn = m.regressor(q[k], dq[k], ddq[k])
        assert np.max(np.abs(Yc - Yn)) <= REL * max(1.0, np.abs(Yn).max())


def test_manifest_and_header(robot_and_model):
    robot, m = robot_and_model
    folder = ROOT / "generated" / robot.name
    man = json.loads((folder / "manifest.json").read_text())
    assert man["robot_file_sha256"] == robot.file_hash, "generated/ is stale: run `make robots`"
    assert man["base_names"] == list(m.BASE_NAMES)
    assert man["counts"]["base"] == len(m.BASE_NAMES)
    assert robot.file_hash in (folder / "__init__.py").read_text().splitlines()[1]
    c = (folder / f"regressor_{robot.name}.c").read_text()
    for kind in ("base", "standard", "payload"):  # the documented API: one comment block, three functions
        sig = f"void {robot.name}_{kind}_regressor(long N, const double* q, const double* dq, const double* ddq, double* out)"
        assert c.index(f" *   {sig};") < c.index("*/") < c.index(sig + "\n{")
    geo = man["geometry_derivative"]   # the derivative w.r.t. the geometry: its own C file, or why it is omitted
    c_files = sorted([f"regressor_{robot.name}.c"] + ([geo["c_file"]] if "omitted" not in geo else []))
    assert "omitted" in geo or geo["c_file"] == f"geometry_{robot.name}.c"
    assert sorted(p.name for p in folder.glob("*.c")) == c_files, "the regressor's C file and the geometry's"
    md = (folder / "base_parameters.md").read_text()
    for n in m.BASE_NAMES:
        if n.endswith("R"):
            assert f"{n} = " in md


def test_lwr4_counts_match_the_papers_model():
    m = load_model("lwr4")
    # Table I model without IA (torque sensors after the gearbox): 7 x 13 standard
    assert len(m.STANDARD_NAMES) == 91
    for n in ("XX2R", "ZZ2R", "MY2R", "XX4R", "ZZ4R", "MY4R", "MY5R", "MY6R"):
        assert n in m.BASE_NAMES, n  # regrouped parameters listed in Table II of the LWR4 paper
    assert m.PAYLOAD_NAMES == ("XX8", "XY8", "XZ8", "YY8", "YZ8", "ZZ8", "MX8", "MY8", "MZ8", "M8")


def test_c_and_numpy_backends_agree(robot_and_model):
    _, m = robot_and_model
    rng = np.random.default_rng(5)
    q, dq, ddq = _states(rng, 300, m.N_JOINTS)
    dq[::7] = 0.0  # sign(0) must agree too
    c_vals = [f(q, dq, ddq) for f in (m.regressor, m.standard_regressor, m.payload_regressor)]
    if m.BACKEND != "c":
        pytest.skip("no C compiler here: only the NumPy backend is available")
    mn = m._MODEL.numpy_only()
    np_vals = [f(q, dq, ddq) for f in (mn.regressor, mn.standard_regressor, mn.payload_regressor)]
    assert mn.backend == "numpy"
    for a, b in zip(c_vals, np_vals):
        assert a.shape == b.shape
        assert np.max(np.abs(a - b), initial=0.0) <= REL * max(1.0, np.abs(b).max(initial=0.0))


def test_out_argument_is_filled_in_place(robot_and_model):
    _, m = robot_and_model
    rng = np.random.default_rng(6)
    q, dq, ddq = _states(rng, 10, m.N_JOINTS)
    out = np.full((10, m.N_JOINTS, len(m.BASE_NAMES)), np.nan)
    r = m.regressor(q, dq, ddq, out=out)
    assert r is out and np.isfinite(out).all()
    # another buffer may differ in alignment, hence SIMD/scalar split: one rounding step
    ref = m.regressor(q, dq, ddq)
    assert np.max(np.abs(out - ref)) <= 1e-13 * max(1.0, np.abs(ref).max())
    with pytest.raises(ValueError, match="out must be"):
        m.regressor(q, dq, ddq, out=np.zeros((9, m.N_JOINTS, len(m.BASE_NAMES))))


def test_emitted_model_equals_pinocchio_rnea(robot_and_model):
    """The emitted regressor (C or NumPy) x parameters == Pinocchio's RNEA + friction terms."""
    from tests.oracles.pinocchio_model import pin_torque, random_parameters

    robot, m = robot_and_model
    rng = np.random.default_rng(7)
    q, dq, ddq = _states(rng, 20, m.N_JOINTS)
    chi, pay = random_parameters(robot, rng)  # physically consistent: Pinocchio needs m > 0
    ref = pin_torque(robot, q, dq, ddq, chi, pay)
    tau = m.regressor(q, dq, ddq) @ m.base_parameters(chi)
    if pay is not None:
        tau = tau + m.payload_regressor(q, dq, ddq) @ pay
    assert np.max(np.abs(tau - ref)) <= REL * np.max(np.abs(ref))
    f = m.casadi_regressor()
    Yc = np.array(f(q[0], dq[0], ddq[0])) @ m.base_parameters(chi)
    if pay is not None:
        Yc = Yc + m.payload_regressor(q[0], dq[0], ddq[0]) @ pay
    assert np.max(np.abs(Yc - ref[0])) <= REL * np.max(np.abs(ref))


def test_generated_package_imports_from_repo_root():
    import importlib

    mod = importlib.import_module("generated.lwr4")
    assert mod.ROBOT == "lwr4" and mod.BASE_NAMES == load_model("lwr4").BASE_NAMES


def test_c_kernel_any_alignment_and_sample_count(robot_and_model):
    """SIMD lanes + scalar remainder, aligned (non-temporal stores) or not: same values."""
    _, m = robot_and_model
    rng = np.random.default_rng(8)
    nb = len(m.BASE_NAMES)
    for N in (1, 3, 4, 5, 11):
        q, dq, ddq = _states(rng, N, m.N_JOINTS)
        ref = np.stack([m.regressor(q[k], dq[k], ddq[k]) for k in range(N)])
        raw = np.empty(N * m.N_JOINTS * nb + 1)
        unaligned = raw[1:].reshape(N, m.N_JOINTS, nb)
        # SIMD lanes and the scalar remainder may round one step differently (1.8e-15 seen)
        tol = 1e-13 * max(1.0, np.abs(ref).max())
        assert np.max(np.abs(m.regressor(q, dq, ddq, out=unaligned) - ref)) <= tol
        assert np.max(np.abs(m.regressor(q, dq, ddq) - ref)) <= tol
