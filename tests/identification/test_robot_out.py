"""``identify -o/--robot-out`` writes what the run identified back into a copy of the robot file: elastic K and D
from a two-encoder log, the fitted scale of a declared friction law (the joint zeros: tests/identification/
test_geometry.py). Each against simulated truth: the written file loads, holds the identified value, and
identify again with it finds the quantity at that value; the input file is unchanged byte for byte."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.cli import main
from symoro_gen.description import load_robot
from symoro_gen.description.friction_law import FrictionLaw
from symoro_gen.description.rewrite import RobotText
from symoro_gen.errors import OptionError, RobotFileError
from symoro_gen.preprocessing.readers.options import make_format
from tests.docs.jsonschema_lite import validate

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[2]
SCHEMA = json.loads((ROOT / "docs" / "schemas" / "identify.schema.json").read_text())

FRAMES = """# a comment kept
elastic = {K = 500.0}

[[frames]]
j = 1
ant = 0
sigma = 0
alpha = 0
d = 0
theta = "q"   # joint variable
r = 0

[[frames]]
j = 2
ant = 1
sigma = 0
alpha = "pi/2"
d = 0.3
theta = "q"
r = 0
elastic = { K = 1000.0 }   # declared
friction_law = {kind = "stribeck", vs = 0.08}

