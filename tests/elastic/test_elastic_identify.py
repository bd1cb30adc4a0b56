"""``identify --positions motor``: link positions q = positions - tau/K on the declared elastic joints (LWR4 paper
eq. 17), checked on synthetic recordings and on the real LWR4 recordings (the physical sign fits better)."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from symoro_gen.description.parse import parse_robot_text
from symoro_gen.errors import OptionError
from symoro_gen.identification.elastic import link_side
from symoro_gen.paths import robots_dir
from symoro_gen.preprocessing.trajectory import Trajectory

LWR4_DIR = Path("kuka_lwr4_flobaroid") / "data" / "KUKA" / "HW"
#: the LWR4 paper's stiffnesses (eq. 17): 10 000 N m/rad on joints 1-5, 7 500 on joints 6-7
LWR4_K = [1e4] * 5 + [7500.0] * 2


def lwr4_elastic_text() -> str:
    """robots/lwr4.toml with the paper's stiffnesses declared (top level, frames 6 and 7 their own)."""
    text = (robots_dir() / "lwr4.toml").read_text()
    text = text.replace('name = "lwr4"', 'name = "lwr4_elastic"', 1)
    text = text.replace("\n[values]", "\nelastic = {K = 10000}\n[values]", 1)
    parts = text.split("[[frames]]")
    for j in (6, 7):
        parts[j] = parts[j].replace("r = ", "elastic = {K = 7500}\nr = ", 1)
    return "[[frames]]".join(parts)


def _traj(n=7, N=200, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(N) * 0.005
    q = rng.normal(size=(N, n))
    return Trajectory(t=t, q=q, tau=50 * rng.normal(size=(N, n)), dq=rng.normal(size=(N, n)),
                      ddq=rng.normal(size=(N, n)), source="synthetic")


def test_link_side_subtracts_tau_over_k_exactly():
    robot = parse_robot_text(lwr4_elastic_text())
    tr = _traj()
    (out,) = link_side(robot, [tr])
    np.testing.assert_allclose(tr.q - out.q, tr.tau / np.array(LWR4_K), rtol=1e-9, atol=1e-13)
    assert out.dq is None and out.ddq is None  # differentiated again from the corrected q
    np.testing.assert_array_equal(out.tau, tr.tau)


def test_link_side_only_on_declared_joints():
    text = lwr4_elastic_text().replace("elastic = {K = 10000}\n", "", 1)  # joints 6 and 7 only
    robot = parse_robot_text(text)
    tr = _traj(seed=1)
    (out,) = link_side(robot, [tr])
    np.testing.assert_array_equal(out.q[:, :5], tr.q[:, :5])
    np.testing.assert_allclose(tr.q[:, 5:] - out.q[:, 5:], tr.tau[:, 5:] / 7500.0, rtol=1e-9, atol=1e-13)


def test_motor_positions_without_elastic_joint_is_an_error():
    robot = parse_robot_text((robots_dir() / "lwr4.toml").read_text(), file="lwr4.toml")
    with pytest.raises(OptionError, match=r"--positions motor.*lwr4\.toml.*no elastic joint"):
        link_side(robot, [_traj()])


def test_positions_option_values():
    from symoro_gen.workflows.identify import IdentifyOptions

    assert IdentifyOptions().positions == "link"
    with pytest.raises(OptionError, match="positions"):
        IdentifyOptions(positions="rotor")


@pytest.mark.realdata
@pytest.mark.slow
def test_lwr4_motor_positions_sign_and_validation(shared_data, tmp_path):
    """On the real LWR4 (files 1, 3 -> 2): the physical correction q = positions - tau/K (the link lags the
    motor under load) fits the validation file better than the opposite sign, and is not worse than the
    uncorrected positions beyond a small band on any joint."""
    from symoro_gen.preprocessing.readers import LogFormat
    from symoro_gen.workflows.base import as_trajectories
    from symoro_gen.workflows.identify import identify

    paths = [shared_data / LWR4_DIR / f"measurements_{i}.npz" for i in (1, 3, 2)]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"LWR4 recordings not found: {missing}")
    f = tmp_path / "lwr4_elastic.toml"
    f.write_text(lwr4_elastic_text())
    rigid = identify("lwr4", paths[:2], validate=paths[2:], method="wls").validation["rel_err"]
    motor = identify(str(f), paths[:2], validate=paths[2:], method="wls", positions="motor").validation["rel_err"]
    # the opposite sign, q = positions + tau/K, given as link positions
    robot = parse_robot_text(lwr4_elastic_text())
    trs, _ = as_trajectories(paths, LogFormat(), robot, loaded=False)
    K = np.array(LWR4_K)
    (c,) = link_side(robot, trs[:1])
    np.testing.assert_allclose(trs[0].q - c.q, trs[0].tau / K, rtol=1e-9, atol=1e-13)
    wrong = [replace(tr, q=tr.q + tr.tau / K, dq=None, ddq=None) for tr in trs]
    opposite = identify("lwr4", wrong[:2], validate=wrong[2:], method="wls").validation["rel_err"]
    motor, rigid, opposite = map(np.asarray, (motor, rigid, opposite))
    assert np.all(motor <= rigid + 0.005), (motor, rigid)
    assert motor.sum() < rigid.sum() < opposite.sum(), (motor, rigid, opposite)
