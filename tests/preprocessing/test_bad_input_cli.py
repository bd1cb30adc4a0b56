"""Damaged and unusual files as users bring them, through the command line: a header without data, a trailing
delimiter on every line, quoted header names, positions in degrees behind a ``--columns`` mapping, and an
export pointed at a result file that is missing or is not JSON. Each refusal names the file (and the line or
column); each file that is only unusual is read to the same numbers as its plain form."""
from __future__ import annotations

import importlib
import warnings
from pathlib import Path

import numpy as np
import pytest

from symoro_gen.preprocessing.readers import DataWarning, load_trajectory, make_format, read_recording

N_J = 4  # the SCARA
DT = 0.002


def _signals(N=400, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(N) * DT
    f = rng.uniform(0.3, 1.5, (2, N_J))
    q = 0.6 * np.sin(2 * np.pi * f[0] * t[:, None] + rng.uniform(0, 6, N_J))
    q[:, 2] *= 0.1  # joint 3 of the SCARA is prismatic: metres
    tau = 2.0 * np.sin(2 * np.pi * f[1] * t[:, None]) + 0.3
    return t, q, tau


def _header(prefix_q="q", prefix_tau="tau", first=1):
    return ["t"] + [f"{prefix_q}{j}" for j in range(first, first + N_J)] + \
        [f"{prefix_tau}{j}" for j in range(first, first + N_J)]


def _write(path, names, data, delim=",", line_end=""):
    lines = [delim.join(names) + line_end] + [delim.join(f"{x:.12g}" for x in row) + line_end for row in data]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


# ---- a header and no data ----------------------------------------------------------------------------------
@pytest.mark.parametrize("options", [[], ["--drop-bad-rows"]])
def test_header_without_data_is_named_as_such(cli, tmp_path, options):
    """A log whose recording never started (the header line alone, or a header and comment lines) is refused
    saying that it has no data rows, naming the file and the header line, not as an empty row range."""
    f = tmp_path / "run.csv"
    f.write_text(",".join(_header()) + "\n# logger stopped\n\n")
    r = cli("inspect", "scara", f, *options, rc=2)
    assert f"{f}" in r.err and "no data rows" in r.err and "line 1" in r.err
    assert "rows 1-0" not in r.err and "Traceback" not in r.err


def test_header_without_data_in_a_split_recording(cli, tmp_path):
    q = tmp_path / "q.csv"
    q.write_text("J1,J2,J3,J4\n")
    tau = tmp_path / "tau.csv"
    tau.write_text("J1,J2,J3,J4\n" + "\n".join("1,2,3,4" for _ in range(100)) + "\n")
    r = cli("inspect", "scara", f"q={q},tau={tau},dt=0.01", rc=2)
    assert f"{q}" in r.err and "no data rows" in r.err
    assert "rows 1-0" not in r.err


# ---- a trailing delimiter, quoted names ----------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["trailing", "quoted", "trailing-crlf"])
def test_trailing_delimiter_and_quoted_names_read_as_the_plain_file(tmp_path, kind):
    """Loggers that end every line with the delimiter (``1,2,3,``), and spreadsheets that quote the header
    names (``"t","q1",...``, RFC 4180): the same numbers as the plain file, every column by its own name."""
    t, q, tau = _signals()
    data = np.column_stack([t, q, tau])
    plain = _write(tmp_path / "plain.csv", _header(), data)
    if kind == "quoted":
        other = _write(tmp_path / "other.csv", [f'"{n}"' for n in _header()], data)
    else:
        other = _write(tmp_path / "other.csv", _header(), data, line_end="," + ("\r" if "crlf" in kind else ""))
    ref = load_trajectory(plain, n_joints=N_J)
    got = load_trajectory(other, n_joints=N_J)
    for a in ("t", "q", "tau"):
        np.testing.assert_array_equal(getattr(got, a), getattr(ref, a))
    assert got.meta["columns"] == ref.meta["columns"]
    (tr,), rep = read_recording(other, make_format(columns="t=t,q=q1:q4,tau=tau1:tau4"), n_joints=N_J)
    np.testing.assert_array_equal(tr.q, ref.q)
    assert rep.rows_dropped == 0


def test_an_empty_column_that_is_not_trailing_is_still_an_error(cli, tmp_path):
    """Only the column that every line leaves empty after its last delimiter is a trailing delimiter; an
    empty cell elsewhere stays an error naming its row and column."""
    t, q, tau = _signals()
    data = np.column_stack([t, q, tau])
    f = _write(tmp_path / "holes.csv", _header(), data, line_end=",")
    lines = (tmp_path / "holes.csv").read_text().split("\n")
    cells = lines[10].split(",")
    cells[3] = ""  # q3 of data row 9
    lines[10] = ",".join(cells)
    (tmp_path / "holes.csv").write_text("\n".join(lines))
    r = cli("inspect", "scara", f, rc=2)
    assert "row" in r.err and "(lines 11)" in r.err and "'q3'" in r.err


# ---- unit warnings name the file's own column ----------------------------------------------------------------
def test_degrees_warning_names_the_mapped_column(cli, tmp_path):
    """With ``--columns q=pos_0:pos_3`` the warning about positions in degrees names the file's column
    (``pos_0``) and the joint, not a ``q1`` the file does not have."""
    t, q, tau = _signals()
    deg = q.copy()
    deg[:, [0, 1, 3]] = np.degrees(deg[:, [0, 1, 3]]) * 20  # beyond 4 pi even for small motions
    names = ["time"] + [f"pos_{j}" for j in range(N_J)] + [f"trq_{j}" for j in range(N_J)]
    f = _write(tmp_path / "log.csv", names, np.column_stack([t, deg, tau]))
    with pytest.warns(DataWarning) as rec:
        cli("inspect", "scara", f, "--columns", "t=time,q=pos_0:pos_3,tau=trq_0:trq_3")
    warns = [str(w.message) for w in rec if "degrees" in str(w.message)]
    assert len(warns) == 3, warns
    for j, w in zip((0, 1, 3), warns):
        assert w.startswith(f"{f}, column pos_{j} (joint {j + 1}): max |q|")
    assert not any("column q1" in w for w in warns)


def test_degrees_warning_of_the_plain_header_unchanged(cli, tmp_path):
    t, q, tau = _signals()
    deg = q.copy()
    deg[:, 0] = np.degrees(deg[:, 0]) * 20
    f = _write(tmp_path / "deg.csv", _header(), np.column_stack([t, deg, tau]))
    with pytest.warns(DataWarning, match=rf"{f}, column q1: max \|q\|"):
        cli("inspect", "scara", f)


# ---- an export pointed at a result that is not one -----------------------------------------------------------
@pytest.mark.parametrize("what", ["missing", "text", "folder"])
def test_export_from_a_missing_or_non_json_result(cli, tmp_path, what):
    """``export-urdf --from`` a path that does not exist, a text file or a folder: the error says which, names
    the file, and the hint is about the identify result, not about generating the model."""
    src = tmp_path / "result.json"
    if what == "text":
        src.write_text("IDIM-WLS identification: 10 equations\n")
    elif what == "folder":
        src.mkdir()
    for cmd in (["export-urdf", "scara", "--from", src], ["export-urdf", "scara", "--params", src],
                ["export-mjcf", "scara", "--from", src]):
        r = cli(*cmd, "-o", tmp_path / "out.xml", rc=2)
        first = r.err_lines[0]
        assert f"{src}" in first
        expected = {"missing": "file not found", "text": "not JSON (line 1", "folder": "a folder"}[what]
        assert expected in first, r.err
        assert "Errno" not in r.err and "generate" not in r.err_lines[1]
        assert "identify" in r.err_lines[1]
        assert not (tmp_path / "out.xml").exists()


# ---- a --reference table that is not one ---------------------------------------------------------------------
def _scara_recording(tmp_path):
    from symoro_gen import load_model
    from symoro_gen.description import load_robot
    from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording

    rng = np.random.default_rng(3)
    robot, model = load_robot("scara"), load_model("scara")
    t, q, dq, ddq = fourier_trajectory(N_J, 4.0, DT, rng)
    rec = simulate_recording(model, t, q, dq, ddq, np.asarray(random_physical_parameters(robot, rng)),
                             noise_tau=0.01, rng=rng)
    return _write(tmp_path / "rec.csv", _header(), np.column_stack([rec.t, rec.q, rec.tau]))


@pytest.mark.parametrize("what", ["empty", "bad-number", "missing", "folder"])
def test_a_bad_reference_table_is_refused_before_the_identification(cli, tmp_path, monkeypatch, what):
    """``identify --reference`` a table that is empty, has a non-numeric estimate, does not exist or is a
    folder: refused naming the file (and the line), with a hint about the table, before anything is fitted
    (an empty table used to print nothing at all)."""
    wf = importlib.import_module("symoro_gen.workflows.identify")  # the module (the package exports a function)
    rec = _scara_recording(tmp_path)
    ref = tmp_path / "ref.csv"
    if what == "empty":
        ref.write_text("\n")
    elif what == "bad-number":
        ref.write_text("ZZ1R,1.25,0.98\nfv1,8.1O,0.51\n")
    elif what == "folder":
        ref.mkdir()

    def no_fit(*a, **k):
        raise AssertionError("the identification ran before the reference table was read")

    monkeypatch.setattr(wf, "fit", no_fit)
    r = cli("identify", "scara", rec, "--method", "ols", "--reference", ref, rc=2)
    first, hint = r.err_lines[0], r.err_lines[1]
    assert f"{ref}" in first
    expected = {"empty": "no rows", "bad-number": "line 2", "missing": "file not found", "folder": "a folder"}[what]
    assert expected in first, r.err
    assert "reference" in hint and "CSV with header t,q1" not in hint


def test_a_good_reference_table_is_compared(cli, tmp_path):
    """The same table, well formed: every row beside our estimate (the check above does not refuse it)."""
    rec = _scara_recording(tmp_path)
    ref = tmp_path / "ref.csv"
    ref.write_text("Izz1 + Ia1 + ...,1.25,0.98\nfv1,8.1,0.51\nnot a parameter,3.0,1.0\n")
    r = cli("identify", "scara", rec, "--method", "ols", "--reference", ref)
    assert f"Beside the reference table {ref}" in r.out
    assert "of 2 comparable parameters agree within 2 sigma" in r.out


# ---- an output pointed at a folder ---------------------------------------------------------------------------
@pytest.mark.parametrize("force", [False, True])
def test_a_file_output_pointed_at_a_folder_is_refused_before_any_work(cli, tmp_path, force):
    """``--json DIR``, ``--report DIR``, ``-o DIR``: a file output never replaces a folder, with or without
    ``--force``, and this is said before any work (nothing printed on stdout, the folder left as it was),
    not as an OS error once the work is done."""
    t, q, tau = _signals()
    rec = _write(tmp_path / "rec.csv", _header(), np.column_stack([t, q, tau]))
    folder = tmp_path / "out"
    folder.mkdir()
    (folder / "keep.txt").write_text("mine\n")
    extra = ["--force"] if force else []
    for cmd in (["inspect", "scara", rec, "--json", folder], ["inspect", "scara", rec, "--report", folder],
                ["export-par", "scara", "-o", folder], ["import-urdf", tmp_path / "none.urdf", "-o", folder]):
        r = cli(*cmd, *extra, rc=2)
        assert r.out == "", r.out
        assert f"{folder}: a folder exists there" in r.err_lines[0], r.err
        assert "--force" not in r.err_lines[1]
        assert sorted(p.name for p in folder.iterdir()) == ["keep.txt"]


# ---- a bad row dropped from a recording timed by --dt ----------------------------------------------------------
def _no_time_with_a_hole(tmp_path, row=150):
    """A 500 Hz log without a time column (the LBR Med's layout) whose data row ``row`` (1-based) has a NaN."""
    t, q, tau = _signals()
    names = [f"q_{j}" for j in range(N_J)] + [f"tau_{j}" for j in range(N_J)]
    f = _write(tmp_path / "log.csv", names, np.column_stack([q, tau]))
    lines = (tmp_path / "log.csv").read_text().split("\n")
    cells = lines[row].split(",")
    cells[5] = "nan"  # tau_1 of data row `row` (file line row + 1)
    lines[row] = ",".join(cells)
    (tmp_path / "log.csv").write_text("\n".join(lines))
    return f, t, q, tau


def test_dropping_a_row_of_a_dt_timed_log_keeps_the_later_samples_at_their_times(cli, tmp_path):
    """Without a time column the time of data row k is (k - 1) dt. Dropping a bad row must not pull every
    later sample one step earlier (a silent shift and a doubled step in the derivatives): without --resample
    the hole is an error naming the row, as a gap in a time column is; with it the row is interpolated and
    every other sample keeps its own value at its own time."""
    f, t, q, tau = _no_time_with_a_hole(tmp_path, row=150)
    cols = "q=q_0:q_3,tau=tau_0:tau_3"
    r = cli("inspect", "scara", f, "--columns", cols, "--dt", DT, "--drop-bad-rows", rc=2)
    assert f"{f}, rows 150 (lines 151)" in r.err_lines[0] and "dropped" in r.err_lines[0], r.err
    assert "--resample" in r.err
    (tr,), rep = read_recording(f, make_format(columns=cols, dt=DT, drop_bad_rows=True, resample=True),
                                n_joints=N_J)
    m = tr.n_samples  # the resampling grid may stop one rounding short of the last stamp
    assert rep.rows_dropped == 1 and m in (t.size - 1, t.size)
    np.testing.assert_allclose(tr.t, t[:m] - t[0], atol=1e-12)
    keep = np.arange(m) != 149
    np.testing.assert_allclose(tr.q[keep], q[:m][keep], rtol=0, atol=1e-9)
    np.testing.assert_allclose(tr.tau[keep], tau[:m][keep], rtol=0, atol=1e-9)
    assert abs(tr.q[149] - q[149]).max() < 1e-4  # cubic through smooth neighbours


def test_dropping_leading_rows_of_a_dt_timed_log_needs_no_resampling(tmp_path):
    """Bad rows at the very start (a logger's first, half-written row) leave no hole: the rest is read."""
    f, t, q, tau = _no_time_with_a_hole(tmp_path, row=1)
    (tr,), rep = read_recording(f, make_format(columns="q=q_0:q_3,tau=tau_0:tau_3", dt=DT, drop_bad_rows=True),
                                n_joints=N_J)
    assert rep.rows_dropped == 1 and tr.n_samples == t.size - 1
    np.testing.assert_allclose(tr.q, q[1:], atol=1e-9)
    np.testing.assert_allclose(np.diff(tr.t), DT, rtol=1e-9)


@pytest.mark.parametrize("force", [False, True])
def test_a_folder_output_pointed_at_a_file_is_refused_before_any_work(cli, tmp_path, monkeypatch, force):
    """``diagnose --plots FILE`` and a Markdown report whose image folder is a file: refused before the
    diagnosis runs (it used to fail with 'cannot write FILE: File exists' once the loop was done), the file
    left as it was."""
    wf = importlib.import_module("symoro_gen.workflows.diagnose")

    def no_run(*a, **k):
        raise AssertionError("the diagnosis ran before the outputs were checked")

    monkeypatch.setattr(wf, "run_loop", no_run)
    t, q, tau = _signals()
    rec = _write(tmp_path / "rec.csv", _header(), np.column_stack([t, q, tau]))
    notes = tmp_path / "notes.txt"
    notes.write_text("mine\n")
    extra = ["--force"] if force else []
    r = cli("diagnose", "scara", rec, "--plots", notes, *extra, rc=2)
    assert r.out == "" and f"--plots {notes}: a file exists there" in r.err_lines[0], r.err
    (tmp_path / "rep_files").write_text("mine\n")
    r = cli("inspect", "scara", rec, "--report", tmp_path / "rep.md", *extra, rc=2)
    assert r.out == "" and f"{tmp_path / 'rep_files'}: a file exists there" in r.err_lines[0], r.err
    assert notes.read_text() == "mine\n" and (tmp_path / "rep_files").read_text() == "mine\n"


# ---- a torque column that holds no measurement ----------------------------------------------------------------
def test_a_constant_torque_column_is_warned_about_by_identify(cli, tmp_path):
    """A torque column that never changes (a channel the logger did not record: zeros) is no measured torque:
    ``identify`` used to fit it silently (estimates 0, error norms nan, no word about the column); it now
    warns, naming the file, the joint and the file's column. A measured torque, even small, is not flagged."""
    rec = _scara_recording(tmp_path)
    a = np.loadtxt(rec, delimiter=",", skiprows=1)
    a[:, 1 + N_J + 2] = 0.0  # tau3
    names = ["t"] + [f"q{j}" for j in range(1, N_J + 1)] + [f"trq{j}" for j in range(1, N_J + 1)]
    f = _write(tmp_path / "zero.csv", names, a)
    with pytest.warns(DataWarning) as got:
        cli("identify", "scara", f, "--method", "ols", "--columns", "t=t,q=q1:q4,tau=trq1:trq4")
    msgs = [str(w.message) for w in got if "constant" in str(w.message)]
    assert len(msgs) == 1, [str(w.message) for w in got]
    assert msgs[0].startswith(f"{f}: the torque of joint 3 (column trq3) is constant (0 in every sample)")
    with warnings.catch_warnings(record=True) as clean:
        warnings.simplefilter("always")
        cli("identify", "scara", rec, "--method", "ols")
    assert not [w for w in clean if "constant" in str(w.message)]


def test_med7_recording_with_a_nan_row_keeps_its_time_base(shared_data, tmp_path):
    """The LBR Med 7 log (100 Hz, no time column) with one torque cell made NaN, as a logger drops a packet:
    with --drop-bad-rows --resample every other sample is read at its own time with its own values (the
    recording as shipped is the reference), and the hole is refused without --resample."""
    src = shared_data / "kuka_lbr_med7_lbrstack" / "data" / "measurements.csv"
    if not src.is_file():
        pytest.skip(f"{src} absent")
    lines = src.read_text().split("\n")
    cells = lines[801].split(",")
    cells[9] = "NaN"  # tau_2 of data row 801
    lines[801] = ",".join(cells)
    bad = tmp_path / "measurements.csv"
    bad.write_text("\n".join(lines))
    cols = "q=q_0:q_6,tau=tau_0:tau_6"
    (ref,), _ = read_recording(str(src), make_format(columns=cols, dt=0.01), n_joints=7)
    with pytest.raises(Exception, match=r"rows 801 \(lines 802\), field 't': 1 row\(s\) dropped"):
        read_recording(str(bad), make_format(columns=cols, dt=0.01, drop_bad_rows=True), n_joints=7)
    (tr,), rep = read_recording(str(bad), make_format(columns=cols, dt=0.01, drop_bad_rows=True, resample=True),
                                n_joints=7)
    m = tr.n_samples
    assert rep.rows_dropped == 1 and m >= ref.n_samples - 1
    keep = np.arange(m) != 800
    np.testing.assert_allclose(tr.t, ref.t[:m], atol=1e-9)
    np.testing.assert_allclose(tr.q[keep], ref.q[:m][keep], atol=1e-9)
    np.testing.assert_allclose(tr.tau[keep], ref.tau[:m][keep], atol=1e-9)


# ---- a clock coarser than the sampling --------------------------------------------------------------------------
@pytest.mark.parametrize("options", [[], ["--resample"]])
def test_repeated_time_stamps_get_the_hint_that_fixes_them(cli, tmp_path, options):
    """A 500 Hz log stamped by a 4 ms clock (each stamp twice, none going back) is not a clock that restarts:
    the hint names the repeated stamps and the option that reads the file (--dt at the sampling period with
    --dt-overrides-time), with the period estimated from the file; following it reads every row."""
    t, q, tau = _signals(N=600)
    stamps = np.floor(t / (2 * DT) + 1e-9) * (2 * DT)
    f = _write(tmp_path / "coarse.csv", _header(), np.column_stack([stamps, q, tau]))
    r = cli("inspect", "scara", f, *options, rc=2)
    hint = r.err_lines[-1]
    assert "restarts" not in hint and "repeated" in hint and "--dt-overrides-time" in hint, r.err
    assert "--dt 0.002 " in hint, hint
    (tr,), rep = read_recording(f, make_format(dt=DT, dt_overrides_time=True), n_joints=N_J)
    assert tr.n_samples == t.size
    np.testing.assert_allclose(tr.q, q, atol=1e-9)


def test_an_npz_member_of_python_objects_is_named(cli, tmp_path):
    """An ``.npz`` whose torque array was saved as Python objects (a list of arrays, a dict): the error names the
    file and that array (never loaded: unpickling runs code), not 'an archive without readable members'."""
    t, q, tau = _signals()
    f = tmp_path / "obj.npz"
    np.savez(f, t=t, q=q, tau=np.array([tau, tau[:-1]], dtype=object))
    r = cli("inspect", "scara", f, rc=2)
    assert f"{f}, field 'tau': " in r.err_lines[0] and "Python objects" in r.err_lines[0], r.err
    assert "allow_pickle" not in r.err


# ---- one recording given twice ---------------------------------------------------------------------------------
def test_a_recording_given_twice_is_refused_and_validation_on_it_warned(cli, tmp_path):
    """``identify ROBOT a.csv ./a.csv`` (a shell glob and the name typed again) counts every equation twice: the
    standard deviations come out sqrt(2) too small, silently. Refused before any work, naming both spellings;
    a split recording is the same when its q file is. ``--validate`` on an identification file is no held-out
    validation: warned, naming the file."""
    rec = _scara_recording(tmp_path)
    other = tmp_path / "sub"
    other.mkdir()
    alias = other / ".." / "rec.csv"
    for cmd in ("identify", "diagnose", "inspect"):
        r = cli(cmd, "scara", rec, alias, rc=2)
        assert r.out == "" and "given twice" in r.err_lines[0] and str(alias) in r.err_lines[0], r.err
    r = cli("identify", "scara", rec, "--loaded", alias, rc=2)
    assert "given twice" in r.err_lines[0]
    a = np.loadtxt(rec, delimiter=",", skiprows=1)
    np.savetxt(tmp_path / "q.csv", a[:, 1:1 + N_J], delimiter=",")
    np.savetxt(tmp_path / "tau.csv", a[:, 1 + N_J:], delimiter=",")
    spec = f"q={tmp_path / 'q.csv'},tau={tmp_path / 'tau.csv'},dt={DT}"
    r = cli("identify", "scara", spec, spec.replace(",dt=", ",fs=").replace(f"{DT}", f"{1 / DT:g}"), rc=2)
    assert "given twice" in r.err_lines[0]
    with pytest.warns(DataWarning, match=r"validation recording .*rec\.csv is also an identification recording"):
        r = cli("identify", "scara", rec, "--method", "ols", "--validate", alias)
    # two different recordings are fine, and so are two split recordings sharing a t= file
    np.savetxt(tmp_path / "t.csv", a[:, 0], delimiter=",")
    half = tmp_path / "q2.csv"
    np.savetxt(half, a[:, 1:1 + N_J], delimiter=",")
    cli("identify", "scara", f"q={tmp_path / 'q.csv'},tau={tmp_path / 'tau.csv'},t={tmp_path / 't.csv'}",
        f"q={half},tau={tmp_path / 'tau.csv'},t={tmp_path / 't.csv'}", "--method", "ols")


def test_a_recording_given_twice_from_python_is_refused(tmp_path):
    """The library calls refuse a recording given twice as the commands do (a path and another spelling of it,
    one in-memory recording listed twice, a file among the identification and the loaded data), before reading
    it; two distinct recordings with the same samples are two experiments; validation on an identification
    recording is warned about."""
    import symoro_gen
    from symoro_gen.errors import OptionError

    rec = _scara_recording(tmp_path)
    (tmp_path / "sub").mkdir()
    alias = tmp_path / "sub" / ".." / "rec.csv"
    for call in (symoro_gen.identify, symoro_gen.diagnose, symoro_gen.inspect):
        with pytest.raises(OptionError, match="given twice") as exc:
            call("scara", [rec, alias])
        assert str(alias) in str(exc.value)
    (tr,), _ = read_recording(rec, n_joints=N_J)
    with pytest.raises(OptionError, match=r"identification data item 2 \(in memory\): that recording is given twice"):
        symoro_gen.identify("scara", [tr, tr], method="ols")
    with pytest.raises(OptionError, match=r"loaded data .*given twice"):
        symoro_gen.identify("scara", rec, loaded=alias, method="ols")
    copy = tmp_path / "copy.csv"
    copy.write_bytes(Path(rec).read_bytes())
    symoro_gen.identify("scara", [rec, copy], method="ols")      # two files: two experiments, as given (no error)
    with pytest.warns(DataWarning, match=r"validation recording .*rec\.csv is also an identification recording"):
        symoro_gen.identify("scara", rec, validate=alias, method="ols")


@pytest.mark.parametrize("header, named", [("t,q1,q1,q3,q4,tau1,tau2,tau3,tau4", "q1 (columns 2 and 3)"),
                                           ("t,q1,q2,q2,q3,q4,tau1,tau2,tau3,tau4", "q2 (columns 3 and 4)")])
def test_a_header_naming_a_joint_twice_is_refused_naming_both_columns(cli, tmp_path, header, named):
    """``q1,q1``: was reported as 'missing q2'; ``q2,q2`` beside q1..q4: one of the two was read, silently. Either
    way the file cannot say which column is the joint's: an error naming the name and both columns."""
    width = header.count(",") + 1
    rows = np.column_stack([np.arange(50) * DT] + [np.zeros(50)] * (width - 1))
    f = _write(tmp_path / "dup.csv", header.split(","), rows)
    r = cli("inspect", "scara", f, rc=2)
    assert "names a q column twice" in r.err and named in r.err and "dup.csv" in r.err, r.err


def test_an_unknown_format_lists_every_suffix_the_readers_read(cli, tmp_path):
    """The unknown-format error lists every suffix a reader takes (it omitted .tsv, .dat and .pq)."""
    from symoro_gen.preprocessing.readers.arrays import ARRAY_SUFFIXES
    from symoro_gen.preprocessing.readers.bag import BAG_SUFFIXES
    from symoro_gen.preprocessing.readers.parquet import PARQUET_SUFFIXES
    from symoro_gen.preprocessing.readers.text import TEXT_SUFFIXES

    f = tmp_path / "log.xyz"
    f.write_text("t,q1\n0,0\n")
    err = cli("inspect", "scara", f, rc=2).err
    assert "unknown data format '.xyz'" in err
    assert all(s in err for s in (*TEXT_SUFFIXES, *ARRAY_SUFFIXES, *PARQUET_SUFFIXES, *BAG_SUFFIXES)), err
