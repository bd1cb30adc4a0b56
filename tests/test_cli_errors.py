"""Errors for users: status 2, one line of what is wrong and where, a ``hint:`` line, no traceback
(``--debug`` adds it); nothing written. Every command path with a bad input of each kind."""
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from symoro_gen import cli as cli_module
from symoro_gen.commands import export_par as export_par_command
from symoro_gen.simulate import write_recording_csv

ROOT = Path(__file__).resolve().parents[1]
PAR = ROOT / "tests" / "description" / "fixtures" / "rx90_symoro.par"


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    """A good simulated SCARA recording, one with a NaN, and a regular file (an unwritable parent)."""
    from symoro_gen.loader import model_for
    from symoro_gen.simulate.parameters import random_physical_parameters
    from symoro_gen.simulate.recording import simulate_recording
    from symoro_gen.simulate.trajectories import fourier_trajectory

    rng = np.random.default_rng(11)
    robot, model = model_for("scara")
    chi = random_physical_parameters(robot, rng)
    chi = getattr(chi, "chi_std", chi)
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, 6.0, 0.002, rng)
    tr = simulate_recording(model, t, q, dq, ddq, chi, noise_q=1e-5, noise_tau=0.01, rng=rng)
    d = tmp_path_factory.mktemp("data")
    write_recording_csv(d / "good.csv", tr)
    write_recording_csv(d / "loaded.csv", tr)  # --loaded: another recording than the DATA one
    head = (d / "good.csv").read_text().splitlines()[0]
    a = np.column_stack([tr.t, tr.q, tr.tau])
    a[10, 2] = np.nan
    np.savetxt(d / "nan.csv", a, delimiter=",", header=head, comments="")
    (d / "a_file").write_text("not a folder\n")
    (d / "bad.par").write_text("garbage\n")
    (d / "bad.urdf").write_text("<robot")
    bad_robot = (ROOT / "robots" / "scara.toml").read_text().replace("sigma = 1", "sigma = 7")
    (d / "bad_robot.toml").write_text(bad_robot)
    return d


def _case(d: Path):
    good, nan, afile, loaded = str(d / "good.csv"), str(d / "nan.csv"), d / "a_file", str(d / "loaded.csv")
    out_under_file = str(afile / "out.json")
    return {
        # name: (argv, substrings of the error line)
        "generate: missing robot file": (["generate", str(d / "missing.toml")], ["missing.toml", "file not found"]),
        "generate: unknown robot": (["generate", "no_such_robot"], ["no_such_robot", "no such robot", "lwr4"]),
        "generate: bad robot file": (["generate", str(d / "bad_robot.toml"), "--out", str(d / "gen")],
                                     ["bad_robot.toml", "frame 3", "sigma"]),
        "generate: unwritable output": (["generate", "scara", "--out", str(afile)], ["cannot write", "a_file"]),
        "import-par: missing file": (["import-par", str(d / "none.par")], ["none.par", "file not found"]),
        "import-par: unwritable output": (["import-par", str(PAR), "-o", str(afile / "x.toml")],
                                          ["cannot write", "x.toml"]),
        "import-urdf: malformed": (["import-urdf", str(d / "bad.urdf")], ["bad.urdf", "line 1", "malformed XML"]),
        "export-par: unknown robot": (["export-par", "no_such_robot"], ["no such robot"]),
        "export-par: unwritable output": (["export-par", "scara", "-o", str(afile / "x.par")], ["cannot write", "x.par"]),
        "identify: unknown robot": (["identify", "no_such_robot", good], ["no such robot"]),
        "identify: missing data": (["identify", "scara", str(d / "missing.csv")], ["missing.csv", "file not found"]),
        "identify: NaN in data": (["identify", "scara", nan], ["nan.csv", "rows 11", "q2", "NaN"]),
        "identify: wrong robot for data": (["identify", "rx90", good], ["good.csv", "q*", "tau*", "6 joints"]),
        "identify: bad --payload": (["identify", "scara", good, "--loaded", loaded, "--payload", "M5"],
                                    ["--payload", "NAME=VALUE"]),
        "identify: --payload on a robot without payload": (["identify", "scara", good, "--loaded", loaded,
                                                             "--payload", "M5=1"], ["--payload M5", "not a payload"]),
        "identify: bad --cutoff": (["identify", "scara", good, "--cutoff", "-5"], ["--cutoff -5", "positive"]),
        "identify: bad --decimate": (["identify", "scara", good, "--decimate", "0"], ["--decimate 0"]),
        "identify: unwritable --json": (["identify", "scara", good, "--json", out_under_file], ["cannot write", "out.json"]),
        "identify: missing --validate": (["identify", "scara", good, "--validate", str(d / "v.csv")], ["v.csv"]),
        "demo: bad --duration": (["demo", "--duration", "0"], ["--duration 0"]),
    }


CASES = list(_case(Path("/x")))
SEVERAL = {"identify: wrong robot for data"}  # files with several problems (one bad sigma is ONE line)


