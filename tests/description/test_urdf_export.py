"""export-urdf: the URDF Pinocchio loads describes the same robot (RNEA == our model)."""
import numpy as np
import pinocchio as pin
import pytest

from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.description.inertia import standard_from_com
from symoro_gen.description.urdf_export import export_urdf, physical_inertial
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.params import INERTIAL_KINDS
from symoro_gen.simulate.parameters import random_payload, random_physical_parameters


def random_parameters(robot, rng):
    """Physically consistent (triangle inequalities included): the exporter keeps them unchanged."""
    chi = np.asarray(random_physical_parameters(robot, rng))
    pay = np.asarray(random_payload(rng)) if robot.payload is not None else None
    return chi, pay


def _rigid(robot, chi):
    """Drive-chain terms zeroed (URDF damping/friction are not in RNEA)."""
    chi = np.array(chi, float)
    for k, n in enumerate(robot.standard_names):
        if n.startswith(("IA", "FV", "FS", "OFF")):
            chi[k] = 0.0
    return chi


@pytest.mark.parametrize("name", ["lwr4", "rx90", "scara", "tx40"])
def test_exported_urdf_matches_model(name):
    robot = load_robot(name)
    rng = np.random.default_rng(0)
    chi, pay = random_parameters(robot, rng)
    chi = _rigid(robot, chi)
    text = export_urdf(robot, chi, pay)
    model = pin.buildModelFromXML(text)
    model.gravity.linear = np.asarray(robot.gravity, float)
    data = model.createData()
    assert model.nq == robot.n_joints
    for _ in range(5):
        q, dq, ddq = rng.normal(size=(3, robot.n_joints))
        ref = inverse_dynamics(robot, q, dq, ddq, chi, pay)
        tau = pin.rnea(model, data, q, dq, ddq)
        assert np.allclose(tau, ref, rtol=1e-9, atol=1e-9 * np.abs(ref).max())


def test_random_robot_with_negative_directions_and_offsets():
    from hypothesis import given, settings

    from tests.strategies import mdh_robots

    @settings(max_examples=15, deadline=None)
    @given(mdh_robots(2, 6))
    def check(text):
        robot = parse_robot_text(text)
        rng = np.random.default_rng(1)
        chi, pay = random_parameters(robot, rng)
        chi = _rigid(robot, chi)
        model = pin.buildModelFromXML(export_urdf(robot, chi, pay))
        model.gravity.linear = np.asarray(robot.gravity, float)
        data = model.createData()
        q, dq, ddq = rng.normal(size=(3, robot.n_joints))
        ref = inverse_dynamics(robot, q, dq, ddq, chi, pay)
        assert np.allclose(pin.rnea(model, data, q, dq, ddq), ref, rtol=1e-8, atol=1e-8 * max(1.0, np.abs(ref).max()))

    check()


def test_physical_parameters_are_kept():
    robot = load_robot("rx90")
    chi, _ = random_parameters(robot, np.random.default_rng(2))
    vals = dict(zip(robot.standard_names, chi))
    for j in range(1, 7):
        p = [vals[f"{k}{j}"] for k in INERTIAL_KINDS]
        m, c, Ic = physical_inertial(p)
        assert np.allclose(standard_from_com(m, c, Ic), p, atol=1e-12)


def test_physical_projection():
    m, c, Ic = physical_inertial([0.0, 0, 0, 0, 0, 0, 0.1, 0, 0, -1.0])
    assert m > 0 and np.all(np.linalg.eigvalsh(Ic) > 0)
    w = np.linalg.eigvalsh(Ic)
    assert w.max() <= w.sum() - w.max() + 1e-12


def test_cli_export_urdf_with_identified_params(tmp_path, cli):
    import json

    res = tmp_path / "res.json"
    res.write_text(json.dumps({"parameters": {"names": ["MX2R", "FV1", "ZZ1R"], "values": [1.0, 2.5, 0.3]}}))
    out = tmp_path / "rx90.urdf"
    with pytest.warns(UserWarning, match="MX2R"):
        cli("export-urdf", "rx90", "--params", res, "-o", out, rc=0)
    text = out.read_text()
    assert 'damping="2.5"' in text
    pin.buildModelFromXML(text)
    cli("export-urdf", "rx90", "--params", tmp_path / "missing.json", rc=2)
