"""The real recordings of ../shared/data load with sane, gravity-consistent values."""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from symoro_gen.description import parse_robot_text
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.preprocessing import DataWarning, choose_filter_settings, filter_and_differentiate, load_trajectory

TX40 = Path("staubli_tx40_figaroh")
LWR4 = Path("kuka_lwr4_flobaroid") / "data" / "KUKA" / "HW"

pytestmark = pytest.mark.realdata

_ALPHA = ["0", "-pi/2", "0", "pi/2", "-pi/2", "pi/2"]
_D = [0, 0, 0.225, 0, 0, 0]
_R = [0, 0, 0.035, 0.225, 0, 0]


def _tx40_robot():
    """TX40 MDH table (README of the data folder) with the drive chain of TX40_config.yaml."""
    txt = 'name = "tx40"\n'
    for j in range(6):
        txt += (f'[[frames]]\nj = {j + 1}\nant = {j}\nsigma = 0\nalpha = "{_ALPHA[j]}"\nd = {_D[j]}\n'
                f'theta = "q"\nr = {_R[j]}\n')
    txt += ("[drive_chain]\nratios = [32, 32, 45, -48, 45, 32]\n"
            "coupling = [[1,0,0,0,0,0],[0,1,0,0,0,0],[0,0,1,0,0,0],[0,0,0,1,0,0],[0,0,0,0,1,0],[0,0,0,0,1,1]]\n"
            f"offsets = [0, {-math.pi / 2!r}, {math.pi / 2!r}, 0, 0, 0]\n")
    return parse_robot_text(txt)


def _folder(shared_data, sub) -> Path:
    d = shared_data / sub
    if not d.exists():
        pytest.skip(f"real data folder {d} absent")
    return d


def test_tx40_split_recording_to_joint_side(shared_data):
    tx40 = _folder(shared_data, TX40)
    robot = _tx40_robot()
    spec = "q=pos_read_data.csv,tau=curr_data.csv,dt=0.0002"
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)  # joint-side values look sane
        tr = load_trajectory(spec, robot=robot, drive_chain=robot.drive_chain, base_dir=tx40 / "data")
    # forgetting the drive chain: motor angles (up to 201 rad) are flagged, column by column
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        load_trajectory(spec, robot=robot, base_dir=tx40 / "data")
    msgs = [str(w.message) for w in rec if issubclass(w.category, DataWarning)]
    assert len(msgs) == 6 and any("pos_read_data.csv, column Joint_4 (joint 4): max |q| = 201.1" in m and "motor-side" in m
                                  for m in msgs)
    assert (tr.n_samples, tr.n_joints) == (45000, 6)
    assert tr.dt == pytest.approx(2e-4)
    # MDH zero at the start and end rest poses (offsets q2 -= pi/2, q3 += pi/2 applied)
    np.testing.assert_allclose(tr.q[0], 0.0, atol=1e-3)
    np.testing.assert_allclose(tr.q[-1], 0.0, atol=1e-3)
    assert np.abs(tr.q).max() < 2 * math.pi  # joint-side, radians
    peak = np.abs(tr.tau).max(axis=0)
    assert np.all(peak > 1.0) and np.all(peak < 200.0), peak  # N m, of order 1-100
    # gravity: the rest torques match the URDF's link masses and centres of mass (tx40_mdh_modified.urdf)
    masses = [10.5, 3.6, 4.07, 3.62, 1.02, 0.2]
    coms = [(0, 0.02, -0.043), (0.109, -0.002, 0.134), (0.008, 0.006, 0.041), (-0.004, 0.002, -0.107),
            (-0.004, -0.003, -0.001), (0, 0, 0.042)]
    chi = np.zeros(len(robot.standard_names))
    idx = {nm: i for i, nm in enumerate(robot.standard_names)}
    for j in range(6):
        chi[idx[f"M{j + 1}"]] = masses[j]
        for k, ax in enumerate("XYZ"):
            chi[idx[f"M{ax}{j + 1}"]] = masses[j] * coms[j][k]
    g = inverse_dynamics(robot, tr.q[-1], np.zeros(6), np.zeros(6), chi)
    rest = tr.tau[-2000:].mean(axis=0)  # last 0.4 s at rest
    assert g[1] < -15.0 and rest[1] < -15.0  # the arm holds its own weight on joint 2, same sign
    assert abs(rest[1] - g[1]) < 0.15 * abs(g[1]), (rest, g)  # within 15 % (friction, offset)
    assert abs(rest[0]) < 2.0 and abs(rest[2] - g[2]) < 2.0


@pytest.mark.parametrize("k", [1, 3])
def test_lwr4_npz(k, shared_data):
    with warnings.catch_warnings():
        warnings.simplefilter("error", DataWarning)
        tr = load_trajectory(_folder(shared_data, LWR4) / f"measurements_{k}.npz", n_joints=7)
    assert (tr.n_samples, tr.n_joints) == (5027, 7)
    assert tr.dt == pytest.approx(0.005, rel=1e-3)  # 200 Hz, time-stamp jitter accepted
    assert 0 < tr.meta["dt_max_rel_jitter"] < 0.5
    assert np.abs(tr.q).max() < math.pi
    peak = np.abs(tr.tau).max(axis=0)
    assert 20 < peak[1] < 100 and peak[6] < 3  # joint 2 carries the arm; the wrist torques are small
    assert set(tr.meta["unused"]) == {"target_positions", "target_velocities", "target_accelerations"}
    # our band-pass velocity agrees with the controller's recorded one
    s = choose_filter_settings(1 / tr.dt, tr.q)
    _, dq, _ = filter_and_differentiate(tr.q, 1 / tr.dt, s.cutoff_hz)
    e = s.edge_samples
    rel = np.linalg.norm(dq[e:-e] - tr.dq[e:-e], axis=0) / np.linalg.norm(tr.dq[e:-e], axis=0)
    assert rel.max() < 0.05, rel
