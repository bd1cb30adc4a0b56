"""The assembly engine (:mod:`symoro_gen.observations.fused`) against an independent reference.

The reference is Gautier's pre-processing written out plainly with NumPy/SciPy (RX-90 paper eq. 14-16), as
the assembly's blocked path computed it before the engine: SciPy's zero-phase Butterworth of ``q`` (odd
extension over 3 periods of the cut-off), ``np.gradient`` and the second central difference, the edge
samples dropped, the model's base regressor on every sample, then ``Y`` and every column of ``W`` through
``scipy.signal.resample_poly`` with the ``20 n_d + 1`` Hamming taps (zero padding, one sample in ``n_d``),
rows grouped per joint over the experiments. ``assemble`` (which goes through the engine for these
options) must give the same ``W`` and ``Y`` to 1e-10 relative, the same provenance and the same
full-rate signals, for SCARA and LWR4, several block sizes, lengths that are not multiples of ``n_d``,
several experiments, and positions that are not C-ordered (as a CSV's are).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal

from symoro_gen import load_model
from symoro_gen.description import load_robot
from symoro_gen.identification.accumulate import accumulate
from symoro_gen.observations import AssemblyOptions, assemble, iter_chunks, observation_settings
from symoro_gen.observations.fused import fused_applies
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording


def _recording(robot: str, seconds: float, seed: int, dt: float = 1e-3, fortran: bool = False) -> Trajectory:
    model = load_model(robot)
    rng = np.random.default_rng(seed)
    chi = random_physical_parameters(load_robot(robot), rng)
    mo = fourier_trajectory(model.N_JOINTS, seconds, dt, rng, vmax=1.5, amax=8.0)
    tr = simulate_recording(model, mo.t, mo.q, mo.dq, mo.ddq, np.asarray(chi, float), noise_q=1e-5,
                            noise_tau=0.02, rng=rng, source=f"{robot}-{seed}")
    if fortran:
        tr = Trajectory(t=tr.t, q=np.asfortranarray(tr.q), tau=np.asfortranarray(tr.tau), source=tr.source)
    return tr


def _reference(model, tr: Trajectory, cutoff_hz: float, n_d: int, edge: int, order: int = 4,
               cutoff_ratio: float = 0.8) -> dict:
    """The decimated system of one experiment, plainly (see the module notes)."""
    fs = 1.0 / tr.dt
    N = tr.n_samples
    sos = signal.butter(order, cutoff_hz, fs=fs, output="sos")
    qf = signal.sosfiltfilt(sos, np.asarray(tr.q, float), axis=0, padlen=min(N - 1, math.ceil(3.0 * fs / cutoff_hz)))
    dt = 1.0 / fs
    dq = np.gradient(qf, dt, axis=0)
    ddq = np.empty_like(qf)
    ddq[1:-1] = (qf[2:] - 2.0 * qf[1:-1] + qf[:-2]) / (dt * dt)
    ddq[0], ddq[-1] = ddq[1], ddq[-2]
    seg = slice(edge, N - edge)
    W = np.asarray(model.regressor(qf[seg], dq[seg], ddq[seg]), float)       # (M, n, nb)
    M, n, nb = W.shape
    h = signal.firwin(20 * n_d + 1, cutoff_ratio / n_d, window="hamming")
    Wd = signal.resample_poly(W.reshape(M, n * nb), 1, n_d, axis=0, window=h).reshape(-1, n, nb)
    Yd = signal.resample_poly(np.asarray(tr.tau, float)[seg], 1, n_d, axis=0, window=h)
    k = -(-M // n_d)
    assert Wd.shape[0] == k and Yd.shape[0] == k
    return {"W": Wd, "Y": Yd, "q": qf[seg], "dq": dq[seg], "ddq": ddq[seg],
            "sample": edge + n_d * np.arange(k)}


def _stack(refs: list[dict], n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Rows grouped per joint: joint 1 of every experiment, then joint 2..."""
    W, Y, J, E, S = [], [], [], [], []
    for j in range(n):
        for ex, r in enumerate(refs):
            W.append(r["W"][:, j, :])
            Y.append(r["Y"][:, j])
            J.append(np.full(r["Y"].shape[0], j))
            E.append(np.full(r["Y"].shape[0], ex))
            S.append(r["sample"])
    return tuple(np.concatenate(x, axis=0) for x in (W, Y, J, E, S))  # type: ignore[return-value]


CASES = [
    # robot, experiments (seconds, seed, dt, F-ordered), options
    ("scara", [(7.3, 1, 1e-3, False), (4.05, 2, 1e-3, False)], {}),
    ("scara", [(6.1, 3, 1e-3, True)], {"chunk_samples": 1000}),
    ("scara", [(8.0, 4, 5e-3, False), (6.31, 5, 5e-3, True)], {"cutoff_hz": 10.0, "n_d": 7}),
    ("lwr4", [(5.3, 6, 1e-3, False), (3.77, 7, 1e-3, False), (4.4, 8, 1e-3, True)], {}),
    ("lwr4", [(9.1, 9, 1e-3, False)], {"chunk_samples": 2500}),
    ("lwr4", [(6.2, 10, 1e-3, False), (5.0, 11, 1e-3, False)], {"chunk_samples": 777, "n_d": 13, "cutoff_hz": 20.0}),
    ("lwr4", [(5.5, 12, 4e-3, False)], {"payload_columns": True}),
]


