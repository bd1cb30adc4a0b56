"""Recordings that used to give silent wrong results: a joint stuck at its encoder noise, q and tau given the
same columns, ``--deg`` on a prismatic joint, a prismatic joint in millimetres (``--mm``), a saturated torque, ``--dt`` beside a time column. Each one is
now a warning naming the file, the joint and the option that fixes it (exit 0, also in the JSON), or an error
naming the file, the field and the option; with the option, the simulated truth comes back within 3 sigma."""
from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.errors import DataFileError
from symoro_gen.loader import model_for
from symoro_gen.paths import robots_dir
from symoro_gen.preprocessing import LogFormat, make_format, read_recording
from symoro_gen.preprocessing.motion import noise_level_joints, saturation_mask
from symoro_gen.preprocessing.readers import DataWarning
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording, write_recording_csv
from symoro_gen.workflows.diagnose import DiagnoseOptions

#: the parameters of joint 1's own motion on the SCARA (its inertia about its axis, viscous and Coulomb friction)
JOINT1_OWN = ("ZZ1R", "FV1", "FS1")


def _simulate(folder, name, *, stuck=False, clip=None, seed=20261128):
    """Two 8 s SCARA recordings at 200 Hz (noise 1e-5 rad on q, 0.02 N m on tau) and the true base parameters.
    ``stuck``: joint 1 held at 0.3 rad (its encoder noise only); ``clip``: tau1 clipped at this quantile of |tau1|."""
    desc, model = model_for("scara")
    rng = np.random.default_rng(seed)
    chi = np.asarray(random_physical_parameters(desc, rng), float)
    files = []
    for k in range(2):
        mo = fourier_trajectory(model.N_JOINTS, 8.0, 0.005, rng, vmax=1.5, amax=8.0)
        q, dq, ddq = np.array(mo.q), np.array(mo.dq), np.array(mo.ddq)
        if stuck:
            q[:, 0], dq[:, 0], ddq[:, 0] = 0.3, 0.0, 0.0
        rec = simulate_recording(model, mo.t, q, dq, ddq, chi, noise_q=1e-5, noise_tau=0.02, rng=rng,
                                 source=f"{name}{k}.csv")
        if clip is not None:
            tau = np.array(rec.tau)
            lim = np.quantile(np.abs(tau[:, 0]), clip)
            tau[:, 0] = np.clip(tau[:, 0], -lim, lim)
            rec = dataclasses.replace(rec, tau=tau)
        path = folder / f"{name}{k}.csv"
        write_recording_csv(path, rec)
        files.append(str(path))
    return files, dict(zip(model.BASE_NAMES, model.base_parameters(chi)))


def _worst_z(out: dict, truth: dict, skip=()) -> tuple[float, str]:
    p = out["parameters"]
    return max((abs(v - truth[n]) / s, n) for n, v, s in zip(p["names"], p["values"], p["std"]) if n not in skip)


def _warning_lines(err: str) -> list[str]:
    return [ln for ln in err.splitlines() if ln.startswith("symoro-gen: warning: ")]


@pytest.fixture(scope="module")
def stuck(tmp_path_factory):
    return _simulate(tmp_path_factory.mktemp("stuck"), "stuck", stuck=True)


@pytest.fixture(scope="module")
def saturated(tmp_path_factory):
    return _simulate(tmp_path_factory.mktemp("sat"), "sat", clip=0.7)


@pytest.fixture(scope="module")
def clean(tmp_path_factory):
    return _simulate(tmp_path_factory.mktemp("clean"), "clean", seed=7)


STILL_RX = (r"symoro-gen: warning: {file}: joint 1 \(position RMS [0-9.e+-]+, noise [0-9.e+-]+\) does not move "
            r"beyond its noise: ")


# ---- a joint stuck at its encoder noise -----------------------------------------------------------------------
def test_stuck_joint_warns_and_leaves_the_filter_rule(stuck, cli, tmp_path):
    files, truth = stuck
    out = tmp_path / "r.json"
    r = cli.subprocess("identify", "scara", *files, "--json", out)  # a real process: its warning lines
    lines = _warning_lines(r.stderr)
    for f in files:
        rx = STILL_RX.format(file=re.escape(f)) + re.escape(
            "left out of the filters' rule; the parameters of its own motion (rotor inertia, friction...) are "
            "fitted to noise: give --drop-unexcited to treat it as still and report them as not identified")
        assert any(re.fullmatch(rx, ln) for ln in lines), lines
    res = json.loads(out.read_text())
    assert sum("joint 1" in w and "--drop-unexcited" in w for w in res["warnings"]) == 2
    # the rule set by the joints that move: low-pass at 10 Hz and decimation, not 80 Hz without decimation
    assert res["rel_err_basis"]["n_d"] == [16, 16] and res["rel_err_basis"]["cutoff_hz"] == [10.0, 10.0]
    z, name = _worst_z(res, truth, skip=JOINT1_OWN)
    assert z < 3.0, (z, name)


