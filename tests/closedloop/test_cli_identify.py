"""`symoro-gen identify palletizer rec.csv`: a closed-loop robot end to end from its recordings (the
actuated joints logged, columns q1..q4 = joints 1, 2, 4, 5), through filtering, decimation and OLS."""
from __future__ import annotations

import json

import numpy as np

from symoro_gen import load_model
from symoro_gen.description import load_robot
from symoro_gen.simulate.parameters import random_physical_parameters
from symoro_gen.simulate.recording import simulate_recording, write_recording_csv


def fourier(rng, t, n, harmonics=5, f0=0.1, amp=0.12):
    """A Fourier motion (Swevers 1997) with |q| < 0.6 rad per joint (inside the parallelogram's range)."""
    q, dq, ddq = (np.zeros((t.size, n)) for _ in range(3))
    for k in range(1, harmonics + 1):
        wk = 2 * np.pi * f0 * k
        a, b = rng.uniform(-amp, amp, (2, n)) / k
        s, c = np.sin(wk * t)[:, None], np.cos(wk * t)[:, None]
        q += s * a - c * b
        dq += wk * (c * a + s * b)
        ddq += wk**2 * (-s * a + c * b)
    return q, dq, ddq


def test_identify_cli_on_a_closed_loop_robot(tmp_path, cli):
    robot, model = load_robot("palletizer"), load_model("palletizer")
    rng = np.random.default_rng(21)
    chi = np.asarray(random_physical_parameters(robot, rng))
    files = []
    for k in range(2):
        t = np.arange(0, 20, 0.002)
        tr = simulate_recording(model, t, *fourier(rng, t, 4), chi, noise_q=1e-6, noise_tau=0.05, rng=rng)
        write_recording_csv(tmp_path / f"rec{k}.csv", tr)
        files.append(tmp_path / f"rec{k}.csv")
    out = tmp_path / "res.json"
    cli("--quiet", "identify", "palletizer", files[0], "--validate", files[1], "--method", "ols", "--json", out)
    d = json.loads(out.read_text())
    assert d["parameters"]["names"] == list(model.BASE_NAMES)
    assert len(d["validation"]["rel_err"]) == 4 and max(d["validation"]["rel_err"]) < 0.05
    truth = model.base_parameters(chi)
    v, s = np.array(d["parameters"]["values"]), np.array(d["parameters"]["std"], float)
    assert np.mean(np.abs(v - truth) <= 3 * s) > 0.9  # filtering and decimation: not exactly the OLS assumptions
