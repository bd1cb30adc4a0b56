"""SYMORO .par import/export: hand-made fixtures in SYMORO+ and OpenSYMORO syntax, round trips,
errors naming file, line and field, and the atomic TOML writer."""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from symoro_gen.description import load_robot, parse_robot_text, q_symbol
from symoro_gen.description.par import export_par, import_par, import_par_text, write_robot_toml
from symoro_gen.dynamics.numeric import inverse_dynamics
from symoro_gen.errors import RobotFileError, SymoroError

FIXTURES = Path(__file__).resolve().parent / "fixtures"
RX90_PAR = FIXTURES / "rx90_symoro.par"
TREE_PAR = FIXTURES / "tree_opensymoro.par"


def same_robot(a, b) -> None:
    """Same MDH rows (exact expressions), gravity, geometric values, payload, drive terms, nominal values."""
    assert len(a.rows) == len(b.rows)
    for ra, rb in zip(a.rows, b.rows):
        assert (ra.j, ra.ant, ra.sigma, ra.mu, ra.drive) == (rb.j, rb.ant, rb.sigma, rb.mu, rb.drive), (ra, rb)
        for k in ("gamma", "b", "alpha", "d", "theta", "r"):
            ea, eb = getattr(ra, k), getattr(rb, k)
            assert sp.simplify(ea - eb) == 0, (ra.j, k, ea, eb)
    assert a.gravity == b.gravity
    assert dict(a.values) == dict(b.values)
    assert a.payload == b.payload
    assert (dict(a.nominal) if a.nominal is not None else None) == (dict(b.nominal) if b.nominal is not None else None)
    assert a.standard_names == b.standard_names and a.payload_names == b.payload_names


def round_trip(robot):
    par = export_par(robot)
    toml = import_par_text(par, file=f"{robot.name}.par")
    return parse_robot_text(toml, file="rt.toml"), par, toml


def torques(robot, seed: int, n_samples: int = 5):
    rng = np.random.default_rng(seed)
    n = robot.n_joints
    q, dq, ddq = (rng.uniform(-1.5, 1.5, (n_samples, n)) for _ in range(3))
    chi = rng.uniform(-1, 1, len(robot.standard_names))
    chi_p = rng.uniform(0.1, 1, len(robot.payload_names)) if robot.payload else None
    return inverse_dynamics(robot, q, dq, ddq, chi, chi_p)


# ============================================================================ import
def test_import_symoro_plus_rx90_matches_shipped_rx90():
    toml = import_par(RX90_PAR)
    assert f'source = "SYMORO .par file {RX90_PAR}"' in toml
    assert "G3" in toml.split("name =")[0]  # the gravity assumption is written down
    imported = parse_robot_text(toml, file="imported.toml")
    shipped = load_robot("rx90")
    assert imported.name == "RX90"
    assert imported.standard_names == shipped.standard_names and imported.payload_names == shipped.payload_names
    assert imported.payload == 7 and imported.gravity == (0.0, 0.0, -9.81)
    assert dict(imported.values) == {"d3": 0.45, "RL4": 0.45}
    assert imported.row(3).d == sp.Symbol("d3", real=True)  # constants stay symbolic
    assert imported.nominal_payload() == pytest.approx(shipped.nominal_payload())
    # same dynamics: numeric Newton-Euler on both descriptions
    np.testing.assert_allclose(torques(imported, 1), torques(shipped, 1), rtol=1e-12, atol=1e-12)


def test_import_opensymoro_tree():
    r = parse_robot_text(import_par(TREE_PAR))
    assert r.name == "tree3"
    assert [x.ant for x in r.rows] == [0, 1, 1, 3, 2] and [x.sigma for x in r.rows] == [0, 0, 1, 0, 2]
    q = [q_symbol(j) for j in range(1, 6)]
    assert r.row(2).theta == q[1] - sp.pi / 2  # offset
    assert r.row(4).theta == -q[3] + sp.pi / 4  # negative direction; atan2(1, 1) evaluated exactly
    assert r.row(3).r == q[2] and r.row(3).theta == 0 and r.row(3).gamma == sp.pi / 2  # prismatic, r3 -> q
    assert r.row(4).alpha == sp.pi / 2  # 1.57079632679000 snapped to the exact angle
    assert r.row(2).d == sp.Symbol("L2", real=True) and r.values["L2"] == 0.3
    assert r.row(5).b == pytest.approx(0.05) and r.payload is None  # fixed frame with zero inertia
    assert r.row(3).drive == ("FV", "FS", "OFF") and r.row(1).drive == ("IA", "FV", "FS", "OFF")
    assert dict(r.nominal) == {"FV1": 0.12, "M3": 2.5}
    assert r.gravity == pytest.approx((0.0, -9.81 * np.sin(0.1), -9.81 * np.cos(0.1)))


