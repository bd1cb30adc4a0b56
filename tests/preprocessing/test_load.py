"""Loaders: good files of every format, and every kind of bad data with its message."""
from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest
import scipy.io

from symoro_gen.description import parse_robot_text
from symoro_gen.errors import DataFileError
from symoro_gen.preprocessing.readers import DataWarning, load_trajectories, load_trajectory, parse_data_spec

N_J = 3
FS = 100.0


def _signals(N=200, n=N_J, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(N) / FS
    q = 0.5 * np.sin(2 * np.pi * 0.5 * t[:, None] + rng.uniform(0, 1, n))
    tau = 10.0 * np.cos(2 * np.pi * 0.3 * t[:, None] + rng.uniform(0, 1, n))
    return t, q, tau


def _write_csv(path, header, rows, delim=","):
    with open(path, "w") as f:
        f.write(delim.join(header) + "\n")
        for r in rows:
            f.write(delim.join(r if isinstance(r[0], str) else (repr(float(x)) for x in r)) + "\n")
    return str(path)


def _std_csv(tmp_path, name="run.csv", N=200, n=N_J, extra=None, delim=","):
    t, q, tau = _signals(N, n)
    header = ["t"] + [f"q{j}" for j in range(1, n + 1)] + [f"tau{j}" for j in range(1, n + 1)]
    data = np.column_stack([t, q, tau])
    if extra:
        for nm, col in extra.items():
            header.append(nm)
            data = np.column_stack([data, col])
    return _write_csv(tmp_path / name, header, data, delim), t, q, tau


def _messages(exc):
    return [str(p) for p in exc.value.problems]


# ---------------------------------------------------------------------------------------------
# good files
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("delim", [",", ";", "\t"])
def test_csv_roundtrip(tmp_path, delim):
    path, t, q, tau = _std_csv(tmp_path, delim=delim, extra={"temperature": np.ones(200)})
    tr = load_trajectory(path, n_joints=N_J)
    np.testing.assert_allclose(tr.t, t)
    np.testing.assert_allclose(tr.q, q)
    np.testing.assert_allclose(tr.tau, tau)
    assert tr.dq is None and tr.source == path and not tr.loaded
    assert tr.meta["unused"] == ["temperature"]
    assert tr.dt == pytest.approx(1 / FS)


def test_csv_optional_derivatives_and_custom_columns(tmp_path):
    t, q, tau = _signals()
    dq = np.gradient(q, axis=0)
    header = ["time_s"] + [f"pos_{j}" for j in range(1, 4)] + ["c1", "c2", "c3"] + [f"dq{j}" for j in range(1, 4)]
    path = _write_csv(tmp_path / "x.csv", header, np.column_stack([t, q, tau, dq]))
    tr = load_trajectory(path, n_joints=3, columns={"t": "time_s", "q": "pos_{j}", "tau": ["c1", "c2", "c3"]},
                         loaded=True)
    np.testing.assert_allclose(tr.q, q)
    np.testing.assert_allclose(tr.tau, tau)
    np.testing.assert_allclose(tr.dq, dq)
    assert tr.loaded


def test_csv_without_time_uses_dt(tmp_path):
    t, q, tau = _signals()
    header = [f"q{j}" for j in range(1, 4)] + [f"tau{j}" for j in range(1, 4)]
    path = _write_csv(tmp_path / "x.csv", header, np.column_stack([q, tau]))
    tr = load_trajectory(path, n_joints=3, dt=0.01)
    np.testing.assert_allclose(tr.t, np.arange(200) * 0.01)
    assert tr.meta["t_from_dt"]


def test_npz_lwr4_keys(tmp_path):
    t, q, tau = _signals(n=7)
    p = tmp_path / "m.npz"
    np.savez(p, times=t + 1.46e9, positions=q, torques=tau, velocities=np.gradient(q, axis=0),
             target_positions=q)
    tr = load_trajectory(p, n_joints=7)
    np.testing.assert_allclose(tr.q, q)
    np.testing.assert_allclose(tr.t - tr.t[0], t - t[0], atol=1e-6)
    assert tr.dq is not None and tr.ddq is None
    assert tr.meta["unused"] == ["target_positions"]


def test_mat_transposed_arrays(tmp_path):
    t, q, tau = _signals()
    p = tmp_path / "m.mat"
    scipy.io.savemat(p, {"t": t[None, :], "q": q.T, "tau": tau.T})  # MATLAB habit: joints x samples
    tr = load_trajectory(p, n_joints=3)
    np.testing.assert_allclose(tr.q, q)
    np.testing.assert_allclose(tr.tau, tau)
    np.testing.assert_allclose(tr.t, t)


def test_split_spec(tmp_path):
    t, q, tau = _signals()
    hdr = ["Joint_1", "Joint_2", "Joint_3"]
    _write_csv(tmp_path / "pos.csv", hdr, q)
    _write_csv(tmp_path / "cur.csv", hdr, tau)
    tr = load_trajectory("q=pos.csv,tau=cur.csv,dt=0.01,loaded=true", n_joints=3, base_dir=tmp_path)
    np.testing.assert_allclose(tr.q, q)
    np.testing.assert_allclose(tr.tau, tau)
    np.testing.assert_allclose(tr.t, np.arange(200) * 0.01)
    assert tr.loaded and tr.meta["format"] == "split"
    # fs= instead of dt=, header-less files
    np.savetxt(tmp_path / "p2.csv", q, delimiter=",")
    np.savetxt(tmp_path / "c2.csv", tau, delimiter=",")
    tr2 = load_trajectory(f"q={tmp_path / 'p2.csv'},tau={tmp_path / 'c2.csv'},fs=100", n_joints=3)
    np.testing.assert_allclose(tr2.q, q)
    assert tr2.dt == pytest.approx(0.01)


def test_parse_spec_errors():
    with pytest.raises(DataFileError) as e:
        parse_data_spec("q=a.csv,torque=b.csv,dt=-1")
    msgs = "\n".join(_messages(e))
    assert "unknown key" in msgs and "torque" in msgs
    assert "dt" in msgs and "positive number" in msgs
    assert "missing: a split recording needs tau=FILE" in msgs


def test_robot_supplies_joint_count(tmp_path):
    robot = parse_robot_text(
        'name = "rp"\n[[frames]]\nj = 1\nant = 0\nsigma = 0\nalpha = 0\nd = 0\ntheta = "q"\nr = 0\n'
        '[[frames]]\nj = 2\nant = 1\nsigma = 1\nalpha = 0\nd = 0.1\ntheta = 0\nr = "q"\n')
    t, q, tau = _signals(n=2)
    header = ["t", "q1", "q2", "tau1", "tau2"]
    path = _write_csv(tmp_path / "rp.csv", header, np.column_stack([t, q, tau]))
    assert load_trajectory(path, robot=robot).n_joints == 2


# ---------------------------------------------------------------------------------------------
# bad data: each case names file, column and rows
# ---------------------------------------------------------------------------------------------
def test_nan_and_inf_named_with_rows_and_lines(tmp_path):
    t, q, tau = _signals()
    tau[4:7, 1] = np.nan
    q[150, 2] = np.inf
    header = ["t", "q1", "q2", "q3", "tau1", "tau2", "tau3"]
    path = _write_csv(tmp_path / "nan.csv", header, np.column_stack([t, q, tau]))
    with pytest.raises(DataFileError) as e:
        load_trajectory(path, n_joints=3)
    msgs = _messages(e)
    assert len(msgs) == 2  # both problems reported at once
    m_tau = next(m for m in msgs if "tau2" in m)
    assert "nan.csv" in m_tau and "rows 5-7" in m_tau and "lines 6-8" in m_tau and "NaN" in m_tau
    m_q = next(m for m in msgs if "q3" in m)
    assert "rows 151" in m_q and "+inf" in m_q


def test_non_numeric_and_missing_values(tmp_path):
    path, *_ = _std_csv(tmp_path)
    lines = Path(path).read_text().splitlines()
    f = lines[10].split(",")
    f[2] = "abc"
    lines[10] = ",".join(f)
    f = lines[20].split(",")
    f[2] = ""
    lines[20] = ",".join(f)
    Path(path).write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError) as e:
        load_trajectory(path, n_joints=3)
    msg = str(e.value)
    assert "run.csv" in msg and "field 'q2'" in msg and "non-numeric" in msg and "'abc'" in msg
    assert "lines 11, 21" in msg and "rows 10, 20" in msg