def test_stuck_joint_is_still_for_drop_unexcited(stuck, cli, tmp_path):
    files, truth = stuck
    out = tmp_path / "r.json"
    r = cli.subprocess("identify", "scara", *files, "--drop-unexcited", "--json", out)
    rx = STILL_RX.format(file=re.escape(files[0])) + re.escape(
        "held still (--drop-unexcited), left out of the filters' rule; the parameters of its own motion are not "
        "identified")
    assert any(re.fullmatch(rx, ln) for ln in _warning_lines(r.stderr)), r.stderr
    res = json.loads(out.read_text())
    assert tuple(res["unexcited"]) == JOINT1_OWN
    z, name = _worst_z(res, truth)
    assert z < 3.0, (z, name)


# ---- q and tau on the same columns ------------------------------------------------------------------------------
def test_columns_shared_by_q_and_tau_is_an_error(clean, cli, tmp_path):
    files, _ = clean
    raw = tmp_path / "nohdr.csv"
    np.savetxt(raw, np.loadtxt(files[0], delimiter=",", skiprows=1), delimiter=",")
    r = cli("identify", "scara", raw, "--columns", "t=0,q=1:5,tau=1:5", rc=2)
    assert r.err_lines[0] == (f"symoro-gen: error: {raw}, field 'q, tau': --columns q=1:5 and tau=1:5 share "
                              "column(s) 1, 2, 3, 4: each column holds one signal")


# ---- --deg converts the revolute joints only ----------------------------------------------------------------------
def test_deg_leaves_the_prismatic_joint_in_metres(clean, cli, tmp_path):
    files, _ = clean
    a = np.loadtxt(files[0], delimiter=",", skiprows=1)
    head = Path(files[0]).read_text().splitlines()[0]
    deg = a.copy()
    deg[:, [1, 2, 4]] = np.rad2deg(deg[:, [1, 2, 4]])  # q1, q2, q4 revolute; q3 (prismatic, m) as it is
    path = tmp_path / "deg.csv"
    np.savetxt(path, deg, delimiter=",", header=head, comments="", fmt="%.17g")
    ref, got = tmp_path / "ref.json", tmp_path / "deg.json"
    cli("--quiet", "identify", "scara", files[0], "--json", ref)
    cli("--quiet", "identify", "scara", path, "--deg", "--json", got)
    p_ref, p_deg = (json.loads(f.read_text())["parameters"] for f in (ref, got))
    assert p_ref["names"] == p_deg["names"]
    np.testing.assert_allclose(p_deg["values"], p_ref["values"], rtol=1e-6, atol=1e-9)
    h = cli.subprocess("identify", "--help").stdout
    assert "revolute joints" in " ".join(h.split()) and "prismatic joints stay in m" in " ".join(h.split())


# ---- --mm converts the prismatic joints' positions only --------------------------------------------------------
def _millimetres(files, folder, *, deg=False):
    """The first clean recording with the prismatic joint 3's position in mm (and, ``deg``, the revolute joints'
    in degrees): the raw columns and the file."""
    a = np.loadtxt(files[0], delimiter=",", skiprows=1)
    head = Path(files[0]).read_text().splitlines()[0]
    b = a.copy()
    b[:, 3] *= 1e3                                       # q3 (prismatic) in mm; tau3 (a force, N) as it is
    if deg:
        b[:, [1, 2, 4]] = np.rad2deg(b[:, [1, 2, 4]])
    path = folder / ("mm_deg.csv" if deg else "mm.csv")
    np.savetxt(path, b, delimiter=",", header=head, comments="", fmt="%.17g")
    return a, b, path