def test_latin1_symoro_plus_header(tmp_path):
    text = "(*       1 rue de la No\xeb, BP 92101         *)\n" + RX90_PAR.read_text()
    path = tmp_path / "rx90_latin1.par"
    path.write_bytes(text.encode("latin-1"))
    assert parse_robot_text(import_par(path)).n_joints == 6


def test_values_argument_overrides_file():
    r = parse_robot_text(import_par(TREE_PAR, values={"L2": 0.5}))
    assert r.values["L2"] == 0.5


def test_import_missing_value_asks_for_it():
    text = RX90_PAR.read_text().replace("d3 = 0.45\n", "")
    with pytest.raises(RobotFileError) as info:
        import_par_text(text, file="rx90.par")
    line = text.splitlines().index("        0,0,d3,0,0,0,0}") + 1
    (p,) = info.value.problems
    assert (p.file, p.where, p.field) == ("rx90.par", f"line {line}, frame 3", "d")
    assert "'d3' has no numeric value" in p.message and "d3 = <number>" in p.message and "values=" in p.message
    # ... and the value given as argument is enough
    r = parse_robot_text(import_par_text(text, file="rx90.par", values={"d3": 0.45}))
    assert r.values["d3"] == 0.45


# ============================================================================ export + round trip
@pytest.mark.parametrize("name", ["lwr4", "rx90", "scara"])
def test_round_trip_shipped(name):
    robot = load_robot(name)
    back, par, toml = round_trip(robot)
    same_robot(robot, back)
    # the export of the imported robot is the same file (idempotent), comments aside
    def strip(t):
        return [l for l in t.splitlines() if not l.startswith("(*")]
    assert strip(export_par(back)) == strip(par)


def test_export_syntax_rx90():
    par = export_par("rx90")
    lines = par.splitlines()
    assert "(* Robotname = 'rx90' *)" in lines
    assert {"NF = 7", "NL = 7", "NJ = 7", "Type = 0 (* Simple *)"} <= set(lines)
    assert "Ant = {0,1,2,3,4,5,6}" in lines and "Sigma = {0,0,0,0,0,0,2}" in lines
    assert "Alpha = {0,-Pi/2,0,Pi/2,-Pi/2,Pi/2,0}" in lines
    assert "Theta = {t1,t2,t3,t4,t5,t6,0}" in lines and "R = {0,0,0,RL4,0,0,0}" in lines
    assert "M = {M1,M2,M3,M4,M5,M6,7.025}" in lines and "IA = {IA1,IA2,IA3,IA4,IA5,IA6,0}" in lines
    assert "G = {0,0,-9.81}" in lines and "D3 = 0.45" in lines
    # a list never shares its line with a comment (OpenSYMORO's reader skips such lines)
    assert not [l for l in lines if "{" in l and "(*" in l]


def test_export_lwr4_excludes_ia():
    lines = export_par("lwr4").splitlines()
    # lwr4 carries nominal values (URDF), exported as numbers; IA is excluded on every joint
    assert "IA = {0,0,0,0,0,0,0,0}" in lines
    fv = next(ln for ln in lines if ln.startswith("FV = {"))
    assert fv.endswith(",0}") and fv.count(",") == 7
    assert "Type = 0 (* Simple *)" in lines and any(ln.startswith("M = {") and ln.endswith(",4.6136}") for ln in lines)


def test_round_trip_fixture_files():
    for path in (RX90_PAR, TREE_PAR):
        robot = parse_robot_text(import_par(path))
        back, par, _ = round_trip(robot)
        same_robot(robot, back)
    assert "Type = 1 (* Tree *)" in export_par(parse_robot_text(import_par(TREE_PAR)))