def test_ragged_line(tmp_path):
    path, *_ = _std_csv(tmp_path)
    lines = Path(path).read_text().splitlines()
    lines[30] = lines[30] + ",1.0"
    Path(path).write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError) as e:
        load_trajectory(path, n_joints=3)
    assert "lines 31" in str(e.value) and "wrong number of fields" in str(e.value)


def test_wrong_column_count_for_robot(tmp_path):
    path, *_ = _std_csv(tmp_path, n=2)
    with pytest.raises(DataFileError) as e:
        load_trajectory(path, n_joints=3)
    msg = str(e.value)
    assert "wrong column count for the robot" in msg and "3 joints" in msg and "missing q3" in msg
    assert "missing tau3" in msg and "run.csv" in msg
    path4, *_ = _std_csv(tmp_path, name="four.csv", n=4)
    with pytest.raises(DataFileError) as e:
        load_trajectory(path4, n_joints=3)
    assert "unexpected q4" in str(e.value)


def test_wrong_column_count_split_and_npz(tmp_path):
    t, q, tau = _signals(n=5)
    _write_csv(tmp_path / "pos.csv", [f"J{j}" for j in range(5)], q)
    _write_csv(tmp_path / "cur.csv", [f"J{j}" for j in range(5)], tau)
    with pytest.raises(DataFileError) as e:
        load_trajectory("q=pos.csv,tau=cur.csv,dt=0.01", n_joints=6, base_dir=tmp_path)
    msg = str(e.value)
    assert "pos.csv" in msg and "cur.csv" in msg and "5 columns" in msg and "expected 6" in msg
    np.savez(tmp_path / "a.npz", t=t, q=q, tau=tau)
    with pytest.raises(DataFileError) as e:
        load_trajectory(tmp_path / "a.npz", n_joints=6)
    assert "a.npz" in str(e.value) and "field 'q'" in str(e.value) and "5 columns, the robot has 6" in str(e.value)


