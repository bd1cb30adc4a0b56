"""A geometric field without a finite value is a one-line robot-file error.

``d = "1/L3"`` with ``L3 = 0`` used to reach base-parameter detection and fail there as an
internal error; it is now reported by the parser, naming the file, the frame and the field.
"""
from __future__ import annotations

import pytest

from symoro_gen.description import parse_robot_text
from symoro_gen.errors import RobotFileError

TEXT = """
name = "bad"
[values]
L3 = {L3}
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
alpha = 0
d = "{d}"
theta = "q + {th}"
r = 0
"""


@pytest.mark.parametrize(("d", "th", "field"), [("1/L3", "0", "d"), ("0", "1/L3", "theta"), ("log(L3)", "0", "d")])
def test_non_finite_geometry_is_a_robot_file_error(d, th, field):
    with pytest.raises(RobotFileError) as exc:
        parse_robot_text(TEXT.format(L3=0, d=d, th=th), file="bad.toml")
    msg = str(exc.value)
    assert "bad.toml" in msg and "frame 2" in msg and f"field {field!r}" in msg, msg
    assert len(exc.value.problems) == 1, msg


def test_finite_geometry_is_accepted():
    robot = parse_robot_text(TEXT.format(L3=2, d="1/L3", th="1/L3"), file="ok.toml")
    assert robot.values["L3"] == 2.0
