"""Robot files (TOML): the shipped robots parse as documented; every kind of bad file is
rejected with one RobotFileError naming file, frame (or line) and field of each problem."""
from __future__ import annotations

import math

import pytest
import sympy as sp

from symoro_gen.description import load_robot, parse_robot, parse_robot_text, q_symbol, robots_dir
from symoro_gen.errors import RobotFileError
from symoro_gen.params import INERTIAL_KINDS, PARAM_KINDS

# A small valid robot: RRP arm + payload frame 4 fixed to frame 3.
GOOD = """\
name = "tiny"
source = "test fixture"
gravity = [0, 0, -9.81]
payload = 4
drive = ["IA", "FV", "FS", "OFF"]

[values]
L2 = 0.3

[[frames]]
j = 1
ant = 0
sigma = 0
alpha = 0
d = 0
theta = "q"
r = 0

[[frames]]
j = 2
ant = 1
sigma = 0
alpha = "pi/2"
d = "L2"
theta = "q - pi/2"
r = 0

[[frames]]
j = 3
ant = 2
sigma = 1
alpha = 0
d = 0
theta = 0
r = "q"

[[frames]]
j = 4
ant = 3
sigma = 2
alpha = 0
d = 0
theta = 0
r = 0

[nominal]
M4 = 1.5
"""


def frame_block(text: str, j: int) -> tuple[int, int]:
    """Start and end offsets of the [[frames]] block with j = <j> in ``text``."""
    start = text.index(f"[[frames]]\nj = {j}\n")
    end = text.find("\n[", start + 1)
    return start, (len(text) if end < 0 else end + 1)


def edit_frame(text: str, j: int, old: str, new: str) -> str:
    s, e = frame_block(text, j)
    block = text[s:e]
    assert old in block, (old, block)
    return text[:s] + block.replace(old, new, 1) + text[e:]


def errors_of(text: str, tmp_path, name: str = "bad.toml") -> tuple[RobotFileError, str]:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    with pytest.raises(RobotFileError) as info:
        parse_robot(path)
    return info.value, str(path)


def assert_problem(err: RobotFileError, file: str, where: str, field: str, *words: str) -> None:
    """One problem of ``err`` is at (file, where, field) and its message contains ``words``;
    the rendered error text names the file, the place and the field."""
    hits = [p for p in err.problems if p.file == file and p.where == where and p.field == field]
    assert hits, f"no problem at {where!r} field {field!r} in:\n{err}"
    msg = " ".join(p.message for p in hits).lower()
    for w in words:
        assert w.lower() in msg, f"{w!r} not in {msg!r}"
    text = str(err)
    assert file in text and where in text and (f"field '{field}'" in text if field else True)


def test_fixture_is_valid(tmp_path):
    p = tmp_path / "tiny.toml"
    p.write_text(GOOD)
    robot = parse_robot(p)
    assert robot.n_joints == 3 and robot.payload == 4 and robot.file == str(p)
    assert robot.standard_names[:14] == tuple(
        f"{k}1" for k in PARAM_KINDS
    )


# ---------------------------------------------------------------- malformed TOML
def test_malformed_toml_names_file_and_line(tmp_path):
    text = GOOD.replace('alpha = "pi/2"', 'alpha = "pi/2', 1)  # unterminated string
    line = text.splitlines().index('alpha = "pi/2') + 1
    err, file = errors_of(text, tmp_path)
    assert len(err.problems) == 1
    p = err.problems[0]
    assert p.file == file and p.where.startswith(f"line {line},")
    assert "malformed TOML" in p.message
    assert file in str(err) and f"line {line}" in str(err)


