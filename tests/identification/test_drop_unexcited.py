"""A joint that stands still: ``identify`` names the file, the joint and the parameters it
cannot identify, and ``--drop-unexcited`` identifies the others and reports those as not identified.

Reference: simulated recordings (truth known) in which joint 2 of the SCARA is held at a constant
position; the parameters that cannot be identified are found independently from the model's own
full-rate regressor (``model.regressor``: columns identically zero over the samples), not from the
filtered, decimated observation matrix the command builds.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from symoro_gen import load_model
from symoro_gen.description import load_robot
from symoro_gen.errors import IdentificationError
from symoro_gen.identification import ObservationSystem, drop_unexcited, fit_wls, unexcited_columns
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording
from symoro_gen.simulate.recording import write_recording_csv

STILL = 1  # 0-based: joint 2


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    rng = np.random.default_rng(11)
    robot, model = load_robot("scara"), load_model("scara")
    chi = np.asarray(random_physical_parameters(robot, rng))
    d = tmp_path_factory.mktemp("still")
    out = {}
    for name, still in (("still.csv", True), ("moving.csv", False)):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, 8.0, 0.004, rng)
        if still:  # joint 2 locked at 0.3 rad (logged as a constant)
            q[:, STILL], dq[:, STILL], ddq[:, STILL] = 0.3, 0.0, 0.0
        tr = simulate_recording(model, t, q, dq, ddq, chi, noise_q=0.0, noise_tau=0.01, rng=rng)
        write_recording_csv(d / name, tr)
        out[name] = (q, dq, ddq)
    zero = np.all(model.regressor(*out["still.csv"]) == 0, axis=(0, 1))
    not_excited = [n for n, z in zip(model.BASE_NAMES, zero) if z]
    return d, model, chi, not_excited


def test_reference_has_unexcited_parameters(recordings):
    _, model, _, not_excited = recordings
    assert not_excited and len(not_excited) < len(model.BASE_NAMES)  # the case is the one we mean


def test_still_joint_is_an_error_naming_file_joint_and_option(cli, recordings):
    d, _, _, not_excited = recordings
    out = d / "no.json"
    res = cli("-q", "identify", "scara", d / "still.csv", "--json", out, rc=2)
    first = res.err.splitlines()[0]
    assert first.startswith("symoro-gen: error: ") and "still.csv" in first and "joint 2 does not move" in first
    assert all(n in first for n in not_excited), first
    assert "hint: give --drop-unexcited" in res.err and "Traceback" not in res.err
    assert not out.exists()


def test_drop_unexcited_identifies_the_others(cli, recordings):
    d, model, chi, not_excited = recordings
    out = d / "res.json"
    res = cli("identify", "scara", d / "still.csv", "--drop-unexcited", "--method", "ols", "--validate",
              d / "moving.csv", "--json", out, rc=0)
    j = json.loads(out.read_text())
    assert j["unexcited"] == not_excited
    p = j["parameters"]
    assert p["names"] == [n for n in model.BASE_NAMES if n not in not_excited]
    assert any("not identified" in w for w in j["warnings"])
    assert "not identified (columns of W zero" in res.out
    # the identified parameters are the truth's where well determined: within 3 sigma plus the few-%
    # bias of the band-pass filter on an 8 s recording (a column or name mix-up would be far off)
    truth = dict(zip(model.BASE_NAMES, model.base_parameters(chi)))
    v = np.array(p["values"])
    s = np.array([x if x is not None else np.inf for x in p["std"]])
    t = np.array([truth[n] for n in p["names"]])
    good = s < 0.1 * np.maximum(np.abs(t), 1e-3)
    assert good.sum() >= 10
    assert np.all(np.abs(v - t)[good] <= 3 * s[good] + 0.05 * np.abs(t[good])), list(zip(p["names"], v, t, s))
    assert np.median(np.abs(v - t)[good] / np.abs(t[good])) < 0.005
    # with joint 2 still, joint 1's and 2's inertias combine: said, not hidden (std inf, a warning)
    assert any("rank-deficient" in w and "ZZ1R" in w for w in j["warnings"])
    # validation on a recording that moves joint 2: its error shows what was not identified
    assert all(x is not None for x in j["validation"]["rel_err"])


def test_drop_unexcited_not_with_closed_loop_methods(cli, recordings):
    d, *_ = recordings
    res = cli("-q", "identify", "scara", d / "still.csv", "--drop-unexcited", "--method", "iv", rc=2)
    assert "--drop-unexcited is not available with --method iv" in res.err


def test_unexcited_columns_count_every_system():
    """A column zero in one system but not in the other one solved with it is excited."""
    rng = np.random.default_rng(0)
    W1 = rng.normal(size=(40, 3))
    W1[:, 2] = 0.0
    W2 = rng.normal(size=(40, 3))
    a = ObservationSystem(W1, rng.normal(size=40), ("A", "B", "C"), np.repeat([0, 1], 20))
    b = ObservationSystem(W2, rng.normal(size=40), ("A", "B", "C"), np.repeat([0, 1], 20))
    assert unexcited_columns([a]) == ("C",)
    assert unexcited_columns([a, b]) == ()
    with pytest.raises(IdentificationError, match=r"parameter\(s\) C \(1 of 3\)"):
        drop_unexcited([a], drop=False)
    (a2,), gone = drop_unexcited([a])
    assert gone == ("C",) and a2.names == ("A", "B")
    # the reduced fit is the fit of the remaining columns
    ref = np.linalg.lstsq(W1[:, :2], a.Y, rcond=None)[0]
    np.testing.assert_allclose(fit_wls(ObservationSystem(W1[:, :2], a.Y, ("A", "B"), a.joint)).values,
                               fit_wls(a2).values)
    assert np.isfinite(ref).all()


def test_diagnose_on_a_still_joint_names_file_and_joint_before_computing(cli, recordings):
    """diagnose refuses a joint that stands still in every identification file with one line naming the
    file and the joint (not the estimator's message about columns), and points at identify's option."""
    d, _, _, _ = recordings
    out = d / "diag.json"
    res = cli("-q", "diagnose", "scara", d / "still.csv", "--json", out, rc=2)
    first = res.err.splitlines()[0]
    assert first.startswith("symoro-gen: error: ") and "still.csv" in first and "joint 2 does not move" in first
    assert "--drop-unexcited" in res.err and "Traceback" not in res.err
    assert not out.exists()
    # a joint still in one file but moving in another is excited: no refusal from this check
    from symoro_gen.preprocessing.readers import load_trajectory
    from symoro_gen.workflows.diagnose import refuse_still_joints

    refuse_still_joints([load_trajectory(d / f, n_joints=4) for f in ("still.csv", "moving.csv")])
