"""Controller logs as they come: synthetic recordings with known truth, written the way real
arms log them (jitter, dropped packets, currents with gains, degrees, no header, malformed rows, nested
MAT structs, two encoders on a compliant joint), read with a LogFormat and identified to the same
result as the clean file (within the estimated standard deviations)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.io

from symoro_gen.errors import DataFileError
from symoro_gen.identification import identify
from symoro_gen.identification.assemble import build_observation
from symoro_gen.loader import model_for
from symoro_gen.preprocessing.readers import (
    LogFormat,
    load_trajectory,
    make_format,
    parse_columns,
    parse_data_spec,
    read_format_file,
    step_regime_changes,
)
from symoro_gen.preprocessing.readers import read_recording as load_log
from symoro_gen.preprocessing.readers import read_recordings as load_logs
from symoro_gen.preprocessing.trajectory import hold_back
from symoro_gen.simulate.parameters import random_physical_parameters
from symoro_gen.simulate.recording import true_torques
from symoro_gen.simulate.trajectories import fourier_trajectory

DT = 0.002
FINE = 4  # simulation grid: DT / FINE, so jittered time stamps hit exact samples


def _revolute_deg(q):
    """Positions as a log in degrees has them: the revolute joints in degrees, the SCARA's prismatic joint 3 in m
    (``--deg`` converts the revolute joints only)."""
    out = np.array(q, float)
    out[:, [0, 1, 3]] = np.rad2deg(out[:, [0, 1, 3]])
    return out


@pytest.fixture(scope="module")
def truth():
    """SCARA, a 12 s exciting motion simulated on a fine grid (exact torques, sensor noise 1 % of the
    signal: the level at which resampling's interpolation error near Coulomb sign changes must vanish)."""
    rng = np.random.default_rng(7)
    robot, model = model_for("scara")
    params = random_physical_parameters(robot, rng)
    chi = getattr(params, "chi_std", params)
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, 12.0, DT / FINE, rng, vmax=1.5, amax=6.0)
    tau = true_torques(model, q, dq, ddq, chi)
    tau = tau + 0.01 * tau.std(axis=0) * rng.normal(size=tau.shape)  # sensor noise 1 % of the signal
    return dict(robot=robot, model=model, t=t, q=q, tau=tau, rng=rng)


def _csv(path, t, q, tau, *, header=True, extra=None):
    n = q.shape[1]
    cols = [t[:, None], q, tau] + ([extra] if extra is not None else [])
    names = ["t"] + [f"q{j + 1}" for j in range(n)] + [f"tau{j + 1}" for j in range(n)]
    if extra is not None:
        names += [f"x{j + 1}" for j in range(extra.shape[1])]
    np.savetxt(path, np.column_stack(cols), delimiter=",", header=",".join(names) if header else "", comments="",
               fmt="%.10g")
    return str(path)


def _uniform(tr):
    k = np.arange(0, tr["t"].size, FINE)
    return tr["t"][k], tr["q"][k], tr["tau"][k]


def _fit(model, trajs):
    sys_ = build_observation(model, trajs, cutoff_hz=20.0, n_d=5)
    return identify(sys_, method="ols")


@pytest.fixture(scope="module")
def clean(truth, tmp_path_factory):
    d = tmp_path_factory.mktemp("clean")
    t, q, tau = _uniform(truth)
    path = _csv(d / "clean.csv", t, q, tau)
    trajs, rep = load_log(path, LogFormat(), robot=truth["robot"])
    return _fit(truth["model"], trajs)


def _same(res, ref, k=3.0):
    """Every base parameter within k combined standard deviations of the clean file's."""
    s = np.hypot(res.std, ref.std)
    dev = np.abs(res.values - ref.values) / np.where(s > 0, s, np.inf)
    worst = sorted(zip(dev, res.names), reverse=True)[:4]
    assert np.all(dev < k), worst


