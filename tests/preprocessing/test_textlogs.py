"""Text logs as labs record them, from the command line: one-value-per-line dumps (sample- or joint-major),
garbage rows before the recording, rows whose time goes backwards, a clock that restarts, ``--dt`` against a
split recording's ``t=`` file, ``--validate-fraction`` on a file split at gaps, and what ``inspect`` says of
the time steps. Every refusal names the file, the rows, the field and the option that fixes it; every
reading is checked against the matrix the files were written from."""
from __future__ import annotations

import json

import numpy as np
import pytest

from symoro_gen.preprocessing.readers import DataWarning, LogFormat, read_recording
from symoro_gen.preprocessing.readers.split import SMOOTH_MAX, one_per_line, roughness
from symoro_gen.preprocessing.trajectory import hold_back, note_hold_back

N_JOINTS = 4  # the SCARA
DT = 0.001


def _signals(n_samples=3000, seed=0):
    """Smooth joint motions and torques (sums of sines, 0.2-1.6 Hz) sampled at 1 kHz."""
    rng = np.random.default_rng(seed)
    t = np.arange(n_samples) * DT
    f = rng.uniform(0.2, 1.6, (2, N_JOINTS))
    ph = rng.uniform(0, 2 * np.pi, (2, N_JOINTS))
    q = 0.5 * np.sin(2 * np.pi * f[0] * t[:, None] + ph[0])
    tau = 3.0 * np.sin(2 * np.pi * f[1] * t[:, None] + ph[1]) + 0.5
    return t, q, tau


def _one_per_line(path, m, order):
    v = m.reshape(-1) if order == "sample-major" else m.T.reshape(-1)
    np.savetxt(path, v, fmt="%.12g")
    return str(path)


def _table(path, t, q, tau):
    hdr = ",".join(["t"] + [f"q{j}" for j in range(1, N_JOINTS + 1)] + [f"tau{j}" for j in range(1, N_JOINTS + 1)])
    np.savetxt(path, np.column_stack([t, q, tau]), delimiter=",", header=hdr, comments="", fmt="%.12g")
    return str(path)


def _json(path):
    return json.loads(path.read_text())


