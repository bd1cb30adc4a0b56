"""Messages that used to be unclear or missing, each now naming the file or option, the field and what to do:
a URDF given where a robot file is expected, absurd numbers in a robot file or an option (1e300, inf, nan),
a non-positive MuJoCo time step."""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

import symoro_gen
from symoro_gen.description import load_robot
from symoro_gen.errors import OptionError, RobotFileError

ROOT = Path(__file__).resolve().parents[1]


def test_a_urdf_given_as_the_robot_says_to_import_it_first(tmp_path, cli):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text('<?xml version="1.0"?>\n<robot name="arm"><link name="base"/></robot>\n')
    for argv in (("identify", urdf, tmp_path / "log.csv"), ("generate", urdf)):
        r = cli(*argv, rc=2)
        assert r.err_lines == [f"symoro-gen: error: {urdf}: a URDF (XML), not a robot file (TOML)",
                               f"hint: convert it first: `symoro-gen import-urdf {urdf} -o {tmp_path / 'arm.toml'}` "
                               "writes the robot file; then give that file"]
    # the conversion it proposes works on a real URDF and gives a robot file the command takes
    (tmp_path / "tree.urdf").write_text(_branch_urdf())
    cli("import-urdf", tmp_path / "tree.urdf", "-o", tmp_path / "tree.toml")
    assert load_robot(str(tmp_path / "tree.toml")).n_joints == 3


def _branch_urdf() -> str:
    inertial = ('<inertial><mass value="1"/><origin xyz="0.01 0.02 0.03"/><inertia ixx="0.1" iyy="0.1" izz="0.1" '
                'ixy="0" ixz="0" iyz="0"/></inertial>')
    links = "".join(f'<link name="{n}">{inertial}</link>' for n in ("base", "a", "b", "c"))
    joint = ('<joint name="{0}" type="revolute"><origin xyz="{1}"/><axis xyz="{2}"/><parent link="{3}"/>'
             '<child link="{4}"/><limit effort="1" lower="-1" upper="1" velocity="1"/></joint>')
    return ('<robot name="tree">' + links + joint.format("j1", "0 0 0.3", "0 0 1", "base", "a")
            + joint.format("j2", "0 0.2 0", "0 1 0", "a", "b") + joint.format("j3", "0 -0.2 0", "1 0 0", "a", "c")
            + "</robot>")


@pytest.mark.parametrize("edit, where, field", [
    (("D2 = 0.35", "D2 = 1e300"), "[values]", "D2"),
    (("gravity = [0, 0, -9.81]", "gravity = [0, 0, -1e300]"), "top level", "gravity"),
    (("d = \"D3\"", "d = 1e300"), "frame 3", "d"),
])
def test_absurd_numbers_in_a_robot_file_are_refused_naming_the_field(edit, where, field, tmp_path):
    text = (ROOT / "robots" / "scara.toml").read_text()
    assert edit[0] in text
    f = tmp_path / "scara.toml"
    f.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(RobotFileError) as err:
        load_robot(str(f))
    msg = [str(p) for p in err.value.problems]
    assert len(msg) == 1 and msg[0].startswith(f"{f}, {where}, field '{field}': "), msg
    assert "|x| <= 1e+12" in msg[0]


@pytest.mark.parametrize("argv, flag, value", [
    (("excite", "scara", "-o", "x.csv", "--duration", "1e300"), "--duration", "1e+300"),
    (("identify", "scara", "x.csv", "--cutoff", "nan"), "--cutoff", "nan"),
    (("export-mjcf", "scara", "--timestep", "inf"), "--timestep", "inf"),
])
def test_non_finite_or_absurd_option_values_are_refused_naming_the_option(argv, flag, value, cli, tmp_path):
    r = cli(*argv, rc=2)
    assert r.err_lines[0] == f"symoro-gen: error: {flag} {value}: not a usable number (finite, |value| <= 1e+12)"


def test_timestep_must_be_positive(cli):
    r = cli("export-mjcf", "scara", "--timestep", "-1", rc=2)
    assert r.err_lines[0] == "symoro-gen: error: --timestep -1: must be a positive number of seconds (MuJoCo's step)"
    assert cli("export-mjcf", "scara", "--timestep", "0", rc=2).err_lines[0].startswith("symoro-gen: error: --timestep 0:")
    with pytest.raises(OptionError, match=re.escape("export_mjcf: timestep -1.0: must be a positive number")):
        symoro_gen.export_mjcf("scara", timestep=-1.0)


