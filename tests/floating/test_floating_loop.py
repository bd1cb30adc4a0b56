"""``diagnose`` of a floating-base robot: the fixed-base loop on its base-wrench and joint rows
(docs/floating-base.md, "The loop per kind of rows").

The truth is the Pinocchio-simulated log of :func:`tests.floating.test_cli_floating.simulate_log` (free-flyer RNEA,
two contact wrenches, IMU and joint noise). A drive effect the robot file does not declare is added to one joint's
logged torque: the loop must name it on that joint's row with its value within 3 standard deviations, and name
nothing on the same robot's clean log.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.identification.floating import RowsAsJoints
from symoro_gen.runtime.floating import FloatingModel, numeric_base
from symoro_gen.workflows import diagnose
from symoro_gen.workflows.floating import row_name, signal_name
from tests.docs.jsonschema_lite import validate

from .pinocchio_floating import pin_floating_torque, random_floating_parameters, random_floating_states
from .test_cli_floating import HOPPER, simulate_log

HERE = Path(__file__).parent
SCHEMA = json.loads((HERE.parents[1] / "docs" / "schemas" / "diagnose.schema.json").read_text())
#: the quadruped with its fl knee (frame 3, the third joint) declared with a rotor inertia only: no friction, no
#: offset in the model (nor in the simulated truth, :func:`random_floating_parameters` draws the declared terms)
KNEE = 3
CONTACTS = {"frame6": 6, "frame9": 9}


def test_rows_as_joints_is_pinocchios_free_flyer():
    """The adapter's regressor (rotation vector in, quaternion to the model) times the identified combinations
    ``K chi`` is Pinocchio's free-flyer RNEA with the drive terms, on every row; the drive terms are named on their
    row (``FV<7 + c>`` for the joint in column ``c``)."""
    robot = parse_robot_text(HOPPER)
    model = FloatingModel(robot)
    rng = np.random.default_rng(4)
    q, dq, ddq = random_floating_states(robot, 40, rng)
    chi = random_floating_parameters(robot, rng)
    W = np.asarray(model.standard_regressor(q, dq, ddq), float)
    rows = RowsAsJoints.of(model, robot, W)
    kept, K = numeric_base(W.transpose(1, 0, 2).reshape(-1, W.shape[2]))
    assert np.array_equal(rows.kept, kept)
    pred = rows.regressor(RowsAsJoints.signals(q), dq, ddq) @ (K @ chi)
    truth = pin_floating_torque(robot, q, dq, ddq, chi)
    assert np.max(np.abs(pred - truth)) < 1e-8 * np.max(np.abs(truth))
    assert 6 + robot.n_joints == rows.N_JOINTS
    drive = {n for n in rows.BASE_NAMES if n.rstrip("0123456789") in ("IA", "FV", "FS", "OFF")}
    assert drive == {f"{k}{7 + c}" for k in ("IA", "FV", "FS", "OFF") for c in range(robot.n_joints)}


def test_row_and_signal_names():
    """Row positions and the loop's signals read on the floating robot (base coordinates, then joints)."""
    assert [row_name(i) for i in (0, 5, 6, 17)] == ["FX0", "MZ0", "tau1", "tau12"]
    assert signal_name("q3") == "q[z]" and signal_name("dq4") == "dq[rx]" and signal_name("ddq9") == "ddq3"
    assert signal_name("tau_hat6") == "tau_hat[MZ0]" and signal_name("tau_hat8") == "tau_hat[tau2]"
    assert signal_name("t") == "t"


def _hopper(d: Path):
    """The hopper of the command-line tests with its knee (frame 2) declared with a rotor inertia only."""
    anchor = "[[frames]]\nj = 2\n"
    assert anchor in HOPPER
    (d / "hopper.toml").write_text(HOPPER.replace(anchor, anchor + 'drive = ["IA"]\n'))
    return load_robot(d / "hopper.toml")


