"""Fuzz: recordings (``identify scara DATA --json OUT``): CSV cells replaced by NaN/inf/huge/negative
values or text, columns and rows dropped or duplicated, truncation, binary garbage, files of the wrong
kind; and split-recording specs (``q=FILE,tau=FILE,dt=...``) with missing, repeated, unknown or bad keys."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from symoro_gen import load_model
from symoro_gen.description import load_robot
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording

from .helpers import _DEEP, FUZZ, run_case

DATA = FUZZ if _DEEP else FUZZ.__class__(FUZZ, max_examples=15)  # each valid case identifies: fewer


def _recording():
    rng = np.random.default_rng(0)
    robot, model = load_robot("scara"), load_model("scara")
    chi = np.asarray(random_physical_parameters(robot, rng))
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, 4.0, 0.004, rng)
    return simulate_recording(model, t, q, dq, ddq, chi, noise_q=1e-5, noise_tau=0.01, rng=rng)


REC = _recording()
HEADER = "t,q1,q2,q3,q4,tau1,tau2,tau3,tau4"
ROWS = [",".join(f"{x:.17g}" for x in row) for row in np.column_stack([REC.t, REC.q, REC.tau])]
CSV = HEADER + "\n" + "\n".join(ROWS) + "\n"
ODD = ["nan", "inf", "-inf", "1e308", "-1e308", "-1", "0", "", "abc", "1,2", "0x1p3", "NaN", "1e-320", "\u00e9"]


@st.composite
def csv_edit(draw):
    rows = [HEADER.split(",")] + [r.split(",") for r in ROWS]
    kind = draw(st.sampled_from(["cell", "cells", "header", "drop_column", "drop_rows", "duplicate_row",
                                 "swap_rows", "truncate", "garbage"]))
    if kind in ("cell", "cells"):
        for _ in range(1 if kind == "cell" else draw(st.integers(2, 50))):
            i, j = draw(st.integers(1, len(rows) - 1)), draw(st.integers(0, 8))
            rows[i][j] = draw(st.sampled_from(ODD))
    elif kind == "header":
        rows[0][draw(st.integers(0, 8))] = draw(st.sampled_from(["q1", "tau9", "", "x", "t", "dq1", "Q1"]))
    elif kind == "drop_column":
        j = draw(st.integers(0, 8))
        rows = [r[:j] + r[j + 1:] for r in rows]
    elif kind == "drop_rows":
        i = draw(st.integers(1, len(rows) - 1))
        rows = rows[:i] + rows[i + draw(st.integers(1, len(rows) - 1)):]
    elif kind == "duplicate_row":
        i = draw(st.integers(1, len(rows) - 1))
        rows = rows[: i + 1] + rows[i:]
    elif kind == "swap_rows":
        i = draw(st.integers(1, len(rows) - 2))
        rows[i], rows[i + 1] = rows[i + 1], rows[i]
    text = "\n".join(",".join(r) for r in rows) + "\n"
    raw = text.encode()
    if kind == "truncate":
        return raw[: draw(st.integers(0, len(raw)))]
    if kind == "garbage":
        cut = draw(st.integers(0, len(raw)))
        return raw[:cut] + draw(st.binary(min_size=1, max_size=40)) + raw[cut + draw(st.integers(0, 40)):]
    return raw


def _identify(cli, d, data_arg, file):
    return run_case(cli, d, ["-q", "identify", "scara", data_arg, "--json", d / "out.json"], output=d / "out.json",
                    file=file)


def test_valid_recording_identifies(cli, tmp_path):
    (tmp_path / "rec.csv").write_text(CSV)
    assert _identify(cli, tmp_path, tmp_path / "rec.csv", None).rc == 0


@DATA
@given(data=csv_edit())
def test_damaged_csv(cli, tmp_path_factory, data):
    d = tmp_path_factory.mktemp("csv")
    f = d / "rec.csv"
    f.write_bytes(data)
    _identify(cli, d, f, "rec.csv")


@pytest.mark.parametrize("name, content", [
    ("empty.csv", b""), ("header_only.csv", HEADER.encode() + b"\n"), ("binary.csv", bytes(range(256)) * 8),
    ("text.npz", CSV.encode()), ("text.mat", CSV.encode()), ("garbage.npz", b"PK\x03\x04" + bytes(100)),
    ("garbage.mat", b"PK\x03\x04" + bytes(100)), ("noise.mat", bytes(range(7, 256)) * 2),
    ("one_row.csv", (HEADER + "\n" + ROWS[0] + "\n").encode()), ("folder.csv", None),
])
def test_files_of_the_wrong_kind(cli, tmp_path, name, content):
    f = tmp_path / name
    if content is None:
        f.mkdir()
    else:
        f.write_bytes(content)
    case = _identify(cli, tmp_path, f, name)
    assert case.rc == 2


# ---- split-recording specs -------------------------------------------------------------------
SPEC_PARTS = ["q={q}", "tau={tau}", "dt=0.004", "fs=250", "dt=abc", "dt=-1", "dt=0", "fs=inf", "dt=nan",
              "q={missing}", "tau={q}", "loaded=true", "loaded=maybe", "foo=1", "t={q}", "dq={tau}", "q=", "=",
              "dt", "tau={garbage}", "ddq={short}"]


@DATA
@given(parts=st.lists(st.sampled_from(SPEC_PARTS), min_size=1, max_size=6))
def test_split_specs(cli, tmp_path_factory, parts):
    d = tmp_path_factory.mktemp("spec")
    np.savetxt(d / "pos.csv", REC.q, delimiter=",")
    np.savetxt(d / "cur.csv", REC.tau, delimiter=",")
    np.savetxt(d / "short.csv", REC.q[:10], delimiter=",")
    (d / "garbage.csv").write_bytes(bytes(range(256)))
    files = dict(q=d / "pos.csv", tau=d / "cur.csv", missing=d / "nope.csv", garbage=d / "garbage.csv",
                 short=d / "short.csv")
    spec = ",".join(p.format(**files) for p in parts)
    case = _identify(cli, d, spec, None)
    if case.rc == 2:
        named = [p.split("=")[0] for p in parts if p.split("=")[0]] + [str(f) for f in files.values()] + [spec]
        assert any(n in case.err for n in named), f"{spec}: the error names no key or file\n{case.err}"


def test_huge_position_names_the_file(cli, tmp_path):
    """Found by this suite: a 1e308 position passed the plain loader and failed later as 'W has non-finite
    values' without the file name; every loader now applies the same |value| bound."""
    rows = [r.split(",") for r in ROWS]
    rows[5][1] = "1e308"
    (tmp_path / "rec.csv").write_text(HEADER + "\n" + "\n".join(",".join(r) for r in rows) + "\n")
    case = _identify(cli, tmp_path, tmp_path / "rec.csv", "rec.csv")
    assert case.rc == 2 and "'q1'" in case.first_error and "rows 6" in case.first_error, case.err
    assert "--drop-bad-rows" in case.err and "warning" not in case.err  # no overflow noise before the error


