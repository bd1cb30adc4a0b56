"""Honest errors: the observations stage's provenance and signals, ``rel_err`` on the filtered,
decimated system beside ``rel_err_raw`` on the raw measured torque, validation on every sample.

References are independent of the code under test: the true parameters of a simulation, the noise
added to the torque, the recordings themselves, and a whole-recording filter of q."""
from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from symoro_gen.identification import identify
from symoro_gen.loader import model_for
from symoro_gen.observations import (
    AssemblyOptions,
    assemble,
    iter_chunks,
    raw_error_sums,
)
from symoro_gen.preprocessing.filtering import filter_and_differentiate
from symoro_gen.simulate import (
    fourier_trajectory,
    random_physical_parameters,
    simulate_recording,
)

NOISE_TAU = 0.5      # N m: large against the decimation band, so the two metrics must differ


@pytest.fixture(scope="module")
def scara():
    robot, model = model_for("scara")
    rng = np.random.default_rng(7)
    chi = np.asarray(random_physical_parameters(robot, rng))
    recs, clean = [], []
    for _ in range(2):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, 12.0, 0.002, rng)
        recs.append(simulate_recording(model, t, q, dq, ddq, chi, noise_q=1e-6, noise_tau=NOISE_TAU, rng=rng))
        clean.append(simulate_recording(model, t, q, dq, ddq, chi))
    theta = dict(zip(model.BASE_NAMES, np.asarray(model.base_parameters(chi), float)))
    return model, recs, clean, theta


def _split_system_rows(asm, j):
    return np.flatnonzero(asm.system.joint == j)