@pytest.mark.parametrize(("robot", "experiments", "kw"), CASES)
def test_engine_rows_equal_an_independent_reference(robot, experiments, kw):
    model = load_model(robot)
    trs = [_recording(robot, s, seed, dt, fortran) for s, seed, dt, fortran in experiments]
    opts = AssemblyOptions(**kw)
    asm = assemble(model, trs, opts, progress=False)
    n = model.N_JOINTS
    refs = []
    for tr, rep in zip(trs, asm.experiments):
        st = rep.settings
        assert fused_applies(tr, st, opts), "the engine computes this case"
        if "n_d" in kw:
            assert st.n_d == kw["n_d"] and st.cutoff_hz == kw["cutoff_hz"]
        assert st.n_d > 1 and (tr.n_samples - 2 * st.edge_samples) % st.n_d != 0, "a length not a multiple of n_d"
        refs.append(_reference(model, tr, st.cutoff_hz, st.n_d, st.edge_samples, st.order, st.cutoff_ratio))
    W, Y, J, E, S = _stack(refs, n)
    nb = len(model.BASE_NAMES)
    Wsys = asm.system.W
    if kw.get("payload_columns"):                     # no payload mounted: its columns are zeros
        assert Wsys.shape[1] == nb + len(model.PAYLOAD_NAMES) and not np.any(Wsys[:, nb:])
        Wsys = Wsys[:, :nb]
    assert Wsys.shape == W.shape
    assert np.max(np.abs(Wsys - W)) <= 1e-10 * np.max(np.abs(W))
    assert np.max(np.abs(asm.system.Y - Y)) <= 1e-10 * np.max(np.abs(Y))
    # provenance: joint, experiment, full-rate sample, time, decimated index of every row
    assert np.array_equal(asm.system.joint, J) and np.array_equal(asm.row_experiment, E)
    assert np.array_equal(asm.row_sample, S)
    assert np.array_equal(asm.row_time, np.array([trs[e].t[s] for e, s in zip(E, S)], float))
    assert np.array_equal(asm.row_index, (S - np.array([asm.experiments[e].settings.edge_samples for e in E]))
                          // np.array([asm.experiments[e].settings.n_d for e in E]))
    for ex, (rep, ref) in enumerate(zip(asm.experiments, refs)):
        assert rep.rows_per_joint == (ref["Y"].shape[0],) * n and rep.removed_low_velocity == (0,) * n
        sig = asm.signals[ex]
        assert sig.first == rep.settings.edge_samples and np.array_equal(sig.decimated_samples, ref["sample"])
        # q to 1e-10; its differences also carry the rounding of q (one ulp of q is eps |q| / dt^k in the k-th
        # difference: 1e-9 rad/s^2 at 1 kHz), which the blocks of the zero-phase filter round differently
        floor = 8 * np.finfo(float).eps * np.max(np.abs(ref["q"]))
        for k, f in enumerate(("q", "dq", "ddq")):
            tol = 1e-10 * np.max(np.abs(ref[f])) + floor / trs[ex].dt ** k
            assert np.max(np.abs(getattr(sig, f) - ref[f])) <= tol, f
        assert np.max(np.abs(sig.tau_rows - ref["Y"])) <= 1e-10 * np.max(np.abs(ref["Y"]))
    # the streamed chunks hold the same rows (Gram matrix of [W Y] per joint)
    acc = accumulate(iter_chunks(model, trs, opts, progress=False))
    assert acc.n_rows == Y.size
    for j in range(n):
        rows = asm.system.joint == j
        A = np.column_stack([asm.system.W[rows], Y[rows]])
        G, Gr = acc.R[j].T @ acc.R[j], A.T @ A
        assert np.max(np.abs(G - Gr)) <= 1e-10 * np.max(np.abs(Gr))


def test_uncovered_options_keep_the_blocked_path():
    """IIR decimation, no decimation, low-velocity row removal, recorded derivatives and the payload columns of
    a loaded experiment are not the engine's: the assembly's blocked path computes them."""
    tr = _recording("scara", 3.0, 13)
    for kw in ({"ftype": "iir"}, {"n_d": 1}, {"min_velocity": 0.05}, {"use_recorded_derivatives": True}):
        opts = AssemblyOptions(**kw)
        assert not fused_applies(tr, observation_settings(tr, opts), opts), kw
    loaded = Trajectory(t=tr.t, q=tr.q, tau=tr.tau, loaded=True, source="loaded")
    opts = AssemblyOptions(payload_columns=True)
    assert not fused_applies(loaded, observation_settings(loaded, opts), opts)