TRICKY = """\
name = "tricky"
source = "round-trip test"
gravity = [0.5, 0, -9.7]
payload = 5
drive = ["FV", "OFF"]

[values]
t2 = 0.1
L1 = 0.25
A3 = 0.3

[[frames]]
j = 1
ant = 0
sigma = 1
gamma = "pi/6"
b = "L1"
alpha = 0
d = 0
theta = "pi/3"
r = "-q + L1"

[[frames]]
j = 2
ant = 1
sigma = 0
alpha = "-pi/2"
d = "t2"
theta = "-q - pi/2"
r = 0
drive = ["IA", "FV", "FS", "OFF"]

[[frames]]
j = 3
ant = 1
sigma = 0
mu = 0
alpha = "A3"
d = "L1*sqrt(2)/2"
theta = "q + 0.1"
r = 0

[[frames]]
j = 4
ant = 2
sigma = 0
alpha = 1.2
d = 0.1
theta = "q"
r = 0
drive = []

[[frames]]
j = 5
ant = 4
sigma = 2
alpha = 0
d = 0
theta = 0
r = 0.05

[nominal]
FV1 = 0.0
OFF2 = 0.0
IA2 = 0.01
XX2 = 0.0
M2 = 3.0
MX5 = 0.0
"""


def test_round_trip_tricky_robot():
    """Tree, prismatic with -q, a constant named like a joint variable (t2), passive joint,
    drive terms excluded per joint, nominal zeros, a payload with only a zero nominal value."""
    robot = parse_robot_text(TRICKY)
    back, par, toml = round_trip(robot)
    same_robot(robot, back)
    assert "Theta = {Pi/3,-th2-Pi/2,th3+0.1,th4,0}" in par.splitlines()  # t2 is taken: th<j>
    assert "R = {L1-r1,0,0,0,0.05}" in par.splitlines() and "B = {L1,0,0,0,0}" in par.splitlines()
    assert "FV1 = 0" in par.splitlines()  # a zero nominal value of a kept parameter
    np.testing.assert_allclose(torques(back, 3), torques(robot, 3), rtol=1e-12, atol=1e-12)


_ANGLES = st.sampled_from(["0", '"pi/2"', '"-pi/2"', '"pi"', '"pi/4"', "0.3", "-1.1"])
_LENGTHS = st.sampled_from(["0", "0.4", '"LB"', '"LB + 0.1"'])


@st.composite
def random_robot(draw):
    """A random tree of 2-6 revolute/prismatic joints (offsets, signs, symbolic constants, drive
    subsets, nominal values), with or without a payload frame."""
    n = draw(st.integers(2, 6))
    payload = n + 1 if draw(st.booleans()) else None
    gx = draw(st.sampled_from([0.0, 0.5, -2.25]))
    lines = ['name = "rnd"', f"gravity = [{gx}, 0, -9.81]", 'drive = ["IA", "FV", "FS", "OFF"]']
    if payload:
        lines.append(f"payload = {payload}")
    lines += ["", "[values]", "LA = 0.31", "LB = -0.2", ""]
    for j in range(1, n + 1):
        sigma = draw(st.sampled_from([0, 0, 1]))
        sign = draw(st.sampled_from(["", "-"]))
        off = draw(st.sampled_from(["", " - pi/2", " + 0.2", " + LA"]))
        var = f'"{sign}q{off}"'
        theta, r = (var, draw(_LENGTHS)) if sigma == 0 else (draw(_ANGLES), var)
        lines += ["[[frames]]", f"j = {j}", f"ant = {draw(st.integers(0, j - 1))}", f"sigma = {sigma}",
                  f"alpha = {draw(_ANGLES)}", f"d = {draw(_LENGTHS)}", f"theta = {theta}", f"r = {r}"]
        if draw(st.booleans()):
            drv = draw(st.lists(st.sampled_from(["IA", "FV", "FS", "OFF"]), unique=True))
            lines.append("drive = [" + ", ".join(f'"{d}"' for d in drv) + "]")
        lines.append("")
    if payload:
        lines += ["[[frames]]", f"j = {payload}", f"ant = {n}", "sigma = 2", "alpha = 0", "d = 0.1", "theta = 0",
                  "r = 0", ""]
    head = "\n".join(lines) + "\n"
    names = [f"{k}{j}" for j in range(1, n + 1) for k in ("XX", "M", "FV")]
    if payload:
        names += [f"MZ{payload}", f"M{payload}"]
    nominal = draw(st.dictionaries(st.sampled_from(names), st.sampled_from([0.0, 1.5, -0.25]), max_size=4))
    # masses and friction coefficients are non-negative (a robot file rejects negative ones)
    nominal = {k: (abs(v) if k[:1] in "MF" and not k.startswith("MZ") else v) for k, v in nominal.items()}
    robot = parse_robot_text(head)
    allowed = set(robot.standard_names) | set(robot.payload_names)
    nominal = {k: v for k, v in nominal.items() if k in allowed}
    if nominal:
        head += "[nominal]\n" + "".join(f"{k} = {v}\n" for k, v in nominal.items())
    return parse_robot_text(head)


