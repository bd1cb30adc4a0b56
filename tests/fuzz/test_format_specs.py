"""Fuzz: the data-format specs (``identify scara DATA --columns SPEC`` and ``--format FILE.toml``, see
docs/data-files.md): column selectors built from roles, indices, slices and header names, valid or not;
format files with known and unknown keys, values of every TOML type, damaged text. Each run exits 0 or
2 with one line naming the option or the file and the key, and writes nothing but its output."""
from __future__ import annotations

import json

from hypothesis import given
from hypothesis import strategies as st

from .helpers import _DEEP, FUZZ, run_case
from .test_data_files import CSV

SPECS = FUZZ if _DEEP else FUZZ.__class__(FUZZ, max_examples=15)  # each valid case identifies: fewer

VALID_COLUMNS = ["t=0,q=1:5,tau=5:9", "t=t,q=q1:q4,tau=tau1:tau4", "q=1:5,tau=-4:,t=0", "t=0,q=q1:q4,tau=5:9"]
TOKENS = ["t", "q", "tau", "dq", "ddq", "q_link", "x", "=", "=", ",", ",", ":", "0", "1", "4", "5", "9", "-1",
          "-9", "q1", "q4", "tau1", "tau4", " ", "::", "1e3", "\u00e9", "99999999999999999999"]


@SPECS
@given(spec=st.one_of(st.sampled_from(VALID_COLUMNS), st.lists(st.sampled_from(TOKENS), max_size=14).map("".join),
                      st.sampled_from(VALID_COLUMNS).flatmap(
                          lambda s: st.integers(0, len(s)).map(lambda i: s[:i] + s[i + 1:]))))
def test_columns_spec(cli, tmp_path_factory, spec):
    d = tmp_path_factory.mktemp("cols")
    (d / "rec.csv").write_text(CSV)
    out = d / "out.json"
    case = run_case(cli, d, ["-q", "identify", "scara", d / "rec.csv", f"--columns={spec}", "--json", out],
                    output=out)
    if case.rc == 2:
        first = case.first_error
        assert "columns" in first or "rec.csv" in first, f"--columns={spec!r}: names neither\n{case.err}"
    if spec in VALID_COLUMNS:
        assert case.rc == 0, case.err


def _toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and v != v:
        return "nan"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{k} = {_toml_value(x)}" for k, x in v.items()) + "}"
    if isinstance(v, list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    if isinstance(v, str):
        return json.dumps(v)
    return repr(v)


KEYS = ["columns", "dt", "tau_scale", "deg", "resample", "max_gap", "drop_bad_rows", "Columns", "foo"]
VALUES = [True, False, 0, 1, -1, 0.004, 1e308, float("nan"), "abc", "", "1,1,1,1", "1,2", "0.5",
          "t=0,q=1:5,tau=5:9", "q=q1:q4", [1.0, 1.0, 1.0, 1.0], [], [1, "a"], {"q": "q1:q4", "tau": "tau1:tau4"},
          {"q": 1}, {"x": "1"}]


@SPECS
@given(items=st.dictionaries(st.sampled_from(KEYS), st.sampled_from(VALUES), max_size=4),
       damage=st.one_of(st.none(), st.binary(min_size=1, max_size=20)))
def test_format_files(cli, tmp_path_factory, items, damage):
    d = tmp_path_factory.mktemp("fmt")
    (d / "rec.csv").write_text(CSV)
    text = "".join(f"{k} = {_toml_value(v)}\n" for k, v in items.items()).encode()
    (d / "fmt.toml").write_bytes(text if damage is None else text[: len(text) // 2] + damage)
    out = d / "out.json"
    case = run_case(cli, d, ["-q", "identify", "scara", d / "rec.csv", "--format", d / "fmt.toml", "--json", out],
                    output=out)
    if case.rc == 2:
        first = case.first_error
        assert "fmt.toml" in first or "rec.csv" in first or "columns" in first, f"{items}: names no file\n{case.err}"
        bad_keys = [k for k in items if k not in KEYS[:7]]
        if bad_keys and damage is None:
            assert any(f"'{k}'" in first for k in bad_keys), case.err


def test_format_file_is_a_folder(cli, tmp_path):
    (tmp_path / "rec.csv").write_text(CSV)
    (tmp_path / "fmt.toml").mkdir()
    out = tmp_path / "out.json"
    case = run_case(cli, tmp_path, ["-q", "identify", "scara", tmp_path / "rec.csv", "--format", tmp_path / "fmt.toml",
                                    "--json", out], output=out, file="fmt.toml", allow_ok=False)
    assert "fmt.toml" in case.first_error