def test_the_readme_install_routes_carry_what_the_commands_need():
    """``pip install -e '.[test]'`` (and ``.[all]``, the README's route by hand) bring every optional dependency the
    commands use: ``--report`` needs matplotlib, which the test route lacked."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]

    def names(reqs):
        return {re.split(r"[<>=\[ ]", r, maxsplit=1)[0].lower() for r in reqs}

    needed = set().union(*(names(v) for k, v in extras.items() if k not in ("test", "all")))
    assert "matplotlib" in needed
    assert needed <= names(extras["all"]) and needed <= names(extras["test"])
    head = (ROOT / "README.md").read_text().split("## ", 1)[0]
    assert "pip install -e '.[all]'" in head
    assert '".[test,plots]"' in (ROOT / "Makefile").read_text() or '".[test]"' in (ROOT / "Makefile").read_text()


def test_the_readme_requirements_name_every_optional_extra():
    """The README's Requirements list every optional extra of ``pyproject.toml`` by name (``bags``, which reads
    ROS bags, was missing), so a user installing by hand sees which extra a command needs."""
    try:
        import tomllib
    except ModuleNotFoundError:  # Python 3.10
        import tomli as tomllib

    extras = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"])
    requirements = (ROOT / "README.md").read_text().split("## Requirements", 1)[1].split("\n## ", 1)[0]
    named = set(re.findall(r"`([a-z]+)` \(", requirements))
    assert extras - {"test", "all"} <= named, f"extras not named in the README's Requirements: {sorted(extras - named)}"


@pytest.mark.parametrize("extra, named", [
    (("--kp", "100", "--kd", "10"), "--kp, --kd"),
    (("--bandwidth", "5"), "--bandwidth"),
    (("--start", "nominal"), "--start"),
])
def test_closed_loop_options_without_their_method_are_refused(extra, named, cli, tmp_path):
    """The controller's gains, bandwidth, iterations and start only act in the closed-loop simulation of IDIM-IV and
    DIDIM: with OLS or WLS they were silently ignored."""
    r = cli("identify", "scara", tmp_path / "log.csv", "--method", "ols", *extra, rc=2)
    it = "them" if "," in named else "it"
    assert r.err_lines[0] == (f"symoro-gen: error: {named}: only act with --method iv or didim (the closed-loop "
                              f"simulation), not with --method ols: add --method iv or didim, or leave {it} out")
    with pytest.raises(OptionError, match="only act with --method iv or didim"):
        symoro_gen.IdentifyOptions(method="wls", kp=[1.0])
    assert symoro_gen.IdentifyOptions(method="didim", kp=[1.0], kd=[1.0]).kp == [1.0]


@pytest.mark.slow
@pytest.mark.parametrize("refine", [("--refine", "0"), ()], ids=["ipopt-only", "with-sdp-refinement"])
def test_an_excitation_design_with_no_room_to_move_is_degenerate_not_ok(refine, tmp_path, cli):
    """Limits of 1e-9 leave the joints no motion: the design respects them (limits_ok) but its regressor has lost
    its rank (cond ~1e20): the summary says DEGENERATE with the bound, the JSON has ``degenerate``, exit status 3.
    The SDP refinement (on by default when cvxpy is installed) is not run on it, and says so, instead of failing
    inside cvxpy on the empty eigenspace of a singular information matrix."""
    from symoro_gen.excite.refine import has_cvxpy

    robot = tmp_path / "tiny.toml"
    robot.write_text((ROOT / "robots" / "scara.toml").read_text() + "\n[limits]\n"
                     + "".join(f"{k} = [{', '.join(['1e-9'] * 4)}]\n" for k in ("q_max", "dq_max", "ddq_max"))
                     + f"q_min = [{', '.join(['-1e-9'] * 4)}]\n")
    r = cli("excite", robot, "-o", tmp_path / "x.csv", "--duration", "2", "--rate", "50", *refine,
            "--json", tmp_path / "x.json", rc=3)
    doc = json.loads((tmp_path / "x.json").read_text())
    assert doc["limits_ok"] is True and doc["degenerate"] is True and doc["cond"] > doc["cond_degenerate"] == 1e10
    # independent of the design's own figure: the stacked regressor of the written trajectory has lost its rank
    assert _written_design_cond(tmp_path / "x.csv") > 1e10
    line = next(ln for ln in r.out.splitlines() if ln.startswith("DEGENERATE"))
    assert line.startswith(f"DEGENERATE design: cond = {doc['cond']:.3g} is above 1e+10: its regressor is "
                           "numerically rank-deficient") and "widen them" in line
    sdp = [ln for ln in r.out.splitlines() if ln.startswith("SDP refinement")]
    if refine or not has_cvxpy():
        assert sdp == []
    else:
        assert sdp == ["SDP refinement of the true cond: not run (degenerate design: cond above 1e+10)"]


def _written_design_cond(csv) -> float:
    """cond of the SCARA's base regressor stacked over the samples of an excitation CSV (t, q, dq, ddq)."""
    import numpy as np

    a = np.loadtxt(csv, delimiter=",", skiprows=1)
    n = (a.shape[1] - 1) // 3
    model = symoro_gen.load_model("scara")
    W = np.asarray(model.regressor(a[:, 1:1 + n], a[:, 1 + n:1 + 2 * n], a[:, 1 + 2 * n:])).reshape(
        -1, len(model.BASE_NAMES))
    return float(np.linalg.cond(W))


