"""The ``friction_law`` field of a robot file: the laws of the diagnosis loop declared per frame, every
problem reported with file, frame and field."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from symoro_gen.description import parse_robot
from symoro_gen.description.friction_law import FrictionLaw, coulomb_columns, viscous_columns
from symoro_gen.diagnostics.friction import FrictionChoice, LawFit
from symoro_gen.errors import RobotFileError

SCARA = (Path(__file__).resolve().parents[2] / "robots" / "scara.toml").read_text()


def with_law(law: str, frame: int = 2, text: str = SCARA) -> str:
    """The SCARA robot file with ``friction_law = <law>`` on ``frame``."""
    key = f"j = {frame}\n"
    assert key in text
    return text.replace(key, f"{key}friction_law = {law}\n", 1)


def parse(tmp_path, text: str):
    p = tmp_path / "robot.toml"
    p.write_text(text, encoding="utf-8")
    return parse_robot(p), str(p)


@pytest.mark.parametrize("law, kind, scale", [('{kind = "stribeck", vs = 0.05}', "stribeck", 0.05),
                                              ('{kind = "tanh", v = 0.02}', "tanh", 0.02),
                                              ('{kind = "power", delta = 0.5}', "power", 0.5)])
def test_declared_law_is_read(tmp_path, law, kind, scale):
    robot, _ = parse(tmp_path, with_law(law))
    assert dict(robot.friction_laws) == {2: FrictionLaw(2, kind, scale)}
    assert parse(tmp_path, SCARA)[0].friction_laws == {}


@pytest.mark.parametrize("law, field, words", [
    ('{kind = "lugre2", vs = 0.05}', "friction_law.kind", ("'stribeck'",)),
    ('{kind = "stribeck", v = 0.05}', "friction_law.vs", ("missing",)),
    ('{kind = "stribeck", vs = 0.05, p = 1}', "friction_law.p", ("unknown",)),
    ('{kind = "stribeck", vs = -0.05}', "friction_law.vs", ("(0, 100]",)),
    ('{kind = "tanh", v = 0}', "friction_law.v", ("(0, 100]",)),
    ('{kind = "power", delta = 4.0}', "friction_law.delta", ("(0, 3]",)),
    ('{kind = "power", delta = true}', "friction_law.delta", ("number",)),
    ('"stribeck"', "friction_law", ("inline table",)),
])
def test_bad_law_names_file_frame_and_field(tmp_path, law, field, words):
    with pytest.raises(RobotFileError) as info:
        parse(tmp_path, with_law(law))
    file = str(tmp_path / "robot.toml")
    hits = [p for p in info.value.problems if p.file == file and p.where == "frame 2" and p.field == field]
    assert hits, str(info.value)
    assert all(w in " ".join(p.message for p in hits) for w in words), str(info.value)
    assert f"field '{field}'" in str(info.value) and "frame 2" in str(info.value)


def test_law_needs_the_coulomb_and_viscous_terms(tmp_path):
    text = with_law('{kind = "tanh", v = 0.02}').replace('drive = ["IA", "FV", "FS", "OFF"]', 'drive = ["IA", "OFF"]')
    with pytest.raises(RobotFileError) as info:
        parse(tmp_path, text)
    assert any(p.where == "frame 2" and p.field == "friction_law" and "FS and FV" in p.message
               for p in info.value.problems), str(info.value)


def test_columns_are_the_loops_laws():
    """One definition: a declared law's columns are those of the loop's FrictionChoice of the same law,
    and the Stribeck/tanh/power formulas themselves (Armstrong-Helouvry et al. 1994, eq. 5)."""
    dq = np.linspace(-1.0, 1.0, 41)
    for law, c, v in ((FrictionLaw(2, "stribeck", 0.05), LawFit("stribeck", 0.05, 0.0), LawFit("linear", None, 0.0)),
                      (FrictionLaw(2, "tanh", 0.02), LawFit("tanh", 0.02, 0.0), LawFit("linear", None, 0.0)),
                      (FrictionLaw(2, "power", 0.5), LawFit("sign", None, 0.0), LawFit("power", 0.5, 0.0))):
        ch = FrictionChoice(1, c, v, ())
        np.testing.assert_array_equal(law.columns(dq), ch.columns(dq))
        assert law.names() == ch.names()
    Fc, dF, vs, Fv = 0.7, 0.4, 0.05, 0.3
    tau = FrictionLaw(1, "stribeck", vs).columns(dq) @ [Fc, dF, Fv]
    np.testing.assert_allclose(tau, (Fc + dF * np.exp(-(dq / vs) ** 2)) * np.sign(dq) + Fv * dq)
    np.testing.assert_allclose(coulomb_columns("tanh", dq, 0.02)[:, 0], np.tanh(dq / 0.02))
    np.testing.assert_allclose(viscous_columns("power", dq, 0.5)[:, 0], np.sqrt(np.abs(dq)) * np.sign(dq))


def test_dynamic_laws_are_read_with_optional_presliding_constants(tmp_path):
    robot, _ = parse(tmp_path, with_law('{kind = "lugre", vs = 0.05, sigma0 = 1e4}'))
    law = robot.friction_laws[2]
    assert (law.kind, law.scale, dict(law.presliding), law.dynamic, law.names()) == \
        ("lugre", 0.05, {"sigma0": 1e4}, True, ("FS2", "FSS2", "FV2"))
    robot, _ = parse(tmp_path, with_law('{kind = "dahl"}'))
    law = robot.friction_laws[2]
    assert (law.kind, law.scale, law.presliding, law.names()) == ("dahl", None, (), ("FS2", "FV2"))
    with pytest.raises(RobotFileError) as info:
        parse(tmp_path, with_law('{kind = "dahl", sigma0 = -3}'))
    assert any(p.where == "frame 2" and p.field == "friction_law.sigma0" for p in info.value.problems), str(info.value)
    with pytest.raises(RobotFileError) as info:
        parse(tmp_path, with_law('{kind = "dahl", vs = 0.1}'))
    assert any(p.field == "friction_law.vs" and "unknown" in p.message for p in info.value.problems), str(info.value)
