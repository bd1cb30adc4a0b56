"""``identify --geometry length``: link-length errors (MDH ``d``, ``r``) identified with the dynamic parameters,
the corrected robot file, which lengths torque data can see, the messages naming frame and field.

Recordings come from the truth bench's independent simulator (``bench/truthsim.py``: Pinocchio's RNEA on the MDH
table of the arm built with the true, lengthened geometry); the fit uses the generated model of the robot file.
"""
from __future__ import annotations

import dataclasses
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from symoro_gen.cli import main
from symoro_gen.description import load_robot
from symoro_gen.description.rewrite import RobotText
from symoro_gen.errors import IdentificationError, OptionError
from symoro_gen.identification.geometry import (
    LengthVisibility,
    add_lengths,
    length_plausible,
    parse_lengths,
    perturbed_robot,
)
from symoro_gen.workflows.identify import IdentifyOptions, identify

pytest.importorskip("pinocchio")

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "bench"))
try:
    import bench_loop_truth as blt
    import truthsim as ts
finally:
    sys.path.remove(str(ROOT / "bench"))

#: the injected error: link 3 of the LWR4 (r of frame 3, RL3 = 0.40 m) 5 mm longer than its robot file says
FRAME, FIELD, ERROR = 3, "r", 0.005


def _record(seed: int, seconds: float, name: str, error: float = ERROR):
    """A simulated LWR4 recording of the arm whose frame-3 ``r`` is ``error`` longer than the robot file's."""
    robot = load_robot("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    rng = np.random.default_rng(seed)
    truth = blt.lwr4_truth(robot, chi, 0.05)
    moved = perturbed_robot(robot, FRAME, FIELD, error)
    tr, _ = ts.record(moved, ts.Rigid(moved, chi), ts.sum_of_sines(robot, rng), truth, seconds, 250.0, rng, name)
    return tr


def test_corrected_lengths_in_the_robot_text(tmp_path):
    """``add_lengths``: a numeric ``d`` gets the sum, an expression ``r = "RL3"`` becomes ``"RL3 + 0.005"``; the
    corrected file parses and its numeric geometry is the robot file's plus the errors (every other frame
    unchanged)."""
    from symoro_gen.description.mdh import row_values

    robot = load_robot("lwr4")
    errors = {(3, "r"): 0.005, (5, "d"): -0.002}
    text = RobotText(robot.file)
    note = add_lengths(text, errors)
    assert "frame 3 r +5 mm" in note and "frame 5 d -2 mm" in note
    p = tmp_path / "corr.toml"
    p.write_text(text.text(["test"]))
    assert 'r = "RL3 + 0.005"' in p.read_text()
    new = load_robot(p)
    s0, s1 = robot.geometry_subs(), new.geometry_subs()
    for a, b in zip(robot.rows, new.rows):
        va, vb = row_values(a, s0), row_values(b, s1)
        assert float(vb[3]) == pytest.approx(float(va[3]) + errors.get((a.j, "d"), 0.0), abs=1e-12)
        assert float(np.ravel(vb[5])[0]) == pytest.approx(float(np.ravel(va[5])[0]) + errors.get((a.j, "r"), 0.0),
                                                          abs=1e-12)


def test_geometry_frames_messages():
    """``--geometry-frames``: a frame the robot lacks, a field that is no length, an invisible length are refused
    naming the robot file, the frame and the field (and the reason); ``3`` takes frame 3's visible lengths; the
    option without ``--geometry length`` is refused."""
    robot = load_robot("lwr4")
    vis = (LengthVisibility(1, "d", 0.0, False, "no torque changes with it"),
           LengthVisibility(3, "d", 0.2, True), LengthVisibility(3, "r", 0.3, True),
           LengthVisibility(4, "r", 0.0, False, "the base parameters absorb it"))
    assert parse_lengths(None, robot, vis) == ((3, "d"), (3, "r"))
    assert parse_lengths(["3r"], robot, vis) == ((3, "r"),)
    assert parse_lengths(["3"], robot, vis) == ((3, "d"), (3, "r"))
    with pytest.raises(IdentificationError, match=r"lwr4.toml has no frame j = 12"):
        parse_lengths(["12r"], robot, vis)
    with pytest.raises(IdentificationError, match=r"frame 3 of .*lwr4.toml: field 'x' is no length"):
        parse_lengths(["3x"], robot, vis)
    with pytest.raises(IdentificationError, match=r"frame 4 field r of .*lwr4.toml is not identifiable.*absorb"):
        parse_lengths(["4r"], robot, vis)
    with pytest.raises(IdentificationError, match="a frame number and a field"):
        parse_lengths(["r3"], robot, vis)
    with pytest.raises(OptionError, match=r"--geometry-frames .* add --geometry length"):
        IdentifyOptions(geometry="joint_zero", geometry_frames=["3r"])
    with pytest.raises(OptionError, match="--geometry 'lengths'"):
        IdentifyOptions(geometry="lengths")
    assert IdentifyOptions(geometry="joint_zero,length").geometry_kinds == ("joint_zero", "length")
    assert main(["identify", "lwr4", "x.csv", "--geometry", "joint_zero", "--geometry-frames", "3r"]) != 0


def test_plausibility_bounds():
    """50 mm and 10 % of the reach, whichever is smaller."""
    assert length_plausible(0.004, 0.8) and not length_plausible(0.06, 0.8)
    assert length_plausible(0.02, 0.3) and not length_plausible(0.04, 0.3)


@pytest.mark.slow
def test_identify_recovers_a_link_length(tmp_path):
    """A 5 mm error on r of frame 3 of the LWR4 (Pinocchio's arm built with it): ``identify --geometry length
    --geometry-frames 3r`` finds it within 3 sigma, sigma below a third of it; the validation error is
    no worse than the plain fit's; the JSON validates against the schema; ``-o`` writes the corrected file (never over
    the input), whose r3 is the file's plus the fit, and identify with it finds the error within 3 sigma of 0;
    a value beyond the plausible bounds is not written (the message names the frame and the field)."""
    from symoro_gen.simulate.recording import write_recording_csv
    from tests.docs.jsonschema_lite import validate

    tr, va = _record(41, 8.0, "len-ident"), _record(42, 4.0, "len-valid")
    res = identify("lwr4", [tr], validate=[va], geometry="length", geometry_frames=["3r"])
    g = res.geometry
    assert g is not None and g.converged and g.lengths == ((FRAME, FIELD),)
    v, s = float(g.length_values[0]), float(g.length_std[0])
    assert abs(v - ERROR) <= 3 * s, (v, s)
    assert s < ERROR / 3
    plain = identify("lwr4", [tr], validate=[va])
    # the error is mostly absorbed by the base parameters (first moments): the validation does not get worse
    assert float(np.sum(res.validation["rel_err"])) <= float(np.sum(plain.validation["rel_err"]))
    d = json.loads(json.dumps(res.to_dict()))
    assert d["geometry"]["lengths"][0]["error_mm"] == pytest.approx(1e3 * v)
    assert {(x["frame"], x["field"]) for x in d["geometry"]["lengths_not_identifiable"]} >= {(1, "d"), (1, "r")}
    schema = json.loads((ROOT / "docs" / "schemas" / "identify.schema.json").read_text())
    assert validate(d, schema) == []
    text = res.summary()
    assert f"frame 3 r {1e3 * v:+.3f} mm (sigma {1e3 * s:.3f} mm" in text
    assert "frame 1 d: not identifiable" in text
    # a wild value is never written
    wild = dataclasses.replace(res, geometry=dataclasses.replace(g, length_values=g.length_values + 0.06))
    with pytest.raises(IdentificationError, match=r"frame 3 field r error \+6\d\.\d mm"):
        wild.write_robot(tmp_path / "wild.toml")
    assert not (tmp_path / "wild.toml").exists()
    # the command: -o writes the corrected file, the input untouched
    shutil.copy(ROOT / "robots" / "lwr4.toml", tmp_path / "lwr4.toml")
    source = (tmp_path / "lwr4.toml").read_bytes()
    data = tmp_path / "a.csv"
    write_recording_csv(data, tr)
    out, js = tmp_path / "lwr4_len.toml", tmp_path / "r.json"
    assert main(["identify", str(tmp_path / "lwr4.toml"), str(data), "--geometry", "length", "--geometry-frames",
                 "3r", "-o", str(out), "--json", str(js), "--quiet"]) == 0
    assert (tmp_path / "lwr4.toml").read_bytes() == source
    full = json.loads(js.read_text())
    assert full["robot_out"]["written"] == {"length": ["3r"]}
    fitted = full["geometry"]["lengths"][0]["error_m"]
    new = load_robot(out)
    assert float(new.row(3).r.subs(new.geometry_subs())) == pytest.approx(0.40 + fitted, abs=1e-9)
    again = identify(out, [data], geometry="length", geometry_frames=["3r"])
    assert abs(again.geometry.length_values[0]) <= 3 * again.geometry.length_std[0]


@pytest.mark.slow
def test_zeros_and_lengths_together():
    """``--geometry joint_zero,length``: a 1 deg zero of joint 2 and the 5 mm error of r3 on the same arm, both
    within 3 sigma (joint 3's zero, not injected, within 3 sigma of 0), each injected one with sigma below a third
    of it; the JSON names both kinds."""
    import math

    robot = load_robot("lwr4")
    chi, _ = ts.nominal_parameters(robot)
    rng = np.random.default_rng(3)
    truth = blt.lwr4_truth(robot, chi, 0.05)
    truth.q_offset[1] = math.radians(1.0)
    moved = perturbed_robot(robot, FRAME, FIELD, ERROR)
    tr, _ = ts.record(moved, ts.Rigid(moved, chi), ts.sum_of_sines(robot, rng), truth, 8.0, 250.0, rng, "combo")
    res = identify("lwr4", [tr], geometry="joint_zero,length", geometry_joints=[2, 3], geometry_frames=["3r"])
    g = res.geometry
    assert g.converged and g.joints == (1, 2) and g.lengths == ((FRAME, FIELD),)
    for want, v, s in ((math.radians(1.0), g.offsets[0], g.std[0]), (0.0, g.offsets[1], g.std[1]),
                       (ERROR, g.length_values[0], g.length_std[0])):
        assert abs(v - want) <= 3 * s, (want, v, s)
        if want:
            assert s < abs(want) / 3
    assert res.to_dict()["geometry"]["parameters"] == "joint_zero,length"


@pytest.mark.slow
def test_the_emitted_derivative_gives_the_central_difference_fit(monkeypatch):
    """The Gauss-Newton column of a length from the package's emitted derivative (first iteration, at the file's
    geometry) and from central differences of the numeric Newton-Euler model throughout (the package without the
    derivative): the same length error within 0.1 sigma and the same sigma within 1 %, with fewer numeric
    Newton-Euler evaluations (the cost the emitted derivative saves)."""
    import symoro_gen.identification.geometry as geometry

    tr = _record(41, 8.0, "len-emitted")
    calls = {"n": 0}
    numeric = geometry.inverse_dynamics

    def counted(*args, **kwargs):
        calls["n"] += 1
        return numeric(*args, **kwargs)

    monkeypatch.setattr(geometry, "inverse_dynamics", counted)
    fast = identify("lwr4", [tr], geometry="length", geometry_frames=["3r"]).geometry
    n_fast, calls["n"] = calls["n"], 0
    monkeypatch.setattr(geometry, "emitted_length_column", lambda *args, **kwargs: None)
    slow = identify("lwr4", [tr], geometry="length", geometry_frames=["3r"]).geometry
    assert fast.converged and slow.converged
    v, s = float(slow.length_values[0]), float(slow.length_std[0])
    assert abs(float(fast.length_values[0]) - v) <= 0.1 * s, (fast.length_values, v, s)
    assert float(fast.length_std[0]) == pytest.approx(s, rel=0.01)
    assert abs(v - ERROR) <= 3 * s
    assert n_fast < calls["n"], (n_fast, calls["n"])