@pytest.mark.parametrize("name", CASES)
def test_user_error_is_one_line_plus_hint(name, data, cli):
    argv, expect = _case(data)[name]
    cap = cli(*argv, rc=2)
    err = cap.err.rstrip("\n").splitlines()
    assert "Traceback" not in cap.err
    assert err[0].startswith("symoro-gen: error: ")
    assert err[-1].startswith("hint: ") and len(err[-1]) > len("hint: ") + 10
    if name not in SEVERAL:
        assert len(err) == 2, cap.err  # what is wrong and where, then the hint
    else:  # several problems: a header, one line per problem (file, where, field), the hint
        assert re.fullmatch(r"symoro-gen: error: \d+ problems in (robot description|data):", err[0])
        assert all(line.startswith("  - ") for line in err[1:-1]) and len(err) >= 4
    for s in expect:
        assert s in "\n".join(err[:-1]), (s, err)
    assert not (data / "gen").exists() and not (data / "a_file" / "out.json").exists()


def test_debug_adds_the_traceback(data, cli):
    argv = ["identify", "scara", str(data / "nan.csv")]
    err = cli("--debug", *argv, rc=2).err
    assert err.startswith("Traceback (most recent call last)") and "DataFileError" in err
    tail = err.rstrip("\n").splitlines()[-2:]
    assert tail[0].startswith("symoro-gen: error: ") and "nan.csv" in tail[0] and tail[1].startswith("hint: ")
    assert "Traceback" in cli(*argv, "--debug", rc=2).err  # also accepted after the command


def test_several_problems_all_listed(data, cli):
    bad = data / "two.toml"
    text = (ROOT / "robots" / "scara.toml").read_text().replace("sigma = 1", "sigma = 7").replace("ant = 2", "ant = 5")
    bad.write_text(text)
    err = cli("generate", bad, "--out", data / "gen", rc=2).err.splitlines()
    assert re.fullmatch(r"symoro-gen: error: \d+ problems in robot description:", err[0])
    assert any("sigma" in x for x in err[1:-1]) and any("ant" in x for x in err[1:-1])
    assert "robot-file" in err[-1]


def test_unexpected_failure_is_an_internal_error(monkeypatch, cli):
    def boom(args):
        raise RuntimeError("something broke\nsecond line")

    monkeypatch.setattr(export_par_command, "run", boom)
    err = cli("export-par", "scara", rc=1).err.splitlines()
    assert err == ["symoro-gen: internal error: RuntimeError: something broke",
                   "hint: this is a bug in symoro-gen; rerun with --debug and report the traceback"]
    assert "Traceback" in cli("--debug", "export-par", "scara", rc=1).err


def test_interrupt(monkeypatch, cli):
    def stop(args):
        raise KeyboardInterrupt

    monkeypatch.setattr(export_par_command, "run", stop)
    assert cli("export-par", "scara", rc=130).err == "symoro-gen: interrupted\n"


def test_warnings_are_one_line(data, cli):
    """A data warning (unit check) prints as one ``symoro-gen: warning:`` line, not a source excerpt."""
    a = np.loadtxt(data / "good.csv", delimiter=",", skiprows=1)
    a[:, 1] *= 180 / np.pi  # q1 in degrees
    f = data / "deg.csv"
    np.savetxt(f, a, delimiter=",", header=(data / "good.csv").read_text().splitlines()[0], comments="")
    r = cli.subprocess("--quiet", "identify", "scara", f, "--method", "ols", rc=0)
    err = r.stderr
    lines = [x for x in err.splitlines() if "q1" in x]
    assert lines and all(x.startswith("symoro-gen: warning: ") for x in lines)
    assert "warnings.warn" not in err


def _commands():
    import argparse

    parser = cli_module.build_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return sub.choices


def test_diagnose_bad_input(data, cli):
    if "diagnose" not in _commands():
        pytest.skip("the diagnose command is not there yet")
    cases = [(["diagnose", "scara", str(data / "missing.csv")], "missing.csv"),
             (["diagnose", "scara", str(data / "nan.csv")], "nan.csv"),
             (["diagnose", "no_such_robot", str(data / "good.csv")], "no such robot")]
    for argv, what in cases:
        err = cli(*argv, rc=2).err_lines
        assert err[0].startswith("symoro-gen: error: ") and what in err[0] and err[-1].startswith("hint: ")


def test_closed_pipe_is_not_an_error(cli):
    """`symoro-gen ... | head`: the reader goes away; no error message, no traceback."""
    p = cli.popen("export-par", "lwr4", stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    p.stdout.close()  # nobody reads
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141 and err == "", err


def test_a_misspelt_robot_name_gets_the_nearest_and_the_help_shows_each_geometry_choice_once(cli, tmp_path):
    """``LWR4`` or ``rx9`` for a robot: the error names the nearest known robot (a name far from all gets the list
    only); ``identify --help`` shows the --geometry choices once each (argparse printed the accepted spellings,
    both orders of the pair included)."""
    for typed, near in (("LWR4", "lwr4"), ("rx9", "rx90")):
        r = cli("identify", typed, tmp_path / "x.csv", rc=2)
        assert f"did you mean {near}?" in r.err, r.err
    r = cli("identify", "zzzz", tmp_path / "x.csv", rc=2)
    assert "did you mean" not in r.err and "known robots: lwr4" in r.err
    out = cli.subprocess("identify", "--help").stdout
    line = next(ln for ln in out.splitlines() if ln.strip().startswith("--geometry "))
    assert line.count("joint_zero") == 2 and "length,joint_zero" not in line, line