def test_split_files_of_different_lengths(tmp_path):
    t, q, tau = _signals()
    _write_csv(tmp_path / "pos.csv", ["a", "b", "c"], q)
    _write_csv(tmp_path / "cur.csv", ["a", "b", "c"], tau[:-3])
    with pytest.raises(DataFileError) as e:
        load_trajectory("q=pos.csv,tau=cur.csv,dt=0.01", n_joints=3, base_dir=tmp_path)
    msg = str(e.value)
    assert "same number of rows" in msg and "200 rows" in msg and "197 rows" in msg


def test_non_increasing_time(tmp_path):
    t, q, tau = _signals()
    t[50] = t[49]
    t[120:] -= 0.5
    header = ["t", "q1", "q2", "q3", "tau1", "tau2", "tau3"]
    path = _write_csv(tmp_path / "time.csv", header, np.column_stack([t, q, tau]))
    with pytest.raises(DataFileError) as e:
        load_trajectory(path, n_joints=3)
    msg = str(e.value)
    assert "time.csv" in msg and "field 't'" in msg and "not strictly increasing" in msg
    assert "rows 51, 121" in msg and "lines 52, 122" in msg


def test_irregular_time(tmp_path):
    t, q, tau = _signals()
    t[100:] += 0.05  # 5 samples missing between rows 100 and 101
    header = ["t", "q1", "q2", "q3", "tau1", "tau2", "tau3"]
    path = _write_csv(tmp_path / "gap.csv", header, np.column_stack([t, q, tau]))
    with pytest.raises(DataFileError) as e:
        load_trajectory(path, n_joints=3)
    msg = str(e.value)
    assert "gap.csv" in msg and "irregular sampling" in msg and "rows 101" in msg and "0.06" in msg
    # small jitter (as the LWR4 logs) is accepted and reported
    t2 = np.arange(200) / FS + np.random.default_rng(1).uniform(-0.002, 0.002, 200)
    path2 = _write_csv(tmp_path / "jit.csv", header, np.column_stack([t2, q, tau]))
    tr = load_trajectory(path2, n_joints=3)
    assert 0.1 < tr.meta["dt_max_rel_jitter"] < 0.5


