"""Rows and signals of the diagnosis frames line up with the assembler's observation system."""
from __future__ import annotations

import numpy as np
import pytest

from symoro_gen.diagnostics.frame import (
    T_ORIGIN_KEY,
    attach_model_torque,
    build_frame,
    common_bandwidth,
    model_torque,
    split_holdout,
)

from .simdata import recording


@pytest.fixture(scope="module")
def scara_frame():
    model, tr = recording("scara", 21, noise_q=1e-4)
    return model, tr, build_frame(model, [tr], dynamics_bandwidth_hz=common_bandwidth([tr]))


def test_full_rate_columns_equal_the_model_columns(scara_frame):
    """sign(dq_j), dq_j, ddq_j evaluated at full rate and decimated == the FS, FV, IA columns of W."""
    model, _, F = scara_frame
    W = F.system.W
    for name, fn in (("FS2", lambda ex: {1: np.sign(ex.dq[:, 1:2])}), ("FV4", lambda ex: {3: ex.dq[:, 3:4]}),
                     ("IA4", lambda ex: {3: ex.ddq[:, 3:4]})):
        X = F.full_rate_columns(fn, 1)[:, 0]
        ref = W[:, F.system.names.index(name)]
        np.testing.assert_allclose(X, ref, rtol=0, atol=1e-9 * np.abs(ref).max())


def test_row_signals_and_model_torque(scara_frame):
    model, tr, F = scara_frame
    J = F.system.joint
    # the measured torque of each row is Y
    np.testing.assert_allclose(F.sig["tau"][np.arange(J.size), J], F.system.Y, atol=1e-9)
    # the model torque of the fitted parameters predicts Y (to the noise)
    th = np.linalg.lstsq(F.system.W, F.system.Y, rcond=None)[0]
    G = attach_model_torque(F, model, dict(zip(F.system.names, th)))
    pred = G.sig["tau_hat"][np.arange(J.size), J]
    rel = np.linalg.norm(pred - F.system.Y) / np.linalg.norm(F.system.Y)
    assert rel < 0.02, rel
    # the rows' time is the sample time of the decimated samples
    t = G.sig["t"][F.rows_of(0)]
    assert np.all(np.diff(t) > 0) and np.allclose(np.diff(t), np.diff(t)[0])


def test_position_noise_estimate(scara_frame):
    _, _, F = scara_frame
    np.testing.assert_allclose(F.experiments[0].q_noise, 1e-4, rtol=0.1)


def test_holdout_keeps_the_time_origin():
    _, tr = recording("scara", 22, duration=10.0)
    a, b = split_holdout([tr], 0.3)
    assert a[0].n_samples + b[0].n_samples == tr.n_samples
    assert b[0].n_samples == pytest.approx(0.3 * tr.n_samples, abs=1)
    assert a[0].meta[T_ORIGIN_KEY] == b[0].meta[T_ORIGIN_KEY] == tr.t[0]
    with pytest.raises(ValueError):
        split_holdout([tr], 1.0)