# ---- one value per line ------------------------------------------------------------------------------------
@pytest.mark.parametrize("order", ["sample-major", "joint-major"])
def test_one_value_per_line_reshaped_in_the_smooth_order(cli, tmp_path, order):
    t, q, tau = _signals()
    qf, tf = _one_per_line(tmp_path / "q.txt", q, order), _one_per_line(tmp_path / "tau.txt", tau, order)
    out = tmp_path / "i.json"
    cli("--quiet", "inspect", "scara", f"q={qf},tau={tf},dt={DT}", "--json", out)
    (blk,) = _json(out)["data"]
    assert blk["rows_read"] == t.size and blk["experiments"] == 1
    notes = " ".join(blk["notes"])
    assert f"{t.size * N_JOINTS} rows reshaped to {t.size} samples x {N_JOINTS} joints, {order}" in notes
    assert "found from the data" in notes
    # the values are the matrix the files were written from
    (tr,), _ = read_recording(f"q={qf},tau={tf},dt={DT}", n_joints=N_JOINTS)
    np.testing.assert_allclose(tr.q, q, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(tr.tau, tau, rtol=1e-10, atol=1e-12)
    # a t= file in the same layout: the stamp of a sample repeated for each joint
    tt = _one_per_line(tmp_path / "t.txt", np.repeat(t[:, None], N_JOINTS, axis=1), order)
    (tr2,), rep = read_recording(f"q={qf},tau={tf},t={tt}", n_joints=N_JOINTS)
    np.testing.assert_allclose(tr2.t, t, atol=1e-12)
    assert any("stamp of each sample repeated" in x for x in rep.notes)
    stamps = t[:, None] + 1e-4 * np.arange(N_JOINTS)  # one stamp per value: not a stamp per sample
    bad = _one_per_line(tmp_path / "tj.txt", stamps, order)
    r = cli("inspect", "scara", f"q={qf},tau={tf},t={bad}", rc=2)
    assert f"{bad}, rows 1-{t.size * N_JOINTS}, field 't'" in r.err and "stamps of a sample differ" in r.err


def test_roughness_tells_the_orders_apart():
    """The test the automatic reshape uses: smooth signals read in their order have a roughness of about
    (2 pi f dt)^2, far below SMOOTH_MAX; read in the other order they jump (or are decimated n times)."""
    t, q, _ = _signals()
    assert roughness(q) < 1e-3 < SMOOTH_MAX
    f = 1.0
    sine = np.sin(2 * np.pi * f * t)[:, None]
    assert roughness(sine) == pytest.approx((2 * np.pi * f * DT) ** 2, rel=0.05)
    assert roughness(np.random.default_rng(1).normal(size=(20000, 1))) == pytest.approx(2.0, rel=0.05)
    for order in ("sample-major", "joint-major"):
        v = q.reshape(-1) if order == "sample-major" else q.T.reshape(-1)
        x, got, r = one_per_line(v, N_JOINTS, None)
        assert got == order and np.array_equal(x, q)
        other = next(o for o in r if o != order)
        assert r[other] > 10 * r[order]
    # two or three joints: joint-major read sample-major is only about n^2 times rougher, still told apart
    for n in (2, 3):
        m = q[:, :n]
        for order in ("sample-major", "joint-major"):
            v = m.reshape(-1) if order == "sample-major" else m.T.reshape(-1)
            x, got, r = one_per_line(v, n, None)
            assert got == order and np.array_equal(x, m), (n, order, r)


def test_one_value_per_line_refused_when_the_order_is_unclear(cli, tmp_path):
    """White noise is smooth in neither order: refused, naming the file, its rows, the field and --reshape;
    with --reshape it is read in the order given."""
    rng = np.random.default_rng(2)
    n = 600
    qf = _one_per_line(tmp_path / "q.txt", rng.normal(size=(n, N_JOINTS)), "sample-major")
    tf = _one_per_line(tmp_path / "tau.txt", rng.normal(size=(n, N_JOINTS)), "sample-major")
    r = cli("inspect", "scara", f"q={qf},tau={tf},dt={DT}", rc=2)
    err = r.err
    assert f"{qf}, rows 1-{n * N_JOINTS}, field 'q'" in err and f"{tf}, rows 1-{n * N_JOINTS}, field 'tau'" in err
    assert "--reshape sample-major or --reshape joint-major" in err
    (tr,), rep = read_recording(f"q={qf},tau={tf},dt={DT}", LogFormat(reshape="sample-major"), n_joints=N_JOINTS)
    np.testing.assert_allclose(tr.q, np.loadtxt(qf).reshape(n, N_JOINTS))
    assert "--reshape sample-major" in rep.options


def test_one_value_per_line_not_a_multiple_of_the_joints(cli, tmp_path):
    t, q, tau = _signals(600)
    qf = tmp_path / "q.txt"
    np.savetxt(qf, q.reshape(-1)[:-1])  # one value short
    tf = _one_per_line(tmp_path / "tau.txt", tau, "sample-major")
    r = cli("inspect", "scara", f"q={qf},tau={tf},dt={DT}", rc=2)
    assert f"{qf}, rows 1-{600 * N_JOINTS - 1}, field 'q'" in r.err and "not a multiple of the 4 joints" in r.err


# ---- garbage rows, time out of order, clock resets ---------------------------------------------------------
def test_garbage_leading_rows_skip_rows_and_drop_bad_rows(cli, tmp_path):
    t, q, tau = _signals()
    f = _table(tmp_path / "g.csv", np.r_[-0.12, 0.79, 0.0, t], np.r_[np.zeros((3, N_JOINTS)), q],
               np.r_[np.zeros((3, N_JOINTS)), tau])
    r = cli("inspect", "scara", f, rc=2)
    first, hint = r.err_lines[0], r.err_lines[-1]
    assert f"{f}, rows 3-4 (lines 4-5), field 't': time is not strictly increasing" in first
    assert hint.startswith("hint:") and "--skip-rows 3" in hint
    # --skip-rows 3: the recording as it was written
    (tr,), rep = read_recording(f, LogFormat(skip_rows=3), n_joints=N_JOINTS)
    np.testing.assert_allclose(tr.t, t, atol=1e-12)
    np.testing.assert_allclose(tr.q, q, atol=1e-11)
    assert rep.rows_read == t.size and "rows 1-3 (lines 2-4) skipped (--skip-rows 3)" in rep.notes
    fmt = tmp_path / "log.toml"
    fmt.write_text("skip_rows = 3\n")
    out = tmp_path / "i.json"
    cli("--quiet", "inspect", "scara", f, "--format", fmt, "--json", out)
    assert "--skip-rows 3" in _json(out)["data"][0]["options"]
    # --drop-bad-rows: the leading rows out of order dropped, counted, and --skip-rows named
    cli("--quiet", "inspect", "scara", f, "--drop-bad-rows", "--json", out)
    blk = _json(out)["data"][0]
    assert blk["rows_dropped"] == 3 and any("rows 1-3 (lines 2-4), t" in x and "--skip-rows 3" in x
                                            for x in blk["dropped"])
    r = cli("inspect", "scara", f, "--skip-rows", "-1", rc=2)
    assert "skip_rows" in r.err


def test_malformed_leading_rows_name_skip_rows(cli, tmp_path):
    """Rows a logger writes before the recording that are not numbers (a banner, a short row): the hint
    names --skip-rows, in the plain reading and with the data options."""
    t, q, tau = _signals(600)
    f = _table(tmp_path / "b.csv", t, q, tau)
    path = tmp_path / "b.csv"
    lines = path.read_text().splitlines()
    path.write_text("\n".join([lines[0], "logging started", "0.5,1"] + lines[1:]) + "\n")
    r = cli("inspect", "scara", f, rc=2)
    assert f"{f}, lines 2-3" in r.err and "wrong number of fields" in r.err
    assert r.err_lines[-1] == "hint: the bad rows are at the start of the file: --skip-rows 2 skips them (also " \
                              "skip_rows in a --format file)"
    r = cli("inspect", "scara", f, "--resample", rc=2)
    assert f"{f}, rows 1-2 (lines 2-3)" in r.err and "--skip-rows 2" in r.err_lines[-1]
    assert "--drop-bad-rows" in r.err_lines[-1]
    (tr,), _ = read_recording(f, LogFormat(skip_rows=2), n_joints=N_JOINTS)
    np.testing.assert_allclose(tr.t, t, atol=1e-12)


def test_isolated_rows_out_of_order_dropped_a_reset_splits(cli, tmp_path):
    t, q, tau = _signals()
    ts = t.copy()
    ts[1000], ts[2000] = 0.5, 2.9  # two stray stamps
    f = _table(tmp_path / "iso.csv", ts, q, tau)
    r = cli("inspect", "scara", f, "--resample", rc=2)
    assert f"{f}, rows 1001, 2002 (lines 1002, 2003), field 't'" in r.err_lines[0]
    assert "2 isolated row(s)" in r.err_lines[-1] and "--drop-bad-rows" in r.err_lines[-1]
    (tr,), rep = read_recording(f, LogFormat(drop_bad_rows=True, resample=True), n_joints=N_JOINTS)
    assert rep.rows_dropped == 2 and rep.experiments == 1
    assert any("rows 1001, 2001 (lines 1002, 2002), t: 2 row(s) whose time is out of order" in x for x in rep.dropped)
    np.testing.assert_allclose(tr.q, q[:tr.n_samples], atol=1e-6)  # resampled on the same 1 ms grid
    # the same rule from a --format file
    fmt = tmp_path / "stray.toml"
    fmt.write_text("drop_bad_rows = true\nresample = true\n")
    out = tmp_path / "iso.json"
    cli("--quiet", "inspect", "scara", f, "--format", fmt, "--json", out)
    (blk,) = _json(out)["data"]
    assert blk["rows_dropped"] == 2 and blk["experiments"] == 1 and "--drop-bad-rows" in blk["options"]
    assert any("2 row(s) whose time is out of order" in x for x in blk["dropped"])
    # a stray stamp among the first rows is not garbage before the recording: only that row is dropped
    ts = t.copy()
    ts[9] = 5.0
    f3 = _table(tmp_path / "early.csv", ts, q, tau)
    r = cli("inspect", "scara", f3, rc=2)
    assert "1 isolated row(s)" in r.err_lines[-1] and "--skip-rows" not in r.err_lines[-1]
    (tr,), rep = read_recording(f3, LogFormat(drop_bad_rows=True, resample=True), n_joints=N_JOINTS)
    assert rep.rows_dropped == 1 and tr.t[0] == 0.0 and any("rows 10 (lines 11), t" in x for x in rep.dropped)
    # the clock restarts half-way: a reset, split with --resample (not dropped as isolated rows)
    half = t.size // 2
    f2 = _table(tmp_path / "reset.csv", np.r_[t[:half], t[:half]], q, tau)
    r = cli("inspect", "scara", f2, rc=2)
    assert f"{f2}, rows {half + 1} (lines {half + 2}), field 't'" in r.err_lines[0]
    assert "--resample splits the file there" in r.err_lines[-1]
    trs, rep = read_recording(f2, LogFormat(resample=True, drop_bad_rows=True), n_joints=N_JOINTS)
    assert rep.experiments == 2 and rep.rows_dropped == 0
    assert any("clock restarts 1 time(s)" in x and f"row {half + 1}" in x for x in rep.notes)
    np.testing.assert_allclose(trs[1].q[:100], q[half:half + 100], atol=1e-6)


# ---- --dt and split recordings -----------------------------------------------------------------------------
def test_dt_with_a_split_recording(cli, tmp_path):
    t, q, tau = _signals(800)
    qf, tf, tt = (str(tmp_path / f"{k}.csv") for k in ("q", "tau", "t"))
    np.savetxt(qf, q, delimiter=",")
    np.savetxt(tf, tau, delimiter=",")
    np.savetxt(tt, t)
    out = tmp_path / "i.json"
    # without t=: --dt is the sampling period, as its help says
    cli("--quiet", "inspect", "scara", f"q={qf},tau={tf}", "--dt", "0.002", "--json", out)
    assert _json(out)["experiments"][0]["fs"] == pytest.approx(500.0)
    # with t=: an error naming the t= file, the field and both ways out
    r = cli("inspect", "scara", f"q={qf},tau={tf},t={tt}", "--dt", "0.002", rc=2)
    assert r.err_lines[0] == (f"symoro-gen: error: {tt}, field 't': the t= file of the split recording gives the "
                              "time and --dt gives a sampling period (0.002 s): leave --dt out to use the t= file, or "
                              "give --dt-overrides-time to ignore the t= file")
    with pytest.warns(DataWarning, match=f"{tt}, column t: ignored, the time base is dt = 0.002 s"):
        cli("--quiet", "inspect", "scara", f"q={qf},tau={tf},t={tt}", "--dt", "0.002", "--dt-overrides-time",
            "--json", out)
    assert _json(out)["experiments"][0]["fs"] == pytest.approx(500.0)


# ---- --validate-fraction on a file split at gaps ------------------------------------------------------------
def _gappy(tmp_path, gaps=(600, 1200, 1800, 2400), step=0.0088):
    t, q, tau = _signals()
    ts = t.copy()
    for k in gaps:
        ts[k:] += step - DT
    return _table(tmp_path / "gaps.csv", ts, q, tau), ts


def test_hold_back_the_last_fraction_of_each_file(tmp_path):
    f, ts = _gappy(tmp_path)
    trs, rep = read_recording(f, LogFormat(resample=True), n_joints=N_JOINTS)
    assert rep.experiments == 5 and rep.gaps == 4
    assert any("4 step(s) longer than --max-gap 0.005 s" in x for x in rep.notes)
    assert "5 experiment(s) made of this file" in rep.notes
    ident, valid = hold_back(trs, 0.3)
    total = sum(tr.n_samples for tr in trs)
    n_valid = sum(tr.n_samples for tr in valid)
    assert n_valid == pytest.approx(0.3 * total, abs=1)
    assert sum(tr.n_samples for tr in ident) + n_valid == total
    # validation is the end of the file: every held-back sample comes after every identification sample
    assert min(tr.t[0] for tr in valid) > max(tr.t[-1] for tr in ident)
    assert [tr.source.split(" [")[1] for tr in valid] == ["experiment 4/5]", "experiment 5/5]"]
    # two files: each held back on its own
    f2 = _table(tmp_path / "b.csv", *_signals(2000))
    tr2, rep2 = read_recording(f2, LogFormat(resample=True), n_joints=N_JOINTS)
    ident, valid = hold_back((*trs, *tr2), 0.3)
    assert valid[-1].n_samples == pytest.approx(0.3 * tr2[0].n_samples, abs=1)
    # the load reports say what the hold-back made of each file, and why
    a, b = note_hold_back((rep, rep2), ident, valid, 0.3)
    n_v = sum(tr.n_samples for tr in valid[:-1])
    assert a.notes[-1] == (f"--validate-fraction 0.3: the last 30 % of the file's duration held back for validation, "
                           f"not 30 % of each of the 5 experiments the file was split into: 2 validation "
                           f"experiment(s) (experiment 4/5 (its last {valid[0].n_samples} samples), 5/5; {n_v} samples "
                           f"from t = {valid[0].t[0]:.6g} s), 4 identification experiment(s) ({total - n_v} samples)")
    assert b.notes[-1] == (f"--validate-fraction 0.3: the last 30 % of the file held back for validation "
                           f"({valid[-1].n_samples} of 2000 samples, from t = {valid[-1].t[0]:.6g} s)")


def test_validate_fraction_from_the_command_line_holds_back_the_end_of_the_file(cli, tmp_path):
    from symoro_gen.loader import model_for
    from symoro_gen.simulate.parameters import random_physical_parameters
    from symoro_gen.simulate.recording import simulate_recording
    from symoro_gen.simulate.trajectories import fourier_trajectory

    rng = np.random.default_rng(5)
    robot, model = model_for("scara")
    chi = np.asarray(random_physical_parameters(robot, rng))
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, 10.0, 0.002, rng)
    rec = simulate_recording(model, t, q, dq, ddq, chi, noise_tau=0.02, rng=rng)
    ts = rec.t.copy()
    for k in (1000, 2000, 3000, 4000):
        ts[k:] += 0.02
    f = _table(tmp_path / "gaps.csv", ts, rec.q, rec.tau)
    out = tmp_path / "id.json"
    r = cli("identify", "scara", f, "--resample", "--validate-fraction", "0.3", "--method", "ols", "--json", out)
    d = _json(out)
    assert d["data"][0]["experiments"] == 5
    assert [s.rsplit("[", 1)[1] for s in d["validation"]["data"]] == ["last 30 % of the file]"] * 2
    assert "5 experiment(s) made of this file" in r.out
    total = sum(d["data"][0]["samples"])
    n_valid = total - int(round(0.7 * total))
    assert ("note: --validate-fraction 0.3: the last 30 % of the file's duration held back for validation, not 30 % of "
            "each of the 5 experiments the file was split into: 2 validation experiment(s) (experiment 4/5 (its last "
            in r.out)
    assert f"; {n_valid} samples from t = " in r.out and f"4 identification experiment(s) ({total - n_valid} samples)" \
        in r.out
    assert d["data"][0]["notes"][-1].startswith("--validate-fraction 0.3: ")


