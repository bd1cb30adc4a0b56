"""``diagnose`` with the robot file's declared friction laws: the loop starts from the declared law (its scale
refined on the identification data only) and does not propose it again; a law the loop names comes with the
robot-file line that declares it, and that line, added to the file and re-run, closes the loop (simulated
SCARA with a Stribeck joint: exact Newton-Euler torques plus the law, noise on q and torque)."""
from __future__ import annotations

import dataclasses
import importlib
import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description.friction_law import FrictionLaw
from symoro_gen.description.parse import parse_robot_text
from symoro_gen.diagnostics import DiagnoseSettings
from symoro_gen.diagnostics import diagnose as loop
from symoro_gen.diagnostics.friction import LawDeclaration, law_declarations
from symoro_gen.identification.friction_law import LawDeclaredModel
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques
from tests.diagnostics.simdata import robot_and_model
from tests.docs.jsonschema_lite import validate
from tests.docs.runner import DOCS

#: the module (``symoro_gen.workflows.diagnose`` the attribute is the function)
diagnose_workflow = importlib.import_module("symoro_gen.workflows.diagnose")
SCHEMA = json.loads((DOCS / "schemas" / "diagnose.schema.json").read_text())
SCARA_FILE = Path(__file__).resolve().parents[2] / "robots" / "scara.toml"

#: the simulated drive of joint 2 (frame 2): Stribeck law, Fc = 1.5, Fs - Fc = 3, Fv = 0.7, vs = 0.1 rad/s
TRUE_VS = 0.1
TRUTH = {"FS2": 1.5, "FSS2": 3.0, "FV2": 0.7}
NOISE_Q, NOISE_TAU = 1e-5, 0.05


class WithRobot:
    """The SCARA model carrying a robot description (``diagnose`` reads the declared laws from it)."""

    def __init__(self, model, robot):
        self._model, self.robot = model, robot

    def __getattr__(self, name):
        return getattr(self._model, name)

    def regressor(self, *a, **k):
        return self._model.regressor(*a, **k)


def simulate_stribeck():
    """(model, robot without declared law, recording): 40 s of a Fourier trajectory, joint 2 with the Stribeck
    law in place of its Coulomb + viscous terms."""
    robot, model = robot_and_model("scara")
    rng = np.random.default_rng(11)
    n = model.N_JOINTS
    amp = np.ones(n)
    amp[2] = 0.1
    t, q, dq, ddq = fourier_trajectory(n, 40.0, 0.002, rng, base_frequency_hz=0.1, amplitude=amp)
    chi = np.asarray(random_physical_parameters(robot, rng), float)
    names = list(robot.standard_names)
    for k in ("FS2", "FV2"):
        chi[names.index(k)] = 0.0
    tau = true_torques(model, q, dq, ddq, chi)
    law = FrictionLaw(2, "stribeck", TRUE_VS)
    tau[:, 1] += law.columns(dq[:, 1]) @ np.array([TRUTH[nm] for nm in law.names()])
    tr = Trajectory(t=t, q=q + NOISE_Q * rng.standard_normal(q.shape),
                    tau=tau + NOISE_TAU * rng.standard_normal(q.shape), source="scara stribeck joint 2")
    return model, dataclasses.replace(robot, friction_laws={}), tr


@pytest.fixture(scope="module")
def stribeck_case():
    return simulate_stribeck()


def with_line(line: str, frame: int) -> str:
    """The SCARA robot file with ``line`` added to the ``[[frames]]`` entry ``j = frame``."""
    text = SCARA_FILE.read_text()
    key = f"[[frames]]\nj = {frame}\n"
    assert text.count(key) == 1
    return text.replace(key, key + line + "\n")


def _joint_effects(results, j: int) -> list:
    return [e for e in results.residual.effects if e.joint == j]


