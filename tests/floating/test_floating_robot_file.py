"""The robot file's ``base`` field: ``"fixed"`` by default, ``"floating"`` gives the base link (frame 0) its
10 inertial parameters; bad values and unsupported combinations are errors naming the file and the field;
the robot id of a fixed-base robot does not change, a floating one differs from it."""
from __future__ import annotations

import pytest

from symoro_gen.description import parse_robot, parse_robot_text
from symoro_gen.description.identity import canonical_description, robot_id
from symoro_gen.dynamics.floating import build_floating_regressor
from symoro_gen.dynamics.newton_euler import build_regressor
from symoro_gen.errors import RobotFileError
from symoro_gen.params import INERTIAL_KINDS

ARM = """\
name = "two_links"
gravity = [0, 0, -9.81]
{base}
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
theta = "q"
r = 0
"""


def _robot(base_line: str):
    return parse_robot_text(ARM.format(base=base_line), "arm.toml")


def test_base_defaults_to_fixed_and_fixed_is_unchanged():
    default, fixed = _robot(""), _robot('base = "fixed"')
    assert default.base == fixed.base == "fixed" and not default.floating
    assert default.standard_names == fixed.standard_names
    assert not any(n.endswith("0") and n[:-1] in INERTIAL_KINDS for n in default.standard_names)
    assert "base" not in canonical_description(default)
    assert robot_id(default) == robot_id(fixed)


def test_floating_base_link_parameters_come_first():
    fixed, floating = _robot(""), _robot('base = "floating"')
    assert floating.floating
    assert floating.standard_names == tuple(f"{k}0" for k in INERTIAL_KINDS) + fixed.standard_names
    assert robot_id(floating) != robot_id(fixed)


@pytest.mark.parametrize("value", ['"free"', "1", '"Floating"'])
def test_bad_base_names_file_and_field(tmp_path, value):
    path = tmp_path / "bad_base.toml"
    path.write_text(ARM.format(base=f"base = {value}"), encoding="utf-8")
    with pytest.raises(RobotFileError) as info:
        parse_robot(path)
    hits = [p for p in info.value.problems if p.field == "base" and p.where == "top level"]
    assert hits and hits[0].file == str(path)
    assert "'fixed', 'floating'" in hits[0].message
    assert str(path) in str(info.value) and "base" in str(info.value)


def test_floating_base_refuses_coupled_joints(tmp_path):
    # the last frame (joint 2) made a coupled copy of joint 1
    text = ARM.format(base='base = "floating"') + "mimic = { joint = 1, multiplier = 1.0, offset = 0.0 }\nmu = 0\n"
    path = tmp_path / "mimic.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(RobotFileError) as info:
        parse_robot(path)
    assert any(p.field == "base" and "mimic" in p.message for p in info.value.problems), str(info.value)


def test_each_model_refuses_the_other_base():
    with pytest.raises(ValueError, match=r"arm\.toml: base = 'floating'"):
        build_regressor(_robot('base = "floating"'))
    with pytest.raises(ValueError, match=r"arm\.toml: base = 'fixed'"):
        build_floating_regressor(_robot(""))


def test_floating_model_rows_and_inputs():
    reg = build_floating_regressor(_robot('base = "floating"'))
    assert reg.base_rows == 6
    rows = {i for i, _ in reg.graph.outputs}
    assert rows == set(range(6 + 2))
    names = [s.name for s in reg.graph.inputs]
    assert names[:9] == ["PX0", "PY0", "PZ0", "QX0", "QY0", "QZ0", "QW0", "q1", "q2"]
    # the base link's own parameters reach the base rows only
    assert {i for i, n in reg.graph.outputs if n == "M0"} <= set(range(6))


def test_nominal_base_link_values_only_on_a_floating_base(tmp_path):
    nominal = "\n[nominal]\nM0 = 12.0\nXX0 = 0.3\nM1 = 1.0\n"
    robot = parse_robot_text(ARM.format(base='base = "floating"') + nominal, "arm.toml")
    assert robot.nominal_vector()[:10] == (0.3, 0, 0, 0, 0, 0, 0, 0, 0, 12.0)
    path = tmp_path / "fixed.toml"
    path.write_text(ARM.format(base="") + nominal, encoding="utf-8")
    with pytest.raises(RobotFileError) as info:
        parse_robot(path)
    assert {p.field for p in info.value.problems} == {"M0", "XX0"}
