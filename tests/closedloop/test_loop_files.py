"""Closed loops in robot files and SYMORO .par files: syntax, errors naming the field, import/export."""
from __future__ import annotations

import math

import numpy as np
import pytest

from symoro_gen.closedloop import LoopKinematics
from symoro_gen.description import export_par, load_robot, parse_robot_text
from symoro_gen.description.par import import_par_text
from symoro_gen.errors import RobotFileError

from .test_fourbar_lagrangian import closed_form, fourbar_text

# A four-bar in SYMORO's closed-loop layout ([KK1986]): links 1..NL, the cut joint NL+1..NJ on one side,
# its closing frame NJ+1..NF (fixed) on the other side; written for this test.
FOURBAR_PAR = """(* Robotname = 'fourbar' *)
NF = 5
NL = 3
NJ = 4
Type = 2
Ant = {0,1,0,2,3}
Sigma = {0,0,0,0,2}
B = {0,0,0,0,0}
d = {0,0.2,0.5,0.45,0.4}
R = {0,0,0,0,0}
gamma = {0,0,0,0,0}
Alpha = {0,0,0,0,0}
Mu = {1,0,0,0,0}
Theta = {th1,th2,th3,th4,0}
XX = {XX1,XX2,XX3}
XY = {XY1,XY2,XY3}
XZ = {XZ1,XZ2,XZ3}
YY = {YY1,YY2,YY3}
YZ = {YZ1,YZ2,YZ3}
ZZ = {ZZ1,ZZ2,ZZ3}
MX = {MX1,MX2,MX3}
MY = {MY1,MY2,MY3}
MZ = {MZ1,MZ2,MZ3}
M = {M1,M2,M3}
IA = {IA1,0,0}
FV = {FV1,0,0}
FS = {FS1,0,0}
G = {0,-9.81,0}
"""


def problems(text: str, file: str = "robot.toml"):
    with pytest.raises(RobotFileError) as e:
        parse_robot_text(text, file=file)
    return e.value.problems


def test_palletizer_par_round_trip():
    robot = load_robot("palletizer")
    par = export_par(robot)
    assert "NF = 8" in par and "NL = 6" in par and "NJ = 7" in par and "Type = 2" in par
    back = parse_robot_text(import_par_text(par, file="palletizer.par"))
    assert back.rows == robot.rows and back.loops == robot.loops
    assert dict(back.nominal) == dict(robot.nominal) and back.standard_names == robot.standard_names


def test_closed_par_import_gives_the_loop_and_it_closes():
    toml = import_par_text(FOURBAR_PAR, file="fourbar.par")
    robot = parse_robot_text(toml)
    assert [r.j for r in robot.rows] == [1, 2, 3] and [r.j for r in robot.actuated] == [1]
    (lp,) = robot.loops
    assert (lp.cut.j, lp.cut.ant, lp.close.j, lp.close.ant) == (4, 2, 5, 3)
    assert "IA2" not in robot.standard_names  # passive joints carry no drive terms
    ph2, ph3 = closed_form(0.0)
    ref = f"\n[loop_reference]\nq2 = {ph2!r}\nq3 = {ph3!r}\nq4 = {ph3 - ph2!r}\n"
    kin = LoopKinematics(parse_robot_text(toml + ref))
    q1 = np.linspace(-3, 3, 13)[:, None]
    x, res = kin.solve_positions(q1)
    assert res.max() < 1e-12
    for i, v in enumerate(q1[:, 0]):
        assert math.remainder(x[i, 2] - closed_form(v)[1], 2 * math.pi) == pytest.approx(0, abs=1e-10)


def test_closed_par_with_a_wrong_frame_count_names_nf():
    with pytest.raises(RobotFileError) as e:
        import_par_text(FOURBAR_PAR.replace("NF = 5", "NF = 6"), file="fourbar.par")
    assert any(p.field == "NF" and p.where == "line 2" and "NF = NJ + (NJ - NL)" in p.message for p in e.value.problems)


@pytest.mark.parametrize("old, new, where, field, words", [
    ('cut = { ant = 2,', 'cut = { ant = 7,', "loop 1, cut", "ant", "must be a link"),
    ('close = { ant = 3,', 'close = { ant = 2,', "loop 1, close", "ant", "same link"),
    ('d = "BC", theta = "q"', 'd = "q", theta = "q"', "loop 1, cut", "d", "may only appear in theta"),
    ('d = "BC", theta = "q"', 'd = "BC", theta = "2*q"', "loop 1, cut", "theta", "q + constant"),
    ('close = { ant = 3,', 'close = { sigma = 0, ant = 3,', "loop 1, close", "sigma", "fixed"),
    ('cut = { ant = 2,', 'cut = { mu = 1, ant = 2,', "loop 1, cut", "mu", "passive"),
    ('d = "BC"', 'd = "XYZ"', "loop 1, cut", "d", "unknown name"),
    ("q2 = ", "q9 = ", "[loop_reference]", "q9", "not a joint variable"),
    ('cut = { ant = 2,', 'extra = 1\ncut = { ant = 2,', "loop 1", "extra", "unknown field"),
])
def test_loop_errors_name_the_loop_and_field(old, new, where, field, words):
    text = fourbar_text()
    assert old in text
    probs = problems(text.replace(old, new, 1))
    assert any(p.file == "robot.toml" and p.where == where and p.field == field and words in p.message
               for p in probs), probs


def test_a_passive_joint_outside_every_loop_is_reported():
    text = fourbar_text().replace("[[loops]]", "[[frames]]\nj = 4\nant = 3\nsigma = 0\nmu = 0\nalpha = 0\nd = 0.1\n"
                                                "theta = \"q\"\nr = 0\n[[loops]]")
    probs = problems(text)
    assert any(p.where == "frame 4" and p.field == "mu" and "closed loop" in p.message for p in probs), probs