def test_a_full_disk_names_the_file_being_written(tmp_path, cli, monkeypatch):
    """ENOSPC surfaces when the written bytes reach the disk (``fsync``) and carries no file name: the error names
    the output the command was writing (and leaves neither it nor a temporary file)."""
    import errno
    import os

    import symoro_gen.atomic as atomic

    def full(fd):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(atomic.os, "fsync", full)
    out = tmp_path / "scara.urdf"
    r = cli("export-urdf", "scara", "-o", out, rc=2)
    assert r.err_lines[0] == f"symoro-gen: error: cannot write {out}: No space left on device"
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(OSError) as err:
        atomic.write_text_atomic(tmp_path / "x.json", "{}")
    assert err.value.errno == errno.ENOSPC and err.value.filename == str(tmp_path / "x.json")


def test_an_over_actuated_four_bar_is_refused_when_its_file_is_read(tmp_path, cli):
    """A four-bar (one degree of freedom) with two actuated joints: refused by ``generate`` (and any load of the
    file), naming the loop, its joints and the actuated ones, instead of a closure failure in ``load_model``."""
    from tests.closedloop.test_fourbar_lagrangian import fourbar_text

    text = fourbar_text()
    over = text.replace("j = 2\nant = 1\nsigma = 0\nmu = 0\n", "j = 2\nant = 1\nsigma = 0\n", 1)
    assert over != text
    f = tmp_path / "fourbar.toml"
    f.write_text(over)
    r = cli("generate", f, "--out", tmp_path / "gen", rc=2)
    assert r.err_lines[0] == (f"symoro-gen: error: {f}, loop 1, field 'mu': over-actuated: the loop through joints "
                              "1, 2, 3 and its cut joint 4 is planar (3 closure equations) and has 1 degree(s) of "
                              "freedom, but its actuated joints are 1, 2: make all but 1 of them passive (mu = 0)")
    assert not (tmp_path / "gen").exists()
    f.write_text(text)  # the four-bar as it is (one actuated joint) is read
    assert [r.mu for r in load_robot(str(f)).rows if r.is_moving] == [1, 0, 0]


