"""When the loop finds ``elasticity`` on a joint read by one motor-side encoder, ``diagnose`` gives the robot-file
line that declares it (text and JSON ``robot_file``); declared, the joint is modelled as elastic: with
``--positions motor`` the candidate is no longer offered and the declared model fits that joint better.
Data: the independent oracle of :mod:`tests.elastic.pinsim` (Pinocchio + Spong, LWR4 joint 4, K = 3000)."""
from __future__ import annotations

import json
import sys

import numpy as np
import pytest

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from symoro_gen.description.elastic import ElasticJoint
from symoro_gen.identification.elastic import elastic_declarations
from tests.elastic.pinsim import JOINT, K_TRUE, elastic_log


@pytest.mark.parametrize("K, D", [(2817.92, 0.0), (123456.7, 2.345), (0.01234, 0.0)])
def test_declaration_line_is_toml_with_the_values(K, D):
    line = ElasticJoint(4, K, D).declaration()
    key, _, value = line.partition(" = ")
    table = tomllib.loads(f"{key} = {value}")["elastic"]
    assert table["K"] == pytest.approx(K, rel=5e-3)
    assert table.get("D", 0.0) == pytest.approx(D, rel=5e-3)
    assert ("D" in table) == (D > 0)


def test_declarations_of_effects():
    """Only plain, one-joint elasticity effects with a positive compliance become declarations; K = 1/c,
    K_std = sigma_c / c^2; the frame is the joint's ``j``."""
    from types import SimpleNamespace

    from symoro_gen.description import load_robot

    robot = load_robot("lwr4")

    def eff(kind="elasticity", joint=3, c=1 / 2500, sc=1e-5, modulation=None):
        return SimpleNamespace(kind=kind, joint=joint, values=np.array([c]), std=np.array([sc]),
                               modulation=modulation, verdict="cause", label=f"{kind}{joint}")

    (d,) = elastic_declarations(robot, [eff(), eff(kind="gain"), eff(c=-1e-4), eff(joint=None),
                                        eff(modulation="abs_dq")])
    assert (d.frame, d.joint) == (robot.model_joints[3].j, 3)
    assert abs(d.K - 2500.0) < 1e-9 and abs(d.K_std - 1e-5 * 2500.0 ** 2) < 1e-9
    assert d.line == "elastic = {K = 2500}"
    assert d.to_dict()["joint"] == 4 and "frame 4 (joint 4): elastic = {K = 2500}" in d.text()


@pytest.mark.slow
def test_found_elasticity_is_declared_and_then_replaces_the_candidate(tmp_path):
    from symoro_gen.description.parse import parse_robot_text
    from symoro_gen.paths import robots_dir
    from symoro_gen.preprocessing.trajectory import Trajectory
    from symoro_gen.workflows.diagnose import diagnose
    from tests.docs.test_schemas import check

    logs = [elastic_log(1, seconds=20.0), elastic_log(2, seconds=10.0)]
    ident, valid = (Trajectory(t=lg.t, q=lg.theta, tau=lg.tau, source=f"motor-{k}") for k, lg in enumerate(logs))
    first = diagnose("lwr4", [ident], validate=[valid])
    (d,) = first.declarations()
    assert (d.frame, d.joint) == (JOINT + 1, JOINT)
    assert abs(d.K - K_TRUE) <= 3 * d.K_std and d.K_std < K_TRUE / 3, (d.K, d.K_std)
    out = json.loads(json.dumps(first.to_dict(), allow_nan=False))
    check(out, "diagnose")
    assert out["robot_file"] == [d.to_dict()] and out["robot_file"][0]["line"] == d.line
    assert d.line in first.summary() and "--positions motor" in first.summary()
    assert d.line in first.report(tmp_path / "first.md").read_text()

    # the line, added to frame 4 of the robot file, declares the joint with that stiffness
    text = (robots_dir() / "lwr4.toml").read_text().replace('name = "lwr4"', 'name = "lwr4_found"', 1)
    parts = text.split("[[frames]]")
    parts[d.frame] = parts[d.frame].replace("r = ", d.line + "\nr = ", 1)
    f = tmp_path / "lwr4_found.toml"
    f.write_text("[[frames]]".join(parts))
    (el,) = parse_robot_text(f.read_text(), file=str(f)).elastic
    assert el.joint == d.frame and abs(el.K - d.K) <= 5e-3 * d.K

    second = diagnose(str(f), [ident], validate=[valid], positions="motor")
    assert not [c for c in second.residual.tried if c.kind == "elasticity" and c.joint == JOINT]
    assert not second.declarations()
    # the declared elastic joint fits its torque about as well as the loop's effect did, better than the rigid one
    b1, a1 = first.residual.before_validation_rel_err[JOINT], first.residual.after_validation_rel_err[JOINT]
    b2 = second.residual.before_validation_rel_err[JOINT]
    assert b2 < b1 and b2 < a1 + 0.25 * (b1 - a1), (b1, a1, b2)
