"""The built-in demo and the `identify` command end to end (simulated data, truth known)."""
import json

import numpy as np

from symoro_gen.simulate import write_recording_csv


def test_demo_recovers_sensor_gains(cli):
    out = cli("demo", "--duration", "10", rc=0).out
    errs = [float(line.split("error")[1].split("%")[0]) for line in out.splitlines() if line.strip().startswith("g") and "identified" in line]
    assert len(errs) == 7 and max(abs(e) for e in errs) < 0.5  # gains within 0.5 %


def test_identify_cli_json_contract(tmp_path, cli):
    from symoro_gen.loader import model_for
    from symoro_gen.simulate.parameters import random_physical_parameters
    from symoro_gen.simulate.recording import simulate_recording
    from symoro_gen.simulate.trajectories import fourier_trajectory

    rng = np.random.default_rng(3)
    robot, model = model_for("rx90")
    params = random_physical_parameters(robot, rng)
    chi = getattr(params, "chi_std", params)
    files = []
    for k in range(2):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, 15.0, 0.002, rng)
        tr = simulate_recording(model, t, q, dq, ddq, chi, noise_q=1e-5, noise_tau=0.05, rng=rng)
        f = tmp_path / f"rec{k}.csv"
        write_recording_csv(f, tr)
        files.append(str(f))
    out = tmp_path / "res.json"
    cli("--quiet", "identify", "rx90", files[0], "--validate", files[1], "--method", "ols", "--json", out, rc=0)
    d = json.loads(out.read_text())
    p = d["parameters"]
    assert set(p) >= {"names", "values", "std", "rel_std_pct"}
    assert p["names"] == list(model.BASE_NAMES)
    assert len(d["rel_err"]) == robot.n_joints and len(d["validation"]["rel_err"]) == robot.n_joints
    assert isinstance(d["cond"], float) and isinstance(d["sigma"], float)
    assert max(d["validation"]["rel_err"]) < 0.05
    # well-identified parameters agree with the truth within 3 sigma
    truth = model.base_parameters(chi)
    v, s = np.array(p["values"]), np.array([x if x is not None else np.inf for x in p["std"]])
    good = s < 0.1 * np.maximum(np.abs(truth), 1e-3)
    assert good.sum() > 10
    assert np.mean(np.abs(v - truth)[good] <= 3 * s[good] + 1e-9) > 0.9


def test_identify_cli_bad_data_exits_2(tmp_path, cli):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,q1,tau1\n0,0,0\n")
    assert "bad.csv" in cli("identify", "rx90", bad, rc=2).err