def _spherical_fourbar(actuated: tuple[int, ...]) -> str:
    """A spherical four-bar: four revolute joints whose axes all pass through the base origin (every MDH frame
    at the origin, d = r = 0; twist angles 60, 90, 45 degrees), so that only the orientation closes the loop:
    3 closure equations, 4 - 3 = 1 degree of freedom (Chiang, "Kinematics of spherical mechanisms", 1988).
    The closing frame is placed where the cut frame is at the reference configuration (q1..q4 = 0.3, 0.5,
    -0.4, 0.7), by the Z-X-Z angles of the rotation between them: the loop is assembled there by construction."""
    import numpy as np

    def rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    def rx(a):
        return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])

    a2, a3, a4 = np.pi / 3, np.pi / 2, np.pi / 4
    q = {1: 0.3, 2: 0.5, 3: -0.4, 4: 0.7}
    r_cut = rz(q[1]) @ rx(a2) @ rz(q[2]) @ rx(a4) @ rz(q[4])
    rel = (rx(a3) @ rz(q[3])).T @ r_cut                  # frame 3 -> cut frame: Rz(gamma) Rx(alpha) Rz(theta)
    al = float(np.arccos(np.clip(rel[2, 2], -1, 1)))
    ga, th = float(np.arctan2(rel[0, 2], -rel[1, 2])), float(np.arctan2(rel[2, 0], rel[2, 1]))
    assert np.allclose(rz(ga) @ rx(al) @ rz(th), rel)
    frames = "".join(f"[[frames]]\nj = {j}\nant = {ant}\nsigma = 0\nmu = {int(j in actuated)}\nalpha = {al_j!r}\n"
                     "d = 0\ntheta = \"q\"\nr = 0\n" for j, ant, al_j in ((1, 0, 0.0), (2, 1, a2), (3, 0, a3)))
    return (f'name = "sphere4"\ngravity = [0, 0, -9.81]\n{frames}'
            f'[[loops]]\ncut = {{ ant = 2, sigma = 0, alpha = {a4!r}, d = 0, theta = "q", r = 0 }}\n'
            f"close = {{ ant = 3, sigma = 2, gamma = {ga!r}, alpha = {al!r}, d = 0, theta = {th!r}, r = 0 }}\n"
            "[loop_reference]\n" + "".join(f"q{j} = {v}\n" for j, v in q.items()))


def test_an_over_actuated_spatial_loop_is_refused_when_its_file_is_read(tmp_path, cli):
    """A loop that is not planar (a spherical four-bar: 3 closure equations, one degree of freedom) with two
    actuated joints: refused when the file is read (``generate``, ``check``, any load), naming the loop, its joints,
    the number of closure equations at its reference assembly and the actuated joints; with one it is read."""
    f = tmp_path / "sphere4.toml"
    f.write_text(_spherical_fourbar(actuated=(1, 2)))
    r = cli("generate", f, "--out", tmp_path / "gen", rc=2)
    assert r.err_lines[0] == (f"symoro-gen: error: {f}, loop 1, field 'mu': over-actuated: the loop through joints "
                              "1, 2, 3 and its cut joint 4 is not planar (3 independent closure equations at its "
                              "reference assembly) and has 1 degree(s) of freedom, but its actuated joints are 1, 2: "
                              "make all but 1 of them passive (mu = 0)")
    assert not (tmp_path / "gen").exists()
    f.write_text(_spherical_fourbar(actuated=(1,)))
    assert [r.mu for r in load_robot(str(f)).rows if r.is_moving] == [1, 0, 0]


@pytest.mark.parametrize("option, value, words", [
    ("--starts", "0", "--starts 0: at least one start is needed"),
    ("--refine", "-2", "--refine -2: must be a number of iterations >= 0"),
])
def test_excite_counts_below_their_minimum_are_refused_naming_the_option(option, value, words, cli, tmp_path):
    """``excite --starts 0`` ended in an AssertionError deep in the optimiser: refused before any work (no output
    written), naming the option."""
    out = tmp_path / "x.csv"
    r = cli("excite", "scara", "-o", out, option, value, rc=2)
    assert r.err_lines[0] == f"symoro-gen: error: {words}"
    assert not out.exists()


def test_the_reliability_table_cites_tests_that_exist():
    """docs/reliability.md maps each bad input to its behaviour and its test: every ``file.py::test_name`` it cites
    (a bare ``::test_name`` is in the file cited before it on the row) is a test function of that file."""
    doc = (ROOT / "docs" / "reliability.md").read_text()
    cited = 0
    for line in doc.splitlines():
        if not line.startswith("|"):
            continue
        current = None
        for m in re.finditer(r"`([\w/]+\.py)?::(test_\w+)`", line):
            current = m.group(1) or current
            assert current is not None, line
            assert f"def {m.group(2)}(" in (ROOT / "tests" / current).read_text(), (current, m.group(2))
            cited += 1
    assert cited >= 30
