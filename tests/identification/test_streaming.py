"""``identify`` in bounded memory: the observation system folded into per-joint QR factors block after block
(:mod:`symoro_gen.identification.streaming`) gives the estimates, statistics, error norms and raw-torque errors
of the whole system in memory (the reference: the same workflow with the streaming turned off) to 1e-9
relative, on simulated LWR4 recordings (OLS, WLS, TLS, a known payload, essential parameters) and on the real LWR4
recordings when present; the factor operations match the same operations on the rows."""
from __future__ import annotations

import importlib
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.identification import Accumulator, fit_ols, fit_wls
from symoro_gen.identification.accumulate import factor_system
from symoro_gen.identification.payload import fit_with_known_payload, fit_with_known_payload_factors
from symoro_gen.identification.streaming import SAMPLE_ROWS, fix_known, pad_columns, stack_factors, stream_assembly
from symoro_gen.identification.systems import fix_parameters, stack_systems
from symoro_gen.observations import AssemblyOptions, ObservationSystem, assemble
from symoro_gen.observations.assembly import iter_kinematics

RTOL = 1e-9
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _workflow_module():
    importlib.import_module("symoro_gen.workflows.identify")
    return sys.modules["symoro_gen.workflows.identify"]     # the package exports a function of that name


def _identify(streamed: bool, monkeypatch, *args, **kw):
    mod = _workflow_module()
    with monkeypatch.context() as mp:
        mp.setattr(mod, "streams", lambda opts: streamed)
        return symoro_gen.identify(*args, **kw)


def _close(a: float, b: float, scale: float = 0.0) -> bool:
    return abs(a - b) <= RTOL * max(abs(a), abs(b), scale) or (math.isnan(a) and math.isnan(b))


def _same(a, b, where="$", scale=0.0):
    """Recursive comparison; floats within RTOL relative (to ``scale`` at least: a parameter near zero is
    compared relative to the largest one), numbers inside texts too."""
    if isinstance(a, dict):
        assert set(a) == set(b), f"{where}: keys differ {sorted(set(a) ^ set(b))}"
        for k in a:
            if where.endswith("parameters") and k in ("values", "rel_std_pct"):
                continue                      # compared in _same_parameters
            _same(a[k], b[k], f"{where}.{k}", scale)
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]", scale)
    elif isinstance(a, bool) or a is None:
        assert a == b, f"{where}: {a!r} != {b!r}"
    elif isinstance(a, (int, float)):
        assert _close(float(a), float(b), scale), f"{where}: {a!r} != {b!r}"
    elif isinstance(a, str) and a != b:
        assert _NUMBER.split(a) == _NUMBER.split(b), f"{where}: {a!r} != {b!r}"
        for x, y in zip(_NUMBER.findall(a), _NUMBER.findall(b)):   # printed numbers (rounded): a few digits
            assert math.isclose(float(x), float(y), rel_tol=1e-3, abs_tol=1e-12), f"{where}: {a!r} != {b!r}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


def _same_results(mem: dict, st: dict) -> None:
    """``to_dict()`` of the two paths: everything within RTOL; the parameter values relative to the largest
    one (a parameter the data leave at ~0 differs at the rounding of the others), %sigma where it is finite
    and the value not at that rounding level."""
    va, vb = np.array(mem["parameters"]["values"], float), np.array(st["parameters"]["values"], float)
    top = float(np.max(np.abs(va)))
    assert np.all(np.abs(va - vb) <= RTOL * top), np.max(np.abs(va - vb)) / top
    ra, rb = (np.array([np.nan if x is None else x for x in d["parameters"]["rel_std_pct"]], float) for d in (mem, st))
    ok = np.abs(va) > 1e-3 * top
    assert np.allclose(ra[ok], rb[ok], rtol=1e-6, equal_nan=True)
    mem, st = dict(mem), dict(st)
    mem.pop("provenance"), st.pop("provenance")
    _same(mem, st)


# ---------------------------------------------------------------------------- factor operations (fast)
def _random_system(rng, rows_per_joint=(40, 35, 30), names=("a", "b", "c", "d")):
    Ws, Ys, Js = [], [], []
    for j, r in enumerate(rows_per_joint):
        Ws.append(rng.normal(size=(r, len(names))))
        Ys.append(rng.normal(size=r))
        Js.append(np.full(r, j))
    return ObservationSystem(np.vstack(Ws), np.concatenate(Ys), names, np.concatenate(Js))


def test_factor_operations_match_the_same_operations_on_rows():
    rng = np.random.default_rng(0)
    un = _random_system(rng, names=("a", "b"))
    lo = _random_system(rng, rows_per_joint=(25, 20, 30), names=("a", "b", "p1", "p2"))
    known = {"p2": 1.7}
    # stacked, padded, fixed: the same WLS estimate and error norms as on the stacked rows
    ref = fit_with_known_payload(un, lo, known, method="wls")
    got = fit_with_known_payload_factors(factor_system(un), factor_system(lo), known, method="wls")
    assert np.allclose(got.values, ref.values, rtol=1e-12, atol=0) and got.names == ref.names
    assert np.allclose(got.std, ref.std, rtol=1e-10) and np.allclose(got.rel_err, ref.rel_err, rtol=1e-10)
    # each operation alone: Gram matrices of [W Y] equal
    full = stack_systems(ObservationSystem(np.c_[un.W, np.zeros((un.W.shape[0], 2))], un.Y, lo.names, un.joint), lo)
    acc = stack_factors(pad_columns(factor_system(un), lo.names), factor_system(lo))
    fixed = fix_parameters(full, known)
    facc = fix_known(acc, known)
    for j in range(3):
        M = np.c_[fixed.W, fixed.Y][fixed.joint == j]
        assert np.allclose(facc.R[j].T @ facc.R[j], M.T @ M, rtol=1e-12, atol=1e-10)
        assert math.isclose(facc.yy[j], float(fixed.Y[fixed.joint == j] @ fixed.Y[fixed.joint == j]), rel_tol=1e-12)
    dropped = factor_system(lo).without(["p1"])
    keep = [0, 1, 3]
    for j in range(3):
        M = np.c_[lo.W[:, keep], lo.Y][lo.joint == j]
        assert np.allclose(dropped.R[j].T @ dropped.R[j], M.T @ M, rtol=1e-12, atol=1e-10)
    assert np.allclose(factor_system(lo).column_sq_norms(), np.sum(lo.W ** 2, axis=0), rtol=1e-12)