# ---------------------------------------------------------------------------------------------
# formats
# ---------------------------------------------------------------------------------------------
def test_parse_columns_and_format_file(tmp_path):
    assert parse_columns("t=0,q=1:7,tau=13:19") == (("t", "0"), ("q", "1:7"), ("tau", "13:19"))
    with pytest.raises(DataFileError, match="unknown role"):
        parse_columns("q=1:3,tau=3:5,tq=5")
    with pytest.raises(DataFileError, match="missing"):
        parse_columns("q=1:3")
    f = tmp_path / "arm.toml"
    f.write_text('columns = "t=0,q=1:3,tau=3:5"\ndt = 0.01\ntau_scale = [2.0, 3.0]\ndeg = true\n')
    fmt = make_format(format_file=f, dt=0.02)  # the command line overrides the file
    assert fmt.dt == 0.02 and fmt.deg and fmt.tau_scale == (2.0, 3.0) and fmt.column_map["q"] == "1:3"
    f.write_text('columns = "q=1:3,tau=3:5"\nsample_rate = 100\n')
    with pytest.raises(DataFileError) as e:
        read_format_file(f)
    assert str(f) in str(e.value) and "sample_rate" in str(e.value)


def test_headerless_file_by_index(truth, clean, tmp_path):
    t, q, tau = _uniform(truth)
    path = _csv(tmp_path / "raw.txt", t, q, tau, header=False, extra=np.zeros((t.size, 2)))
    fmt = make_format(columns="t=0,q=1:5,tau=5:9")
    trajs, rep = load_log(path, fmt, robot=truth["robot"])
    np.testing.assert_allclose(trajs[0].q, q, rtol=1e-9, atol=1e-12)
    _same(_fit(truth["model"], trajs), clean, k=1e-3)
    assert rep.rows_read == t.size and not rep.resampled


def test_named_ranges_degrees_and_currents(truth, clean, tmp_path):
    """A 'currents' log: positions in degrees, tau logged as currents i = tau / k (k per joint)."""
    t, q, tau = _uniform(truth)
    k = np.array([2.5, 4.0, 0.5, 0.8])
    path = _csv(tmp_path / "cur.csv", t, _revolute_deg(q), tau / k)
    fmt = make_format(columns="t=t,q=q1:q4,tau=tau1:tau4", deg=True, tau_scale=",".join(map(str, k)))
    trajs, rep = load_log(path, fmt, robot=truth["robot"])
    np.testing.assert_allclose(trajs[0].tau, tau, rtol=1e-8, atol=1e-9)
    _same(_fit(truth["model"], trajs), clean)
    assert "--deg" in rep.options and any(o.startswith("--tau-scale") for o in rep.options)


def test_jitter_resampled(truth, clean, tmp_path):
    rng = np.random.default_rng(1)
    base = np.arange(FINE, truth["t"].size - FINE, FINE)
    idx = base + rng.integers(-1, 2, base.size)  # time stamps off by up to DT / 4
    path = _csv(tmp_path / "jit.csv", truth["t"][idx], truth["q"][idx], truth["tau"][idx])
    with pytest.raises(DataFileError) as e:  # without --resample: named rows and the option
        load_log(path, LogFormat(), robot=truth["robot"])
    assert "irregular sampling" in str(e.value) and "--resample" in str(e.value) and "jit.csv" in str(e.value)
    trajs, rep = load_log(path, make_format(resample=True), robot=truth["robot"])
    assert rep.resampled and rep.step_to == pytest.approx(DT, rel=1e-6) and rep.step_jitter > 0.2
    _same(_fit(truth["model"], trajs), clean)


def test_dropped_packets_split(truth, clean, tmp_path):
    t, q, tau = _uniform(truth)
    keep = np.ones(t.size, bool)
    keep[2500:2560] = False  # 0.12 s lost
    path = _csv(tmp_path / "gap.csv", t[keep], q[keep], tau[keep])
    trajs, rep = load_log(path, make_format(resample=True), robot=truth["robot"])
    assert rep.gaps == 1 and rep.experiments == 2 and len(trajs) == 2
    assert trajs[0].t[-1] < t[2500] and trajs[1].t[0] >= t[2560] - 1e-12  # no sample bridges the gap
    _same(_fit(truth["model"], trajs), clean)