def test_too_short_to_filter(tmp_path):
    path, *_ = _std_csv(tmp_path, N=10)
    with pytest.raises(DataFileError) as e:
        load_trajectory(path, n_joints=3)
    assert "too short to filter: 10 samples" in str(e.value) and "run.csv" in str(e.value)


def test_missing_time_and_dt(tmp_path):
    t, q, tau = _signals()
    path = _write_csv(tmp_path / "x.csv", ["q1", "q2", "q3", "tau1", "tau2", "tau3"], np.column_stack([q, tau]))
    with pytest.raises(DataFileError) as e:
        load_trajectory(path, n_joints=3)
    assert "no time column" in str(e.value) and "no dt given" in str(e.value)
    _write_csv(tmp_path / "a.csv", ["a", "b", "c"], q)
    _write_csv(tmp_path / "b.csv", ["a", "b", "c"], tau)
    with pytest.raises(DataFileError) as e:
        load_trajectory("q=a.csv,tau=b.csv", n_joints=3, base_dir=tmp_path)
    assert "a split recording without a t= file needs dt= (or fs=)" in str(e.value)


def test_missing_file_and_unknown_format(tmp_path):
    with pytest.raises(DataFileError, match="file not found"):
        load_trajectory(tmp_path / "nope.csv", n_joints=3)
    p = tmp_path / "x.xlsx"
    p.write_text("hello")
    with pytest.raises(DataFileError, match=r"unknown data format '\.xlsx'"):
        load_trajectory(p, n_joints=3)


def test_header_required_for_single_csv(tmp_path):
    t, q, tau = _signals()
    np.savetxt(tmp_path / "nh.csv", np.column_stack([t, q, tau]), delimiter=",")
    with pytest.raises(DataFileError, match="no header line"):
        load_trajectory(tmp_path / "nh.csv", n_joints=3)


def test_load_trajectories_reports_all_files(tmp_path):
    good, *_ = _std_csv(tmp_path, name="good.csv")
    bad1, *_ = _std_csv(tmp_path, name="bad1.csv", N=5)
    bad2, *_ = _std_csv(tmp_path, name="bad2.csv", n=2)
    with pytest.raises(DataFileError) as e:
        load_trajectories([good, bad1, bad2], n_joints=3)
    msg = str(e.value)
    assert "bad1.csv" in msg and "bad2.csv" in msg and "good.csv" not in msg
    trs = load_trajectories([good, good], n_joints=3)
    assert len(trs) == 2


# ---------------------------------------------------------------------------------------------
# unit mix-ups: warnings naming file and column, data kept
# ---------------------------------------------------------------------------------------------
def _header(n=3):
    return ["t"] + [f"q{j}" for j in range(1, n + 1)] + [f"tau{j}" for j in range(1, n + 1)]


def test_positions_in_degrees_warn(tmp_path):
    t, q, tau = _signals()
    q[:, 1] = np.degrees(q[:, 1]) * 4  # up to ~115 "rad"
    path = _write_csv(tmp_path / "deg.csv", _header(), np.column_stack([t, q, tau]))
    with pytest.warns(DataWarning) as rec:
        tr = load_trajectory(path, n_joints=3)
    msgs = [str(w.message) for w in rec]
    assert any("deg.csv" in m and "column q2" in m and "degrees" in m for m in msgs)
    np.testing.assert_allclose(tr.q, q)  # nothing dropped or changed


