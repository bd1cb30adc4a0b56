"""Fuzz: robot files and MDH expressions (``export-par FILE -o OUT``, which parses and validates the
robot file and writes nothing else). Mutations of valid files: a value of the wrong type, NaN/inf,
huge or negative numbers, a dropped or duplicated line, truncation, binary garbage."""
from __future__ import annotations

import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from tests.conftest import ROOT
from tests.description.test_robot_files import GOOD

from .helpers import FUZZ, run_case

BASES = {
    "tiny": GOOD,  # payload frame, [values], [nominal]
    "scara": (ROOT / "robots" / "scara.toml").read_text(),
    "tx40": (ROOT / "robots" / "tx40.toml").read_text(),  # [drive_chain]
}
_KV = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*) = (.+)$", re.M)
WRONG_TYPE = ["true", '[1, "a"]', "{ x = 1 }", "nan", "inf", "-inf", "1979-05-27"]
NUMBERS = ["-1", "0", "1e308", "-1e308", "1e-300", "123456789012345678901234567890", "-0.0", "2"]


def _case_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("robot")


def _run(cli, d, text: bytes | str, **kw):
    f = d / "robot.toml"
    f.write_bytes(text.encode() if isinstance(text, str) else text)
    return run_case(cli, d, ["export-par", f, "-o", d / "out.par"], output=d / "out.par", file=str(f), **kw)


@st.composite
def key_value_edit(draw, values):
    base = draw(st.sampled_from(sorted(BASES)))
    text = BASES[base]
    matches = list(_KV.finditer(text))
    m = draw(st.sampled_from(matches))
    new = draw(st.sampled_from(values))
    return m.group(1), text[: m.start(2)] + new + text[m.end(2):]


@FUZZ
@given(edit=key_value_edit(WRONG_TYPE))
def test_wrong_type_is_one_line_naming_the_field(cli, tmp_path_factory, edit):
    key, text = edit
    case = _run(cli, _case_dir(tmp_path_factory), text, fields=(key,), allow_ok=False)
    assert "problems in robot description" not in case.err, f"one bad field, several lines:\n{case.err}"


@FUZZ
@given(edit=key_value_edit(NUMBERS))
def test_odd_numbers(cli, tmp_path_factory, edit):
    _run(cli, _case_dir(tmp_path_factory), edit[1])


@st.composite
def line_edit(draw):
    text = BASES[draw(st.sampled_from(sorted(BASES)))]
    lines = text.splitlines(keepends=True)
    i = draw(st.integers(0, len(lines) - 1))
    kind = draw(st.sampled_from(["drop", "duplicate", "truncate", "garbage"]))
    if kind == "drop":
        return "".join(lines[:i] + lines[i + 1:]).encode()
    if kind == "duplicate":
        return "".join(lines[: i + 1] + lines[i:]).encode()
    raw = text.encode()
    cut = draw(st.integers(0, len(raw)))
    if kind == "truncate":
        return raw[:cut]
    junk = draw(st.binary(min_size=1, max_size=40))
    return raw[:cut] + junk + raw[cut + draw(st.integers(0, 40)):]


@FUZZ
@given(data=line_edit())
def test_damaged_files(cli, tmp_path_factory, data):
    _run(cli, _case_dir(tmp_path_factory), data)


# ---- expressions ---------------------------------------------------------------------------
TOKENS = ["q", "pi", "L2", "L9", "x", "1", "0", "2.5", "1e300", "e", "+", "-", "*", "/", "**", "(", ")", ",",
          "sin(", "cos(", "sqrt(", "atan2(", "abs(", "exp(", "__import__(", ".", "[", "]", " ", "lambda", "if",
          "9**9**9", "nan", "inf", "oo", "zoo", "I", "%", "@", "~", "<", "==", ":"]


@FUZZ
@given(expr=st.lists(st.sampled_from(TOKENS), min_size=0, max_size=10).map("".join))
def test_expressions(cli, tmp_path_factory, expr):
    text = GOOD.replace('d = "L2"', f'd = "{expr}"', 1)
    case = _run(cli, _case_dir(tmp_path_factory), text)
    if case.rc == 2:
        assert "frame 2" in case.first_error and "field 'd'" in case.first_error, case.err
        assert "problems in robot description" not in case.err, case.err


@pytest.mark.parametrize("expr", ["9**9**9", "2**10**10", "10**400", "1/(L2-0.3)", "atan2(0, 0)", "sqrt(-1)",
                                  "exp(1000)", "q*0", "L2/0", "(-8)**(1/3)", "1e309"])
def test_pathological_expressions(cli, tmp_path, expr):
    text = GOOD.replace('d = "L2"', f'd = "{expr}"', 1)
    case = _run(cli, tmp_path, text)
    if case.rc == 2:
        assert "frame 2" in case.first_error and "field 'd'" in case.first_error, case.err