def _hopper_log(robot, d: Path, seed: int, duration: float, friction: bool) -> Path:
    path = d / f"hopper_{seed}_{friction}.csv"
    simulate_log(robot, path, seed=seed, duration=duration, fs=200.0, contacts={"frame1": 1, "foot": 3})
    if friction:
        names = path.read_text().split("\n", 1)[0].split(",")
        table = np.loadtxt(path, delimiter=",", skiprows=1)
        dq = np.gradient(table[:, names.index("q2")], table[:, 0])
        table[:, names.index("tau2")] += 1.5 * dq + 1.0 * np.sign(dq)
        np.savetxt(path, table, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
    return path


def test_hopper_clean_log_names_nothing(tmp_path):
    """The loop end to end on a short clean log of the hopper (8 s): no effect on any row, no unexplained
    structure, every row reported (the other seeds in the slow test below)."""
    robot = _hopper(tmp_path)
    res = diagnose(robot.file, [str(_hopper_log(robot, tmp_path, 3, 8.0, False))])
    d = json.loads(json.dumps(res.to_dict(), allow_nan=False))
    errs = validate(d, SCHEMA["$defs"]["floating_diagnose"], root=SCHEMA)
    assert not errs, errs[:5]
    loop = d["floating"]["loop"]
    assert loop["rows"] == ["FX0", "FY0", "FZ0", "MX0", "MY0", "MZ0", "tau1", "tau2"]
    assert loop["effects"] == [] and not any(u["flagged"] for u in loop["unexplained"])
    assert len(loop["rel_err_after"]) == 8
    assert "Residual analysis per row" in res.summary()


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 4, 5])
def test_hopper_clean_logs_name_nothing(tmp_path, seed):
    robot = _hopper(tmp_path)
    res = diagnose(robot.file, [str(_hopper_log(robot, tmp_path, seed, 8.0, False))])
    loop = res.to_dict()["floating"]["loop"]
    assert loop["effects"] == [] and not any(u["flagged"] for u in loop["unexplained"])