@settings(max_examples=25, deadline=None)
@given(random_robot())
def test_round_trip_random_robots(robot):
    back, _, _ = round_trip(robot)
    same_robot(robot, back)


# ============================================================================ errors
def par_error(text: str, **kw) -> RobotFileError:
    with pytest.raises(RobotFileError) as info:
        import_par_text(text, file="robot.par", **kw)
    return info.value


def line_no(text: str, fragment: str) -> int:
    """Number of the first line starting with ``fragment``."""
    return next(i for i, l in enumerate(text.splitlines(), start=1) if l.startswith(fragment))


def has(err: RobotFileError, where: str, field: str, *words: str) -> None:
    hits = [p for p in err.problems if p.file == "robot.par" and p.where == where and p.field == field]
    assert hits, f"nothing at {where!r} {field!r} in:\n{err}"
    msg = " ".join(p.message for p in hits).lower()
    assert all(w.lower() in msg for w in words), msg
    assert "robot.par" in str(err) and where in str(err)


BASE = TREE_PAR.read_text()


@pytest.mark.parametrize("old, new, fragment, frame, field, words", [
    ("d = {0,L2,0,0,0}", "d = {0,L2,0,0,D9}", "d = {0,L2", 5, "d", ["'D9' has no numeric value", "D9 = <number>"]),
    ("d = {0,L2,0,0,0}", "d = {0,L2,0,0,__import__('os')}", "d = {0,L2", 5, "d", ["call of '__import__'"]),
    ("d = {0,L2,0,0,0}", "d = {0,L2,0,0,L2.real}", "d = {0,L2", 5, "d", ["attribute access"]),
    ("d = {0,L2,0,0,0}", "d = {0,L2,0,0,3*/2}", "d = {0,L2", 5, "d", ["cannot parse"]),
    ("d = {0,L2,0,0,0}", "d = {0,L2,th1,0,0}", "d = {0,L2", 3, "d", ["joint variable of frame 1"]),
    ("theta = {th1,", "theta = {0,", "theta = {", 1, "theta", ["needs its joint variable"]),
    ("theta = {th1,", "theta = {th1+X7,", "theta = {", 1, "theta", ["several symbols", "th1", "X7"]),
    ("theta = {th1,", "theta = {2*th1,", "theta = {", 1, "theta", ["th1 + constant"]),
    ("sigma = {0,0,1,0,2}", "sigma = {0,0,3,0,2}", "sigma = {", 3, "sigma", ["0 (revolute)"]),
    ("sigma = {0,0,1,0,2}", "sigma = {0,0.5,1,0,2}", "sigma = {", 2, "sigma", ["integer"]),
    ("ant = {0,1,1,3,2}", "ant = {0,1,1,4,2}", "ant = {", 4, "ant", ["points forward"]),
    ("ant = {0,1,1,3,2}", "ant = {0,-1,1,3,2}", "ant = {", 2, "ant", ["out of range"]),
    ("mu = {1,1,1,1,0}", "mu = {1,1,1,1,1}", "mu = {", 5, "mu", ["cannot be actuated"]),
    ("M = {M1,M2,2.5,M4,0}", "M = {M1,M2,2*M3,M4,0}", "M = {", 3, "M", ["number or a single parameter symbol"]),
    ("YZ = {YZ1,", "YZ = {YY1,", "YZ = {", 1, "YZ", ["YY1 already stands for YY1"]),
])
def test_import_errors_name_line_frame_field(old, new, fragment, frame, field, words):
    assert old in BASE
    text = BASE.replace(old, new, 1)
    err = par_error(text)
    has(err, f"line {line_no(text, fragment)}, frame {frame}", field, *words)


