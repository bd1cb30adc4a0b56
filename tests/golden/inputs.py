"""Fixed inputs of the golden JSON files: two simulated SCARA recordings (8 s at 200 Hz, known truth, noise)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from symoro_gen.loader import model_for
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording, write_recording_csv

ROBOT = "scara"
FILES = ("scara_a.csv", "scara_b.csv")


def write_inputs(folder) -> list[Path]:
    """Write the recordings into ``folder`` and return their paths (same bytes on every run and machine up to
    the last bits of the simulated torques)."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    desc, model = model_for(ROBOT)
    rng = np.random.default_rng(20261128)
    chi = np.asarray(random_physical_parameters(desc, rng), float)
    out = []
    for name in FILES:
        mo = fourier_trajectory(model.N_JOINTS, 8.0, 0.005, rng, vmax=1.5, amax=8.0)
        rec = simulate_recording(model, mo.t, mo.q, mo.dq, mo.ddq, chi, noise_q=1e-5, noise_tau=0.02, rng=rng,
                                 source=name)
        write_recording_csv(folder / name, rec)
        out.append(folder / name)
    return out
