"""Real controller logs from the command line: the three recordings of ../shared/data in
their original formats, the LBR Med 7 identified from its URDF with validation on a held-back part,
`symoro-gen inspect`, and one-line errors naming file, rows and column."""
from __future__ import annotations

import json

import numpy as np
import pytest

from symoro_gen.cli import main


def _revolute_deg(q):
    """Positions as a log in degrees has them: the revolute joints in degrees, the SCARA's prismatic joint 3 in m
    (``--deg`` converts the revolute joints only)."""
    out = np.array(q, float)
    out[:, [0, 1, 3]] = np.rad2deg(out[:, [0, 1, 3]])
    return out


def _json(path):
    return json.loads(path.read_text())


@pytest.fixture(scope="module")
def med7(shared_data, tmp_path_factory):
    d = tmp_path_factory.mktemp("med7")
    urdf = shared_data / "kuka_lbr_med7_lbrstack" / "urdf" / "med7dock.urdf"
    toml = d / "med7.toml"
    assert main(["--quiet", "import-urdf", str(urdf), "-o", str(toml)]) == 0
    return toml, shared_data / "kuka_lbr_med7_lbrstack" / "data" / "measurements.csv"


@pytest.mark.realdata
def test_lbr_med7_identified_from_urdf_with_held_back_validation(med7, tmp_path, capsys):
    toml, csv = med7
    out = tmp_path / "med7.json"
    args = ["identify", str(toml), str(csv), "--columns", "q=q_0:q_6,tau=tau_0:tau_6", "--dt", "0.01",
            "--validate-fraction", "0.3", "--json", str(out)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "1647 rows read, 0 dropped" in text and "--columns q=q_0:q_6,tau=tau_0:tau_6" in text
    d = _json(out)
    (blk,) = d["data"]
    assert blk["rows_read"] == 1647 and blk["rows_dropped"] == 0 and blk["experiments"] == 1
    assert blk["step_from"] == pytest.approx(0.01) and not blk["resampled"]
    assert d["validation"]["data"] == [f"{csv} [last 30 %]"]
    fit, val = np.array(d["rel_err"]), np.array(d["validation"]["rel_err"])
    # the data README: ill-conditioned, extrapolates badly on joints 1, 3, 5; joints 2 and 4 (gravity) hold
    assert d["cond"] > 1e3
    assert np.all(val[[0, 2, 4]] > 1.0) and np.all(val[[1, 3]] < 0.3) and np.all(fit < 0.5)


@pytest.mark.realdata
def test_lbr_med7_inspect(med7, tmp_path):
    pytest.importorskip("matplotlib")
    toml, csv = med7
    js, html = tmp_path / "i.json", tmp_path / "i.html"
    assert main(["--quiet", "inspect", str(toml), str(csv), "--columns", "q=q_0:q_6,tau=tau_0:tau_6", "--dt",
                 "0.01", "--json", str(js), "--report", str(html)]) == 0
    d = _json(js)
    assert d["usable"] and d["experiments"][0]["fs"] == pytest.approx(100.0)
    assert len(d["experiments"][0]["joints"]) == 7 and d["cond_scaled"] > 10
    assert 0 < len(d["unidentifiable"]) < len(d["parameters"]["names"])
    page = html.read_text()
    assert page.count("<img") >= 7 and "Predicted identifiability" in page


@pytest.mark.realdata
def test_lwr4_npz_original_format(shared_data, tmp_path):
    npz = shared_data / "kuka_lwr4_flobaroid" / "data" / "KUKA" / "HW" / "measurements_1.npz"
    out = tmp_path / "lwr4.json"
    # jittered epoch time stamps (+-35 %): read as they are, then resampled on the median step
    assert main(["--quiet", "inspect", "lwr4", str(npz), "--json", str(out)]) == 0
    plain = _json(out)["data"][0]
    assert plain["rows_read"] == 5027 and not plain["resampled"] and 0.2 < plain["step_jitter"] < 0.5
    assert main(["--quiet", "inspect", "lwr4", str(npz), "--resample", "--json", str(out)]) == 0
    d = _json(out)
    rs = d["data"][0]
    assert rs["resampled"] and rs["step_to"] == pytest.approx(0.005, rel=1e-3) and rs["experiments"] == 1
    assert d["usable"] and d["experiments"][0]["fs"] == pytest.approx(200.0, rel=1e-3)


@pytest.mark.realdata
def test_tx40_split_csv_with_drive_chain(shared_data, tmp_path):
    data = shared_data / "staubli_tx40_figaroh" / "data"
    spec = f"q={data / 'pos_read_data.csv'},tau={data / 'curr_data.csv'},dt=0.0002"
    out = tmp_path / "tx40.json"
    assert main(["--quiet", "inspect", "tx40", spec, "--json", str(out)]) == 0
    d = _json(out)
    assert d["data"][0]["rows_read"] == 45000 and d["experiments"][0]["fs"] == pytest.approx(5000.0)
    # point-to-point motion then rest: every joint stands still part of the time, none all of it
    still = [j["standstill"] for j in d["experiments"][0]["joints"]]
    assert all(0.02 < s < 0.9 for s in still), still
    # dt given twice (spec and option) with different values: an error naming it
    assert main(["--quiet", "inspect", "tx40", spec, "--dt", "0.001"]) == 2


# ---------------------------------------------------------------------------------------------
# error paths: one line naming file, rows and column; exit 2
# ---------------------------------------------------------------------------------------------
def _scara_csv(path, n=400, bad=None):
    t = np.arange(n) * 0.002
    q = np.column_stack([np.sin(t * (k + 1)) for k in range(4)])
    rows = [",".join(["t"] + [f"q{j}" for j in range(1, 5)] + [f"tau{j}" for j in range(1, 5)])]
    rows += [",".join(f"{x:.8g}" for x in np.r_[t[i], q[i], q[i]]) for i in range(n)]
    for r, text in (bad or {}).items():
        rows[r] = text
    path.write_text("\n".join(rows) + "\n")
    return str(path)


@pytest.mark.parametrize("extra, bad, needles", [
    (["--columns", "t=t,q=q1:q4,tau=tau1:tau5"], None, ["x.csv", "field 'tau'", "no column named 'tau5'"]),
    ([], {50: "0.1,2"}, ["x.csv", "rows 50 (lines 51)", "wrong number of fields"]),
    ([], {60: "0.12,1,2,3,4,5,6,7,nan"}, ["x.csv", "rows 60 (lines 61)", "field 'tau4'", "non-finite"]),
    (["--tau-scale", "1,2"], None, ["x.csv", "field 'tau_scale'", "2 factors"]),
])
def test_errors_one_line(tmp_path, capsys, extra, bad, needles):
    f = _scara_csv(tmp_path / "x.csv", bad=bad)
    if not extra:
        extra = ["--columns", "t=t,q=q1:q4,tau=tau1:tau4"]
    assert main(["inspect", "scara", f, *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("symoro-gen: error:") and err[1].startswith("hint:") and len(err) == 2, err
    for s in needles:
        assert s in err[0], (s, err[0])
    if bad:
        assert "--drop-bad-rows" in err[1]


def test_drop_bad_rows_counted_in_json(tmp_path):
    f = _scara_csv(tmp_path / "x.csv", bad={50: "0.1,2", 60: "0.12,1,2,3,4,5,6,7,oops"})
    out = tmp_path / "o.json"
    main(["--quiet", "inspect", "scara", f, "--drop-bad-rows", "--resample", "--json", str(out)])
    d = _json(out)["data"][0]
    assert d["rows_read"] == 400 and d["rows_dropped"] == 2 and d["resampled"]
    assert any("rows 50 (lines 51)" in x for x in d["dropped"])


def test_format_file_unknown_key(tmp_path, capsys):
    f = _scara_csv(tmp_path / "x.csv")
    fmt = tmp_path / "arm.toml"
    fmt.write_text('columns = "t=t,q=q1:q4,tau=tau1:tau4"\nrate = 500\n')
    assert main(["inspect", "scara", f, "--format", str(fmt)]) == 2
    err = capsys.readouterr().err
    assert "arm.toml" in err and "field 'rate'" in err and "unknown key" in err


def test_inspect_not_usable_exit_2(tmp_path, capsys):
    """A recording in which no joint moves: identification impossible, exit 2 with the reason."""
    n = 400
    rows = ["t,q1,q2,q3,q4,tau1,tau2,tau3,tau4"] + [f"{i * 0.002:.4f},0,0,0,0,0,0,1,0" for i in range(n)]
    f = tmp_path / "still.csv"
    f.write_text("\n".join(rows) + "\n")
    assert main(["inspect", "scara", str(f)]) == 2
    out = capsys.readouterr().out
    assert "not usable" in out and "never moves" in out


def test_identify_currents_in_degrees_same_as_clean(tmp_path):
    """From the command line: a log with positions in degrees and currents (tau / k) identifies to the
    clean file's parameters, within their standard deviations; the JSON says what was done."""
    from symoro_gen.loader import model_for
    from symoro_gen.simulate.parameters import random_physical_parameters
    from symoro_gen.simulate.recording import simulate_recording
    from symoro_gen.simulate.trajectories import fourier_trajectory

    rng = np.random.default_rng(11)
    robot, model = model_for("scara")
    chi = np.asarray(random_physical_parameters(robot, rng))
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, 12.0, 0.002, rng)
    rec = simulate_recording(model, t, q, dq, ddq, chi, noise_tau=0.05, rng=rng)
    n = robot.n_joints
    clean = tmp_path / "clean.csv"
    hdr = ",".join(["t"] + [f"q{j}" for j in range(1, n + 1)] + [f"tau{j}" for j in range(1, n + 1)])
    np.savetxt(clean, np.column_stack([rec.t, rec.q, rec.tau]), delimiter=",", header=hdr, comments="")
    k = np.array([2.0, 0.5, 10.0, 0.25])
    raw = tmp_path / "raw.txt"  # headerless, degrees, currents, a status column first
    np.savetxt(raw, np.column_stack([np.ones_like(rec.t), rec.t, _revolute_deg(rec.q), rec.tau / k]), fmt="%.12g")
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    assert main(["--quiet", "identify", "scara", str(clean), "--method", "ols", "--json", str(a)]) == 0
    assert main(["--quiet", "identify", "scara", str(raw), "--method", "ols", "--json", str(b),
                 "--columns", "t=1,q=2:6,tau=6:10", "--deg", "--tau-scale", ",".join(map(str, k))]) == 0
    ra, rb = _json(a), _json(b)
    va, vb = np.array(ra["parameters"]["values"]), np.array(rb["parameters"]["values"])
    sa = np.array(ra["parameters"]["std"])
    assert ra["parameters"]["names"] == rb["parameters"]["names"]
    assert np.all(np.abs(va - vb) < sa), np.abs(va - vb) / sa
    assert rb["data"][0]["options"] == ["--columns t=1,q=2:6,tau=6:10", "--tau-scale 2,0.5,10,0.25", "--deg"]
    assert ra["data"][0]["options"] == [] and ra["data"][0]["rows_read"] == t.size