def test_not_utf8_and_missing_file(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(GOOD.replace("test fixture", "caf\xe9").encode("latin-1"))
    with pytest.raises(RobotFileError, match="not UTF-8"):
        parse_robot(path)
    with pytest.raises(RobotFileError, match="file not found"):
        parse_robot(tmp_path / "nope.toml")


# ---------------------------------------------------------------- fields
@pytest.mark.parametrize("fld", ["ant", "sigma", "alpha", "d", "theta", "r", "j"])
def test_missing_frame_field(tmp_path, fld):
    s, e = frame_block(GOOD, 2)
    block = "\n".join(l for l in GOOD[s:e].splitlines() if not l.startswith(f"{fld} =")) + "\n"
    err, file = errors_of(GOOD[:s] + block + GOOD[e:], tmp_path)
    where = "frame 2"
    assert_problem(err, file, where, fld, "missing")


def test_missing_frames_table(tmp_path):
    text = GOOD[: GOOD.index("[[frames]]")]
    err, file = errors_of(text, tmp_path)
    assert_problem(err, file, "top level", "frames", "missing")


def test_unknown_top_level_field(tmp_path):
    err, file = errors_of("colour = 'red'\n" + GOOD, tmp_path)
    assert_problem(err, file, "top level", "colour", "unknown field")


def test_unknown_frame_field(tmp_path):
    err, file = errors_of(edit_frame(GOOD, 3, "r = \"q\"", "r = \"q\"\nlength = 2"), tmp_path)
    assert_problem(err, file, "frame 3", "length", "unknown field")


# ---------------------------------------------------------------- structure
@pytest.mark.parametrize("sigma", ["3", "-1", "true", '"0"', "0.5"])
def test_sigma_outside_0_1_2(tmp_path, sigma):
    err, file = errors_of(edit_frame(GOOD, 2, "sigma = 0", f"sigma = {sigma}"), tmp_path)
    assert_problem(err, file, "frame 2", "sigma", "0 (revolute), 1 (prismatic) or 2 (fixed)")


def test_ant_pointing_forward(tmp_path):
    err, file = errors_of(edit_frame(GOOD, 2, "ant = 1", "ant = 3"), tmp_path)
    assert_problem(err, file, "frame 2", "ant", "points forward")
    err, file = errors_of(edit_frame(GOOD, 2, "ant = 1", "ant = 2"), tmp_path)
    assert_problem(err, file, "frame 2", "ant", "points forward")


def test_ant_out_of_range(tmp_path):
    err, file = errors_of(edit_frame(GOOD, 1, "ant = 0", "ant = -1"), tmp_path)
    assert_problem(err, file, "frame 1", "ant", "out of range")
    err, file = errors_of(edit_frame(GOOD, 3, "ant = 2", 'ant = "two"'), tmp_path)
    assert_problem(err, file, "frame 3", "ant", "integer")


def test_frames_misnumbered(tmp_path):
    text = edit_frame(GOOD, 3, "j = 3", "j = 5")
    err, file = errors_of(text, tmp_path)
    assert_problem(err, file, "frame 5", "j", "numbered 1, 2, ...", "entry 3")


def test_moving_frame_after_fixed_one(tmp_path):
    text = edit_frame(GOOD, 2, "sigma = 0", "sigma = 2")
    text = edit_frame(text, 2, 'theta = "q - pi/2"', "theta = 0")
    err, file = errors_of(text.replace("payload = 4\n", ""), tmp_path)
    assert_problem(err, file, "frame 3", "sigma", "moving frames must come before fixed ones")


# ---------------------------------------------------------------- expressions
@pytest.mark.parametrize("expr, words", [
    ('"pi/"', ["cannot parse"]),
    ('"q - - "', ["cannot parse"]),
    ('""', ["empty"]),
    ('"1/0"', ["division by zero"]),
    ('"tan(pi/2)"', ["not finite"]),
    ("nan", ["finite"]),
    ('"2**10**10"', ["exponent"]),
])
def test_unparsable_expression(tmp_path, expr, words):
    err, file = errors_of(edit_frame(GOOD, 2, 'alpha = "pi/2"', f"alpha = {expr}"), tmp_path)
    assert_problem(err, file, "frame 2", "alpha", *words)


@pytest.mark.parametrize("expr, words", [
    ("\"__import__('os')\"", ["call of '__import__'"]),
    ('"math.pi"', ["attribute access"]),
    ('"L2.real"', ["attribute access"]),
    ('"(lambda: 1)()"', ["call"]),
    ('"L2[0]"', ["indexing"]),
    ('"open(\'x\')"', ["call of 'open'"]),
    ('"L2 if L2 else 0"', ["conditional"]),
    ('"\'abc\'"', ["constant"]),
])
def test_forbidden_constructs(tmp_path, expr, words):
    err, file = errors_of(edit_frame(GOOD, 2, 'd = "L2"', f"d = {expr}"), tmp_path)
    assert_problem(err, file, "frame 2", "d", *words)


def test_symbol_without_value(tmp_path):
    err, file = errors_of(edit_frame(GOOD, 3, "d = 0", 'd = "L3"'), tmp_path)
    assert_problem(err, file, "frame 3", "d", "L3", "[values]")


def test_value_not_a_number(tmp_path):
    err, file = errors_of(GOOD.replace("L2 = 0.3", 'L2 = "short"'), tmp_path)
    assert_problem(err, file, "[values]", "L2", "number")
    # the symbol's uses are not reported a second time as "no numeric value" (one bad field, one line)
    assert [(p.where, p.field) for p in err.problems] == [("[values]", "L2")]


def test_reserved_value_name(tmp_path):
    err, file = errors_of(GOOD.replace("L2 = 0.3", "L2 = 0.3\nq = 1.0"), tmp_path)
    assert_problem(err, file, "[values]", "q", "reserved")


@pytest.mark.parametrize("j, old, new, fld, words", [
    (2, "d = \"L2\"", 'd = "q"', "d", ["only appear in theta"]),
    (3, "theta = 0", 'theta = "q"', "theta", ["only appear in r"]),
    (4, "r = 0", 'r = "q"', "r", ["fixed frame", "no joint variable"]),
])
def test_q_in_wrong_field(tmp_path, j, old, new, fld, words):
    err, file = errors_of(edit_frame(GOOD, j, old, new), tmp_path)
    assert_problem(err, file, f"frame {j}", fld, *words)


@pytest.mark.parametrize("theta, words", [("0", ["must contain the joint variable"]),
                                          ('"2*q"', ["q + constant"]), ('"sin(q)"', ["q + constant"])])
def test_joint_field_without_plain_q(tmp_path, theta, words):
    err, file = errors_of(edit_frame(GOOD, 1, 'theta = "q"', f"theta = {theta}"), tmp_path)
    assert_problem(err, file, "frame 1", "theta", *words)


# ---------------------------------------------------------------- payload, gravity, drive, nominal, chain
def test_payload_on_missing_link(tmp_path):
    err, file = errors_of(GOOD.replace("payload = 4", "payload = 9"), tmp_path)
    assert_problem(err, file, "top level", "payload", "does not exist")


def test_bad_payload_reported_once(tmp_path):
    # the nominal M4 of the rejected payload frame is not reported a second time
    err, file = errors_of(GOOD.replace("payload = 4", "payload = 9").replace("M4 = 1.5", "M9 = 1.5"), tmp_path)
    assert [(p.where, p.field) for p in err.problems] == [("top level", "payload")]


def test_payload_on_moving_frame(tmp_path):
    err, file = errors_of(GOOD.replace("payload = 4", "payload = 2").replace("M4 = 1.5", "M2 = 1.5"), tmp_path)
    assert_problem(err, file, "frame 2", "sigma", "payload frame must be fixed")


def test_payload_not_an_integer(tmp_path):
    err, file = errors_of(GOOD.replace("payload = 4", 'payload = "4"'), tmp_path)
    assert_problem(err, file, "top level", "payload", "frame number")


@pytest.mark.parametrize("g", ["[0, -9.81]", '[0, 0, "g"]', "-9.81", "[0, 0, inf]", "[0, true, 0]"])
def test_bad_gravity(tmp_path, g):
    err, file = errors_of(GOOD.replace("gravity = [0, 0, -9.81]", f"gravity = {g}"), tmp_path)
    assert_problem(err, file, "top level", "gravity", "3 numbers")


@pytest.mark.parametrize("drive, words", [('["IA", "XX"]', ["unknown drive-chain", "XX"]),
                                          ('"FV"', ["must be a list"]), ("[1, 2]", ["must be a list"])])
def test_bad_drive_list(tmp_path, drive, words):
    err, file = errors_of(GOOD.replace('drive = ["IA", "FV", "FS", "OFF"]', f"drive = {drive}"), tmp_path)
    assert_problem(err, file, "top level", "drive", *words)
    err, file = errors_of(edit_frame(GOOD, 2, "r = 0", f"r = 0\ndrive = {drive}"), tmp_path)
    assert_problem(err, file, "frame 2", "drive", *words)


def test_drive_on_fixed_frame(tmp_path):
    err, file = errors_of(edit_frame(GOOD, 4, "r = 0", 'r = 0\ndrive = ["FV"]'), tmp_path)
    assert_problem(err, file, "frame 4", "drive", "no drive chain")


def test_drive_excludes_parameters():
    robot = parse_robot_text(edit_frame(GOOD, 2, "r = 0", 'r = 0\ndrive = ["FV", "OFF"]'))
    assert [n for n in robot.standard_names if n.endswith("2") and n[:2] in ("IA", "FV", "FS", "OF")] == ["FV2", "OFF2"]
    assert len(robot.standard_names) == 14 + 12 + 14


@pytest.mark.parametrize("nominal, key, words", [
    ("XX9 = 1.0", "XX9", ["not a standard parameter"]),
    ("FOO = 1.0", "FOO", ["not a standard parameter"]),
    ("IA4 = 1.0", "IA4", ["not a standard parameter"]),  # payload has no drive terms
    ('M1 = "heavy"', "M1", ["number"]),
])
def test_bad_nominal_names(tmp_path, nominal, key, words):
    err, file = errors_of(GOOD.replace("M4 = 1.5", nominal), tmp_path)
    assert_problem(err, file, "[nominal]", key, *words)


def test_nominal_of_excluded_drive_term(tmp_path):
    text = edit_frame(GOOD, 1, 'theta = "q"', 'theta = "q"\ndrive = ["FV"]').replace("M4 = 1.5", "IA1 = 0.1")
    err, file = errors_of(text, tmp_path)
    assert_problem(err, file, "[nominal]", "IA1", "not a standard parameter")


@pytest.mark.parametrize("chain, key, words", [
    ("ratios = [100, 100]", "ratios", ["list of 3 numbers"]),
    ("ratios = [100, 0, 50]", "ratios", ["non-zero"]),
    ("directions = [1, 2, -1]", "directions", ["+1 or -1"]),
    ("coupling = [[1, 0, 0], [1, 0, 0], [0, 0, 1]]", "coupling", ["singular"]),
    ("coupling = [[1, 0], [0, 1]]", "coupling", ["3x3"]),
    ("gears = [1, 1, 1]", "gears", ["unknown field"]),
])
def test_bad_drive_chain(tmp_path, chain, key, words):
    err, file = errors_of(GOOD + f"\n[drive_chain]\n{chain}\n", tmp_path)
    assert_problem(err, file, "[drive_chain]", key, *words)


def test_good_drive_chain():
    robot = parse_robot_text(GOOD + "\n[drive_chain]\nratios = [100, -80, 50]\ndirections = [1, -1, 1]\n")
    assert robot.drive_chain.ratios == (100.0, -80.0, 50.0)
    assert robot.drive_chain.coupling == ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


# ---------------------------------------------------------------- [limits] of the passive joints
def palletizer_with(limits: str) -> str:
    """The shipped palletizer (actuated joints 1, 2, 4, 5; passive joints 3, 6) with this ``[limits]`` table instead of its own."""
    return (robots_dir() / "palletizer.toml").read_text().split("\n[limits]", 1)[0] + f"\n[limits]\n{limits}\n"


@pytest.mark.parametrize("unit, scale", [("rad", 1.0), ("deg", math.pi / 180)])
def test_passive_limits_in_si_units(unit, scale):
    text = palletizer_with(f'angles = "{unit}"\nq_min = [-2, -1, -3, -1]\nq_max = [2, 1, 3, 1]\n'
                           "passive_q_min = [-2.5, -1.5]\npassive_q_max = [-0.5, 1.5]")
    lim = parse_robot_text(text, file="pal.toml").limits
    assert lim.passive_joints == (3, 6)
    assert lim.passive_q_min == pytest.approx((-2.5 * scale, -1.5 * scale), rel=1e-15)
    assert lim.passive_q_max == pytest.approx((-0.5 * scale, 1.5 * scale), rel=1e-15)
    assert lim.q_min == pytest.approx((-2 * scale, -scale, -3 * scale, -scale), rel=1e-15)  # actuated: unchanged


def test_passive_limits_alone_and_of_a_prismatic_coupled_joint():
    lim = parse_robot_text(palletizer_with("passive_q_min = [-2, -1]\npassive_q_max = [0, 1]")).limits
    assert lim.q_min is None and lim.passive_q_min == (-2.0, -1.0) and lim.passive_joints == (3, 6)
    assert parse_robot_text(palletizer_with("q_min = [-2, -1, -3, -1]\nq_max = [2, 1, 3, 1]")).limits.passive_joints == ()
    # joint 3 (prismatic) follows joint 2: its range is in m whatever the angle unit
    text = edit_frame(GOOD, 3, 'r = "q"', 'r = "q"\nmimic = { joint = 2, multiplier = 0.1, offset = 0 }')
    text += '\n[limits]\nangles = "deg"\nq_min = [-90, -45]\nq_max = [90, 45]\npassive_q_min = [-0.1]\npassive_q_max = [0.2]\n'
    lim = parse_robot_text(text).limits
    assert lim.passive_joints == (3,) and lim.passive_q_min == (-0.1,) and lim.passive_q_max == (0.2,)
    assert lim.q_max == pytest.approx((math.pi / 2, math.pi / 4), rel=1e-15)


@pytest.mark.parametrize("limits, where, fld, words", [
    ("passive_q_min = [-1]\npassive_q_max = [1, 1]", "[limits]", "passive_q_min",
     ["list of 2 numbers", "passive joint", "joints 3, 6"]),
    ("passive_q_min = [-1, -1]\npassive_q_max = [1, 1, 1]", "[limits]", "passive_q_max", ["list of 2 numbers"]),
    ("passive_q_min = -1\npassive_q_max = [1, 1]", "[limits]", "passive_q_min", ["list of 2 numbers"]),
    ("passive_q_min = [-1, 2]\npassive_q_max = [1, 1]", "[limits] passive joint 6", "passive_q_min",
     ["passive_q_min 2 must be below passive_q_max 1"]),
    ("passive_q_min = [1, -1]\npassive_q_max = [1, 1]", "[limits] passive joint 3", "passive_q_min", ["must be below"]),
    ("passive_q_min = [-1, -1]", "[limits]", "passive_q_max", ["missing", "given together"]),
    ("passive_q_max = [1, 1]", "[limits]", "passive_q_min", ["missing", "given together"]),
    ('passive_q_min = ["a", -1]\npassive_q_max = [1, 1]', "[limits] passive joint 3", "passive_q_min",
     ["finite number", "'a'"]),
    ("passive_q_min = [-1, -1]\npassive_q_max = [1, nan]", "[limits] passive joint 6", "passive_q_max",
     ["finite number"]),
    ("passive_q_min = [-1, true]\npassive_q_max = [1, 1]", "[limits] passive joint 6", "passive_q_min",
     ["finite number"]),
    ("passive_min = [-1, -1]", "[limits]", "passive_min", ["unknown field", "passive_q_min"]),
])
def test_bad_passive_limits(tmp_path, limits, where, fld, words):
    err, file = errors_of(palletizer_with(limits), tmp_path, "pal.toml")
    assert_problem(err, file, where, fld, *words)
    assert len(err.problems) == 1, str(err)


def test_passive_limits_on_a_robot_without_passive_joints(tmp_path):
    err, file = errors_of(GOOD + "\n[limits]\npassive_q_min = [-1]\npassive_q_max = [1]\n", tmp_path)
    assert_problem(err, file, "[limits]", "passive_q_min", "no passive joints")
    assert_problem(err, file, "[limits]", "passive_q_max", "no passive joints")


# ---------------------------------------------------------------- several problems at once
def test_one_error_lists_every_problem(tmp_path):
    text = "colour = 1\n" + GOOD.replace("payload = 4", "payload = 9")
    text = text.replace("gravity = [0, 0, -9.81]", "gravity = [0, 0]")
    text = edit_frame(text, 1, "sigma = 0", "sigma = 7")
    text = edit_frame(text, 2, "ant = 1", "ant = 2")
    text = edit_frame(text, 2, 'd = "L2"', "d = \"__import__('os')\"")
    text = edit_frame(text, 3, "d = 0", 'd = "L9"')
    text = edit_frame(text, 3, "r = \"q\"", "r = \"q\"\nwidth = 1")
    text = text.replace("M4 = 1.5", "M4 = 1.5\nFOO2 = 1.0")
    err, file = errors_of(text, tmp_path)
    expected = [
        ("top level", "colour"), ("top level", "gravity"), ("top level", "payload"),
        ("frame 1", "sigma"), ("frame 2", "ant"), ("frame 2", "d"),
        ("frame 3", "d"), ("frame 3", "width"), ("[nominal]", "FOO2"),
    ]
    got = {(p.where, p.field) for p in err.problems}
    assert set(expected) <= got, got
    assert str(err).startswith(f"{len(err.problems)} problems in robot description")
    assert len(err.problems) >= len(expected)
    assert all(p.file == file for p in err.problems)
    # one line per problem, each naming the file
    lines = str(err).splitlines()[1:]
    assert len(lines) == len(err.problems) and all(file in l for l in lines)


def test_error_is_a_value_error(tmp_path):
    _, _ = errors_of("", tmp_path)
    with pytest.raises(ValueError):
        parse_robot_text("")


# ---------------------------------------------------------------- happy path: shipped robots
INERTIAL = INERTIAL_KINDS


@pytest.mark.parametrize("name, n, drive, n_std, payload", [
    ("lwr4", 7, ("FV", "FS", "OFF"), 91, 8),
    ("rx90", 6, ("IA", "FV", "FS", "OFF"), 84, 7),
    ("scara", 4, ("IA", "FV", "FS", "OFF"), 56, None),
])
def test_shipped_robots(name, n, drive, n_std, payload):
    r = load_robot(name)
    assert r.name == name and r.source
    assert r.n_joints == n and len(r.standard_names) == n_std == n * (10 + len(drive))
    expected = tuple(f"{k}{j}" for j in range(1, n + 1) for k in INERTIAL + drive)
    assert r.standard_names == expected
    assert r.payload == payload
    if payload is None:
        assert r.payload_names == ()
    else:
        assert r.payload_names == tuple(f"{k}{payload}" for k in INERTIAL)
        assert r.row(payload).sigma == 2 and r.row(payload).ant == payload - 1
    assert r.gravity == (0.0, 0.0, -9.81)
    assert len(r.file_hash) == 64


def test_shipped_geometry_keeps_symbols():
    lwr = load_robot("lwr4")
    RL3, RL5 = sp.Symbol("RL3", real=True), sp.Symbol("RL5", real=True)
    assert lwr.row(3).r == RL3 and lwr.row(5).r == RL5
    assert dict(lwr.values) == {"RL3": 0.40, "RL5": 0.39}
    assert set(lwr.geometry_symbols) == {RL3, RL5}
    assert lwr.row(2).alpha == sp.pi / 2 and lwr.row(3).alpha == -sp.pi / 2
    assert lwr.nominal_payload()[INERTIAL.index("M")] == pytest.approx(4.6136)
    rx = load_robot("rx90")
    assert rx.row(3).d == sp.Symbol("D3", real=True) and rx.row(4).r == sp.Symbol("RL4", real=True)
    assert rx.nominal_payload() == pytest.approx((0.161, 0, 0, 0.161, 0, 0.035, 0, 0, 1.003, 7.025))
    sc = load_robot("scara")
    assert sc.row(3).sigma == 1 and sc.row(3).r == q_symbol(3) and sc.row(3).theta == 0
    assert sc.row(2).d.subs(sc.geometry_subs()) == pytest.approx(0.35)


def test_offset_and_negative_direction():
    text = edit_frame(GOOD, 1, 'theta = "q"', 'theta = "-q + pi"')
    r = parse_robot_text(text)
    q1, q2 = q_symbol(1), q_symbol(2)
    assert sp.simplify(r.row(1).theta - (-q1 + sp.pi)) == 0
    assert sp.simplify(r.row(2).theta - (q2 - sp.pi / 2)) == 0
    assert sp.diff(r.row(1).theta, q1) == -1
    # symbolic constant kept symbolic, value applied only on substitution
    L2 = sp.Symbol("L2", real=True)
    assert r.row(2).d == L2 and r.row(2).d.subs(r.geometry_subs()) == pytest.approx(0.3)
    assert math.isclose(float(r.row(2).theta.subs(q2, 0)), -math.pi / 2)


def test_symbolic_offset_in_joint_field():
    text = GOOD.replace("L2 = 0.3", "L2 = 0.3\nTH0 = 0.1")
    r = parse_robot_text(edit_frame(text, 1, 'theta = "q"', 'theta = "q + TH0"'))
    assert r.row(1).theta == q_symbol(1) + sp.Symbol("TH0", real=True)


def test_defaults():
    text = GOOD.replace("gravity = [0, 0, -9.81]\n", "").replace('drive = ["IA", "FV", "FS", "OFF"]\n', "")
    r = parse_robot_text(text)
    assert r.gravity == (0.0, 0.0, -9.81)
    assert all(row.drive == ("IA", "FV", "FS", "OFF") for row in r.joints)
    assert r.row(4).drive == () and r.row(4).mu == 0
    assert r.row(1).gamma == 0 and r.row(1).b == 0 and r.row(1).mu == 1


# ---------------------------------------------------------------- one bad field, one line
@pytest.mark.parametrize("value", ["nan", "inf", "-inf", '"short"', "true", "[1, 2]"])
def test_bad_value_reported_once(tmp_path, value):
    err, file = errors_of(GOOD.replace("L2 = 0.3", f"L2 = {value}"), tmp_path)
    assert [(p.where, p.field) for p in err.problems] == [("[values]", "L2")], str(err)
    assert len(str(err).splitlines()) == 2


@pytest.mark.parametrize("j, sigma", [(1, "3"), (2, "-1"), (3, "3"), (3, "true"), (4, "7"), (2, '"1"')])
def test_bad_sigma_reported_once(tmp_path, j, sigma):
    # frame 3 is prismatic (q in r) and frame 4 fixed: a default sigma would add theta/r/order complaints
    old = "sigma = 1" if j == 3 else ("sigma = 2" if j == 4 else "sigma = 0")
    err, file = errors_of(edit_frame(GOOD, j, old, f"sigma = {sigma}"), tmp_path)
    assert [(p.where, p.field) for p in err.problems] == [(f"frame {j}", "sigma")], str(err)


def test_missing_sigma_reported_once(tmp_path):
    s, e = frame_block(GOOD, 3)
    block = GOOD[s:e].replace("sigma = 1\n", "")
    err, file = errors_of(GOOD[:s] + block + GOOD[e:], tmp_path)
    assert [(p.where, p.field) for p in err.problems] == [("frame 3", "sigma")], str(err)


def test_bad_theta_reported_once(tmp_path):
    err, file = errors_of(edit_frame(GOOD, 2, 'theta = "q - pi/2"', 'theta = "q - pi/"'), tmp_path)
    assert [(p.where, p.field) for p in err.problems] == [("frame 2", "theta")], str(err)


@pytest.mark.parametrize("drive", ['["FV", "FV"]', '["IA", "fv", "FV"]'])
def test_duplicate_drive_terms(tmp_path, drive):
    err, file = errors_of(GOOD.replace('drive = ["IA", "FV", "FS", "OFF"]', f"drive = {drive}"), tmp_path)
    assert_problem(err, file, "top level", "drive", "listed twice", "FV")
    err, file = errors_of(edit_frame(GOOD, 2, "r = 0", f"r = 0\ndrive = {drive}"), tmp_path)
    assert_problem(err, file, "frame 2", "drive", "listed twice")
    assert len(err.problems) == 1


@pytest.mark.parametrize("key, words", [("M4", ["mass", "negative"]), ("M2", ["mass", "negative"]),
                                        ("IA1", ["rotor inertia"]), ("FV3", ["viscous"]), ("FS2", ["coulomb"])])
def test_negative_nominal(tmp_path, key, words):
    err, file = errors_of(GOOD.replace("M4 = 1.5", f"M4 = 1.5\n{key} = -0.5" if key != "M4" else "M4 = -0.5"), tmp_path)
    assert_problem(err, file, "[nominal]", key, *words)
    assert len(err.problems) == 1


def test_negative_offset_is_fine():
    robot = parse_robot_text(GOOD.replace("M4 = 1.5", "M4 = 1.5\nOFF2 = -0.5"))
    assert robot.nominal["OFF2"] == -0.5


def test_inconsistent_nominal_inertia_warns(tmp_path):
    from symoro_gen.errors import RobotFileWarning

    # triangle inequality violated: ZZ > XX + YY about the centre of mass
    text = GOOD.replace("M4 = 1.5", "M4 = 1.5\nM2 = 2.0\nXX2 = 0.01\nYY2 = 0.01\nZZ2 = 0.05")
    path = tmp_path / "warn.toml"
    path.write_text(text)
    with pytest.warns(RobotFileWarning) as rec:
        robot = parse_robot(path)
    assert robot.nominal["ZZ2"] == 0.05  # kept: a warning, not an error
    msgs = [str(w.message) for w in rec]
    assert len(msgs) == 1 and str(path) in msgs[0] and "'M2'" in msgs[0] and "triangle" in msgs[0]


def test_consistent_nominal_does_not_warn(recwarn):
    from symoro_gen.errors import RobotFileWarning

    # a rigid body, a point mass and a mass alone are all accepted silently
    text = GOOD.replace("M4 = 1.5", "M4 = 1.5\nM2 = 2.0\nXX2 = 0.02\nYY2 = 0.03\nZZ2 = 0.04\nMX2 = 0.1\n"
                                    "M3 = 1.0\nMX3 = 0.2\nXX3 = 0.0\n")
    parse_robot_text(text)
    for name in ("lwr4", "rx90", "scara", "tx40"):
        load_robot(name)
    assert not [w for w in recwarn if issubclass(w.category, RobotFileWarning)]


def test_binary_robot_file_names_file(tmp_path):
    path = tmp_path / "robots" / "blob.toml"
    path.parent.mkdir()
    path.write_bytes(bytes(range(256)) * 4)
    for load in (parse_robot, load_robot):
        with pytest.raises(RobotFileError) as info:
            load(path)
        assert len(info.value.problems) == 1
        p = info.value.problems[0]
        assert p.file == str(path) and "not UTF-8" in p.message and "byte 128" in p.where
    with pytest.raises(RobotFileError, match="cannot read"):
        parse_robot(tmp_path / "robots")


@pytest.mark.parametrize("text_edit", [
    lambda t: t.replace('drive = ["IA", "FV", "FS", "OFF"]', "drive = true"),
    lambda t: edit_frame(t, 2, "r = 0", "r = 0\ndrive = 3"),
    lambda t: t.replace("payload = 4", "payload = true"),
    lambda t: t.replace("[values]\nL2 = 0.3", "values = 3"),
])
def test_bad_field_does_not_cascade(tmp_path, text_edit):
    # found by tests/fuzz: a bad drive list rejected every [nominal] drive term, a bad payload its
    # nominal values, a [values] that is not a table every symbol
    text = text_edit(GOOD.replace("M4 = 1.5", "M4 = 1.5\nFV2 = 0.3\nIA1 = 0.01"))
    err, file = errors_of(text, tmp_path)
    assert len(err.problems) == 1, str(err)