def test_assembly_provenance_and_signals(scara):
    """Every row knows its sample; ``Y`` is the decimated measured torque of that sample; the kept
    signals are the whole-recording band-pass filter of q (blocks stitched to 1e-8)."""
    model, recs, _, _ = scara
    opts = AssemblyOptions(cutoff_hz=20.0, n_d=5, chunk_samples=1500)
    asm = assemble(model, recs, opts)
    assert len(asm.signals) == len(recs)
    for e, (sg, tr) in enumerate(zip(asm.signals, recs)):
        e0 = sg.settings.edge_samples
        np.testing.assert_array_equal(sg.tau_raw, tr.tau[e0:tr.n_samples - e0])
        qf, dq, ddq = filter_and_differentiate(tr.q, 1.0 / tr.dt, 20.0, sg.settings.order)
        seg = slice(e0, tr.n_samples - e0)
        for a, b in ((sg.q, qf[seg]), (sg.dq, dq[seg]), (sg.ddq, ddq[seg])):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-8 * np.abs(b).max())
        m = asm.row_experiment == e
        np.testing.assert_array_equal(asm.row_time[m], tr.t[asm.row_sample[m]])
        np.testing.assert_array_equal((asm.row_sample[m] - e0) % 5, 0)
        np.testing.assert_array_equal(asm.row_index[m], (asm.row_sample[m] - e0) // 5)
        np.testing.assert_allclose(sg.tau_rows[asm.row_index[m], asm.system.joint[m]], asm.system.Y[m], rtol=0,
                                   atol=1e-12 * np.abs(asm.system.Y).max())
    # the streamed chunks are the same rows
    chunks = list(iter_chunks(model, recs, opts))
    assert sum(c.Y.size for c in chunks) == asm.system.Y.size


def test_assembly_options_are_validated_once():
    with pytest.raises(ValueError, match="min_velocity"):
        AssemblyOptions(min_velocity=-0.1)
    with pytest.raises(ValueError, match="ftype"):
        AssemblyOptions(ftype="median")
    with pytest.raises(ValueError, match="n_d"):
        AssemblyOptions(n_d=0)
    with pytest.raises(TypeError, match="cutof"):
        AssemblyOptions.from_keywords(cutof_hz=3.0)
    assert AssemblyOptions().summary() == "defaults (the papers' rules)"
    assert "n_d = 4" in AssemblyOptions(n_d=4).summary()


def test_true_model_raw_error_is_the_torque_noise(scara):
    """With the true parameters, ``rel_err_raw`` is the added noise over the raw torque (per joint),
    while ``rel_err`` of the same model on the filtered, decimated system is far smaller (the
    decimation removes most of the white noise)."""
    model, recs, clean, theta = scara
    asm = assemble(model, recs, AssemblyOptions(n_d=10, cutoff_hz=15.0))
    rho2, y2 = raw_error_sums(model, theta, asm)
    raw = np.sqrt(rho2 / y2)
    e0 = [sg.settings.edge_samples for sg in asm.signals]
    noise2 = sum(np.sum((tr.tau - c.tau)[e:tr.n_samples - e] ** 2, axis=0) for tr, c, e in zip(recs, clean, e0))
    expected = np.sqrt(noise2 / y2)
    np.testing.assert_allclose(raw, expected, rtol=0.05)
    W = asm.system.W
    th = np.array([theta[n] for n in asm.system.names])
    rho = asm.system.Y - W @ th
    J = asm.system.joint
    filt = np.sqrt(np.bincount(J, rho ** 2) / np.bincount(J, asm.system.Y ** 2))
    assert np.all(filt < 0.5 * raw), (filt, raw)


def test_identified_result_reports_both_metrics(scara):
    model, recs, _, _ = scara
    asm = assemble(model, recs[:1], AssemblyOptions(n_d=10, cutoff_hz=15.0))
    res = identify(asm.system, method="ols").with_raw_error(model, asm)
    assert res.rel_err_raw is not None and res.rel_err_raw.shape == res.rel_err.shape
    assert np.all(res.rel_err < res.rel_err_raw)
    d = res.to_dict()
    assert d["rel_err_raw"] == pytest.approx(list(res.rel_err_raw))
    b = d["rel_err_basis"]
    assert b["cutoff_hz"] == [15.0] and b["n_d"] == [10] and b["rows"] == res.n_rows
    assert b["samples"] == asm.signals[0].n_samples
    text = res.summary()
    assert "cut-off 15 Hz" in text and "n_d = 10" in text and "raw measured torque" in text


def _csv(path, tr):
    n = tr.q.shape[1]
    head = ",".join(["t"] + [f"q{j + 1}" for j in range(n)] + [f"tau{j + 1}" for j in range(n)])
    np.savetxt(path, np.column_stack([tr.t, tr.q, tr.tau]), delimiter=",", header=head, comments="")


def test_cli_min_velocity_selects_identification_rows_only(scara, tmp_path):
    """--min-velocity removes identification rows; validation is on every sample either way, and the
    JSON has both metrics with what they are computed on."""
    from symoro_gen.cli import main

    _, recs, _, _ = scara
    files = [tmp_path / f"r{k}.csv" for k in range(2)]
    for f, tr in zip(files, recs):
        _csv(f, tr)
    out = {}
    for tag, extra in (("all", []), ("slow", ["--min-velocity", "0.2"])):
        js = tmp_path / f"{tag}.json"
        assert main(["--quiet", "identify", "scara", str(files[0]), "--validate", str(files[1]), "--method", "ols",
                     "--json", str(js)] + extra) == 0
        out[tag] = json.loads(js.read_text())
    a, s = out["all"], out["slow"]
    for d in (a, s):
        assert len(d["rel_err_raw"]) == len(d["rel_err"]) == 4
        assert len(d["validation"]["rel_err_raw"]) == len(d["validation"]["rel_err"]) == 4
        assert {"cutoff_hz", "n_d", "rows", "samples"} <= set(d["rel_err_basis"])
    assert s["n_rows"] < a["n_rows"] and s["rel_err_basis"]["min_velocity"] == 0.2
    assert a["rel_err_basis"]["min_velocity"] is None
    assert s["validation"]["rel_err_basis"]["rows"] == a["validation"]["rel_err_basis"]["rows"]
    assert s["validation"]["rel_err_basis"]["samples"] == a["validation"]["rel_err_basis"]["samples"] > 0
    assert s["validation"]["rel_err_basis"]["min_velocity"] is None
    # the torque noise is large: the raw-torque errors are larger than the filtered ones on every joint
    assert all(r > f for r, f in zip(a["validation"]["rel_err_raw"], a["validation"]["rel_err"]))


def test_raw_error_needs_the_signals(scara):
    model, recs, _, theta = scara
    asm = assemble(model, recs[:1], AssemblyOptions(n_d=10, keep_signals=False))
    assert asm.signals == ()
    with pytest.raises(ValueError, match="keep_signals"):
        raw_error_sums(model, theta, asm)
    # the filtered system does not depend on keeping the signals
    ref = assemble(model, recs[:1], replace(asm.options, keep_signals=True))
    np.testing.assert_array_equal(ref.system.W, asm.system.W)
