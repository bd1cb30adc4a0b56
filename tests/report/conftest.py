"""Simulated RX-90 recordings (truth known) and the reports the ``identify`` command writes from them.

Two 8 s Fourier-series recordings at 500 Hz of random physically consistent parameters, with noise
on q and on the torque; identification on the first, validation on the second. The reports are
written once per session (``identify --report``), in HTML and in Markdown, with the JSON beside.
"""
import json

import numpy as np
import pytest

from symoro_gen.simulate import write_recording_csv

DURATION_S = 8.0
DT_S = 0.002
NOISE_TAU = 0.5   # N m: visible in the torque plots
NOISE_Q = 1e-5    # rad


@pytest.fixture(scope="session")
def rx90_recordings(tmp_path_factory):
    """Paths of two simulated RX-90 CSV recordings (identification, validation)."""
    from symoro_gen.loader import model_for
    from symoro_gen.simulate.parameters import random_physical_parameters
    from symoro_gen.simulate.recording import simulate_recording
    from symoro_gen.simulate.trajectories import fourier_trajectory

    rng = np.random.default_rng(3)
    robot, model = model_for("rx90")
    params = random_physical_parameters(robot, rng)
    chi = getattr(params, "chi_std", params)
    folder = tmp_path_factory.mktemp("rx90_recordings")
    files = []
    for k in range(2):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, DURATION_S, DT_S, rng)
        tr = simulate_recording(model, t, q, dq, ddq, chi, noise_q=NOISE_Q, noise_tau=NOISE_TAU, rng=rng)
        f = folder / f"rec{k}.csv"
        write_recording_csv(f, tr)
        files.append(f)
    return files


def _identify_report(cli, rec, out_dir, name):
    report = out_dir / name
    js = out_dir / (report.stem + ".json")
    cli("--quiet", "identify", "rx90", rec[0], "--validate", rec[1], "--method", "wls", "--json", js,
        "--report", report, rc=0)
    return report, json.loads(js.read_text())


@pytest.fixture(scope="session")
def rx90_html_report(rx90_recordings, tmp_path_factory, cli):
    """``(path of report.html, JSON of the same run)``."""
    pytest.importorskip("matplotlib", reason="report plots need matplotlib (the 'plots' extra)")
    return _identify_report(cli, rx90_recordings, tmp_path_factory.mktemp("html_report"), "report.html")


@pytest.fixture(scope="session")
def rx90_md_report(rx90_recordings, tmp_path_factory, cli):
    """``(path of report.md, JSON of the same run)``."""
    pytest.importorskip("matplotlib", reason="report plots need matplotlib (the 'plots' extra)")
    return _identify_report(cli, rx90_recordings, tmp_path_factory.mktemp("md_report"), "report.md")