def test_malformed_rows(truth, clean, tmp_path):
    t, q, tau = _uniform(truth)
    path = tmp_path / "bad.csv"
    _csv(path, t, q, tau)
    lines = path.read_text().splitlines()
    lines[101] = "0.2,1,2"                         # wrong field count (data row 101)
    parts = lines[301].split(",")
    parts[2] = "oops"                               # unparsable q2 (data row 301)
    lines[301] = ",".join(parts)
    parts = lines[401].split(",")
    parts[6] = "1e12"                               # absurd tau2 (data row 401)
    lines[401] = ",".join(parts)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFileError) as e:
        load_log(str(path), make_format(columns="t=t,q=q1:q4,tau=tau1:tau4"), robot=truth["robot"])
    msgs = [str(p) for p in e.value.problems]
    assert any("bad.csv" in m and "rows 101 (lines 102)" in m and "wrong number of fields" in m for m in msgs)
    assert any("rows 301" in m and "'q2'" in m and "unparsable" in m for m in msgs)
    assert any("rows 401" in m and "'tau2'" in m and "absurd" in m for m in msgs)
    assert "--drop-bad-rows" in e.value.hint
    fmt = make_format(columns="t=t,q=q1:q4,tau=tau1:tau4", drop_bad_rows=True, resample=True)
    trajs, rep = load_log(str(path), fmt, robot=truth["robot"])
    assert rep.rows_dropped == 3 and rep.rows_read == t.size and len(rep.dropped) == 3
    _same(_fit(truth["model"], trajs), clean)


def test_nested_mat_struct(truth, clean, tmp_path):
    t, q, tau = _uniform(truth)
    path = tmp_path / "rec.mat"
    scipy.io.savemat(path, {"rec": {"time": t, "act": {"pos_deg": _revolute_deg(q).T}, "trq": tau}})
    fmt = make_format(columns="t=rec.time,q=rec.act.pos_deg,tau=rec.trq", deg=True)
    trajs, rep = load_log(str(path), fmt, robot=truth["robot"])
    _same(_fit(truth["model"], trajs), clean)
    with pytest.raises(DataFileError, match=r"rec.mat.*no field 'pos' in rec.act"):
        load_log(str(path), make_format(columns="t=rec.time,q=rec.act.pos,tau=rec.trq"), robot=truth["robot"])


def test_two_encoders_compliant_joint(truth, clean, tmp_path):
    """Motor- and link-side encoders: the motor side is ahead of the link by tau / K (elastic joint)."""
    t, q, tau = _uniform(truth)
    K = np.array([2000.0, 800.0, 1e5, 400.0])
    motor = q + tau / K
    path = _csv(tmp_path / "enc.csv", t, motor, tau, extra=q)
    fmt = make_format(columns="t=t,q=q1:q4,tau=tau1:tau4,q_link=x1:x4")
    trajs, rep = load_log(path, fmt, robot=truth["robot"])
    np.testing.assert_allclose(trajs[0].q, q, atol=1e-9)
    np.testing.assert_allclose(trajs[0].deflection, tau / K, atol=1e-9)
    _same(_fit(truth["model"], trajs), clean, k=1e-3)
    # the motor encoder alone gives a different (biased) model: the two sources matter
    motor_only, _ = load_log(path, make_format(columns="t=t,q=q1:q4,tau=tau1:tau4"), robot=truth["robot"])
    assert np.abs(motor_only[0].q - q).max() > 1e-3


def test_hold_back_last_fraction(truth, tmp_path):
    t, q, tau = _uniform(truth)
    trajs, _ = load_log(_csv(tmp_path / "c.csv", t, q, tau), LogFormat(), robot=truth["robot"])
    a, b = hold_back(trajs, 0.3)
    assert a[0].n_samples + b[0].n_samples == t.size and b[0].t[0] > a[0].t[-1]
    assert abs(b[0].n_samples / t.size - 0.3) < 1e-3


# ---------------------------------------------------------------------------------------------
# silently wrong inputs become errors
# ---------------------------------------------------------------------------------------------
def test_sampling_period_change_detected(tmp_path):
    """2 ms then 4 ms: both steps within 50 % of the median, still a change of regime."""
    t = np.r_[np.arange(500) * 0.002, 1.0 + np.arange(501) * 0.004]  # 500 steps of each: median 3 ms
    n = 2
    q = np.column_stack([np.sin(t), np.cos(t)])
    path = _csv(tmp_path / "regime.csv", t, q, q)
    with pytest.raises(DataFileError) as e:
        load_trajectory(path, n_joints=n)
    m = str(e.value)
    assert "regime.csv" in m and "sampling period changes" in m and "--resample" in m and "rows " in m
    # each stretch is set against the other (not against the 3 ms median, which no step has)
    assert "0.002 s per step in these rows, 0.004 s elsewhere" in m and "0.004 s per step in these rows, 0.002 s" in m
    assert "--resample" in e.value.hint
    found = step_regime_changes(t)
    assert [round(x, 4) for _, _, x in found] == [0.002, 0.004]
    assert found[0][0] <= 20 and found[1][1] == t.size  # from the start, to the last row
    # LWR4-like jitter (short/long pairs, +-35 %) is not a change of regime
    rng = np.random.default_rng(0)
    tj = np.cumsum(0.005 + 0.0017 * rng.uniform(-1, 1, 3000))
    assert step_regime_changes(tj) == []