@pytest.mark.parametrize("old, new, fragment, field, words", [
    ("Type = 1", "Type = 2", "Type = 2", "Type", ["closed-loop"]),
    ("NJ = 5", "NJ = 6", "NJ = 6", "NJ", ["closed loops"]),
    ("NL = 5\nNJ = 5", "NL = 4\nNJ = 4", "NL = 4", "NL", ["differs from the number of frames 5"]),
    ("is_mobile = 0", "is_mobile = 1", "is_mobile", "is_mobile", ["fixed-base"]),
    ("NL = 5", "NL = five", "NL = five", "NL", ["integer"]),
    ("b = {0,0,0,0,0.05}", "b = {0,0,0,0}", "b = {", "b", ["4 entries, expected 5"]),
    ("FS = {FS1,FS2,FS3,FS4,0}", "FS = {FS1,FS2,FS3,FS4}", "FS = {", "FS", ["4 entries, expected 5"]),
    ("W0 = {0,0,0}", "W0 = {0,0,1}", "W0 = {", "W0", ["fixed-base"]),
    ("Z = {1,0,0,0,", "Z = {0,1,0,0,", "Z = {", "Z", ["identity"]),
    ("G = {0,-9.81*sin(0.1),-9.81*cos(0.1)}", "G = {G1,0,G3}", "G = {", "G", ["G1, G3", "no numeric value"]),
    ("G = {0,-9.81*sin(0.1),-9.81*cos(0.1)}", "G = {0,0}", "G = {", "G", ["3 entries"]),
    ("QP = {", "QQ = {", "QQ = {", "QQ", ["unknown list"]),
    ("L2 = 0.3", "L2 = short", "L2 = short", "L2", ["must be a number"]),
    ("gamma = {0,0,pi/2,0,0}", "gamma = {0,0,pi/2,0,0}\ngamma = {0,0,0,0,0}", "gamma = {0,0,0,", "gamma",
     ["given twice"]),
    ("GAM = {GAM1,GAM2,GAM3,GAM4,GAM5}", "GAM = {GAM1,GAM2,GAM3,GAM4,GAM5", "GAM = {", "GAM", ["never closed"]),
    ("G = {", "G = {0,0,-9.81} extra\nGX = {", "G = {0,0,-9.81} extra", "G", ["unexpected text"]),
    ("d = {0,L2,0,0,0}", "d = {0,L2,,0,0}", "d = {", "d", ["empty entry number 3"]),
])
def test_import_errors_name_line_field(old, new, fragment, field, words):
    assert old in BASE
    text = BASE.replace(old, new, 1)
    err = par_error(text)
    has(err, f"line {line_no(text, fragment)}", field, *words)


def test_missing_list_and_garbage_and_open_comment():
    text = BASE.replace("alpha = {0,pi/2,0,1.57079632679000,0}\n", "")
    has(par_error(text), "", "Alpha", "missing list")
    text = BASE.replace("(* Joint parameters *)", "Joint parameters follow")
    has(par_error(text), f"line {line_no(text, 'Joint parameters follow')}", "", "expected 'NAME = {...}'")
    text = BASE.replace("(* Joint parameters *)", "(* Joint parameters")
    has(par_error(text), f"line {line_no(text, '(* Joint parameters')}", "", "never closed")


def _append_frame(text: str, entries: dict[str, str], default: str = "0") -> str:
    """Add a 6th frame/link to the tree fixture: one more entry at the end of every list."""
    out = []
    for line in text.splitlines():
        m = re.match(r"^(\w+) = \{(.*)\}$", line)
        if m and m.group(1) not in ("W0", "WP0", "V0", "VP0", "G", "Z"):
            line = f"{m.group(1)} = {{{m.group(2)},{entries.get(m.group(1), default)}}}"
        out.append(line)
    return "\n".join(out).replace("NL = 5\nNJ = 5\nNF = 5", "NL = 6\nNJ = 6\nNF = 6") + "\n"


def test_two_payload_candidates():
    # frame 6 fixed to frame 5; frames 5 and 6 both carry a mass
    text = _append_frame(BASE, {"ant": "5", "sigma": "2", "mu": "0", "theta": "0"})
    text = text.replace("M = {M1,M2,2.5,M4,0,0}", "M = {M1,M2,2.5,M4,1.5,M6}")
    err = par_error(text)
    (p,) = err.problems
    has(err, f"line {line_no(text, 'XX = {')}", "XX", "fixed frames [5, 6]", "one payload", "payload=")
    # choosing one is not enough while the other still carries inertia
    err = par_error(text, payload=6)
    has(err, f"line {line_no(text, 'XX = {')}", "XX", "fixed frames [5]", "payload is frame 6")
    # once the other is cleared, the chosen payload is used
    r = parse_robot_text(import_par_text(text.replace("1.5,M6}", "0,M6}"), file="robot.par"))
    assert r.payload == 6 and r.payload_names[-1] == "M6"
    assert parse_robot_text(import_par_text(_append_frame(BASE, {"ant": "5", "sigma": "2", "mu": "0", "theta": "0"}),
                                            file="robot.par")).payload is None