# ---- inspect: the time steps -------------------------------------------------------------------------------
def test_inspect_step_statistics(cli, tmp_path):
    f, ts = _gappy(tmp_path)
    out = tmp_path / "i.json"
    r = cli("inspect", "scara", f, "--resample", "--json", out)
    (st,) = _json(out)["steps"]
    d = np.diff(ts)
    assert st["p50"] == pytest.approx(np.median(d)) and st["p99"] == pytest.approx(np.percentile(d, 99))
    assert st["max"] == pytest.approx(0.0088) and st["n_outliers"] == 4 and st["over_gap"] == 4
    assert [o["row"] for o in st["outliers"]] == [601, 1201, 1801, 2401]
    assert [o["line"] for o in st["outliers"]] == [602, 1202, 1802, 2402]
    assert st["jitter"] < 1e-6 and not st["max_gap_given"] and st["max_gap"] == pytest.approx(0.005)
    assert "splits the file at the 4 step(s) longer than it into 5 experiments" in st["max_gap_effect"]
    assert "781 %" not in r.out and "780 %" not in r.out
    assert "steps: p50 0.001 s, p99 0.001 s, max 0.0088 s" in r.out
    assert "row 601 (line 602): 0.0088 s" in r.out
    r = cli("inspect", "scara", f, "--resample", "--max-gap", "0.01", "--json", out)
    (st,) = _json(out)["steps"]
    assert st["over_gap"] == 0 and st["max_gap_given"] and "bridges them all" in st["max_gap_effect"]
    assert _json(out)["data"][0]["experiments"] == 1
    # many outliers: the first ten listed by row, the rest counted
    f2, _ = _gappy(tmp_path, gaps=tuple(range(100, 2900, 200)), step=0.003)
    r = cli("inspect", "scara", f2, "--resample", "--json", out)
    (st,) = _json(out)["steps"]
    assert st["n_outliers"] == 14 and len(st["outliers"]) == 10 and "and 4 more" in r.out
    assert st["over_gap"] == 0 and "bridges them all" in st["max_gap_effect"]


