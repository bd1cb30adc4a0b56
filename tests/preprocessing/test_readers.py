"""The front door of the readers: every format through ``read_recording``, Parquet logs by segment of row
groups, and the cases where the plain reading and the reading with the data options now agree."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from symoro_gen.errors import DataFileError
from symoro_gen.preprocessing.readers import LogFormat, load_trajectory, make_format, read_recording
from symoro_gen.preprocessing.readers.parquet import parquet_rows


def _signals(N=400, n=3):
    t = np.arange(N) * 0.004
    q = 0.4 * np.sin(np.outer(t, np.arange(1, n + 1)))
    tau = np.cos(np.outer(t, np.arange(1, n + 1)))
    return t, q, tau


def _csv(path, t, q, tau, extra_lines=()):
    n = q.shape[1]
    rows = [",".join(["t"] + [f"q{j}" for j in range(1, n + 1)] + [f"tau{j}" for j in range(1, n + 1)])]
    rows += [",".join(f"{x:.12g}" for x in r) for r in np.column_stack([t, q, tau])]
    for i, text in extra_lines:
        rows.insert(i, text)
    path.write_text("\n".join(rows) + "\n")
    return str(path)


def test_parquet_segments_read_by_row_groups(tmp_path):
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    t, q, tau = _signals(1000)
    cols = {"t": t, **{f"q{j + 1}": q[:, j] for j in range(3)}, **{f"tau{j + 1}": tau[:, j] for j in range(3)}}
    path = tmp_path / "log.parquet"
    pq.write_table(pa.table(cols), path, row_group_size=128)
    assert parquet_rows(str(path)) == 1000
    (whole,), rep = read_recording(path, n_joints=3)
    np.testing.assert_array_equal(whole.q, q)
    assert rep.rows_read == 1000 and whole.meta["format"] == "parquet"
    (seg,), rep = read_recording(str(path), n_joints=3, start=300, stop=700)
    np.testing.assert_array_equal(seg.t, t[300:700])
    np.testing.assert_array_equal(seg.tau, tau[300:700])
    assert seg.source == rep.file == f"{path}[300:700]" and seg.meta["rows"] == (300, 700)
    # a bad value of a segment is named by its row in the segment and its row in the file
    cols["q2"] = q[:, 1].copy()
    cols["q2"][450] = np.nan
    pq.write_table(pa.table(cols), path, row_group_size=128)
    with pytest.raises(DataFileError, match=r"rows 151 \(lines 451\), field 'q2': 1 non-finite"):
        read_recording(str(path), n_joints=3, start=300, stop=700)
    # the plain reading from Python reads Parquet too
    with pytest.raises(DataFileError, match=r"rows 451 \(lines 451\), field 'q2': 1 non-finite value\(s\) \(NaN\)"):
        load_trajectory(path, n_joints=3)
    cols["q2"] = q[:, 1]
    pq.write_table(pa.table(cols), tmp_path / "clean.parquet")
    np.testing.assert_array_equal(load_trajectory(tmp_path / "clean.parquet", n_joints=3).q, q)
    with pytest.raises(ValueError, match="only Parquet logs are read by segment"):
        read_recording(_csv(tmp_path / "a.csv", t, q, tau), n_joints=3, start=0, stop=10)


def test_split_recording_takes_the_dt_option(tmp_path):
    """``--dt`` gives the time base of a split recording without dt= (the plain reading ignored it)."""
    t, q, tau = _signals()
    np.savetxt(tmp_path / "pos.csv", q, delimiter=",")
    np.savetxt(tmp_path / "cur.csv", tau, delimiter=",")
    (tr,), rep = read_recording("q=pos.csv,tau=cur.csv", LogFormat(dt=0.004), n_joints=3, base_dir=tmp_path)
    np.testing.assert_allclose(tr.t, t)
    assert rep.options == ("--dt 0.004",)
    with pytest.raises(DataFileError, match=r"needs dt= \(or fs=\), or the --dt option"):
        read_recording("q=pos.csv,tau=cur.csv", n_joints=3, base_dir=tmp_path)


def test_arrays_of_different_lengths_with_the_data_options(tmp_path):
    """Named as in the plain reading (the data options used to fail on them with an IndexError)."""
    t, q, tau = _signals()
    np.savez(tmp_path / "d.npz", t=t, q=q, tau=tau[:-5])
    for fmt in (LogFormat(), make_format(tau_scale="1")):
        with pytest.raises(DataFileError, match=r"d\.npz: arrays have different numbers of samples"):
            read_recording(tmp_path / "d.npz", fmt, n_joints=3)


def test_comment_lines_are_skipped_by_both_readings(tmp_path):
    t, q, tau = _signals()
    path = _csv(tmp_path / "c.csv", t, q, tau, extra_lines=[(50, "# controller paused"), (51, "")])
    plain = load_trajectory(path, n_joints=3)
    (opts,), rep = read_recording(path, make_format(tau_scale="1"), n_joints=3)
    np.testing.assert_allclose(plain.q, q, rtol=1e-10, atol=1e-12)
    np.testing.assert_array_equal(opts.q, plain.q)
    assert rep.rows_read == t.size and rep.rows_dropped == 0


def test_malformed_row_named_alike_after_a_comment(tmp_path):
    """Rows count the data rows, lines the file lines (a comment line in between)."""
    t, q, tau = _signals()
    path = _csv(tmp_path / "m.csv", t, q, tau, extra_lines=[(10, "# note")])
    lines = Path(path).read_text().split("\n")
    lines[100] = "0.1,2"
    Path(path).write_text("\n".join(lines))
    with pytest.raises(DataFileError, match=r"lines 101: wrong number of fields"):
        load_trajectory(path, n_joints=3)
    with pytest.raises(DataFileError, match=r"rows 99 \(lines 101\): 1 row\(s\) with the wrong number of fields"):
        read_recording(path, make_format(tau_scale="1"), n_joints=3)