def test_damaged_npz_and_npy_name_the_file(cli, tmp_path):
    """Found by this suite: a damaged .npz gave 'internal error: BadZipFile'; a .npy cut short a numpy
    message without the file."""
    np.savez(tmp_path / "rec.npz", t=REC.t, q=REC.q, tau=REC.tau)
    raw = (tmp_path / "rec.npz").read_bytes()
    (tmp_path / "half.npz").write_bytes(raw[: len(raw) // 2])
    crc = bytearray(raw)
    crc[200:260] = bytes(60)
    (tmp_path / "crc.npz").write_bytes(bytes(crc))
    np.save(tmp_path / "q.npy", REC.q)
    np.save(tmp_path / "tau.npy", REC.tau)
    (tmp_path / "short.npy").write_bytes((tmp_path / "q.npy").read_bytes()[:150])
    for arg, name in [(tmp_path / "half.npz", "half.npz"), (tmp_path / "crc.npz", "crc.npz"),
                      (f"q={tmp_path / 'short.npy'},tau={tmp_path / 'tau.npy'},dt=0.004", "short.npy")]:
        case = _identify(cli, tmp_path, arg, name)
        assert case.rc == 2 and name in case.first_error and "pickle" not in case.err, case.err


def test_stray_byte_and_empty_spec_value(cli, tmp_path):
    """Found by the deep search (SYMORO_FUZZ_EXAMPLES=150): one non-UTF-8 byte in a data row gave
    "'utf-8' codec can't decode byte 0x80" without the file; ``q=`` (no file) read the current folder
    ("Is a directory") and added a second, wrong complaint that q= was missing."""
    raw = CSV.encode()
    i = raw.index(b"\n", 3000) + 20
    (tmp_path / "byte.csv").write_bytes(raw[:i] + b"\x80" + raw[i + 1:])
    line = raw[:i].count(b"\n") + 1
    for extra in ([], ["--tau-scale", "1"]):  # plain loader, and logformat's
        out = tmp_path / "out.json"
        case = run_case(cli, tmp_path, ["-q", "identify", "scara", tmp_path / "byte.csv", *extra, "--json", out],
                        output=out, file="byte.csv", allow_ok=False)
        assert f"byte.csv, line {line}: not UTF-8 text" in case.first_error, case.err
    np.savetxt(tmp_path / "cur.csv", REC.tau, delimiter=",")
    case = _identify(cli, tmp_path, f"tau={tmp_path / 'cur.csv'},q=", None)
    assert case.rc == 2 and "field 'q': no file given" in case.first_error, case.err
    assert "missing" not in case.err and "directory" not in case.err.lower(), case.err