def test_a_noisy_file_takes_the_order_of_the_others(tmp_path):
    """Torques noisier than smooth in either order (roughness above SMOOTH_MAX both ways) follow the order the
    positions of the same logger show; the report says so."""
    t, q, tau = _signals(seed=3)
    noisy = tau + 2.0 * np.random.default_rng(4).normal(size=tau.shape)
    qf = _one_per_line(tmp_path / "q.txt", q, "joint-major")
    tf = _one_per_line(tmp_path / "tau.txt", noisy, "joint-major")
    _, got, r = one_per_line(np.loadtxt(tf), N_JOINTS, None)
    assert got is None and min(r.values()) > SMOOTH_MAX
    (tr,), rep = read_recording(f"q={qf},tau={tf},dt={DT}", n_joints=N_JOINTS)
    np.testing.assert_allclose(tr.tau, noisy, rtol=1e-10, atol=1e-11)
    assert any(f"{tf} (tau)" in x and "joint-major (as q=: its own data do not tell)" in x for x in rep.notes)


@pytest.mark.slow
def test_inspect_report_lists_the_outlier_steps(cli, tmp_path):
    """The HTML report of inspect has the same table (one plot per experiment and joint: slow)."""
    pytest.importorskip("matplotlib")
    f, _ = _gappy(tmp_path)
    html = tmp_path / "i.html"
    cli("--quiet", "inspect", "scara", f, "--resample", "--report", html)
    page = html.read_text()
    assert "Time steps as logged" in page and "4: 601: 0.0088, 1201: 0.0088" in page and "splits the file" in page


@pytest.mark.parametrize("t0, h", [(0.1, 0.1), (0.3, 0.01), (12.345, 0.002), (1.1, 0.0002)])
def test_resampling_a_uniform_log_keeps_its_last_sample(t0, h):
    """Stamps written as decimals ``t0 + k h`` (as a logger prints them): the uniform grid's last point may pass
    the last stamp by rounding; it is that stamp's sample, kept (it was dropped in about a quarter of such
    logs), and every resampled value is the logged one."""
    from symoro_gen.preprocessing.readers.logs import resample

    for n in (7, 100, 333, 1001):
        t = np.array([float(f"{t0 + k * h:.10g}") for k in range(n)])
        x = {"q": np.sin(3 * t)[:, None], "tau": np.cos(2 * t)[:, None]}
        (grid, seg), = resample(t, x, h, 10 * h)[0]
        assert grid.size == n, (t0, h, n)
        assert np.allclose(seg["q"][:, 0], x["q"][:, 0], atol=1e-9) and np.allclose(seg["tau"], x["tau"], atol=1e-9)