def test_dt_and_fs_conflict():
    with pytest.raises(DataFileError) as e:
        parse_data_spec("q=a.csv,tau=b.csv,dt=0.001,fs=500")
    assert "fs" in str(e.value) and "dt" in str(e.value) and "not both" in str(e.value)
    assert parse_data_spec("q=a.csv,tau=b.csv,fs=500").dt == pytest.approx(0.002)


def test_npz_that_is_text(tmp_path):
    p = tmp_path / "rec.npz"
    p.write_text("t,q1,tau1\n0,0,0\n")
    with pytest.raises(DataFileError) as e:
        load_trajectory(str(p), n_joints=1)
    m = str(e.value) + (e.value.hint or "")
    assert "rec.npz" in m and "text" in m and "pickle" not in m.lower()


def test_error_paths_name_file_rows_column(truth, tmp_path):
    t, q, tau = _uniform(truth)
    path = _csv(tmp_path / "e.csv", t[:100], q[:100], tau[:100])
    cases = [
        (make_format(columns="t=t,q=q1:q3,tau=tau1:tau4"), "'q'", "3 column(s) selected"),
        (make_format(columns="t=t,q=q1:q4,tau=tau1:tau9"), "'tau'", "no column named 'tau9'"),
        (make_format(columns="t=0,q=1:5,tau=5:12"), "'tau'", "the file has 9 columns"),
        (make_format(columns="q=q1:q4,tau=tau1:tau4"), "'t'", "no --dt"),
        (make_format(columns="t=t,q=q1:q4,tau=tau1:tau4", tau_scale="1,2"), "'tau_scale'", "2 factors"),
    ]
    for fmt, field, what in cases:
        with pytest.raises(DataFileError) as e:
            load_log(path, fmt, robot=truth["robot"])
        assert len(e.value.problems) == 1, e.value
        line = str(e.value.problems[0])
        assert "e.csv" in line and field in line and what in line, line
    # too short after splitting
    with pytest.raises(DataFileError, match="too short"):
        load_log(_csv(tmp_path / "s.csv", t[:20], q[:20], tau[:20]), make_format(resample=True),
                 robot=truth["robot"])
    # several files: problems of all of them together
    with pytest.raises(DataFileError) as e:
        load_logs([str(tmp_path / "none.csv"), path], make_format(columns="t=t,q=q1:q3,tau=tau1:tau4"),
                  robot=truth["robot"])
    assert len(e.value.problems) == 2


def test_two_encoders_through_a_coupled_drive_chain(tmp_path):
    """TX40 drive chain (ratios, coupled wrist, offsets): motor encoders read q + delta on the joint side,
    link encoders q; the deflection is delta, the model's q the link side."""
    from symoro_gen.description import load_robot
    from symoro_gen.preprocessing.drive_chain import joint_to_motor

    robot = load_robot("tx40")
    rng = np.random.default_rng(3)
    N, n = 200, robot.n_joints
    t = np.arange(N) * 0.001
    q = 0.5 * np.sin(np.outer(t, rng.uniform(1, 3, n)) * 2 * np.pi)
    delta = 1e-3 * rng.normal(size=(N, n))
    tau_j = rng.normal(size=(N, n))
    qm, taum, _, _ = joint_to_motor(robot.drive_chain, q=q + delta, tau=tau_j)
    cols = np.column_stack([t, qm, taum, q])
    names = ["t"] + [f"m{j}" for j in range(n)] + [f"c{j}" for j in range(n)] + [f"l{j}" for j in range(n)]
    path = tmp_path / "enc.csv"
    np.savetxt(path, cols, delimiter=",", header=",".join(names), comments="", fmt="%.15g")
    fmt = make_format(columns=f"t=t,q=m0:m{n - 1},tau=c0:c{n - 1},q_link=l0:l{n - 1}")
    (tr,), rep = load_log(str(path), fmt, robot=robot, drive_chain=robot.drive_chain)
    np.testing.assert_allclose(tr.q, q, atol=1e-12)
    np.testing.assert_allclose(tr.deflection, delta, atol=1e-9)
    np.testing.assert_allclose(tr.tau, tau_j, atol=1e-9)
