"""No output ever clobbers an input (symoro_gen.atomic.check_outputs, one rule for every writer).

* an output that is one of the command's inputs (same path however spelled, symbolic or hard link) is
  refused, even with ``--force``, before any work: the input's bytes are unchanged;
* two outputs of one command are never the same file;
* an existing file symoro-gen did not write is replaced only with ``--force``; a previous run's output
  (it carries symoro-gen's mark) is replaced without it -- except robot files (``import-*``), never
  replaced without ``--force``;
* ``generate`` does not replace a package generated from another robot file of the same robot name.

The commands run in this process on a short simulated SCARA recording, with the smallest settings.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from symoro_gen.atomic import check_outputs, same_file, written_by_symoro
from symoro_gen.errors import OutputError

from .fuzz.helpers import FUZZ

pytestmark = pytest.mark.filterwarnings("ignore:.*have no <inertial>")

ROOT = Path(__file__).resolve().parents[1]
SCARA = ROOT / "robots" / "scara.toml"
FOREIGN = "a file of the user's, not symoro-gen's\n"


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.fixture(scope="module")
def ws(tmp_path_factory):
    """A workspace: robot.toml (a copy of the SCARA's), a.csv and b.csv (3 s recordings), result.json
    (their identification), scara.par and scara.urdf (exports) and fl/<robot>/<day>.csv (a tiny fleet)."""
    from symoro_gen.cli import main
    from symoro_gen.loader import model_for
    from symoro_gen.simulate.parameters import random_physical_parameters
    from symoro_gen.simulate.recording import simulate_recording, write_recording_csv
    from symoro_gen.simulate.trajectories import fourier_trajectory

    d = tmp_path_factory.mktemp("ws")
    shutil.copy(SCARA, d / "robot.toml")
    rng = np.random.default_rng(5)
    robot, model = model_for("scara")
    chi = random_physical_parameters(robot, rng)
    chi = getattr(chi, "chi_std", chi)

    def record(path, duration=3.0, dt=0.004, gain=1.0):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, duration, dt, rng)
        write_recording_csv(path, simulate_recording(model, t, q, dq, ddq, gain * np.asarray(chi), noise_q=1e-5,
                                                     noise_tau=0.01, rng=rng))

    record(d / "a.csv")
    record(d / "b.csv")
    for r in range(3):
        for day in range(2):
            (d / "fl" / f"r{r}").mkdir(parents=True, exist_ok=True)
            record(d / "fl" / f"r{r}" / f"d{day}.csv", duration=2.0, dt=0.008, gain=1.0 + 0.01 * r)
    assert main(["-q", "identify", str(d / "robot.toml"), str(d / "a.csv"), "--json", str(d / "result.json")]) == 0
    assert main(["-q", "export-par", "scara", "-o", str(d / "scara.par")]) == 0
    assert main(["-q", "export-urdf", "scara", "-o", str(d / "scara.urdf")]) == 0
    return d


@dataclass(frozen=True)
class Cmd:
    """A command: its arguments (``{d}`` is the workspace), its output options (option -> file name) and
    the workspace files it reads."""

    argv: tuple[str, ...]
    outputs: dict[str, str]
    inputs: tuple[str, ...]
    robot_files: bool = False  # import-*: an existing output is never replaced without --force
    ok: tuple[int, ...] = (0,)
    needs: tuple[str, ...] = field(default=())
    required: tuple[str, ...] = ()  # output options the command cannot run without

    def args(self, d: Path, outs: dict[str, Path], *extra: str) -> list[str]:
        """The command line; a required output not in ``outs`` goes to a path never written (the runs
        that leave it out are refused before any work)."""
        argv = [a.format(d=d) for a in self.argv]
        outs = {**{o: d / "unwritten" / self.outputs[o] for o in self.required if o not in outs}, **outs}
        for opt, p in outs.items():
            argv += [opt, str(p)]
        return argv + list(extra)


EXCITE_SMALL = ("--duration", "2", "--harmonics", "2", "--starts", "1", "--pool", "1", "--max-iter", "3",
                "--refine", "0", "--rate", "20")
FLEET_INPUTS = tuple(f"fl/r{r}/d{day}.csv" for r in range(3) for day in range(2))
COMMANDS = {
    "identify": Cmd(("identify", "{d}/robot.toml", "{d}/a.csv", "--validate", "{d}/b.csv", "--method", "ols"),
                    {"--json": "id.json", "--report": "id.md"}, ("robot.toml", "a.csv", "b.csv")),
    "diagnose": Cmd(("diagnose", "{d}/robot.toml", "{d}/a.csv", "--max-effects", "1", "--candidates", "offset"),
                    {"--json": "dg.json", "--report": "dg.html", "--plots": "dg_plots"}, ("robot.toml", "a.csv")),
    "inspect": Cmd(("inspect", "{d}/robot.toml", "{d}/a.csv"), {"--json": "in.json", "--report": "in.md"},
                   ("robot.toml", "a.csv")),
    "excite": Cmd(("excite", "{d}/robot.toml", *EXCITE_SMALL),
                  {"-o": "ex.csv", "--json": "ex.json", "--plot": "ex.png", "--report": "ex.md"}, ("robot.toml",),
                  ok=(0, 3), required=("-o",)),
    "export-urdf": Cmd(("export-urdf", "{d}/robot.toml", "--from", "{d}/result.json"), {"-o": "ex.urdf"},
                       ("robot.toml", "result.json"), needs=("cvxpy", "clarabel")),
    "export-mjcf": Cmd(("export-mjcf", "{d}/robot.toml"), {"-o": "ex.xml"}, ("robot.toml",)),
    "export-par": Cmd(("export-par", "{d}/robot.toml"), {"-o": "ex.par"}, ("robot.toml",)),
    "import-par": Cmd(("import-par", "{d}/scara.par"), {"-o": "im1.toml"}, ("scara.par",), robot_files=True),
    "import-urdf": Cmd(("import-urdf", "{d}/scara.urdf"), {"-o": "im2.toml"}, ("scara.urdf",), robot_files=True),
    "fleet": Cmd(("fleet", "{d}/robot.toml", "{d}/fl", "--by", "{{robot}}/{{day}}.csv", "--scheduler", "threads:1"),
                 {"--json": "fl.json", "--report": "fl.md"}, ("robot.toml", *FLEET_INPUTS), needs=("dask",)),
}
LABEL = {"-o": "-o/--output"}  # how the messages spell an option
PAIRS = [(c, o) for c, cmd in COMMANDS.items() for o in cmd.outputs]


def _needs(cmd: Cmd) -> None:
    for mod in cmd.needs:
        pytest.importorskip(mod)


def _digests(d: Path, names) -> dict[str, str]:
    return {n: _digest(d / n) for n in names}


def _alias(d: Path, target: Path, how: str, tag: str) -> Path:
    """Another name of ``target``: spelt differently, or a symbolic or hard link to it."""
    links = d / "links"
    links.mkdir(exist_ok=True)
    rel = target.relative_to(d)
    if how == "same":
        return target
    if how == "dotted":
        return d / "." / rel.parent / "." / rel.name
    if how == "parent":
        return d / "links" / ".." / rel
    if how == "relative":
        return Path(os.path.relpath(target))
    p = links / f"{tag}-{how}-{rel.name}"
    if not p.exists():
        (os.symlink if how == "symlink" else os.link)(target, p)
    return p


# ---- every (command, output option), pointed at every input, however spelt: refused -----------
@FUZZ
@given(pair=st.sampled_from(PAIRS), which=st.integers(0, 20),
       how=st.sampled_from(["same", "dotted", "parent", "relative", "symlink", "hardlink"]),
       force=st.booleans())
def test_an_output_never_replaces_an_input(cli, ws, pair, which, how, force):
    command, option = pair
    cmd = COMMANDS[command]
    name = cmd.inputs[which % len(cmd.inputs)]
    before = _digests(ws, cmd.inputs)
    out = _alias(ws, ws / name, how, f"{command}{option}")
    res = cli(*cmd.args(ws, {option: out}, *(["--force"] if force else [])), rc=2)
    first = res.err_lines[0]
    assert first.startswith(f"symoro-gen: error: {LABEL.get(option, option)} ") and "is an input of the command" in first, res.err
    assert "even with --force" in first and str(out) in first
    assert _digests(ws, cmd.inputs) == before


@FUZZ
@given(command=st.sampled_from([c for c, cmd in COMMANDS.items() if len(cmd.outputs) > 1]), data=st.data())
def test_two_outputs_are_never_one_file(cli, ws, tmp_path_factory, command, data):
    cmd = COMMANDS[command]
    a, b = data.draw(st.lists(st.sampled_from(list(cmd.outputs)), min_size=2, max_size=2, unique=True))
    out = tmp_path_factory.mktemp("two") / "same.out"
    res = cli(*cmd.args(ws, {a: out, b: out}, "--force"), rc=2)
    assert "are the same file" in res.err_lines[0] and a in res.err_lines[0] and b in res.err_lines[0], res.err
    assert not out.exists()


# ---- a user's file: refused without --force, replaced with it; a previous output: replaced -----
def _foreign(path: Path, option: str) -> Path:
    """A file of the user's where ``option`` writes; returns the file (for --plots: one in the folder)."""
    if option == "--plots":
        path.mkdir(parents=True, exist_ok=True)
        path = path / "diagnosis-errors.png"
    path.write_text(FOREIGN)
    return path


@pytest.mark.parametrize("command", list(COMMANDS))
def test_users_files_need_force_and_previous_outputs_are_replaced(cli, ws, tmp_path, command):
    cmd = COMMANDS[command]
    _needs(cmd)
    outs = {opt: tmp_path / name for opt, name in cmd.outputs.items()}
    inputs = _digests(ws, cmd.inputs)
    foreign = {opt: _foreign(p, opt) for opt, p in outs.items()}
    for opt in outs:  # each option alone, before any work
        res = cli(*cmd.args(ws, {opt: outs[opt]}), rc=2)
        first = res.err_lines[0]
        assert first.startswith(f"symoro-gen: error: {opt}") and str(foreign[opt]) in first, res.err
        assert "not overwritten (--force replaces it)" in first, res.err
        assert ("was not written by symoro-gen" in first) != cmd.robot_files
        assert foreign[opt].read_text() == FOREIGN
    res = cli(*cmd.args(ws, outs, "--force"), rc=None)  # replaced
    assert res.rc in cmd.ok, res.err
    for opt, p in foreign.items():
        assert p.read_text(errors="replace") != FOREIGN, f"{command} {opt}: not replaced"
        written = outs[opt] if opt != "--plots" else p
        assert cmd.robot_files or written_by_symoro(written), f"{command} {opt}: its output carries no mark"
    if command == "export-urdf":  # with --from: the sidecar OUT.json too
        assert written_by_symoro(Path(str(outs["-o"]) + ".json"))
    for p in outs.values():
        if p.suffix == ".md" and (p.parent / (p.stem + "_files")).is_dir():  # a report's images: marked
            assert all(written_by_symoro(f) for f in (p.parent / (p.stem + "_files")).iterdir())
    res = cli(*cmd.args(ws, outs), rc=None)  # the same command again, no --force
    if cmd.robot_files:  # robot files are edited by hand: never replaced without --force
        assert res.rc == 2 and "not overwritten (--force replaces it)" in res.err_lines[0], res.err
    else:
        assert res.rc in cmd.ok, res.err
    assert _digests(ws, cmd.inputs) == inputs


# ---- the cases users reported (all exited 0 and replaced the input) ---------------------------
REPORTED = [
    (["identify", "scara", "{d}/a.csv", "--json", "{d}/a.csv"], "--json", "DATA", "a.csv"),
    (["identify", "scara", "{d}/a.csv", "--validate", "{d}/b.csv", "--json", "{d}/b.csv"], "--json", "--validate", "b.csv"),
    (["identify", "{d}/robot.toml", "{d}/a.csv", "--json", "{d}/robot.toml"], "--json", "ROBOT", "robot.toml"),
    (["identify", "scara", "{d}/a.csv", "--json", "{d}/a.csv.json"], None, None, None),  # a control: not an input
    (["diagnose", "scara", "{d}/a.csv", "--json", "{d}/a.csv"], "--json", "DATA", "a.csv"),
    (["inspect", "scara", "{d}/a.csv", "--json", "{d}/a.csv"], "--json", "DATA", "a.csv"),
    (["inspect", "scara", "q={d}/a.csv,tau={d}/b.csv,dt=0.004", "--json", "{d}/b.csv"], "--json", "DATA", "b.csv"),
    (["export-urdf", "{d}/robot.toml", "-o", "{d}/robot.toml"], "-o/--output", "ROBOT", "robot.toml"),
    (["export-mjcf", "{d}/robot.toml", "-o", "{d}/robot.toml"], "-o/--output", "ROBOT", "robot.toml"),
    (["export-par", "{d}/robot.toml", "-o", "{d}/robot.toml", "--force"], "-o/--output", "ROBOT", "robot.toml"),
    (["export-urdf", "scara", "--params", "{d}/result.json", "-o", "{d}/result.json"], "-o/--output", "--params",
     "result.json"),
    (["excite", "{d}/robot.toml", "-o", "{d}/robot.toml"], "-o/--output", "ROBOT", "robot.toml"),
    (["import-par", "{d}/scara.par", "-o", "{d}/scara.par", "--force"], "-o/--output", "FILE", "scara.par"),
]


@pytest.mark.parametrize("argv, option, role, name", REPORTED, ids=[f"{c[0][0]}-{i}" for i, c in enumerate(REPORTED)])
def test_reported_cases(cli, ws, argv, option, role, name):
    before = _digests(ws, ["robot.toml", "a.csv", "b.csv", "result.json", "scara.par"])
    args = [a.format(d=ws) for a in argv]
    if option is None:  # not a clobbering case: a control that such a command still runs
        cli("-q", *args, rc=0)
        assert written_by_symoro(ws / "a.csv.json")
        (ws / "a.csv.json").unlink()
        return
    res = cli(*args, rc=2)
    first = res.err_lines[0]
    assert first == (f"symoro-gen: error: {option} {ws / name}: that file is an input of the command ({role} "
                     f"{ws / name}); an output never replaces an input, even with --force"), res.err
    assert res.err_lines[1] == f"hint: write {option} to another path"
    assert _digests(ws, ["robot.toml", "a.csv", "b.csv", "result.json", "scara.par"]) == before


def test_excite_output_and_json_are_not_one_file(cli, ws):
    before = _digest(ws / "a.csv")
    res = cli("excite", "scara", "-o", ws / "a.csv", "--json", ws / "a.csv", rc=2)
    assert res.err_lines[0] == (f"symoro-gen: error: -o/--output {ws / 'a.csv'} and --json {ws / 'a.csv'} are the "
                                "same file: each output needs its own path"), res.err
    assert _digest(ws / "a.csv") == before


def test_a_report_folder_holding_an_input_is_refused(cli, ws, tmp_path):
    """``--report r.md`` replaces ``r_files/`` whole: an input there is refused, even with --force."""
    (tmp_path / "r_files").mkdir()
    shutil.copy(ws / "a.csv", tmp_path / "r_files" / "a.csv")
    res = cli("identify", "scara", tmp_path / "r_files" / "a.csv", "--report", tmp_path / "r.md", "--force", rc=2)
    assert "this folder is replaced whole and holds" in res.err_lines[0] and "(DATA " in res.err_lines[0], res.err
    assert (tmp_path / "r_files" / "a.csv").read_bytes() == (ws / "a.csv").read_bytes()


# ---- generate: a package knows the robot file it came from -------------------------------------
def test_generate_does_not_replace_a_package_of_another_robot_file(cli, tmp_path, monkeypatch):
    """A copy of robots/scara.toml with another D2 (same name) does not replace the shipped package."""
    from symoro_gen import cli as cli_module
    from symoro_gen.commands import generate as generate_command

    repo = tmp_path / "repo"
    (repo / "robots").mkdir(parents=True)
    shutil.copy(SCARA, repo / "robots" / "scara.toml")
    shutil.copytree(ROOT / "generated" / "scara", repo / "generated" / "scara",
                    ignore=shutil.ignore_patterns("__pycache__", "_build"))
    man = json.loads((repo / "generated" / "scara" / "manifest.json").read_text())
    assert man["robot_file_path"] == "robots/scara.toml"
    copy = tmp_path / "r.toml"
    copy.write_text(SCARA.read_text().replace("D2 = 0.35", "D2 = 0.4"))
    assert "D2 = 0.4" in copy.read_text()
    shipped = {p.name: p.read_bytes() for p in (repo / "generated" / "scara").iterdir()}
    monkeypatch.setattr(cli_module, "generated_dir", lambda: repo / "generated")
    monkeypatch.setattr(generate_command, "generated_dir", lambda: repo / "generated")
    for argv in (["generate", copy], ["generate", copy, "--out", repo / "generated"]):  # default --out, and given
        res = cli(*argv, rc=2)
        assert res.err_lines[0] == (f"symoro-gen: error: {repo / 'generated' / 'scara'} was generated from the robot "
                                    f"file {repo / 'robots' / 'scara.toml'}; {copy} is another robot file with the same "
                                    "name 'scara': not replacing the package"), res.err
        assert "pass --force" in res.err_lines[1]
        assert {p.name: p.read_bytes() for p in (repo / "generated" / "scara").iterdir()} == shipped
    cli("-q", "generate", copy, "--force", rc=0)  # replaced
    man = json.loads((repo / "generated" / "scara" / "manifest.json").read_text())
    assert man["robot_file_path"] == "../r.toml" and "'D2': 0.4" in (repo / "generated" / "scara" / "__init__.py").read_text()
    copy.write_text(copy.read_text().replace("D2 = 0.4", "D2 = 0.45"))  # edited: the same file, regenerated
    cli("-q", "generate", copy, rc=0)
    assert "'D2': 0.45" in (repo / "generated" / "scara" / "__init__.py").read_text()
    res = cli("generate", repo / "robots" / "scara.toml", rc=2)  # and now the shipped file is the other one
    assert "r.toml" in res.err_lines[0]


def test_a_package_regenerated_from_its_file_however_named(cli, tmp_path):
    """The same robot file reached through a symbolic link, or an older package that records only the file
    name: regenerated without --force."""
    src = tmp_path / "robots" / "scara.toml"
    src.parent.mkdir()
    shutil.copy(SCARA, src)
    cli("-q", "generate", src, "--out", tmp_path / "gen", rc=0)
    man_path = tmp_path / "gen" / "scara" / "manifest.json"
    man = json.loads(man_path.read_text())
    assert man["robot_file_path"] == "robots/scara.toml"
    del man["robot_file_path"]  # as written before the field existed: the file name is compared
    man_path.write_text(json.dumps(man))
    cli("-q", "generate", src, "--out", tmp_path / "gen", rc=0)
    (tmp_path / "link.toml").symlink_to(src)
    cli("-q", "generate", tmp_path / "link.toml", "--out", tmp_path / "gen", rc=0)


# ---- the rule itself, and the writers of the Python API ----------------------------------------
def test_check_outputs_compares_files_not_spellings(tmp_path):
    a = tmp_path / "a.csv"
    a.write_text("t,q1,tau1\n0,0,0\n")
    os.link(a, tmp_path / "hard.csv")
    (tmp_path / "soft.csv").symlink_to(a)
    for out in (a, tmp_path / "hard.csv", tmp_path / "soft.csv", tmp_path / "x" / ".." / "a.csv"):
        assert same_file(out, a)
        with pytest.raises(OutputError, match="is an input of the command"):
            check_outputs({"--json": out}, [("DATA", a)], force=True)
    check_outputs({"--json": tmp_path / "new.json"}, [("DATA", a)])
    with pytest.raises(OutputError, match="are the same file"):
        check_outputs({"--json": tmp_path / "n.json", "--report": tmp_path / "." / "n.json"}, [])


@pytest.mark.parametrize("text, ours", [
    ('{\n  "generator": "symoro-gen identify",\n  "robot": "scara"\n}\n', True),
    ('{"robot": "scara", "generator": "symoro-gen identify"}\n', False),    # not the first key: not the mark
    ("<?xml version=\"1.0\"?>\n<robot name=\"x\">\n  <!-- exported by symoro_gen from x.toml -->\n", True),
    ("(* SYMORO+ : parameters of a robot, written by symoro_gen *)\nNF = 4\n", True),
    ("# Report\n\ntext\n\n<!-- written by symoro-gen -->\n", True),
    ("<!DOCTYPE html>\n<html>\n<head>\n<meta charset=\"utf-8\">\n<meta name=\"generator\" content=\"symoro-gen\">\n", True),
    ("t,q1,q2,dq1,dq2,ddq1,ddq2\n0,0,0,0,0,0,0\n", True),                     # excite's trajectory
    ("t,q1,q2,tau1,tau2\n0,0,0,0,0\n", False),                              # a recording
    ("t,q1,q2,dq1,dq3,ddq1,ddq2\n", False),
    ("# written by me about symoro-gen\n", False),
    ("", False),
])
def test_written_by_symoro(tmp_path, text, ours):
    (tmp_path / "f").write_text(text)
    assert written_by_symoro(tmp_path / "f") is ours


def test_python_api_writers(tmp_path):
    """Each writer that takes a path: a user's file needs force=True; a recording is never replaced
    without it; a previous output is replaced."""
    from symoro_gen.excite import write_trajectory_csv
    from symoro_gen.preprocessing.trajectory import Trajectory
    from symoro_gen.report import Paragraph, Report
    from symoro_gen.report.document import write_report_files
    from symoro_gen.simulate import write_recording_csv

    t = np.linspace(0, 1, 5)
    q = np.zeros((5, 2))
    user = tmp_path / "user.txt"
    writers = {
        "trajectory": lambda p, **k: write_trajectory_csv(p, t, q, q, q, **k),
        "report": lambda p, **k: write_report_files(Report("r", (Paragraph("x"),)), p.with_suffix(".html"), **k),
        "recording": lambda p, **k: write_recording_csv(p, Trajectory(t=t, q=q, tau=q), **k),
    }
    for name, write in writers.items():
        target = user if name != "report" else user.with_suffix(".html")
        target.write_text(FOREIGN)
        with pytest.raises(OutputError, match="force=True replaces it"):
            write(user)
        assert target.read_text() == FOREIGN
        write(user, force=True)
        assert target.read_text() != FOREIGN
        if name == "recording":
            with pytest.raises(OutputError, match="the file exists"):
                write(user)
        else:
            write(user)  # its own previous output


def test_parquet_logs(tmp_path):
    """Parquet logs (``write_parquet``, the fleet simulator's writer) are inputs of other commands: a
    Parquet file symoro-gen did not write is refused with an error naming it (its bytes unchanged) and
    replaced with force=True; a log symoro-gen wrote (its schema metadata ``generator: symoro-gen``) is
    re-written. ``simulate_fleet`` checks every log before writing any."""
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    from symoro_gen.fleet import simulate_fleet, write_parquet
    from symoro_gen.preprocessing.trajectory import Trajectory

    def foreign(path: Path) -> str:
        path.parent.mkdir(parents=True, exist_ok=True)
        pq.write_table(pa.table({"t": [0.0, 1.0], "q1": [0.0, 0.0], "tau1": [1.0, 1.0]}), path)  # a measured log
        assert not written_by_symoro(path)
        return _digest(path)

    t = np.linspace(0, 1, 5)
    rec = Trajectory(t=t, q=np.zeros((5, 2)), tau=np.ones((5, 2)))
    log = tmp_path / "log.parquet"
    before = foreign(log)
    with pytest.raises(OutputError, match=f"{re.escape(str(log))}: the file exists and was not written by symoro-gen"):
        write_parquet(log, rec)
    assert _digest(log) == before
    write_parquet(log, rec, force=True)
    assert written_by_symoro(log) and _digest(log) != before
    write_parquet(log, Trajectory(t=t, q=np.ones((5, 2)), tau=np.ones((5, 2))))    # its own log: re-written
    assert pq.read_table(log).column("q1").to_pylist() == [1.0] * 5

    kw = dict(n_robots=2, n_days=1, duration=0.5, fs=100.0, drifts=())
    truth = simulate_fleet(tmp_path / "fl", **kw)
    assert all(written_by_symoro(f) for f in truth.files)
    simulate_fleet(tmp_path / "fl", **kw, seed=1)                                   # its own logs: re-written
    first, second = truth.files
    before = foreign(second)
    mtime = first.stat().st_mtime_ns
    with pytest.raises(OutputError, match=re.escape(str(second))):
        simulate_fleet(tmp_path / "fl", **kw)
    assert _digest(second) == before and first.stat().st_mtime_ns == mtime       # nothing written
    simulate_fleet(tmp_path / "fl", **kw, force=True)
    assert written_by_symoro(second)
