"""The fused per-chunk kernel against the assembly's rows, and how a fleet reads its logs: data options
on Parquet (as on every format), the robot's drive chain applied in the workers, and the closed loop
(``diagnose``) on a flagged robot."""
from __future__ import annotations

import json

import numpy as np
import pytest

from symoro_gen import load_model
from symoro_gen.description import load_robot
from symoro_gen.fleet import Drift, FleetOptions, identify_fleet, open_client, read_log, simulate_fleet, write_parquet
from symoro_gen.fleet.fused import fold_trajectory
from symoro_gen.identification import fit_wls
from symoro_gen.identification.accumulate import accumulate
from symoro_gen.observations import AssemblyOptions, iter_chunks, observation_settings
from symoro_gen.observations.fused import (
    WELCH_SEGMENT,
    column_map,
    dynamics_bandwidth,
    filter_settings,
    fused_applies,
)
from symoro_gen.preprocessing.drive_chain import joint_to_motor
from symoro_gen.preprocessing.filtering import choose_filter_settings, estimate_dynamics_bandwidth
from symoro_gen.preprocessing.readers import make_format
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording

BY = "{robot}/{day}.parquet"


@pytest.fixture(scope="module")
def threads_client():
    with open_client("threads:2") as c:
        yield c


def _recording(robot: str, seconds: float, seed: int = 0) -> Trajectory:
    model = load_model(robot)
    rng = np.random.default_rng(seed)
    chi = random_physical_parameters(load_robot(robot), rng)
    mo = fourier_trajectory(model.N_JOINTS, seconds, 1e-3, rng, vmax=1.5, amax=8.0)
    return simulate_recording(model, mo.t, mo.q, mo.dq, mo.ddq, np.asarray(chi, float), noise_q=1e-5,
                              noise_tau=0.02, rng=rng, source=f"{robot}-sim")


def _gram_close(a, b, rtol):
    for Ra, Rb in zip(a.R, b.R):
        G, G1 = Ra.T @ Ra, Rb.T @ Rb
        assert np.max(np.abs(G - G1)) <= rtol * np.max(np.abs(G1))


@pytest.mark.parametrize("kw", [{}, {"batch_super_rows": 3, "outer_samples": 1000, "fold_rows": 50}])
def test_fused_kernel_gives_the_rows_of_the_assembly(kw):
    """Polyphase FIR with state across batches, distinct columns only, folds every few rows: the same factors
    as the assembly's blocked FIR (Gram matrices to 1e-12; estimates to 1e-12 cond(W)^2; sigma, a difference of close
    sums, to 1e-6), whatever the batch and block sizes (partial super-rows, batch borders, block borders)."""
    model = load_model("lwr4")
    tr = _recording("lwr4", 7.3)
    opts = AssemblyOptions(keep_signals=False)
    st = observation_settings(tr, opts)
    assert fused_applies(tr, st, opts) and st.n_d > 1
    ref = accumulate(iter_chunks(model, tr, opts, progress=False))
    got = fold_trajectory(model, tr, opts, **kw)
    assert got.rows == ref.rows and got.names == ref.names
    _gram_close(got, ref, 1e-12)
    fr, fg = fit_wls(ref), fit_wls(got)
    # first-order perturbation of the normal equations: relative error <= cond(G) x that of G (cond(G) = cond(W)^2)
    assert np.linalg.norm(fg.values - fr.values) <= 1e-12 * fr.cond ** 2 * np.linalg.norm(fr.values)
    assert np.linalg.norm(fg.std - fr.std) <= 1e-6 * np.linalg.norm(fr.std)