@pytest.mark.slow
def test_found_law_declared_is_not_proposed_again(stribeck_case, monkeypatch):
    """Undeclared, the loop names the Stribeck law on joint 2 and prints its line (``vs`` near the truth);
    that line added to frame 2 of the robot file and re-run: the loop starts from the law (scale refined
    within 3 sigma of the truth, on the identification part only), names nothing on joint 2, and its
    validation error there is at least as good."""
    model, robot, tr = stribeck_case
    found = symoro_gen.diagnose(WithRobot(model, robot), [tr], max_effects=2)
    kinds = {e.kind for e in _joint_effects(found, 1)}
    assert kinds & {"friction_law", "stribeck"}, [e.label for e in found.residual.effects]
    decl = [d for d in found.declarations() if isinstance(d, LawDeclaration)]
    assert [(d.frame, d.law, d.scale_name) for d in decl] == [(2, "stribeck", "vs")], decl
    assert abs(decl[0].scale - TRUE_VS) < 0.2 * TRUE_VS, decl[0]
    assert decl[0].line in found.summary()
    doc = found.to_dict()
    validate(doc, SCHEMA)
    assert doc["declared_friction_laws"] == []
    assert [r["line"] for r in doc["robot_file"] if r["kind"] == "friction_law"] == [decl[0].line]

    # the line through the robot-file parser
    parsed = parse_robot_text(with_line(decl[0].line, 2), "scara.toml")
    assert parsed.friction_laws[2].kind == "stribeck"
    assert math.isclose(parsed.friction_laws[2].scale, decl[0].scale, rel_tol=5e-3)

    seen: list[int] = []
    refine = diagnose_workflow.refine_scales

    def recording_refine(model_, laws, trajectories, options):
        seen.extend(t.n_samples for t in trajectories)
        return refine(model_, laws, trajectories, options)
    monkeypatch.setattr(diagnose_workflow, "refine_scales", recording_refine)
    declared_robot = dataclasses.replace(robot, friction_laws=dict(parsed.friction_laws))
    again = symoro_gen.diagnose(WithRobot(model, declared_robot), [tr], max_effects=2)
    # refined on the leading 70 % the loop identifies on, never the held-out validation share
    assert seen and sum(seen) <= round(0.7 * tr.n_samples) + 1, (seen, tr.n_samples)
    (fit,) = again.friction_laws
    assert fit.fitted and abs(fit.scale - TRUE_VS) <= 3 * fit.std, fit
    assert not _joint_effects(again, 1), [e.label for e in again.residual.effects]
    assert not [c for c in again.residual.tried if c.joint == 1 and c.kind in ("friction_law", "stribeck")]
    assert not [d for d in again.declarations() if d.joint == 1]
    v_found = np.asarray(found.residual.after_validation_rel_err)
    v_again = np.asarray(again.residual.after_validation_rel_err)
    assert v_again[1] <= v_found[1], (v_found, v_again)
    assert float(np.sum(v_again ** 2)) <= float(np.sum(v_found ** 2)), (v_found, v_again)
    doc = again.to_dict()
    validate(doc, SCHEMA)
    assert [(e["frame"], e["kind"], e["fitted"]) for e in doc["declared_friction_laws"]] == [(2, "stribeck", True)]
    assert "Declared friction laws" in again.summary()


def _effect(kind: str, joint: int, physical: dict, names=("Fst",), verdict: str = "cause", modulation=None):
    return SimpleNamespace(kind=kind, joint=joint, physical=physical, names=names, verdict=verdict,
                           label=f"{kind}{joint + 1}", modulation=modulation)