def test_small_range_degrees_caught_by_velocity(tmp_path):
    t = np.arange(400) / 1000.0
    q = np.column_stack([np.degrees(0.2 * np.sin(2 * np.pi * 2 * t))] + [0.1 * np.sin(t)] * 2)  # deg, small
    q[:, 0] += 0  # max ~ 11.5 < 4 pi, but the 'velocity' is ~144 units/s
    tau = np.ones((400, 3))
    path = _write_csv(tmp_path / "degv.csv", _header(), np.column_stack([t, q, tau]))
    with pytest.warns(DataWarning, match=r"degv\.csv, column q1: velocity .* degrees"):
        load_trajectory(path, n_joints=3)


def test_prismatic_in_mm_and_torque_in_nmm_and_time_in_ms(tmp_path):
    robot = parse_robot_text(
        'name = "rp"\n[[frames]]\nj = 1\nant = 0\nsigma = 0\nalpha = 0\nd = 0\ntheta = "q"\nr = 0\n'
        '[[frames]]\nj = 2\nant = 1\nsigma = 1\nalpha = 0\nd = 0.1\ntheta = 0\nr = "q"\n')
    t, q, tau = _signals(n=2)
    q[:, 1] = 300 + 100 * q[:, 1]  # mm
    tau[:, 0] *= 1000 * 10  # N mm, up to 1e5
    t = t * 1000  # ms
    path = _write_csv(tmp_path / "units.csv", _header(2), np.column_stack([t, q, tau]))
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        load_trajectory(path, robot=robot)
    msgs = [str(w.message) for w in rec if issubclass(w.category, DataWarning)]
    assert any("column q2" in m and "mm" in m for m in msgs)
    assert any("column tau1" in m and "N mm" in m for m in msgs)
    assert any("column t" in m and "milliseconds" in m for m in msgs)
    assert all("units.csv" in m for m in msgs)