def test_batched_full_rate_columns_equal_the_whole_recording_ones(scara_frame):
    """Columns on every joint's rows evaluated over short stretches of samples (each with its filter window)
    and decimated equal the same columns evaluated and decimated over the whole recording, and so do the
    joint-zero tangents built that way against the tangent of the whole recording's regressor."""
    from symoro_gen.diagnostics.geometry import decimated_zero_matrix, regressor_secant

    model, _, F = scara_frame
    ex = F.experiments[0]
    assert ex.settings.ftype == "fir" and ex.settings.n_d > 1
    n, p = F.n_joints, 3

    def cols(e, a, b):
        x = np.stack([np.sin(e.q[a:b] * (i + 1)) + e.dq[a:b] ** i for i in range(p)], axis=2)
        return x * (1.0 + np.arange(n))[None, :, None]

    ref = F.full_rate_columns(lambda e: {k: cols(e, 0, e.n_samples)[:, k, :] for k in range(n)}, p)
    for batch in (1, 8 * n * p * 3 * ex.settings.n_d * 16 + 5, 2 ** 30):    # window-sized, odd, whole
        got = F.full_rate_columns_batched(cols, p, batch_bytes=batch)
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    D = decimated_zero_matrix(F, model, 1)
    whole = regressor_secant(model, ex.q, ex.dq, ex.ddq, 1, 0.0)
    P = whole.shape[2]
    ref = F.full_rate_columns(lambda e: {k: whole[:, k, :] for k in range(n)}, P)
    np.testing.assert_allclose(D[:, :P], ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    assert np.abs(ref).max() > 0


def test_batched_columns_bound_the_callbacks_work(scara_frame):
    """The callback of ``full_rate_columns_batched`` is called on at most ``call_samples`` samples at a time
    (its own work arrays are bounded, whatever it returns), and the columns do not depend on that split: the
    same as one call over each whole stretch and as the unbatched ``full_rate_columns``."""
    _, _, F = scara_frame
    ex = F.experiments[0]
    n, p = F.n_joints, 2
    sizes = []

    def cols(e, a, b):
        sizes.append(b - a)
        return np.stack([np.cos(e.q[a:b]) * e.ddq[a:b], np.abs(e.dq[a:b]) ** 1.5], axis=2)

    ref = F.full_rate_columns(lambda e: {k: cols(e, 0, e.n_samples)[:, k, :] for k in range(n)}, p)
    for call in (1, 37, 256, 10 ** 9):
        sizes.clear()
        got = F.full_rate_columns_batched(cols, p, call_samples=call)
        assert max(sizes) == min(call, ex.n_samples)
        assert sum(sizes) == ex.n_samples      # one stretch: every sample evaluated once
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12 * np.abs(ref).max())


def test_model_torque_does_not_depend_on_the_regressor_batches(scara_frame):
    """``IDM(q, dq, ddq) chi`` in regressor calls of a few samples (bounded transient) equals one call over the
    whole recording, and the regressor's own product with ``chi``."""
    model, _, F = scara_frame
    ex = F.experiments[0]
    theta = {nm: 0.1 * (i + 1) for i, nm in enumerate(F.system.names)}
    chi = np.array([theta.get(nm, 0.0) for nm in model.BASE_NAMES])
    whole = np.asarray(model.regressor(ex.q, ex.dq, ex.ddq), float) @ chi
    for batch in (7, 1024, 10 ** 9):
        np.testing.assert_allclose(model_torque(model, theta, ex.q, ex.dq, ex.ddq, batch=batch), whole,
                                   rtol=0, atol=1e-12 * np.abs(whole).max())


def test_frame_rows_are_the_streamed_engines_rows():
    """The diagnosis frame's ``W`` and ``Y`` are the rows ``identify``'s streaming path folds
    (:func:`symoro_gen.observations.iter_chunks`, block after block, several Butterworth blocks here),
    regrouped per joint: one assembly engine for both."""
    from dataclasses import replace

    from symoro_gen.observations import iter_chunks

    model, tr = recording("scara", 23, duration=60.0, noise_q=1e-4)
    F = build_frame(model, [tr], chunk_samples=400)
    chunks = list(iter_chunks(model, [tr], replace(F.assembly.options, keep_signals=False), progress=False))
    assert len(chunks) > 2
    n = F.n_joints
    W = np.concatenate([c.W[c.joint == j] for j in range(n) for c in chunks])
    Y = np.concatenate([c.Y[c.joint == j] for j in range(n) for c in chunks])
    assert W.shape == F.system.W.shape
    scale = np.abs(F.system.W).max(axis=0) + 1e-300
    np.testing.assert_allclose(W / scale, F.system.W / scale, rtol=0, atol=1e-12)
    np.testing.assert_allclose(Y, F.system.Y, rtol=0, atol=1e-12 * np.abs(F.system.Y).max())