@pytest.mark.parametrize("effect, law", [
    (_effect("friction_law", 1, {"vs": 0.0734, "v_sign": 1e-4}, ("FS2", "FSS2", "FV2")), FrictionLaw(2, "stribeck", 0.0734)),
    (_effect("friction_law", 3, {"v": 0.0213}, ("FS4", "FV4")), FrictionLaw(4, "tanh", 0.0213)),
    (_effect("friction_law", 0, {"delta": 0.62}, ("FS1", "FV1")), FrictionLaw(1, "power", 0.62)),
    (_effect("stribeck", 1, {"vs": 0.0456, "Fst": 2.0}), FrictionLaw(2, "stribeck", 0.0456)),
])
def test_declaration_line_parses_back_to_the_law(effect, law):
    """The line of a friction effect, added to its frame of the SCARA file, is read back by the robot-file
    parser as the law the effect names (kind and scale to the 3 digits written)."""
    robot, _ = robot_and_model("scara")
    (d,) = law_declarations(dataclasses.replace(robot, friction_laws={}), [effect])
    assert (d.frame, d.joint, d.law) == (law.frame, effect.joint, law.kind)
    got = parse_robot_text(with_line(d.line, d.frame), "scara.toml").friction_laws[law.frame]
    assert got.kind == law.kind and math.isclose(got.scale, law.scale, rel_tol=5e-3), (d.line, got)
    assert d.line in d.text() and d.to_dict()["joint"] == effect.joint + 1


@pytest.mark.parametrize("effect", [
    _effect("friction_law", 1, {"vs": 0.05, "delta": 0.6}, ("FS2", "FSS2", "FV2")),   # no single kind declares both
    _effect("friction_law", 1, {"v": 0.05}, ("FS2", "FV2", "OFF2")),                   # joint declared without friction
    _effect("stribeck", 1, {"vs": 0.05}, modulation="q1"),                             # a modulated dip
    _effect("friction_law", 1, {"delta": 5.0}, ("FS2", "FV2")),                         # outside the file's range
    _effect("time_delay", 1, {"vs": 0.05}),                                            # not a friction law
])
def test_no_declaration_line_for_what_one_law_does_not_declare(effect):
    robot, _ = robot_and_model("scara")
    assert law_declarations(dataclasses.replace(robot, friction_laws={}), [effect]) == []


def test_no_declaration_line_on_a_joint_that_declares_a_law():
    robot, _ = robot_and_model("scara")
    declared = dataclasses.replace(robot, friction_laws={2: FrictionLaw(2, "tanh", 0.02)})
    assert law_declarations(declared, [_effect("stribeck", 1, {"vs": 0.05})]) == []


@pytest.mark.slow
@pytest.mark.parametrize("kind, scale, stribeck_offered", [("tanh", 0.02, True), ("stribeck", 0.1, False),
                                                           ("lugre", 0.1, False)])
def test_what_the_loop_offers_on_a_declared_joint(stribeck_case, kind, scale, stribeck_offered):
    """On a joint whose law is declared, the friction-law stage offers no replacement (no ``friction_law``
    candidate); the loop's Stribeck dip is still a candidate unless the declared law has the Stribeck term
    (Stribeck, LuGre), and the other candidates stay (docs/loop-plausibility.md, "Declared friction laws")."""
    model, _, tr = stribeck_case
    short = Trajectory(t=tr.t[:7501], q=tr.q[:7501], tau=tr.tau[:7501], source="first 15 s")
    kw = dict(candidates=("stribeck", "gain"), friction_laws=True, composed=False, structure=False,
              unexplained=False, stability=False, max_effects=1)
    free = loop(model, short, DiagnoseSettings(**kw))
    # undeclared, the stage offers the Stribeck law of the simulated drive on joint 2
    assert ("friction_law", 1) in {(c.kind, c.joint) for c in free.tried} | {(e.kind, e.joint) for e in free.effects}
    declared = LawDeclaredModel(model, [(1, FrictionLaw(2, kind, scale))])
    rep = loop(declared, short, DiagnoseSettings(**kw, declared_laws=(1,)))
    tried = {(c.kind, c.joint) for c in rep.tried}
    assert ("friction_law", 1) not in tried
    assert (("stribeck", 1) in tried) is stribeck_offered, sorted(tried)
    assert ("gain", 1) in tried and ("stribeck", 0) in tried