@pytest.mark.slow
def test_hopper_knee_offset_is_flagged_ambiguous(tmp_path):
    """A 2 N m offset on the hopper's knee (declared without one), whose row the foot's wrench reaches (16 s log):
    the loop names it on row tau2 within 3 sigma; a sensor gain the contact checks accept on the joint rows for
    the same residual is reported as ambiguous with it."""
    robot = _hopper(tmp_path)
    path = _hopper_log(robot, tmp_path, 2, 16.0, False)
    names = path.read_text().split("\n", 1)[0].split(",")
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    table[:, names.index("tau2")] += 2.0
    np.savetxt(path, table, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
    res = diagnose(robot.file, [str(path)])
    eff = _effects(res)
    assert set(eff) == {("tau2", "offset")}
    (name, value), = eff[("tau2", "offset")]["params"].items()
    assert abs(value - 2.0) < 3 * eff[("tau2", "offset")]["std"][name]
    assert not validate(res.to_dict(), SCHEMA["$defs"]["floating_diagnose"], root=SCHEMA)
    loop = res.to_dict()["floating"]["loop"]
    # the foot's sensor reaches the knee's row, the thigh's (frame 1, above the knee) does not
    found = {c["frame"] for c in res.found if c["kind"] == "joints"}
    assert "foot" in found
    assert [a.split(" and ")[0] for a in loop["ambiguous"]] == ["the gain of the sensor at foot"]
    assert "row tau2" in loop["ambiguous"][0]


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_hopper_knee_friction(tmp_path, seed):
    """Friction on the hopper's knee, whose row also carries the foot's contact wrench (16 s logs): named on row
    tau2 by the friction-law stage, FV and FS within 3 sigma, no structure left on any row. Seed 2: the knee's
    gains over the 20 sub-blocks of the law's test span 0.9 to 119, all positive; the t test of their mean left
    the law out (p 0.006), the signed-rank test keeps it (p 1e-6)."""
    robot = _hopper(tmp_path)
    res = diagnose(robot.file, [str(_hopper_log(robot, tmp_path, seed, 16.0, True))])
    eff = _effects(res)
    assert {row for row, _ in eff} == {"tau2"}
    law = next(iter(eff.values()))
    for name, truth in (("FV8", 1.5), ("FS8", 1.0)):
        assert abs(law["params"][name] - truth) < 3 * law["std"][name], name
    assert not any(u["flagged"] for u in res.to_dict()["floating"]["loop"]["unexplained"])


def _knee_friction_z(tmp_path, seed: int) -> dict[str, float]:
    """The error of the knee's friction law named on row tau2 over its reported standard deviation, per constant
    (the truth: FV 1.5 N m s/rad, FS 1 N m, no offset), on an 8 s log of the hopper."""
    tmp_path.mkdir(exist_ok=True)
    robot = _hopper(tmp_path)
    res = diagnose(robot.file, [str(_hopper_log(robot, tmp_path, seed, 8.0, True))])
    eff = _effects(res)
    assert set(eff) == {("tau2", "friction_law")}
    law = eff[("tau2", "friction_law")]
    truth = {"FV8": 1.5, "FS8": 1.0, "OFF8": 0.0}
    assert {"FV8", "FS8"} <= set(law["params"]) <= set(truth)
    return {nm: (law["params"][nm] - truth[nm]) / law["std"][nm] for nm in law["params"]}


def test_hopper_knee_friction_short_log(tmp_path):
    """Friction on the hopper's knee, 8 s log (seed 1: its estimates are the farthest from the truth of seeds 1 to
    12, FV 1.71, FS 0.79): named on row tau2, each constant within 3 sigma of the truth. The loop's standard
    deviations take the rows as independent; the within-sample sandwich of ``identify`` was measured to be
    optimistic here (docs/floating-base.md)."""
    z = _knee_friction_z(tmp_path, 1)
    assert all(abs(v) < 3 for v in z.values()), z


@pytest.mark.slow
def test_hopper_knee_friction_sigma_over_seeds(tmp_path):
    """The same over 8 s logs of seeds 2 to 6: every constant within 3 sigma, and the mean of z^2 over them (at
    most 15, correlated within a law) below 2: the standard deviations are not optimistic."""
    z = [v for seed in range(2, 7) for v in _knee_friction_z(tmp_path / str(seed), seed).values()]
    assert max(abs(v) for v in z) < 3, z
    assert float(np.mean(np.square(z))) < 2.0, z


def _quadruped(d: Path):
    text = (HERE / "quadruped.toml").read_text()
    anchor = f"[[frames]]  # fl knee\nj = {KNEE}\n"
    assert anchor in text
    (d / "quad.toml").write_text(text.replace(anchor, anchor + 'drive = ["IA"]\n'))
    return load_robot(d / "quad.toml")


def _log(robot, d: Path, seed: int, duration: float, effect: str | None) -> Path:
    """The simulated log, with ``effect`` added to the knee's logged torque (the motor's torque: the rigid body's
    and the drive's)."""
    path = d / f"quad_{seed}_{effect}.csv"
    simulate_log(robot, path, seed=seed, duration=duration, fs=200.0, contacts=CONTACTS)
    return path if effect is None else _with_effect(path, effect)


def _with_effect(path: Path, effect: str, out: Path | None = None) -> Path:
    """``path`` with ``effect`` on a torque: ``offset`` (2 N m on the knee), ``friction`` (viscous 1.5 N m s/rad and
    Coulomb 1 N m on the knee, its velocity from the logged positions: the simulated motion is smooth) or ``gain``
    (joint 2's torque read 10 % too high) ``ripple`` (``sin(4 q2)`` N m on joint 2's torque) or ``delay`` (joint 2's torque logged 10 ms late)."""
    names = path.read_text().split("\n", 1)[0].split(",")
    table = np.loadtxt(path, delimiter=",", skiprows=1)
    col = names.index(f"tau{KNEE}")
    dq = np.gradient(table[:, names.index(f"q{KNEE}")], table[:, 0])
    if effect == "gain":
        table[:, names.index("tau2")] *= 1.1
    elif effect == "ripple":
        table[:, names.index("tau2")] += np.sin(4 * table[:, names.index("q2")])
    elif effect == "delay":
        table[:, names.index("tau2")] = np.interp(table[:, 0] - 0.01, table[:, 0], table[:, names.index("tau2")])
    else:
        table[:, col] += 2.0 if effect == "offset" else 1.5 * dq + 1.0 * np.sign(dq)
    out = out or path
    np.savetxt(out, table, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
    return out


@pytest.fixture(scope="module")
def quad30(tmp_path_factory):
    """The quadruped and a clean 30 s log (seed 11): a 15 s log leaves 28 acceptance rows per row, below the
    loop's 30, so the rounds' candidates need the longer one."""
    d = tmp_path_factory.mktemp("quad30")
    robot = _quadruped(d)
    return robot, _log(robot, d, 11, 30.0, None)


def _effects(res) -> dict:
    loop = res.to_dict()["floating"]["loop"]
    print(res.summary())
    return {(e["row"], e["kind"]): e for e in loop["effects"]}


@pytest.mark.slow
def test_clean_30s_log_names_and_flags_nothing(quad30):
    """The clean 30 s log (seed 11): no effect on any row and no row flagged by the ``unexplained`` check. Its
    rows' noise differs by a factor 10 to 40 in variance (the base-wrench rows carry the contact sensors' noise and,
    through the base's columns, the IMU's): tested on the unweighted fit's residual, the quiet row tau2 was
    flagged (out-of-fold R^2 0.11 against tau_hat[MZ0], the noisy rows' estimation error spread onto it); the
    loop tests the per-joint weighted refit's residual."""
    robot, clean = quad30
    res = diagnose(robot.file, [str(clean)])
    loop = res.to_dict()["floating"]["loop"]
    assert _effects(res) == {}
    assert [u["row"] for u in loop["unexplained"]] == loop["rows"]
    assert not any(u["flagged"] for u in loop["unexplained"]), loop["unexplained"]


@pytest.mark.slow
def test_loop_names_a_knee_offset(quad30, tmp_path):
    """A 2 N m offset on the knee's torque: named on row tau3 (round 1), within 3 sigma; nothing else named."""
    robot, clean = quad30
    res = diagnose(robot.file, [str(_with_effect(clean, "offset", tmp_path / "offset.csv"))])
    eff = _effects(res)
    assert not validate(res.to_dict(), SCHEMA["$defs"]["floating_diagnose"], root=SCHEMA)
    assert set(eff) == {("tau3", "offset")}
    e = eff[("tau3", "offset")]
    (name, value), = e["params"].items()
    assert abs(value - 2.0) < 3 * e["std"][name]
    assert e["verdict"] == "cause"


@pytest.mark.slow
def test_loop_names_a_torque_gain(quad30, tmp_path):
    """Joint 2's torque read 10 % too high (a row no contact wrench reaches: the loop's gain column, the row's model
    torque, is then the drive's torque): named on row tau2, ``gamma = 0.1`` within 3 sigma; nothing else named."""
    robot, clean = quad30
    res = diagnose(robot.file, [str(_with_effect(clean, "gain", tmp_path / "gain.csv"))])
    eff = _effects(res)
    assert set(eff) == {("tau2", "gain")}
    e = eff[("tau2", "gain")]
    (name, value), = e["params"].items()
    assert abs(value - 0.1) < 3 * e["std"][name]


@pytest.mark.slow
def test_loop_names_a_position_ripple(quad30, tmp_path):
    """A ripple ``sin(4 q2)`` N m on joint 2's torque: ``position_ripple`` of order 4 on row tau2, its sine and
    cosine amplitudes (1 and 0) within 3 sigma; no other effect."""
    robot, clean = quad30
    res = diagnose(robot.file, [str(_with_effect(clean, "ripple", tmp_path / "ripple.csv"))])
    eff = _effects(res)
    assert set(eff) == {("tau2", "position_ripple")}
    e = eff[("tau2", "position_ripple")]
    assert e["physical"]["k"] == 4
    for name, truth in (("position_ripple8.a_sin", 1.0), ("position_ripple8.a_cos", 0.0)):
        assert abs(e["params"][name] - truth) < 3 * e["std"][name], name


@pytest.mark.slow
def test_loop_names_a_time_delay(quad30, tmp_path):
    """Joint 2's torque logged 10 ms late (linear interpolation of the log): ``time_delay`` on row tau2, the delay
    within 3 sigma of 10 ms; no other effect."""
    robot, clean = quad30
    res = diagnose(robot.file, [str(_with_effect(clean, "delay", tmp_path / "delay.csv"))])
    eff = _effects(res)
    assert set(eff) == {("tau2", "time_delay")}
    e = eff[("tau2", "time_delay")]
    assert abs(e["params"]["time_delay8.d"] - 0.01) < 3 * e["std"]["time_delay8.d"]


@pytest.mark.slow
def test_loop_names_knee_friction(tmp_path):
    """Viscous (1.5 N m s/rad) and Coulomb (1 N m) friction on the knee, declared without: the friction-law
    stage names them on row tau3, each within 3 sigma; no other row gets an effect."""
    robot = _quadruped(tmp_path)
    res = diagnose(robot.file, [str(_log(robot, tmp_path, 11, 15.0, "friction"))])
    eff = _effects(res)
    assert {row for row, _ in eff} == {"tau3"}
    law = next(e for (row, _), e in eff.items() if row == "tau3")
    for name, truth in ((f"FV{6 + KNEE}", 1.5), (f"FS{6 + KNEE}", 1.0)):
        assert abs(law["params"][name] - truth) < 3 * law["std"][name], name


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 12, 13])
def test_loop_names_nothing_on_a_clean_log(tmp_path, seed):
    """The same robot, no effect added: no effect named on any row, no row flagged (the contact checks find nothing
    either)."""
    robot = _quadruped(tmp_path)
    res = diagnose(robot.file, [str(_log(robot, tmp_path, seed, 15.0, None))])
    assert _effects(res) == {}
    assert res.found == []
    loop = res.to_dict()["floating"]["loop"]
    assert [u["row"] for u in loop["unexplained"]] == loop["rows"]
    assert not any(u["flagged"] for u in loop["unexplained"]), loop["unexplained"]