def test_compiled_helpers_and_numpy_scipy_give_identical_factors(monkeypatch):
    """The compiled helpers (row gather of the distinct columns, Butterworth sections with the channels
    together) and their fallbacks without a C compiler (``np.take``, SciPy's ``sosfiltfilt``) give the
    same numbers: bit-identical filtered positions and factors; and an accumulator given to fold into gets
    the merge of its rows and the new ones (same Gram matrix as both experiments folded at once)."""
    from symoro_gen.observations import fused
    from symoro_gen.preprocessing.filtering import lowpass_positions

    if fused.compiled_helpers() is None:
        pytest.skip("no C compiler here: only the NumPy/SciPy fallbacks can run")
    model = load_model("lwr4")
    tr = _recording("lwr4", 4.1, seed=3)
    opts = AssemblyOptions(keep_signals=False)
    for q in (tr.q, tr.q[:900, :3]):
        assert np.array_equal(fused._zero_phase_rows(q, 1000.0, 12.5, 4, "x"), lowpass_positions(q, 1000.0, 12.5, 4))
    assert fused._raw_regressor(model) is not None                # the generated C, called by address
    compiled = fold_trajectory(model, tr, opts)
    monkeypatch.setattr(fused, "_KERNELS", [None])
    monkeypatch.setattr(fused, "_raw_regressor", lambda m: None)  # model.regressor, its checked call
    numpy_copy = fold_trajectory(model, tr, opts)
    for a, b in zip(compiled.R, numpy_copy.R):
        assert np.array_equal(a, b)
    assert compiled.yy == numpy_copy.yy and compiled.rows == numpy_copy.rows
    tr2 = _recording("lwr4", 3.2, seed=4)
    both = fold_trajectory(model, tr2, opts, acc=compiled)
    ref = accumulate(list(iter_chunks(model, tr, opts, progress=False)) + list(iter_chunks(model, tr2, opts, progress=False)))
    assert both.rows == ref.rows
    _gram_close(both, ref, 1e-12)


