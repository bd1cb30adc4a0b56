"""The files of one split recording in different layouts: one-value-per-line dumps of different orders (each
order found from its own data: smoothness, or for a noisy file the levels of its joints) are each read in their
own order with a warning naming every file and its order; headers numbering the joints in different orders are
an error naming both files. What the files cannot tell (a noisy file whose joints share one level, headerless
columns in another order) is read as documented (docs/data-files.md, one value per line), pinned here."""
from __future__ import annotations

import warnings

import numpy as np
import pytest

from symoro_gen.errors import DataFileError
from symoro_gen.preprocessing.readers import DataWarning, LogFormat, read_recording
from symoro_gen.preprocessing.readers.split import LEVELS_NONE, LEVELS_TELL, SMOOTH_MAX, level_share, one_per_line

N_JOINTS = 4  # the SCARA
DT = 0.001
N = 3000


def _smooth(seed=0):
    """Smooth joint motions and torques (sums of sines, 0.2-1.6 Hz) sampled at 1 kHz."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    f = rng.uniform(0.2, 1.6, (2, N_JOINTS))
    ph = rng.uniform(0, 2 * np.pi, (2, N_JOINTS))
    return 0.5 * np.sin(2 * np.pi * f[0] * t[:, None] + ph[0]), 3.0 * np.sin(2 * np.pi * f[1] * t[:, None] + ph[1])


def _noisy(levels, seed=5, sigma=0.05):
    """Torques at a standstill: noise about one level per joint."""
    return np.asarray(levels, float) + sigma * np.random.default_rng(seed).normal(size=(N, N_JOINTS))


def _dump(path, m, order):
    np.savetxt(path, m.reshape(-1) if order == "sample-major" else m.T.reshape(-1), fmt="%.12g")
    return str(path)


def _read(spec, fmt=None):
    """Read, returning the trajectory, the report and the data warnings."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        (tr,), rep = read_recording(spec, fmt, n_joints=N_JOINTS)
    return tr, rep, [str(w.message) for w in caught if issubclass(w.category, DataWarning)]


def _layout_warning(ws):
    return [w for w in ws if "different layouts" in w]