def test_mm_warned_without_the_option_and_identifies_as_metres_with_it(clean, cli, tmp_path):
    files, _ = clean
    _, _, path = _millimetres(files, tmp_path)
    _, _, both = _millimetres(files, tmp_path, deg=True)
    with pytest.warns(DataWarning) as caught:
        cli("--quiet", "identify", "scara", path, "--json", tmp_path / "raw.json")
    (w,) = [str(x.message) for x in caught if "column q3" in str(x.message)]
    assert re.search(r"mm\.csv, column q3: max \|q\| = [0-9.]+ > 5 m for a prismatic joint: positions in mm\? "
                     r"\(expected m; --mm reads millimetres\)", w), w
    ref, got, got2 = tmp_path / "ref.json", tmp_path / "mm.json", tmp_path / "both.json"
    cli("--quiet", "identify", "scara", files[0], "--json", ref)
    with warnings.catch_warnings(record=True) as after:
        warnings.simplefilter("always")
        cli("--quiet", "identify", "scara", path, "--mm", "--json", got)
    assert not [str(x.message) for x in after if issubclass(x.category, DataWarning)]
    cli("--quiet", "identify", "scara", both, "--mm", "--deg", "--json", got2)
    p_ref, p_mm, p_both = (json.loads(f.read_text())["parameters"] for f in (ref, got, got2))
    assert p_ref["names"] == p_mm["names"] == p_both["names"]
    np.testing.assert_allclose(p_mm["values"], p_ref["values"], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(p_both["values"], p_ref["values"], rtol=1e-6, atol=1e-9)
    assert json.loads(got.read_text())["data"][0]["options"] == ["--mm"]
    # without the option the millimetres are read as metres: another (wrong) model
    p_raw = json.loads((tmp_path / "raw.json").read_text())["parameters"]
    assert np.max(np.abs(np.subtract(p_raw["values"], p_ref["values"])) / np.asarray(p_ref["std"])) > 100
    with pytest.raises(SystemExit) as ex, contextlib.redirect_stdout(io.StringIO()) as out:
        cli("inspect", "--help", capture=False)
    h = " ".join(out.getvalue().split())
    assert ex.value.code == 0
    assert "--mm" in h and "prismatic joints are logged in millimetres" in h


def test_mm_in_the_python_api_leaves_revolute_joints_and_forces(clean, tmp_path):
    files, _ = clean
    a, b, path = _millimetres(files, tmp_path)
    robot = load_robot("scara")
    (tr,), rep = read_recording(path, make_format(mm=True), robot=robot)
    np.testing.assert_array_equal(tr.q[:, [0, 1, 3]], b[:, [1, 2, 4]])   # revolute joints untouched
    np.testing.assert_allclose(tr.q[:, 2], a[:, 3], rtol=1e-15)          # q3 back in metres
    np.testing.assert_array_equal(tr.tau, b[:, 5:9])                     # the prismatic joint's force untouched
    assert rep.options == ("--mm",)
    fmt_file = tmp_path / "lab.toml"
    fmt_file.write_text("mm = true\n")
    assert make_format(format_file=fmt_file).mm and not make_format(format_file=fmt_file, mm=False).mm
    ref = symoro_gen.identify("scara", files[0], method="ols").to_dict()["parameters"]
    got = symoro_gen.identify("scara", path, method="ols", data_format=LogFormat(mm=True)).to_dict()["parameters"]
    np.testing.assert_allclose(got["values"], ref["values"], rtol=1e-6, atol=1e-9)


def test_mm_needs_a_prismatic_joint_on_the_joint_side(clean, tmp_path):
    """--mm that would convert nothing is an error naming the file and why: no robot (no joint types), a robot
    without a prismatic joint, a drive chain (motor angles) without a link-side q_link column; with q_link, the
    link side of the prismatic joint is converted."""
    files, _ = clean
    a, b, path = _millimetres(files, tmp_path)
    with pytest.raises(DataFileError, match=r"mm\.csv.*field 'mm'.*no robot"):
        read_recording(path, make_format(mm=True), n_joints=4)
    six = tmp_path / "six.csv"
    np.savetxt(six, np.column_stack([a[:, 0], np.zeros((a.shape[0], 12))]), delimiter=",", comments="",
               header=",".join(["t"] + [f"q{j}" for j in range(1, 7)] + [f"tau{j}" for j in range(1, 7)]))
    with pytest.raises(DataFileError, match="the robot has no prismatic joint"):
        read_recording(six, make_format(mm=True), robot=load_robot("rx90"))
    text = (robots_dir() / "scara.toml").read_text()
    chained = tmp_path / "scara_chain.toml"
    chained.write_text(text.replace('name = "scara"', 'name = "scara_chain"')
                       + "\n[drive_chain]\nratios = [10, 10, 1000, 10]\n")
    robot = load_robot(chained)
    ratios = np.array([10.0, 10.0, 1000.0, 10.0])
    head = ",".join(["t"] + [f"m{j}" for j in range(4)] + [f"tau{j}" for j in range(4)] + [f"l{j}" for j in range(4)])
    log = tmp_path / "motor.csv"
    np.savetxt(log, np.column_stack([a[:, 0], a[:, 1:5] * ratios, a[:, 5:9] / ratios, b[:, 1:5]]), delimiter=",",
               header=head, comments="", fmt="%.17g")
    motor = "t=t,q=m0:m3,tau=tau0:tau3"
    with pytest.raises(DataFileError, match="drive chain makes the logged q, dq, ddq motor angles"):
        read_recording(log, make_format(columns=motor, mm=True), robot=robot, drive_chain=robot.drive_chain)
    (tr,), _ = read_recording(log, make_format(columns=motor + ",q_link=l0:l3", mm=True), robot=robot,
                              drive_chain=robot.drive_chain)
    np.testing.assert_allclose(tr.q, a[:, 1:5], rtol=1e-12, atol=1e-15)      # link side, q3 in m
    np.testing.assert_allclose(tr.deflection, 0.0, atol=1e-12)               # the motor side mapped by the ratios


# ---- saturated torque -------------------------------------------------------------------------------------------
def test_saturated_torque_warns_and_drop_saturated_restores_the_truth(saturated, cli, tmp_path):
    files, truth = saturated
    out = tmp_path / "r.json"
    r = cli.subprocess("identify", "scara", *files, "--json", out)
    msg = (f"symoro-gen: warning: {files[0]}: tau1 at its limit 30.0 % of the samples (plateaus of >= 5 samples): "
           "a clipped torque biases the identification: give --drop-saturated to leave those rows out")
    assert msg in _warning_lines(r.stderr), r.stderr
    res = json.loads(out.read_text())
    assert msg.removeprefix("symoro-gen: warning: ") in res["warnings"]
    z_before, _ = _worst_z(res, truth)
    assert z_before > 5.0  # the clipped torque biases ZZ1R (the reason for the warning)
    out2 = tmp_path / "r2.json"
    r2 = cli.subprocess("identify", "scara", *files, "--drop-saturated", "--json", out2)
    assert (f"symoro-gen: warning: {files[1]}: tau1 at its limit 30.0 % of the samples (plateaus of >= 5 "
            "samples): those rows are left out (--drop-saturated)") in _warning_lines(r2.stderr)
    z, name = _worst_z(json.loads(out2.read_text()), truth)
    assert z < 3.0, (z, name)


def test_drop_saturated_in_the_python_api(saturated):
    files, truth = saturated
    with pytest.warns(DataWarning, match="tau1 at its limit"):
        res = symoro_gen.identify("scara", files, drop_saturated=True)
    assert any("--drop-saturated" in w for w in res.result.warnings)
    z, name = _worst_z(res.to_dict(), truth)
    assert z < 3.0, (z, name)
    assert DiagnoseOptions(drop_saturated=True).assembly((5.0,) * 4).drop_saturated


# ---- --dt beside a time column ---------------------------------------------------------------------------------
def test_dt_with_a_time_column_is_an_error_unless_overridden(clean, cli):
    files, _ = clean
    r = cli("identify", "scara", files[0], "--dt", "0.01", rc=2)
    assert r.err_lines[0] == (f"symoro-gen: error: {files[0]}, field 't': the file has a time column and dt = 0.01 s "
                              "is given (--dt, or dt=/fs= of a split spec): leave dt out to use the time column, or "
                              "give --dt-overrides-time to ignore it")
    r2 = cli.subprocess("--quiet", "identify", "scara", files[0], "--dt", "0.005", "--dt-overrides-time")
    assert (f"symoro-gen: warning: {files[0]}, column t: ignored, the time base is dt = 0.005 s "
            "(--dt-overrides-time)") in _warning_lines(r2.stderr)


def test_split_spec_time_and_dt(clean, cli, tmp_path):
    files, _ = clean
    a = np.loadtxt(files[0], delimiter=",", skiprows=1)
    for name, cols in (("t", [0]), ("q", [1, 2, 3, 4]), ("tau", [5, 6, 7, 8])):
        np.savetxt(tmp_path / f"{name}.csv", a[:, cols], delimiter=",", fmt="%.17g")
    t, q, tau = (str(tmp_path / f"{k}.csv") for k in ("t", "q", "tau"))
    r = cli("identify", "scara", f"q={q},tau={tau},t={t},dt=0.005", rc=2)
    assert r.err_lines[0] == (f"symoro-gen: error: {t}, field 't': the t= file of the split recording gives the "
                              "time and the spec's dt= gives a sampling period (0.005 s): leave dt= out to use the "
                              "t= file, or give --dt-overrides-time to ignore the t= file")
    cli("--quiet", "identify", "scara", f"q={q},tau={tau}", "--dt", "0.005")  # --dt: the period without t=


# ---- the definitions ------------------------------------------------------------------------------------------
def test_saturation_at_a_declared_limit_or_a_plateau():
    rng = np.random.default_rng(3)
    tau = rng.normal(0.0, 1.0, (400, 2))
    tau[100:120, 0] = 2.5                                   # at the declared limit of joint 1
    tau[200:204, 1] = tau[:, 1].max() + 1.0                 # 4 samples at the extreme: no plateau
    m = saturation_mask(tau, (2.5, 100.0))
    assert m[100:120, 0].all() and m[:, 0].sum() == 20 + int(np.sum(np.abs(np.delete(tau[:, 0], range(100, 120)))
                                                                  >= 2.5 * (1 - 1e-6)))
    assert not m[:, 1].any()
    tau[300:306, 1] = tau[:, 1].min()                       # 6 samples at the minimum: a plateau
    assert saturation_mask(tau)[300:306, 1].all() and saturation_mask(tau)[:, 1].sum() == 6


def test_noise_level_joints():
    rng = np.random.default_rng(4)
    t = np.arange(2000) * 0.005
    q = np.column_stack([0.3 + 1e-5 * rng.standard_normal(t.size),        # held still: encoder noise
                         0.2 * np.sin(2 * np.pi * 0.5 * t) + 1e-5 * rng.standard_normal(t.size),
                         np.round((0.1 + 5e-4 * rng.standard_normal(t.size)) / 1e-3) * 1e-3,  # quantised, flickers
                         np.full(t.size, 1.0)])                            # exactly constant
    assert noise_level_joints(q) == (0, 2, 3)


# ---- diagnose -------------------------------------------------------------------------------------------------
def test_diagnose_warns_on_saturation_and_refuses_a_joint_at_its_noise(saturated, stuck, cli, tmp_path):
    files, _ = saturated
    out = tmp_path / "d.json"
    cli("--quiet", "diagnose", "scara", *files, "--candidates", "spring", "--max-effects", "0", "--drop-saturated",
        "--json", out)
    w = json.loads(out.read_text())["warnings"]
    assert (f"{files[0]}: tau1 at its limit 30.0 % of the samples (plateaus of >= 5 samples): those rows are left "
            "out (--drop-saturated)") in w
    r = cli("diagnose", "scara", *stuck[0], rc=2)
    assert r.err_lines[0].startswith(f"symoro-gen: error: {stuck[0][0]}, {stuck[0][1]}: joint 1 does not move (q1 "
                                     "spans at most ")


def test_inspect_names_the_joint_at_its_noise_and_the_option(stuck, clean, cli):
    """``inspect`` names the joint held at its encoder noise (each recording, its motion and noise) and the option
    that treats it as still; on the clean recordings it names none."""
    r = cli("inspect", "scara", *stuck[0])
    rx = (r"warning: {file}: joint 1 \(position RMS [0-9.e+-]+, noise [0-9.e+-]+\) does not move beyond its noise: "
          r"identify and diagnose would fit the parameters of its own motion \(rotor inertia, friction\.\.\.\) to "
          r"noise: give --drop-unexcited to treat it as still")
    lines = r.out.splitlines()
    for f in stuck[0]:
        assert any(re.fullmatch(rx.format(file=re.escape(f)), ln) for ln in lines), r.out
    assert not any("joint 2 (position RMS" in ln or "joint 3 (position RMS" in ln for ln in lines), r.out
    assert "does not move beyond its noise" not in cli("inspect", "scara", *clean[0]).out
