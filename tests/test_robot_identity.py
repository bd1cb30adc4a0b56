"""Results carry their robot's identity (``robot_id``, a hash of the canonical description): the same robot
file reformatted keeps it, a changed geometric constant changes it, and the exports refuse another robot's
result (``--params``, ``--from``) while accepting an older result without it, with a warning."""
from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from symoro_gen.description import load_robot
from symoro_gen.description.identity import robot_id
from symoro_gen.loader import model_for
from symoro_gen.paths import robots_dir
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording, write_recording_csv

SCARA_TOML = (robots_dir() / "scara.toml").read_text()


@pytest.fixture(scope="module")
def scara_result(tmp_path_factory, cli):
    """``symoro-gen identify scara REC.csv --json scara.json`` on a simulated recording."""
    robot, model = model_for("scara")
    rng = np.random.default_rng(3)
    mo = fourier_trajectory(robot.n_joints, 6.0, 0.002, rng, n_harmonics=4)
    rec = simulate_recording(model, mo.t, mo.q, mo.dq, mo.ddq, np.asarray(random_physical_parameters(robot, rng)),
                             noise_tau=0.01, rng=rng)
    tmp = tmp_path_factory.mktemp("identity")
    write_recording_csv(tmp / "rec.csv", rec)
    cli("-q", "identify", "scara", tmp / "rec.csv", "--method", "ols", "--json", tmp / "scara.json")
    return tmp / "scara.json"


def _reformatted(text: str) -> str:
    """The same robot written differently: comments dropped and added, blank lines, the top-level keys
    reordered (``[values]`` moved after the frames), ``0.35`` written ``3.5e-1``."""
    lines = [ln.split("#")[0].rstrip() for ln in text.splitlines()]
    body = "\n".join(ln for ln in lines if ln)
    head, rest = body.split("[values]", 1)
    values, tables = rest.split("[[frames]]", 1)
    top = "\n".join(sorted(head.strip().splitlines(), reverse=True))  # name, gravity, drive... in another order
    return (f"# reformatted\n{top}\n\n[[frames]]{tables}\n\n# the constants, last\n[values]{values}\n"
            ).replace("0.35", "3.5e-1")


def test_identity_ignores_formatting_and_follows_the_geometry(tmp_path):
    ref = robot_id(load_robot("scara"))
    assert len(ref) == 16 and int(ref, 16) >= 0
    f = tmp_path / "scara.toml"
    f.write_text(_reformatted(SCARA_TOML))
    assert f.read_text() != SCARA_TOML
    assert robot_id(load_robot(f)) == ref
    # a geometric constant changed: another robot
    g = tmp_path / "scara_long.toml"
    assert "D2 = 0.35" in SCARA_TOML
    g.write_text(SCARA_TOML.replace("D2 = 0.35", "D2 = 0.36"))
    assert robot_id(load_robot(g)) != ref
    # the name, the nominal parameters and the limits are not the robot's identity
    h = tmp_path / "renamed.toml"
    h.write_text(SCARA_TOML.replace('name = "scara"', 'name = "scara_b"'))
    assert robot_id(load_robot(h)) == ref
    assert len({robot_id(load_robot(n)) for n in ("scara", "lwr4", "rx90", "tx40", "palletizer")}) == 5


def test_identify_json_carries_the_robot_id(scara_result):
    doc = json.loads(scara_result.read_text())
    keys = list(doc)
    assert keys[keys.index("robot") + 1] == "robot_id"
    assert doc["robot_id"] == robot_id(load_robot("scara"))


@pytest.mark.parametrize("option", ["--params", "--from"])
def test_another_robots_result_is_refused(scara_result, tmp_path, cli, option):
    out = tmp_path / "lwr4.urdf"
    r = cli("export-urdf", "lwr4", option, scara_result, "-o", out, rc=2)
    sid, lid = robot_id(load_robot("scara")), robot_id(load_robot("lwr4"))
    assert r.err_lines == [
        f"symoro-gen: error: export-urdf {option} {scara_result}: a result of robot 'scara' (robot_id {sid}), not "
        f"of 'lwr4' (robot_id {lid}): its parameters belong to another robot",
        "hint: give a result of `symoro-gen identify lwr4 ... --json` (robot_id is a hash of the robot's geometry, "
        "joints, drive chain, payload frame and gravity; see docs/json-output.md)"]
    assert not out.exists()


def test_export_mjcf_refuses_another_robots_result(scara_result, tmp_path, cli):
    r = cli("export-mjcf", "lwr4", "--from", scara_result, "-o", tmp_path / "lwr4.xml", rc=2)
    assert r.err_lines[0].startswith(f"symoro-gen: error: export-mjcf --from {scara_result}: a result of robot "
                                     "'scara'")


def test_the_same_robot_reformatted_accepts_the_result(scara_result, tmp_path, cli):
    f = tmp_path / "scara.toml"
    f.write_text(_reformatted(SCARA_TOML))
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        cli("export-urdf", f, "--params", scara_result, "-o", tmp_path / "scara.urdf")
    assert [str(w.message) for w in caught if "parameters not applied" in str(w.message)]  # warnings recorded
    assert not [str(w.message) for w in caught if "robot_id" in str(w.message)]
    assert (tmp_path / "scara.urdf").exists()


def test_an_older_result_without_robot_id_is_accepted_with_a_warning(scara_result, tmp_path, cli):
    doc = json.loads(scara_result.read_text())
    del doc["robot_id"]
    old = tmp_path / "old.json"
    old.write_text(json.dumps(doc))
    r = cli.subprocess("export-urdf", "scara", "--params", old, "-o", tmp_path / "scara.urdf")
    assert (f"symoro-gen: warning: export-urdf --params {old}: the result has no robot_id (written by an older "
            "symoro-gen): not checked that it is a result of scara (it names robot 'scara')") in r.stderr.splitlines()
    assert (tmp_path / "scara.urdf").exists()
