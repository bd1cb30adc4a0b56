"""Declared elastic joints in the robot file: parsed, defaulted, validated (errors name file, frame, field)."""
import re

import pytest

from symoro_gen.description.parse import parse_robot_text
from symoro_gen.errors import RobotFileError

_FRAME = """
[[frames]]
j = {j}
ant = {ant}
sigma = {sigma}
alpha = 0
d = 0.3
theta = "{theta}"
r = 0
{extra}
"""


def _robot(top="", extras=("", "", ""), sigmas=(0, 0, 2)):
    frames = "".join(_FRAME.format(j=j, ant=j - 1, sigma=s, theta="q" if s == 0 else "0", extra=e)
                     for j, (s, e) in enumerate(zip(sigmas, extras), start=1))
    return f'name = "two"\n{top}\n{frames}'


def _problems(text):
    with pytest.raises(RobotFileError) as ei:
        parse_robot_text(text, file="arm.toml")
    return [(p.file, p.where, p.field, p.message) for p in ei.value.problems]


def test_rigid_by_default():
    r = parse_robot_text(_robot())
    assert r.elastic == ()
    assert r.elastic_joint(1) is None


def test_per_frame_elastic_with_default_damping():
    r = parse_robot_text(_robot(extras=("", "elastic = {K = 7500}", "")))
    assert [(e.joint, e.K, e.D) for e in r.elastic] == [(2, 7500.0, 0.0)]
    assert r.elastic_joint(1) is None and r.elastic_joint(2).K == 7500.0
    assert r.elastic_joint(2).deflection(15.0) == pytest.approx(15.0 / 7500.0)


def test_top_level_for_every_actuated_joint_and_frame_override():
    r = parse_robot_text(_robot(top="elastic = {K = 1e4, D = 2.5}", extras=("", "elastic = {K = 7500}", "")))
    # the fixed frame 3 gets none; frame 2's own table replaces the default (its D is its own: 0)
    assert [(e.joint, e.K, e.D) for e in r.elastic] == [(1, 1e4, 2.5), (2, 7500.0, 0.0)]


def test_immutable():
    r = parse_robot_text(_robot(top="elastic = {K = 1e4}"))
    with pytest.raises(AttributeError):
        r.elastic[0].K = 1.0  # type: ignore[misc]
    assert isinstance(r.elastic, tuple)


@pytest.mark.parametrize("table, field, words", [
    ("{K = 0}", "elastic.K", "positive"),
    ("{K = -5}", "elastic.K", "positive"),
    ("{K = inf}", "elastic.K", "positive"),
    ("{K = nan}", "elastic.K", "positive"),
    ("{K = true}", "elastic.K", "positive"),
    ("{K = 100, D = -1}", "elastic.D", ">= 0"),
    ("{K = 100, D = inf}", "elastic.D", ">= 0"),
    ("{D = 1}", "elastic.K", "missing"),
    ("{K = 100, C = 1}", "elastic.C", "unknown field"),
    ("5", "elastic", "must be a table"),
])
def test_invalid_tables_name_file_frame_field(table, field, words):
    probs = _problems(_robot(extras=("", f"elastic = {table}", "")))
    assert len(probs) == 1
    file, where, fld, msg = probs[0]
    assert (file, where, fld) == ("arm.toml", "frame 2", field)
    assert re.search(re.escape(words), msg)


def test_invalid_top_level_table():
    probs = _problems(_robot(top="elastic = {K = -1}"))
    assert [(p[1], p[2]) for p in probs] == [("top level", "elastic.K")]


def test_fixed_frame_cannot_be_elastic():
    probs = _problems(_robot(extras=("", "", "elastic = {K = 100}")))
    assert [(p[1], p[2]) for p in probs] == [("frame 3", "elastic")]
    assert "fixed frame" in probs[0][3]


def test_lwr4_paper_stiffness_in_a_real_robot_file(tmp_path):
    """The LWR4 file with the paper's K (eq. 17: 10 000 N m/rad joints 1-5, 7 500 joints 6-7) parses."""
    from symoro_gen.paths import robots_dir

    text = (robots_dir() / "lwr4.toml").read_text()
    text = text.replace("\n[values]", '\nelastic = {K = 10000}\n[values]', 1)
    parts = text.split("[[frames]]")
    for j in (6, 7):
        parts[j] = parts[j].replace("r = ", "elastic = {K = 7500}\nr = ", 1)
    r = parse_robot_text("[[frames]]".join(parts))
    assert [e.K for e in r.elastic] == [1e4] * 5 + [7500.0] * 2