def test_every_problem_listed_once():
    text = BASE.replace("Type = 1", "Type = 7").replace("sigma = {0,0,1,0,2}", "sigma = {0,0,1,9,2}")
    text = text.replace("d = {0,L2,0,0,0}", "d = {0,L2,0,0,D9}").replace("QP = {", "QQ = {")
    err = par_error(text)
    got = {(p.where, p.field) for p in err.problems}
    assert {(f"line {line_no(text, 'Type = 7')}", "Type"), (f"line {line_no(text, 'sigma = {')}, frame 4", "sigma"),
            (f"line {line_no(text, 'd = {0,L2')}, frame 5", "d"), (f"line {line_no(text, 'QQ = {')}", "QQ")} <= got
    assert len(err.problems) == 4, str(err)  # no cascade (th4 is not reported as a constant without value)


def test_missing_par_file(tmp_path):
    with pytest.raises(RobotFileError, match="file not found"):
        import_par(tmp_path / "nope.par")


# ============================================================================ writing
def test_write_robot_toml(tmp_path):
    text = import_par(RX90_PAR)
    dest = tmp_path / "rx90_imported.toml"
    assert write_robot_toml(text, dest) == dest
    assert dest.read_text() == text
    same_robot(parse_robot_text(text), load_robot(dest))
    # refuses to overwrite, file untouched
    other = import_par(TREE_PAR)
    with pytest.raises(FileExistsError, match="not overwritten") as info:
        write_robot_toml(other, dest)
    assert isinstance(info.value, SymoroError) and "--force" in info.value.hint
    assert dest.read_text() == text
    write_robot_toml(other, dest, overwrite=True)
    assert dest.read_text() == other
    # invalid text: nothing written
    bad = tmp_path / "bad.toml"
    with pytest.raises(RobotFileError):
        write_robot_toml(text.replace("sigma = 2", "sigma = 5"), bad)
    assert not bad.exists()
    assert sorted(os.listdir(tmp_path)) == ["rx90_imported.toml"]  # no temporary file left


def test_round_trip_shared_strategy():
    """Round trip over the project's shared random MDH robots (gamma, b, payloads, symbolic constants)."""
    strategies = pytest.importorskip("tests.strategies", reason="tests/strategies.py (shared robot strategy) absent")

    @settings(max_examples=20, deadline=None)
    @given(strategies.mdh_robots(2, 6, random_gravity=True))
    def check(text):
        robot = parse_robot_text(text)
        back, _, _ = round_trip(robot)
        same_robot(robot, back)

    check()


def test_cli_import_par(tmp_path, cli):
    out = tmp_path / "rx90.toml"
    cli("--quiet", "import-par", RX90_PAR, "-o", out, rc=0)
    assert out.read_text() == import_par(RX90_PAR)
    before = out.read_text()
    err = cli("import-par", TREE_PAR, "-o", out, rc=2).err  # exists: refused
    assert out.read_text() == before and "not overwritten" in err
    cli("--quiet", "import-par", TREE_PAR, "-o", out, "--force", rc=0)
    assert "tree3" in out.read_text()
    bad = tmp_path / "bad.par"
    bad.write_text(BASE.replace("Type = 1", "Type = 2"))
    err = cli("import-par", bad, "-o", tmp_path / "bad.toml", rc=2).err
    assert "bad.par" in err and "line 7" in err and "Type" in err and not (tmp_path / "bad.toml").exists()


def test_huge_float_angle_is_refused_with_its_field():
    # found by tests/fuzz: snapping gamma = 1e308 to a multiple of pi/12 overflowed round(); such a value is
    # not an angle of a robot: refused, naming the frame and the field (robot numbers are finite, |x| <= 1e12)
    from symoro_gen.description import load_robot as _load
    from symoro_gen.description.par import export_par, import_par_text
    from symoro_gen.errors import RobotFileError

    text = export_par(_load("scara")).replace("gamma = {0,0,0,0}", "gamma = {1e308,0,0,0}")
    with pytest.raises(RobotFileError) as err:
        parse_robot_text(import_par_text(text))
    msg = str(err.value)
    assert "frame 1" in msg and "'gamma'" in msg and "1e+12" in msg