[nominal]
M1 = 1.0
"""


def test_robot_text_edits_fields_by_key(tmp_path):
    """Inline tables edited by key (a missing key appended), a missing table added to its frame, string fields
    edited; every other line and comment unchanged; the result parses as TOML with the new values."""
    src = tmp_path / "r.toml"
    src.write_text(FRAMES)
    t = RobotText(src)
    t.set_inline(2, "elastic", {"K": "2500.0", "D": "6.0"})
    t.set_inline(1, "elastic", {"K": "4000.0", "D": "0.0"}, create=True)
    t.set_inline(2, "friction_law", {"vs": "0.05"})
    t.edit_string(1, "theta", lambda s: s + " + 0.1")
    out = t.text(["a header"])
    doc = tomllib.loads(out)
    f1, f2 = doc["frames"]
    assert f1["elastic"] == {"K": 4000.0, "D": 0.0} and f1["theta"] == "q + 0.1"
    assert f2["elastic"] == {"K": 2500.0, "D": 6.0}
    assert f2["friction_law"] == {"kind": "stribeck", "vs": 0.05}
    assert doc["elastic"] == {"K": 500.0} and doc["nominal"] == {"M1": 1.0}
    new = out.splitlines()
    assert new[0] == "# a header"
    old = FRAMES.splitlines()
    changed = [ln for ln in new[1:] if ln not in old]
    assert len(changed) == 4 and all("#" not in ln or "declared" in ln or "joint variable" in ln for ln in changed)
    assert "# a comment kept" in new and 'theta = "q + 0.1"   # joint variable' in new
    assert src.read_text() == FRAMES
    with pytest.raises(RobotFileError, match=r"r\.toml.*frame j = 1.*friction_law"):
        t.set_inline(1, "friction_law", {"vs": "0.1"})
    inline = tmp_path / "inline.toml"
    inline.write_text('frames = [{j = 1, ant = 0, sigma = 0, alpha = 0, d = 0, theta = "q", r = 0}]\n')
    with pytest.raises(RobotFileError, match=r"inline\.toml.*frame j = 1.*theta"):
        RobotText(inline).edit_string(1, "theta", str)


def test_elastic_k_d_written_and_read_back(tmp_path):
    """Two-encoder log of an elastic arm (true K, D): identify -o writes the estimated K, D on the frames
    (declared 1000, 0); the written file declares them, identify with it again estimates K at the written value
    (within a hundredth of its sigma: the written digits; its declared K now the written one), and both are the truth within 1 %."""
    from tests.elastic.test_elastic_stiffness import D_TRUE, K_TRUE, ROBOT, _robot, two_encoder_log

    t, qm, tau, ql, _, _ = two_encoder_log(_robot(), duration=4.0)
    csv = tmp_path / "encoders.csv"
    np.savetxt(csv, np.column_stack([t, qm, tau, ql]), delimiter=",", header="t,qm0,qm1,tau0,tau1,ql0,ql1",
               comments="", fmt="%.12g")
    src = tmp_path / "arm2e.toml"
    src.write_text(ROBOT.format(k1=1000.0, k2=1000.0, d1=0.0, d2=0.0))
    before = src.read_bytes()
    fmt = make_format(columns="t=t,q=qm0:qm1,tau=tau0:tau1,q_link=ql0:ql1")
    res = symoro_gen.identify(str(src), [csv], method="ols", data_format=fmt)
    out = tmp_path / "arm2e_identified.toml"
    res = res.write_robot(out)
    assert src.read_bytes() == before
    est = res.elasticity
    written = load_robot(out)
    for e, k, d, kt in zip(written.elastic, est.K, est.D, K_TRUE):
        assert pytest.approx(k, rel=1e-5) == e.K and pytest.approx(max(d, 0.0), rel=1e-5, abs=1e-9) == e.D
        assert abs(e.K - kt) < 0.01 * kt
    assert written.nominal == load_robot(src).nominal
    text = out.read_text()
    assert str(src) in text.splitlines()[0] and "elastic K, D" in text and "[nominal] unchanged" in text
    assert f"Robot file written (-o): {out}" in res.summary() and "elastic K, D of frames 1, 2" in res.summary()
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert d["robot_out"] == {"path": str(out), "robot_file": str(src), "written": {"elastic": [1, 2]}}
    assert validate(d, SCHEMA) == []
    bad = json.loads(json.dumps(d))
    bad["robot_out"]["written"]["nominal"] = [1]
    assert validate(bad, SCHEMA)  # the schema names what can be written: never [nominal]
    # the command (no --geometry: the robot file declares elastic joints) writes the same file
    cli_out = tmp_path / "cli.toml"
    assert main(["identify", str(src), str(csv), "--method", "ols", "--columns",
                 "t=t,q=qm0:qm1,tau=tau0:tau1,q_link=ql0:ql1", "-o", str(cli_out), "--quiet"]) == 0
    assert cli_out.read_text() == out.read_text()
    again = symoro_gen.identify(str(out), [csv], method="ols", data_format=fmt).elasticity
    assert again.declared_K == tuple(e.K for e in written.elastic)
    for k2, kw, s in zip(again.K, again.declared_K, again.K_std):
        assert abs(k2 - kw) <= 0.01 * s  # the value as written: its 6 digits round far below its sigma
    assert D_TRUE  # the damping truth is the simulator's (tested in test_elastic_stiffness)


@pytest.mark.slow
def test_friction_law_scale_written_and_read_back(tmp_path):
    """SCARA with a Stribeck law on joint 2 (true vs = 0.05), declared vs = 0.08 in a copy of robots/scara.toml:
    identify -o writes the fitted vs; identify with the written file refits vs within its sigma of the written
    value (and the truth within 3 sigma)."""
    from tests.friction.test_identify_declared_law import simulate

    _, tr, _ = simulate(FrictionLaw(2, "stribeck", 0.05), {"FS2": 1.5, "FSS2": 1.0, "FV2": 0.7}, seed=11,
                        duration=12.0)
    text = (ROOT / "robots" / "scara.toml").read_text()
    head, sep, rest = text.partition('d = "D2"\ntheta = "q"\nr = 0\n')
    assert sep, "robots/scara.toml changed: frame 2 not found"
    src = tmp_path / "scara.toml"
    src.write_text(head + sep + 'friction_law = {kind = "stribeck", vs = 0.08}\n' + rest)
    before = src.read_bytes()
    res = symoro_gen.identify(str(src), [tr], method="wls")
    (fit,) = res.friction_laws
    assert fit.fitted and abs(fit.scale - 0.05) <= 3 * fit.std
    out = tmp_path / "scara_identified.toml"
    res = res.write_robot(out)
    assert src.read_bytes() == before
    law = load_robot(out).friction_laws[2]
    assert law.kind == "stribeck" and law.scale == pytest.approx(fit.scale, rel=1e-5)
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    assert d["robot_out"]["written"] == {"friction_law": [2]} and validate(d, SCHEMA) == []
    assert "vs = " + repr(float(f"{fit.scale:.6g}")) in out.read_text()
    (refit,) = symoro_gen.identify(str(out), [tr], method="wls").friction_laws
    assert refit.law.scale == law.scale and abs(refit.scale - law.scale) <= refit.std


def test_refused_when_nothing_was_identified(tmp_path, capsys):
    """The command refuses -o before the computation when the robot file declares nothing it could write and
    --geometry is not given, naming what each quantity needs; the API refuses a run that identified none."""
    out = tmp_path / "x.toml"
    assert main(["identify", "scara", "q=0,tau=0,dt=0.01", "-o", str(out), "--quiet"]) != 0
    err = capsys.readouterr().err
    assert "-o/--robot-out" in err and "scara.toml" in err and "--geometry joint_zero" in err
    assert "elastic = {K = ...} on a frame" in err and "friction_law" in err and "[nominal]" in err
    assert not out.exists()
    from symoro_gen.preprocessing.trajectory import Trajectory
    from tests.elastic.test_elastic_stiffness import ROBOT, _robot, two_encoder_log

    t, _, tau, ql, _, _ = two_encoder_log(_robot(), duration=1.0)
    src = tmp_path / "arm2e.toml"
    src.write_text(ROBOT.format(k1=1000.0, k2=1000.0, d1=0.0, d2=0.0))
    # an elastic robot, but one encoder: no K, D estimated, nothing to write
    res = symoro_gen.identify(str(src), [Trajectory(t=t, q=ql, tau=tau, source="one encoder")], method="ols")
    assert res.elasticity is None
    with pytest.raises(OptionError, match=r"identified none .*arm2e\.toml.*q_link"):
        res.write_robot(out)
    assert not out.exists()


def test_input_robot_file_never_overwritten(tmp_path):
    """-o onto the input robot file is refused even with force (and leaves it as it was)."""
    from symoro_gen.errors import OutputError
    from symoro_gen.preprocessing.trajectory import Trajectory
    from tests.elastic.test_elastic_stiffness import ROBOT, _robot, two_encoder_log

    t, qm, tau, ql, _, _ = two_encoder_log(_robot(), duration=1.0)
    src = tmp_path / "arm2e.toml"
    src.write_text(ROBOT.format(k1=1000.0, k2=1000.0, d1=0.0, d2=0.0))
    before = src.read_bytes()
    res = symoro_gen.identify(str(src), [Trajectory(t=t, q=ql, tau=tau, deflection=qm - ql, source="two")],
                              method="ols")
    assert res.elasticity is not None
    with pytest.raises(OutputError, match="input"):
        res.write_robot(src, force=True)
    assert src.read_bytes() == before