def _long_log_checks(q: np.ndarray, fs: float) -> None:
    assert q.shape[0] > 2 * WELCH_SEGMENT                         # Welch's path, several segments
    for ef in (0.9, 0.99, 0.999, 0.9999):
        ref = estimate_dynamics_bandwidth(q, fs, energy_fraction=ef, min_bandwidth_hz=0.0)
        assert ref > 0 and dynamics_bandwidth(q, fs, energy_fraction=ef, min_bandwidth_hz=0.0) == ref, ef
    # a segment count that leaves a tail (the last half-segment of the log unused, as Welch's loop does)
    q2 = q[:q.shape[0] - WELCH_SEGMENT // 3]
    assert dynamics_bandwidth(q2, fs, min_bandwidth_hz=0.0) == estimate_dynamics_bandwidth(q2, fs, min_bandwidth_hz=0.0)


def test_filters_rule_on_long_logs_is_the_assemblys(monkeypatch):
    """The fleet's f_dyn (Welch's periodogram with per-half-segment sums, :func:`dynamics_bandwidth`; its
    compiled segment passes and their NumPy fallback) is ``estimate_dynamics_bandwidth``'s on a long
    simulated log (4 energy fractions, f_dyn above the resolution), and the filter settings are
    ``observation_settings``' (cut-off, n_d, notes), which are those of ``choose_filter_settings`` estimating
    f_dyn itself."""
    from symoro_gen.observations import fused

    rng = np.random.default_rng(5)
    mo = fourier_trajectory(7, 20.0, 1e-3, rng, vmax=1.5, amax=30.0)
    t = np.arange(200_000) * 1e-3
    q = mo.series.evaluate(t).q + rng.normal(0, 1e-5, (t.size, 7))
    _long_log_checks(q, 1000.0)
    with monkeypatch.context() as mp:
        mp.setattr(fused, "_KERNELS", [None])
        _long_log_checks(q, 1000.0)
    tr = Trajectory(t=t, q=q, tau=np.zeros_like(q), source="long")
    for opts in (AssemblyOptions(keep_signals=False), AssemblyOptions(keep_signals=False, energy_fraction=0.99),
                 AssemblyOptions(keep_signals=False, cutoff_hz=8.0)):
        st = filter_settings(tr, opts)
        assert st == observation_settings(tr, opts) and st.bandwidth_estimated
        assert st == choose_filter_settings(1.0 / tr.dt, tr.q, **opts.rule_keywords())


def test_filters_rule_on_a_long_real_log(shared_data):
    """The same on real positions: the three LWR4 recordings (FloBaRoID, 200 Hz), put end to end five times
    (a log longer than two Welch segments)."""
    d = shared_data / "kuka_lwr4_flobaroid" / "data" / "KUKA" / "HW"
    q = np.concatenate([np.load(d / f"measurements_{i}.npz")["positions"] for i in (1, 2, 3)] * 9)
    _long_log_checks(q, 200.0)


def test_fused_kernel_falls_back_to_the_assembly_for_other_options():
    """Options the fused kernel does not cover (IIR decimation, no decimation, low-velocity rows) give the
    assembly's own factors."""
    model = load_model("scara")
    tr = _recording("scara", 3.0, seed=1)
    for opts in (AssemblyOptions(keep_signals=False, ftype="iir"), AssemblyOptions(keep_signals=False, n_d=1),
                 AssemblyOptions(keep_signals=False, min_velocity=0.05)):
        assert not fused_applies(tr, observation_settings(tr, opts), opts)
        ref = accumulate(iter_chunks(model, tr, opts, progress=False))
        got = fold_trajectory(model, tr, opts)
        assert got.rows == ref.rows
        _gram_close(got, ref, 1e-14)


def test_column_map_reproduces_every_entry():
    """Distinct columns times their factor rebuild every non-zero entry of the regressor on new states."""
    model = load_model("lwr4")
    n, nb = 7, len(model.BASE_NAMES)
    cm = column_map(model, n, nb)
    rng = np.random.default_rng(99)
    q, dq, ddq = (rng.uniform(-3, 3, (40, n)) for _ in range(3))
    W = model.regressor(q, dq, ddq).reshape(40, n * nb)
    rebuilt = np.zeros_like(W)
    rebuilt[:, cm.entry] = W[:, cm.source][:, cm.column] * cm.scale
    assert np.allclose(rebuilt, W, rtol=1e-12, atol=1e-12 * np.abs(W).max())
    assert cm.source.size < cm.entry.size < n * nb


def test_parquet_logs_honour_the_data_options(tmp_path, threads_client, cli):
    """A Parquet log with its own column names, positions in degrees and torques as a scaled signal, read
    with --columns --deg --tau-scale (the options of every command that reads data), gives the numbers of
    the plain log. The SCARA's joint 3 is prismatic: --deg leaves it in metres, as identify reads it."""
    simulate_fleet(tmp_path / "plain", "scara", n_robots=2, n_days=1, duration=4.0, drifts=(), seed=4)
    pa = pytest.importorskip("pyarrow")
    import pyarrow.parquet as pq

    sigma = [j.sigma for j in load_robot("scara").model_joints]
    assert sigma == [0, 0, 1, 0]
    for r in ("r00", "r01"):
        tr = read_log(str(tmp_path / "plain" / r / "d00.parquet"), 4)
        cols = {"time": tr.t}
        cols.update({f"pos_{j}": np.rad2deg(tr.q[:, j]) if sigma[j] == 0 else tr.q[:, j] for j in range(4)})
        cols.update({f"cur_{j}": tr.tau[:, j] / 2.5 for j in range(4)})
        cols["temperature"] = np.full(tr.n_samples, 40.0)
        (tmp_path / "raw" / r).mkdir(parents=True)
        pq.write_table(pa.table(cols), tmp_path / "raw" / r / "d00.parquet")
    fmt = make_format(columns="t=time,q=pos_0:pos_3,tau=cur_0:cur_3", tau_scale="2.5", deg=True)
    plain = identify_fleet("scara", [tmp_path / "plain"], BY, client=threads_client)
    got = identify_fleet("scara", [tmp_path / "raw"], BY, FleetOptions(data_format=fmt), client=threads_client)
    assert not got.skipped
    for r in ("r00", "r01"):
        a, b = got.days[r]["d00"].values, plain.days[r]["d00"].values
        assert np.linalg.norm(a - b) <= 1e-8 * np.linalg.norm(b)
    assert got.settings["data_options"] and got.settings["segment_samples"] is None
    # the same from the command line; without the options the file's columns are not found: named, skipped
    out = tmp_path / "f.json"
    cli("fleet", "scara", tmp_path / "raw", "--by", BY, "--scheduler", "threads:1", "--json", out,
        "--columns", "t=time,q=pos_0:pos_3,tau=cur_0:cur_3", "--tau-scale", "2.5", "--deg")
    doc = json.loads(out.read_text())
    assert np.allclose(doc["robots"]["r01"]["days"]["d00"]["values"], plain.days["r01"]["d00"].values, rtol=1e-8,
                       atol=1e-10)
    with pytest.raises(Exception, match="no log could be used"):
        identify_fleet("scara", [tmp_path / "raw"], BY, client=threads_client)


def test_mm_converts_the_prismatic_joint_as_identify_does(tmp_path, threads_client, cli):
    """A SCARA log whose prismatic joint 3 is in millimetres: the fleet with --mm gives the plain log's numbers
    and identify's on the same file with the same option (the workers convert the joints the robot file says
    are prismatic); without --mm the numbers are others."""
    simulate_fleet(tmp_path / "plain", "scara", n_robots=1, n_days=1, duration=4.0, drifts=(), seed=5)
    (tmp_path / "mm" / "r00").mkdir(parents=True)
    tr = read_log(str(tmp_path / "plain" / "r00" / "d00.parquet"), 4)
    q = tr.q.copy()
    q[:, 2] *= 1000.0
    write_parquet(tmp_path / "mm" / "r00" / "d00.parquet", Trajectory(t=tr.t, q=q, tau=tr.tau, source="mm"))
    plain = identify_fleet("scara", [tmp_path / "plain"], BY, client=threads_client).days["r00"]["d00"]
    got = identify_fleet("scara", [tmp_path / "mm"], BY, FleetOptions(data_format=make_format(mm=True)),
                         client=threads_client).days["r00"]["d00"]
    assert np.linalg.norm(got.values - plain.values) <= 1e-8 * np.linalg.norm(plain.values)
    raw = identify_fleet("scara", [tmp_path / "mm"], BY, client=threads_client).days["r00"]["d00"]
    assert np.linalg.norm(raw.values - plain.values) > 1e-3 * np.linalg.norm(plain.values)
    out = tmp_path / "id.json"
    cli("identify", "scara", tmp_path / "mm" / "r00" / "d00.parquet", "--mm", "--method", "wls", "--json", out)
    ident = json.loads(out.read_text())["parameters"]
    by_name = dict(zip(ident["names"], ident["values"]))
    mine = np.array([by_name[nm] for nm in got.names])
    assert np.linalg.norm(got.values - mine) <= 1e-8 * np.linalg.norm(mine)


def test_motor_side_logs_go_through_the_robots_drive_chain(tmp_path, threads_client):
    """TX40 logs recorded on the motor side (its robot file's [drive_chain]): the workers map them to the
    joint side with the function identify uses, giving the numbers of the joint-side logs."""
    chain = load_robot("tx40").drive_chain
    assert chain is not None
    for r in ("r00", "r01"):
        tr = _recording("tx40", 4.0, seed=int(r[-1]) + 10)
        write_parquet(tmp_path / "joint" / r / "d00.parquet", tr)
        qm, taum = joint_to_motor(chain, tr.q, tr.tau)[:2]
        write_parquet(tmp_path / "motor" / r / "d00.parquet", Trajectory(t=tr.t, q=qm, tau=taum, source="motor"))
    joint = identify_fleet("tx40", [tmp_path / "joint"], BY, client=threads_client,
                           load_kw={"drive_chain": None})
    motor = identify_fleet("tx40", [tmp_path / "motor"], BY, client=threads_client)
    assert motor.settings["drive_chain"] and not joint.settings["drive_chain"]
    for r in ("r00", "r01"):
        a, b = motor.days[r]["d00"].values, joint.days[r]["d00"].values
        assert np.linalg.norm(a - b) <= 1e-8 * np.linalg.norm(b)
    # read without the chain, the same motor-side logs give other (wrong) numbers
    raw = identify_fleet("tx40", [tmp_path / "motor"], BY, client=threads_client, load_kw={"drive_chain": None})
    assert np.linalg.norm(raw.days["r00"]["d00"].values - joint.days["r00"]["d00"].values) > 0.1 * np.linalg.norm(
        joint.days["r00"]["d00"].values)


def test_diagnose_closes_the_loop_on_the_flagged_robot(tmp_path, threads_client):
    """--diagnose runs the public diagnose() on the flagged robot's last flagged day only; its summary and
    JSON report are in the result, the JSON and the text."""
    simulate_fleet(tmp_path, "scara", n_robots=4, n_days=3, duration=6.0, drifts=(Drift("r02", "FS2", 0.2),),
                   seed=2)
    res = identify_fleet("scara", [tmp_path], BY, FleetOptions(diagnose=True), client=threads_client)
    assert "r02" in {f["robot"] for f in res.flagged}
    assert set(res.diagnoses) == {f["robot"] for f in res.flagged}          # one diagnosis per flagged robot
    d = res.diagnoses["r02"]
    assert "error" not in d, d.get("error")
    assert d["day"] == sorted(next(f for f in res.flagged if f["robot"] == "r02")["days"])[-1]
    assert d["files"] == [str(tmp_path / "r02" / f"{d['day']}.parquet")]
    assert isinstance(d["summary"], str) and d["summary"]
    assert {"before", "after", "effects"} <= set(d["report"])
    doc = json.loads(json.dumps(res.to_dict()))
    assert doc["diagnoses"]["r02"]["day"] == d["day"]
    assert "diagnosis of r02" in res.summary()


def test_every_qr_fold_and_merge_runs_on_one_blas_thread(monkeypatch):
    """The kernel's LAPACK folds, the last one (``result()``) included, and the TSQR merges run with one
    OpenBLAS thread even in a process whose OpenBLAS has more (a ``threads:N`` client, the CLI: outside
    Dask's nanny, which sets OPENBLAS_NUM_THREADS=1); multi-threaded, each 2k-row dgeqrf cost ~0.4 s CPU on
    this 2-core machine against 0.004 s. The process's own setting is restored afterwards."""
    from symoro_gen.fleet import fused, kernel
    from symoro_gen.preprocessing import filtering

    controls = filtering._openblas_thread_controls()
    if not controls:
        pytest.skip("no OpenBLAS thread control in this process")
    get, set_ = controls[0]
    before = get()
    seen: list[int] = []
    fold, qr = fused._Folder._fold, np.linalg.qr

    def spy_fold(self):
        seen.append(get())
        return fold(self)

    def spy_qr(*a, **k):
        seen.append(get())
        return qr(*a, **k)

    model = load_model("scara")
    tr = _recording("scara", 3.0, seed=2)
    monkeypatch.setattr(fused._Folder, "_fold", spy_fold)
    monkeypatch.setattr(kernel.np.linalg, "qr", spy_qr)
    set_(2)
    try:
        a = fold_trajectory(model, tr, AssemblyOptions(keep_signals=False))
        kernel.merge_partials(kernel.Partial(("a",), a, 1), kernel.Partial(("b",), a, 1))
        assert get() == 2
    finally:
        set_(before)
    assert len(seen) >= 2 and set(seen) == {1}, seen


def test_positions_not_c_ordered_give_the_same_factors():
    """A log whose positions are not C-ordered (a CSV read column by column) gives the factors of the same
    log C-ordered: the compiled Butterworth sections read rows (before the engine they read the Fortran-ordered
    buffer as rows and the estimates were hundreds of sigma off)."""
    model = load_model("scara")
    tr = _recording("scara", 4.0, seed=21)
    trF = Trajectory(t=tr.t, q=np.asfortranarray(tr.q), tau=np.asfortranarray(tr.tau), source="F")
    assert not trF.q.flags.c_contiguous
    a = fold_trajectory(model, tr, AssemblyOptions(keep_signals=False))
    b = fold_trajectory(model, trF, AssemblyOptions(keep_signals=False))
    for Ra, Rb in zip(a.R, b.R):
        assert np.array_equal(Ra, Rb)