def test_rel_err_on_factors_equals_rel_err_on_rows():
    rng = np.random.default_rng(1)
    s = _random_system(rng)
    res = fit_ols(s)
    v = _random_system(rng, rows_per_joint=(20, 22, 24))
    assert np.allclose(res.rel_err_on(factor_system(v)), res.rel_err_on(v), rtol=1e-12)
    assert np.allclose(fit_wls(Accumulator.empty(s.names, 3).add(s)).values, fit_wls(s).values, rtol=1e-12)


# ---------------------------------------------------------------------------- simulated LWR4
@pytest.fixture(scope="module")
def lwr4_recordings():
    from symoro_gen.simulate.recording import simulate_recording
    from symoro_gen.simulate.trajectories import fourier_trajectory

    model = symoro_gen.load_model("lwr4")
    chi = model.nominal_parameters()
    payload = np.array([0.02, 0.0, 0.0, 0.02, 0.0, 0.01, 0.3, -0.2, 0.5, 4.6])

    def rec(duration, seed, name, chi_payload=None):
        rng = np.random.default_rng(seed)
        mo = fourier_trajectory(7, duration, 1e-3, rng, vmax=1.5, amax=6.0, base_frequency_hz=0.1)
        return simulate_recording(model, mo.t, mo.q, mo.dq, mo.ddq, chi, chi_payload=chi_payload, rng=rng,
                                  noise_q=1e-5, noise_tau=0.05, source=name)

    # 90 s at 1 kHz: two Butterworth blocks of the engine per recording
    return model, {"a": rec(90, 1, "a"), "b": rec(70, 2, "b"), "loaded": rec(80, 4, "l", payload),
                   "valid": rec(40, 5, "v")}


def test_kinematics_blocks_are_the_assembly_signals(lwr4_recordings):
    model, rec = lwr4_recordings
    tr = rec["b"]
    asm = assemble(model, tr, AssemblyOptions())
    sg = asm.signals[0]
    covered = 0
    for a, b, q, dq, ddq in iter_kinematics(model, tr, AssemblyOptions(), sg.settings):
        assert a == covered
        covered = b
        for x, ref in ((q, sg.q), (dq, sg.dq), (ddq, sg.ddq)):
            assert np.array_equal(x, ref[a:b])
    assert covered == sg.n_samples
    streamed = stream_assembly(model, tr, AssemblyOptions())
    assert streamed.accumulator.n_rows == asm.system.Y.size
    assert streamed.metric_basis() == asm.metric_basis()
    assert 0 < streamed.sample.Y.size <= 2 * SAMPLE_ROWS * 7
    # the thinned copy for figures: every stride-th row of each joint of the whole system
    thin = stream_assembly(model, tr, AssemblyOptions(), sample_rows=50)
    assert thin.stride > 1
    for j in range(7):
        whole = asm.system.W[asm.system.joint == j]
        got = thin.sample.W[thin.sample.joint == j]
        ref = whole[::thin.stride]
        assert got.shape == ref.shape and np.allclose(got, ref, rtol=1e-9, atol=1e-12 * np.abs(whole).max())


@pytest.mark.slow
@pytest.mark.parametrize("case", ["ols", "wls", "tls", "payload", "essential"])
def test_streamed_identify_equals_the_in_memory_one(lwr4_recordings, monkeypatch, case):
    _, rec = lwr4_recordings
    kw: dict = {"method": case if case in ("ols", "tls") else "wls"}
    if case in ("ols", "wls", "tls"):
        kw["validate"] = [rec["valid"]]
    if case == "payload":
        kw.update(loaded=[rec["loaded"]], payload={"M8": 4.6})
    if case == "essential":
        kw["essential"] = True
    mem = _identify(False, monkeypatch, "lwr4", [rec["a"], rec["b"]], **kw)
    st = _identify(True, monkeypatch, "lwr4", [rec["a"], rec["b"]], **kw)
    assert isinstance(mem.assemblies["unloaded"].system, ObservationSystem)
    assert isinstance(st.assemblies["unloaded"].system, Accumulator)           # the streamed path ran
    _same_results(mem.to_dict(), st.to_dict())
    assert st.summary().splitlines()[0] == mem.summary().splitlines()[0]


# ---------------------------------------------------------------------------- real LWR4 recordings
LWR4_DIR = Path("kuka_lwr4_flobaroid") / "data" / "KUKA" / "HW"


@pytest.mark.slow
@pytest.mark.realdata
def test_streamed_identify_equals_the_in_memory_one_on_the_real_lwr4(shared_data, monkeypatch):
    paths = [shared_data / LWR4_DIR / f"measurements_{i}.npz" for i in (1, 2, 3)]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"LWR4 recordings not found: {missing}")
    data, valid = [str(paths[0]), str(paths[2])], [str(paths[1])]
    mem = _identify(False, monkeypatch, "lwr4", data, validate=valid, method="wls")
    st = _identify(True, monkeypatch, "lwr4", data, validate=valid, method="wls")
    _same_results(mem.to_dict(), st.to_dict())