@pytest.mark.parametrize("q_order, tau_order", [("joint-major", "sample-major"), ("sample-major", "joint-major")])
def test_smooth_dumps_of_different_orders_read_each_in_its_own_with_a_warning(tmp_path, q_order, tau_order):
    q, tau = _smooth()
    qf, tf = _dump(tmp_path / "q.txt", q, q_order), _dump(tmp_path / "tau.txt", tau, tau_order)
    tr, rep, ws = _read(f"q={qf},tau={tf},dt={DT}")
    np.testing.assert_allclose(tr.q, q, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(tr.tau, tau, rtol=1e-10, atol=1e-12)
    (w,) = _layout_warning(ws)
    assert f"{qf} (q) {q_order}, {tf} (tau) {tau_order}" in w and "--reshape" in w
    # a t= file repeating each stamp in one of the two layouts follows it
    t = np.arange(N) * DT
    tt = _dump(tmp_path / "t.txt", np.repeat(t[:, None], N_JOINTS, axis=1), tau_order)
    tr2, rep2, _ = _read(f"q={qf},tau={tf},t={tt}")
    np.testing.assert_allclose(tr2.t, t, atol=1e-12)
    assert any(f"stamp of each sample repeated for the 4 joints ({tau_order}" in x for x in rep2.notes)


@pytest.mark.parametrize("order", ["sample-major", "joint-major"])
def test_consistent_dumps_give_no_layout_warning(tmp_path, order):
    """The documented rule on files of one layout: no warning, whatever the order (smooth files, and a noisy file
    about distinct levels in the sample-major order of the positions)."""
    q, tau = _smooth(1)
    qf, tf = _dump(tmp_path / "q.txt", q, order), _dump(tmp_path / "tau.txt", tau, order)
    tr, _, ws = _read(f"q={qf},tau={tf},dt={DT}")
    assert not _layout_warning(ws) and np.allclose(tr.tau, tau)
    noisy = _noisy([0.5, 3.0, -1.0, 0.2])
    qs, ns = _dump(tmp_path / "qs.txt", q, "sample-major"), _dump(tmp_path / "ns.txt", noisy, "sample-major")
    tr, rep, ws = _read(f"q={qs},tau={ns},dt={DT}")
    assert not _layout_warning(ws)
    np.testing.assert_allclose(tr.tau, noisy, rtol=1e-10, atol=1e-12)
    assert any(f"{ns} (tau)" in x and "sample-major (as q=: its own data do not tell)" in x for x in rep.notes)


def test_a_noisy_dump_of_another_order_is_told_by_its_joints_levels(tmp_path):
    """Torques at a standstill (noise about one level per joint) tell no order by their smoothness; their levels
    do: in the order of the file the column means explain nearly all the variance, in the other nearly none.
    Written sample-major beside joint-major positions, the file is read sample-major (not in the positions'
    order), with the warning."""
    q, _ = _smooth(2)
    noisy = _noisy([0.5, 3.0, -1.0, 0.2])
    v_sm = noisy.reshape(-1)
    _, got, r = one_per_line(v_sm, N_JOINTS, None)
    assert got is None and min(r.values()) > SMOOTH_MAX          # smoothness does not tell
    assert level_share(noisy) > LEVELS_TELL and level_share(v_sm.reshape(N_JOINTS, N).T) < LEVELS_NONE
    qf, tf = _dump(tmp_path / "q.txt", q, "joint-major"), _dump(tmp_path / "tau.txt", noisy, "sample-major")
    tr, rep, ws = _read(f"q={qf},tau={tf},dt={DT}")
    np.testing.assert_allclose(tr.tau, noisy, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(tr.q, q, rtol=1e-10, atol=1e-12)
    assert any(f"{tf} (tau)" in x and "sample-major (found from the levels of its joints" in x
               and "not joint-major as q=" in x for x in rep.notes)
    (w,) = _layout_warning(ws)
    assert f"{qf} (q) joint-major, {tf} (tau) sample-major" in w


def test_what_the_files_cannot_tell_is_read_as_documented(tmp_path):
    """Pinned limitations: (1) a noisy dump whose joints share one level tells its order neither way: it is read
    in the positions' order, whatever its logger wrote (the note says so); (2) a noisy dump about distinct levels,
    joint-major like the positions, looks smooth read sample-major (each column then holds one joint after the
    other, whose distinct levels make the column's variance large beside its sample-to-sample noise): read so, with
    the layout warning, and --reshape reads it right; (3) headerless columns in another joint order are read in
    order."""
    q, _ = _smooth(3)
    same = _noisy([1.0] * N_JOINTS, seed=6)
    qf, tf = _dump(tmp_path / "q.txt", q, "joint-major"), _dump(tmp_path / "tau.txt", same, "sample-major")
    tr, rep, ws = _read(f"q={qf},tau={tf},dt={DT}")
    np.testing.assert_allclose(tr.tau, same.reshape(-1).reshape(N_JOINTS, N).T, rtol=1e-10, atol=1e-12)
    assert any("joint-major (as q=: its own data do not tell)" in x for x in rep.notes) and not _layout_warning(ws)
    levels = _noisy([0.5, 3.0, -1.0, 0.2], seed=7)
    lf = _dump(tmp_path / "lev.txt", levels, "joint-major")
    tr, rep, ws = _read(f"q={qf},tau={lf},dt={DT}")
    assert not np.allclose(tr.tau, levels)
    (w,) = _layout_warning(ws)
    assert f"{qf} (q) joint-major, {lf} (tau) sample-major" in w
    tr, _, ws = _read(f"q={qf},tau={lf},dt={DT}", LogFormat(reshape="joint-major"))
    np.testing.assert_allclose(tr.tau, levels, rtol=1e-10, atol=1e-12)
    assert not _layout_warning(ws)
    qc, tc = tmp_path / "qc.csv", tmp_path / "tc.csv"
    _, tau = _smooth(3)
    np.savetxt(qc, q, delimiter=",")
    np.savetxt(tc, tau[:, ::-1], delimiter=",")
    tr, _, ws = _read(f"q={qc},tau={tc},dt={DT}")
    np.testing.assert_allclose(tr.tau, tau[:, ::-1], rtol=1e-10, atol=1e-12)
    assert not _layout_warning(ws)


def test_headers_numbering_the_joints_in_different_orders_are_an_error(tmp_path):
    q, tau = _smooth(4)
    qf, tf = tmp_path / "q.csv", tmp_path / "tau.csv"
    np.savetxt(qf, q, delimiter=",", header="q1,q2,q3,q4", comments="")
    np.savetxt(tf, tau[:, ::-1], delimiter=",", header="tau4,tau3,tau2,tau1", comments="")
    with pytest.raises(DataFileError) as e:
        read_recording(f"q={qf},tau={tf},dt={DT}", n_joints=N_JOINTS)
    msg = str(e.value)
    assert f"{qf} (q): q1, q2, q3, q4; {tf} (tau): tau4, tau3, tau2, tau1" in msg
    assert "number the joints in different orders" in msg and "field 'q, tau'" in msg
    # the same order, numbered differently (0-based against 1-based, a suffix): read as it is
    np.savetxt(tf, tau, delimiter=",", header="tau_0_Nm,tau_1_Nm,tau_2_Nm,tau_3_Nm", comments="")
    tr, _, ws = _read(f"q={qf},tau={tf},dt={DT}")
    np.testing.assert_allclose(tr.tau, tau, rtol=1e-10, atol=1e-12)
    assert not ws
