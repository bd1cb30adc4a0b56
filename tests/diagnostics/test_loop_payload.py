"""``diagnose --loaded ... --payload ...``: recordings with a payload go through the loop
as in ``identify`` - their rows get the payload's columns, known payload parameters are moved to ``Y``."""
from __future__ import annotations

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.diagnostics import DiagnoseSettings, diagnose
from symoro_gen.errors import IdentificationError
from symoro_gen.simulate import fourier_trajectory, random_payload, random_physical_parameters, simulate_recording

FAST = DiagnoseSettings(max_effects=0, composed=False, friction_laws=False, unexplained=False, stability=False,
                        structure=False)


@pytest.fixture(scope="module")
def lwr4_loaded():
    robot, model = load_robot("lwr4"), symoro_gen.load_model("lwr4")
    rng = np.random.default_rng(3)
    chi = np.asarray(random_physical_parameters(robot, rng))
    pay = np.asarray(random_payload(rng, robot=robot, mass_range=(2.0, 4.0)))
    recs = []
    for chi_p in (None, pay):
        t, q, dq, ddq = fourier_trajectory(7, 16.0, 0.005, rng, base_frequency_hz=0.1)
        recs.append(simulate_recording(model, t, q, dq, ddq, chi, chi_payload=chi_p, noise_q=1e-5, noise_tau=0.02,
                                       rng=rng))
    return model, recs[0], recs[1], pay


def test_known_payload_moves_to_y_and_predicts_the_loaded_data(lwr4_loaded):
    model, unl, lod, pay = lwr4_loaded
    m = float(pay[9])                                         # XX XY XZ YY YZ ZZ MX MY MZ M
    good = diagnose(model, unl, FAST, loaded=lod, payload={"M8": m})
    names = good.result_after.names
    assert "M8" not in names and "MX8" in names               # known mass fixed, the rest identified
    assert good.to_dict()["settings"]["known_payload"] == {"M8": m}
    # the held-out ends include loaded samples: predicted with the payload (both metrics)
    assert np.all(good.after_validation_rel_err < 0.1), good.after_validation_rel_err
    assert np.all(good.after_validation_rel_err_raw < 0.15), good.after_validation_rel_err_raw
    bad = diagnose(model, unl, FAST, loaded=lod, payload={"M8": 3.0 * m})
    # a wrong known mass is forced into the other parameters: the fit is worse somewhere
    assert np.max(bad.after_rel_err / good.after_rel_err) > 1.5, (good.after_rel_err, bad.after_rel_err)


def test_payload_errors_are_one_line(lwr4_loaded):
    model, unl, lod, _ = lwr4_loaded
    with pytest.raises(IdentificationError, match="--loaded"):
        diagnose(model, unl, FAST, payload={"M8": 1.0})
    with pytest.raises(IdentificationError, match="not a payload parameter"):
        diagnose(model, unl, FAST, loaded=lod, payload={"M9": 1.0})