def test_clean_file_gives_no_warning(tmp_path):
    path, *_ = _std_csv(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_trajectory(path, n_joints=3)


def test_drive_chain_applied_on_load(tmp_path):
    from symoro_gen.description.model import DriveChain

    chain = DriveChain(ratios=(10.0, -20.0, 5.0), coupling=((1, 0, 0), (0, 1, 0), (0, 1, 1)),
                       offsets=(0.0, -math.pi / 2, 0.1), directions=(1.0, 1.0, -1.0))
    from symoro_gen.preprocessing.drive_chain import joint_to_motor

    t, q, tau = _signals()
    qm, taum, _, _ = joint_to_motor(chain, q, tau)
    _write_csv(tmp_path / "pos.csv", ["a", "b", "c"], qm)
    _write_csv(tmp_path / "cur.csv", ["a", "b", "c"], taum)
    tr = load_trajectory("q=pos.csv,tau=cur.csv,dt=0.01", n_joints=3, base_dir=tmp_path, drive_chain=chain)
    np.testing.assert_allclose(tr.q, q, atol=1e-12)
    np.testing.assert_allclose(tr.tau, tau, atol=1e-10)
    assert tr.meta["drive_chain"]


def test_matlab_v73_refused_with_hint(tmp_path):
    hdr = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Jan  1 00:00:00 2024 HDF5 schema 1.00 ."
    p = tmp_path / "v73.mat"
    p.write_bytes(hdr.ljust(116, b" ") + b"\x00" * 8 + b"\x00\x02" + b"IM" + b"\x00" * 512)
    with pytest.raises(DataFileError) as e:
        load_trajectory(p, n_joints=3)
    assert "v73.mat" in str(e.value) and "v7.3 (HDF5)" in str(e.value) and "-v7" in e.value.hint


def test_npz_arrays_of_different_lengths(tmp_path):
    t, q, tau = _signals()
    np.savez(tmp_path / "d.npz", t=t, q=q, tau=tau[:150])
    with pytest.raises(DataFileError, match=r"d\.npz: arrays have different numbers of samples \(t: 200, q: 200, tau: 150\)"):
        load_trajectory(tmp_path / "d.npz", n_joints=3)


# ---------------------------------------------------------------------------------------------
# damaged binary files and absurd values: the same one-problem errors from both loaders
# ---------------------------------------------------------------------------------------------
def _damaged_archives(tmp_path):
    """name -> bytes: an .npz cut in half, one with a zeroed stretch (CRC), a zip header with nothing behind,
    a .npy cut short, a .mat cut short and one of random bytes."""
    t, q, tau = _signals()
    np.savez(tmp_path / "ok.npz", t=t, q=q, tau=tau)
    npz = (tmp_path / "ok.npz").read_bytes()
    crc = bytearray(npz)
    crc[200:260] = bytes(60)
    np.save(tmp_path / "ok.npy", q)
    scipy.io.savemat(tmp_path / "ok.mat", {"t": t, "q": q, "tau": tau})
    mat = (tmp_path / "ok.mat").read_bytes()
    return {"half.npz": npz[: len(npz) // 2], "crc.npz": bytes(crc), "header.npz": b"PK\x03\x04" + bytes(100),
            "short.npy": (tmp_path / "ok.npy").read_bytes()[:150], "half.mat": mat[: len(mat) // 2],
            "zip.mat": b"PK\x03\x04" + bytes(100), "noise.mat": np.random.default_rng(1).bytes(300)}


@pytest.mark.parametrize("plain", [True, False], ids=["load_trajectory", "load_log"])
def test_damaged_binary_files_name_the_file(tmp_path, plain):
    from symoro_gen.preprocessing.readers import make_format
    from symoro_gen.preprocessing.readers import read_recording as load_log

    for name, data in _damaged_archives(tmp_path).items():
        (tmp_path / name).write_bytes(data)
        path = f"q={tmp_path / name},tau={tmp_path / 'ok.npy'},dt=0.01" if name.endswith(".npy") else tmp_path / name
        with pytest.raises(DataFileError) as e:
            if plain:
                load_trajectory(path, n_joints=3)
            else:  # through logformat's reader (options given: not the plain path)
                load_log(path, make_format(tau_scale="1"), n_joints=3)
        msgs = _messages(e)
        assert len(msgs) == 1 and name in msgs[0], (name, msgs)
        assert "pickle" not in str(e.value) and "\n" not in msgs[0]


@pytest.mark.parametrize("plain", [True, False], ids=["load_trajectory", "load_log"])
def test_absurd_value_is_an_error_in_every_loader(tmp_path, plain):
    """A 1e308 position used to pass the plain loader (a degrees warning) and fail later as 'W has
    non-finite values' without the file; both loaders now name file, row and column."""
    from symoro_gen.preprocessing.readers import ABSURD_VALUE, make_format
    from symoro_gen.preprocessing.readers import read_recording as load_log

    t, q, tau = _signals()
    q[20, 1] = 1e308
    tau[30, 2] = -2 * ABSURD_VALUE
    t[50] += 1e-9  # the time column is not held to the bound (absolute times are large)
    header = ["t", "q1", "q2", "q3", "tau1", "tau2", "tau3"]
    path = _write_csv(tmp_path / "huge.csv", header, np.column_stack([t + 1.7e9, q, tau]))
    with pytest.raises(DataFileError) as e:
        if plain:
            load_trajectory(path, n_joints=3)
        else:
            load_log(path, make_format(tau_scale="1"), n_joints=3)
    msgs = _messages(e)
    assert len(msgs) == 2, msgs
    assert any("huge.csv" in m and "rows 21" in m and "'q2'" in m and "absurd" in m for m in msgs)
    assert any("rows 31" in m and "'tau3'" in m and "absurd" in m for m in msgs)
    if not plain:
        return
    # just below the bound: loaded (a unit warning for the position, no error)
    q[20, 1], tau[30, 2] = 0.5, ABSURD_VALUE
    path = _write_csv(tmp_path / "big.csv", header, np.column_stack([t, q, tau]))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DataWarning)
        assert load_trajectory(path, n_joints=3).tau[30, 2] == ABSURD_VALUE
