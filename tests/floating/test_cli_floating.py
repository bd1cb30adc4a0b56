"""``symoro-gen identify`` of floating-base robots from logs (docs/floating-base.md, "Log format"), end to end.

The truth is simulated by an independent oracle, Pinocchio with a free-flyer root
(:mod:`tests.floating.pinocchio_floating`): a smooth motion of the base (position and orientation given as
functions of time, the orientation as ZYX angles) and of the joints; Pinocchio's RNEA gives the base wrench and
the joint torques, which two contact frames carry (Pinocchio's ``LOCAL`` joint Jacobians: one contact's wrench
chosen, the other's solving the base rows, their joint share taken off the torques). The log holds what sensors
would give, with noise: the orientation quaternion, a gyroscope (the body rate), an accelerometer (the specific
force ``R^T (a - g)``), or a motion-capture pose instead; the joint positions, torques and the contact wrenches in
the frames' axes. ``identify`` filters the log as documented and must recover the identifiable combinations
``K chi`` within their standard deviations.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from symoro_gen.description import load_robot
from symoro_gen.errors import DataFileError, OptionError
from symoro_gen.identification.floating import frame_jacobian
from symoro_gen.preprocessing.floating import quaternion_matrices, read_floating, so3_log
from symoro_gen.workflows import diagnose, identify
from tests.oracles.pinocchio_model import constant_placement

from .pinocchio_floating import build_floating_pinocchio, pin_floating_torque, random_floating_parameters

HERE = Path(__file__).parent
HOPPER = """name = "hopper_log"
base = "floating"
gravity = [0, 0, -9.81]

[values]
L1 = 0.4
L2 = 0.35

[[frames]]
j = 1
ant = 0
sigma = 0
alpha = "pi/2"
d = 0.05
theta = "q"
r = 0

[[frames]]
j = 2
ant = 1
sigma = 0
alpha = 0
d = "L1"
theta = "q"
r = 0.02

[[frames]]
j = 3
ant = 2
sigma = 2
name = "foot"
alpha = 0
d = "L2"
theta = 0
r = 0
"""
NOISE = {"gyro": 2e-3, "acc": 2e-2, "wrench": 0.3, "tau": 0.1, "q": 1e-5, "pose": 1e-5, "attitude": 1e-4}


def _rot(angles: np.ndarray) -> np.ndarray:
    """ZYX angles (N, 3) -> rotation matrices (N, 3, 3), base axes to world axes."""
    z, y, x = angles.T
    cz, sz, cy, sy, cx, sx = np.cos(z), np.sin(z), np.cos(y), np.sin(y), np.cos(x), np.sin(x)
    o, n = np.ones_like(z), np.zeros_like(z)
    Rz = np.stack([np.stack([cz, -sz, n], -1), np.stack([sz, cz, n], -1), np.stack([n, n, o], -1)], -2)
    Ry = np.stack([np.stack([cy, n, sy], -1), np.stack([n, o, n], -1), np.stack([-sy, n, cy], -1)], -2)
    Rx = np.stack([np.stack([o, n, n], -1), np.stack([n, cx, -sx], -1), np.stack([n, sx, cx], -1)], -2)
    return Rz @ Ry @ Rx


class Motion:
    """Sums of sines with random amplitudes and phases (frequencies up to ``f_max``)."""

    def __init__(self, rng, dim: int, amp: float, f_max: float = 0.8, k: int = 4):
        self.a = rng.uniform(-amp, amp, (k, dim)) / k
        self.f = rng.uniform(0.15, f_max, (k, dim))
        self.ph = rng.uniform(0, 2 * np.pi, (k, dim))

    def __call__(self, t, d: int = 0):
        w = 2 * np.pi * self.f
        arg = w[None] * np.asarray(t)[:, None, None] + self.ph[None]
        terms = [np.sin(arg), np.cos(arg), -np.sin(arg), -np.cos(arg)][d % 4]
        return np.sum(self.a[None] * w[None] ** d * terms, axis=1)


def _body_rates(angles: Motion, t: np.ndarray, h: float = 1e-5):
    """Body angular velocity (R^T dR/dt by central differences of the analytic R) and its derivative."""
    def omega(tt):
        R = _rot(angles(tt))
        dR = (_rot(angles(tt + h)) - _rot(angles(tt - h))) / (2 * h)
        S = np.transpose(R, (0, 2, 1)) @ dR
        return np.stack([S[:, 2, 1], S[:, 0, 2], S[:, 1, 0]], -1)
    return omega(t), (omega(t + 1e-3) - omega(t - 1e-3)) / 2e-3


def pin_contact_jacobians(robot, chi, q, contacts: dict[str, int]) -> dict[str, np.ndarray]:
    """Pinocchio ``LOCAL`` Jacobians (N, 6, 6 + n) of MDH frames: a joint's frame, or a fixed frame carried by the
    moving frame below it (its placement composed by the oracle's :func:`constant_placement`)."""
    model, data = build_floating_pinocchio(robot, chi)
    where = {}
    for c, j in contacts.items():
        placement = pin.SE3.Identity()
        while robot.row(j).sigma == 2:
            placement = constant_placement(robot, j)[0] * placement
            j = robot.row(j).ant
        where[c] = (model.getJointId(f"joint{j}"), placement)
    out = {c: [] for c in contacts}
    for k in range(q.shape[0]):
        pin.computeJointJacobians(model, data, q[k])
        for c, (jid, pl) in where.items():
            out[c].append(pl.inverse().action @ pin.getJointJacobian(model, data, jid, pin.ReferenceFrame.LOCAL))
    return {c: np.array(v) for c, v in out.items()}


def simulate_log(robot, path: Path, *, seed: int, duration: float, fs: float, contacts: dict[str, int],
                 mocap: bool = False, torques: bool = True, noisy: bool = True):
    """Write a floating-base log of a simulated motion at ``path``; return the true standard parameters."""
    rng = np.random.default_rng(seed)
    n = robot.n_joints
    t = np.arange(0.0, duration, 1.0 / fs)
    N = t.size
    pos, ang, joints = Motion(rng, 3, 0.3), Motion(rng, 3, 0.8), Motion(rng, n, 2.0)
    R = _rot(ang(t))
    Rt = np.transpose(R, (0, 2, 1))
    w, dw = _body_rates(ang, t)
    v = np.einsum("kij,kj->ki", Rt, pos(t, 1))
    a_cl = np.einsum("kij,kj->ki", Rt, pos(t, 2))
    quat = np.array([pin.Quaternion(Rk).coeffs() for Rk in R])  # x y z w
    q = np.hstack([pos(t), quat, joints(t)])
    dq = np.hstack([v, w, joints(t, 1)])
    ddq = np.hstack([a_cl - np.cross(w, v), dw, joints(t, 2)])  # Pinocchio's spatial acceleration
    chi = random_floating_parameters(robot, rng)
    rows = pin_floating_torque(robot, q, dq, ddq, chi)
    names = list(contacts)
    Js = pin_contact_jacobians(robot, chi, q, contacts)
    wrench = {c: Motion(rng, 6, 30.0)(t) for c in names[:-1]}
    rest = rows[:, :6] - sum(np.einsum("kri,kr->ki", Js[c][:, :, :6], wrench[c]) for c in names[:-1])
    last = names[-1]
    wrench[last] = np.linalg.solve(np.transpose(Js[last][:, :, :6], (0, 2, 1)), rest[:, :, None])[:, :, 0]
    tau = rows[:, 6:] - sum(np.einsum("kri,kr->ki", Js[c][:, :, 6:], wrench[c]) for c in names)
    g = np.asarray(robot.gravity, float)
    acc = np.einsum("kij,kj->ki", Rt, pos(t, 2) - g)
    s = dict.fromkeys(NOISE, 0.0) if not noisy else NOISE
    # the logged orientation: the true one turned by a small random rotation (attitude or pose noise)
    logged = np.array([pin.Quaternion(Rk @ pin.exp3(e)).coeffs() for Rk, e in
                       zip(R, rng.normal(scale=s["attitude"], size=(N, 3)))])
    cols = {"t": t[:, None], "qx": logged[:, :1], "qy": logged[:, 1:2], "qz": logged[:, 2:3], "qw": logged[:, 3:]}
    if mocap:
        p = q[:, :3] + rng.normal(scale=s["pose"], size=(N, 3))
        cols.update(px=p[:, :1], py=p[:, 1:2], pz=p[:, 2:3])
    else:
        gy = w + rng.normal(scale=s["gyro"], size=w.shape)
        ac = acc + rng.normal(scale=s["acc"], size=acc.shape)
        cols.update({f"gyro_{x}": gy[:, i:i + 1] for i, x in enumerate("xyz")})
        cols.update({f"acc_{x}": ac[:, i:i + 1] for i, x in enumerate("xyz")})
    qj = q[:, 7:] + rng.normal(scale=s["q"], size=(N, n))
    cols.update({f"q{j + 1}": qj[:, j:j + 1] for j in range(n)})
    if torques:
        tn = tau + rng.normal(scale=s["tau"], size=tau.shape)
        cols.update({f"tau{j + 1}": tn[:, j:j + 1] for j in range(n)})
    for c in names:
        fw = wrench[c] + rng.normal(scale=s["wrench"], size=(N, 6))
        cols.update({f"{c}{suf}": fw[:, i:i + 1] for i, suf in enumerate(("_fx", "_fy", "_fz", "_mx", "_my", "_mz"))})
    header = ",".join(cols)
    np.savetxt(path, np.hstack(list(cols.values())), delimiter=",", header=header, comments="", fmt="%.10g")
    return chi


def _check_within(d: dict, chi: np.ndarray) -> np.ndarray:
    """Each identified combination against the truth ``K chi`` in units of its standard deviation: at least 95 %
    within 3 sigma (a Gaussian's share is 99.7 %), none beyond 4 sigma (for 100 combinations, a chance of 0.6 %),
    and the mean of z^2 that of a chi-square (1, within 4 of its standard deviations sqrt(2 / p), the estimates
    taken as independent). With joint rows this holds with the covariance of a contact's noise reaching several
    rows of a sample and of the decimated noise (docs/floating-base.md, "Standard deviations"); the rows taken as
    independent gave a mean z^2 of 1.57 and a max |z| of 4.8 on the quadruped's log."""
    K = np.array(d["floating"]["relations"], float)
    values = np.array(d["parameters"]["values"], float)
    std = np.array(d["parameters"]["std"], float)
    z = (values - K @ chi) / std
    print(f"{d['floating']['kind']}: {z.size} combinations, {np.mean(np.abs(z) < 3):.3f} within 3 sigma, "
          f"max |z| {np.abs(z).max():.2f}, mean z^2 {np.mean(z ** 2):.2f}")
    assert np.mean(np.abs(z) < 3) >= 0.95
    assert np.abs(z).max() < 4
    assert abs(np.mean(z ** 2) - 1) < 4 * np.sqrt(2 / z.size)
    return z


@pytest.fixture(scope="module")
def hopper(tmp_path_factory):
    d = tmp_path_factory.mktemp("hopper")
    f = d / "hopper.toml"
    f.write_text(HOPPER)
    return load_robot(f), d


def test_frame_jacobian_is_pinocchios(hopper):
    """The contact frames' poses and ``LOCAL`` Jacobians from the MDH transforms equal Pinocchio's (the oracle's
    joint frames are the MDH frames; the fixed foot frame is placed on joint 2's body)."""
    robot, _ = hopper
    rng = np.random.default_rng(1)
    model, data = build_floating_pinocchio(robot, random_floating_parameters(robot, rng))
    for _ in range(4):
        quat = rng.normal(size=4)
        q = np.concatenate([rng.normal(size=3), quat / np.linalg.norm(quat), rng.uniform(-3, 3, robot.n_joints)])
        pin.computeJointJacobians(model, data, q)
        pin.forwardKinematics(model, data, q)
        for j in (1, 2, 3):
            _, Jm = frame_jacobian(robot, q[None, 7:], j)
            Jp = pin_contact_jacobians(robot, random_floating_parameters(robot, rng), q[None], {"c": j})["c"]
            assert np.abs(Jm[0] - Jp[0]).max() < 1e-12
        for j in (1, 2):
            T, _ = frame_jacobian(robot, q[None, 7:], j)
            jid = model.getJointId(f"joint{j}")
            assert np.abs(T[0] - (data.oMi[1].inverse() * data.oMi[jid]).homogeneous).max() < 1e-12


def test_declared_contacts_use_the_models_kernel(tmp_path):
    """A contact frame the robot file declares (``contacts``) takes its Jacobian from the model's kernel, any
    other from the MDH forward kinematics: the two routes give the same LOCAL Jacobian, whatever the base pose."""
    from symoro_gen.loader import load_model
    from symoro_gen.workflows.floating import contact_jacobian

    f = tmp_path / "hopper.toml"
    f.write_text(HOPPER.replace('base = "floating"\n', 'base = "floating"\ncontacts = ["foot", 2]\n', 1))
    robot, model = load_robot(f), load_model(f)
    assert set(model.CONTACT_FRAMES) == {"foot", "frame2"}
    rng = np.random.default_rng(4)
    quat = rng.normal(size=(5, 4))
    q = np.concatenate([rng.normal(size=(5, 3)), quat / np.linalg.norm(quat, axis=1, keepdims=True),
                        rng.uniform(-3, 3, (5, robot.n_joints))], axis=1)
    for name, j in (("foot", 3), ("frame2", 2)):
        J_model = contact_jacobian(model, robot, name, j, q)
        J_mdh = frame_jacobian(robot, q[:, 7:], j)[1]
        assert J_model.shape == J_mdh.shape == (5, 6, 6 + robot.n_joints)
        assert np.abs(J_model - J_mdh).max() < 1e-12
    J_other = contact_jacobian(model, robot, "frame1", 1, q)
    assert np.abs(J_other - frame_jacobian(robot, q[:, 7:], 1)[1]).max() == 0


def test_so3_log_inverts_exp():
    rng = np.random.default_rng(2)
    r = rng.normal(size=(20, 3))
    r *= rng.uniform(1e-6, 3.0, (20, 1)) / np.linalg.norm(r, axis=1, keepdims=True)
    R = np.array([pin.exp3(x) for x in r])
    assert np.abs(so3_log(R) - r).max() < 1e-9
    quat = np.array([pin.Quaternion(Rk).coeffs() for Rk in R])
    assert np.abs(quaternion_matrices(quat) - R).max() < 1e-12


@pytest.fixture(scope="module")
def hopper_fit(hopper):
    """The hopper, contacts at its foot frame and at its knee (frame 2), a log without torque column, identified
    through the command line: ``(robot, folder, chi_true, result path)``."""
    from tests.conftest import CliRunner

    robot, d = hopper
    log = d / "walk.csv"
    chi = simulate_log(robot, log, seed=3, duration=12.0, fs=200.0, contacts={"frame2": 2, "foot": 3},
                       torques=False)
    out = d / "walk.json"
    CliRunner()("identify", str(robot.file), str(log), "--method", "wls", "--json", str(out))
    return robot, d, chi, out


def test_identify_base_rows_from_an_imu_log(hopper_fit):
    """The base rows alone (no torque column in the log) recover every base-row combination within 3 sigma."""
    robot, _, chi, out = hopper_fit
    res = json.loads(out.read_text())
    assert res["floating"]["kind"] == "base"  # no torques: the base rows
    assert res["floating"]["rows"] == ["FX0", "FY0", "FZ0", "MX0", "MY0", "MZ0"]
    drive = {f"{k}{j}" for k in ("IA", "FV", "FS", "OFF") for j in (1, 2)}
    assert set(res["floating"]["not_identifiable"]) == drive
    assert res["floating"]["files"][0]["orientation"] == "gyroscope"
    _check_within(res, chi)


def test_export_from_a_floating_result(hopper_fit, cli):
    """``export-urdf --from`` a floating-base result: a physically consistent standard set whose combinations
    ``K chi`` are the identified values. Checked with Pinocchio's RNEA on the exported URDF (its ``floating`` joint
    a free-flyer): its base-wrench rows at random states equal ``W_base[:, kept] @ values``, the rows the
    identified values predict (to the sidecar's base error when the set is not exact)."""
    from symoro_gen.loader import load_model

    from .pinocchio_floating import random_floating_states

    robot, d, _, out = hopper_fit
    res = json.loads(out.read_text())
    urdf = d / "identified.urdf"
    cli("export-urdf", str(robot.file), "--from", str(out), "-o", str(urdf))
    sidecar = json.loads(Path(str(urdf) + ".json").read_text())
    pmodel = pin.buildModelFromXML(urdf.read_text())
    assert pmodel.joints[1].shortname() == "JointModelFreeFlyer"
    pmodel.gravity.linear = np.asarray(robot.gravity, float)
    data = pmodel.createData()
    idx_q = [pmodel.joints[pmodel.getJointId(f"joint{r.j}")].idx_q for r in robot.joints]
    idx_v = [pmodel.joints[pmodel.getJointId(f"joint{r.j}")].idx_v for r in robot.joints]
    q, dq, ddq = random_floating_states(robot, 20, np.random.default_rng(5))
    pin_rows = []
    for k in range(q.shape[0]):
        qp, vp, ap = np.zeros(pmodel.nq), np.zeros(pmodel.nv), np.zeros(pmodel.nv)
        qp[:7], vp[:6], ap[:6] = q[k, :7], dq[k, :6], ddq[k, :6]
        qp[idx_q], vp[idx_v], ap[idx_v] = q[k, 7:], dq[k, 6:], ddq[k, 6:]
        pin_rows.append(pin.rnea(pmodel, data, qp, vp, ap)[:6])
    model = load_model(robot.file)
    kept = [model.STANDARD_NAMES.index(n.removesuffix("R")) for n in res["parameters"]["names"]]
    predicted = model.standard_regressor(q, dq, ddq)[:, :6, kept] @ np.array(res["parameters"]["values"])
    err = np.abs(np.array(pin_rows) - predicted).max() / np.abs(predicted).max()
    print(f"export-urdf --from (exact: {sidecar['exact']}, base error {sidecar['base_error']:.2e}): Pinocchio's base "
          f"rows vs the identified values' prediction, max relative error {err:.2e}")
    assert err < (1e-6 if sidecar["exact"] else 0.05)


def test_log_errors_name_file_and_column(hopper, tmp_path):
    robot, _ = hopper
    log = tmp_path / "bad.csv"
    np.savetxt(log, np.zeros((5, 6)), delimiter=",", header="t,qx,qy,qz,qw,q1", comments="")
    with pytest.raises(DataFileError) as exc:
        read_floating(log, 2)
    msg = str(exc.value)
    assert "bad.csv" in msg and "q2" in msg and "gyro_x" in msg and "acc_x" in msg
    rows = np.zeros((5, 12))
    rows[:, 0] = np.arange(5)
    rows[:, 4] = 1.0
    rows[2, 4] = 2.0  # a quaternion of norm 2
    np.savetxt(log, rows, delimiter=",", comments="",
               header="t,qx,qy,qz,qw,q1,q2,gyro_x,gyro_y,gyro_z,foot_fx,foot_fy")
    with pytest.raises(DataFileError) as exc:
        read_floating(log, 2)
    msg = str(exc.value)
    assert "foot_fz" in msg and "acc_x" in msg
    good = "t,qx,qy,qz,qw,q1,q2,gyro_x,gyro_y,gyro_z,acc_x,acc_y,acc_z"
    rows = np.hstack([rows[:, :10], np.zeros((5, 3))])
    rows[3, 1] = np.nan
    np.savetxt(log, rows, delimiter=",", comments="", header=good)
    with pytest.raises(DataFileError, match=r"bad.csv, line 5, field 'qx'.*non-finite.*row 4"):
        read_floating(log, 2)
    rows[3, 1] = 0.0
    np.savetxt(log, rows, delimiter=",", comments="", header=good)
    with pytest.raises(DataFileError, match=r"bad.csv, line 4, field 'qx qy qz qw': quaternion of norm 2.*row 3"):
        read_floating(log, 2)


def test_fixed_base_options_refused(hopper, tmp_path):
    robot, d = hopper
    with pytest.raises(OptionError, match="--essential"):
        identify(robot.file, [str(tmp_path / "x.csv")], essential=True)
    with pytest.raises(OptionError, match="--kind"):
        identify("scara", [str(tmp_path / "x.csv")], kind="base")


@pytest.fixture(scope="module")
def quadruped(tmp_path_factory):
    return load_robot(HERE / "quadruped.toml"), tmp_path_factory.mktemp("quadruped")


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["base", "joints", "both"])
def test_identify_with_validation_through_the_cli(quadruped, cli, kind):
    """The quadruped-like tree, contacts at two knees: the base rows, the joint rows, then every row (WLS per kind),
    through the command line with a validation log; the JSON follows the identify schema and the validation errors
    are those of the noise."""
    from tests.docs.test_schemas import check

    robot, d = quadruped
    contacts = {"frame3": 3, "frame9": 9}
    chi = simulate_log(robot, d / "a.csv", seed=11, duration=15.0, fs=200.0, contacts=contacts)
    chi_b = simulate_log(robot, d / "b.csv", seed=11, duration=8.0, fs=200.0, contacts=contacts)
    assert np.array_equal(chi, chi_b)  # same robot (the seed draws the parameters first), another motion
    out = d / f"{kind}.json"
    cli("identify", str(robot.file), str(d / "a.csv"), "--kind", kind, "--validate", str(d / "b.csv"),
        "--json", str(out))
    res = json.loads(out.read_text())
    check(res, "identify")
    # the closed-form base parameters (docs/floating-base.md); the base rows: less the 48 drive terms; the joint
    # rows: 18 standard parameters absent (the base link's among them)
    assert len(res["parameters"]["names"]) == {"base": 94, "joints": 132, "both": 142}[kind]
    assert len(res["floating"]["not_identifiable"]) == {"base": 48, "joints": 18, "both": 0}[kind]
    _check_within(res, chi)
    assert len(res["validation"]["rel_err"]) == {"base": 6, "joints": 12, "both": 18}[kind]
    # validation on another motion: of the size of the identification's (noise), not of a wrong model
    assert max(res["validation"]["rel_err"]) < 2 * max(res["rel_err"]) + 0.02


@pytest.mark.slow
def test_identify_base_rows_from_a_mocap_pose(quadruped):
    """No IMU: the base's rates from the motion-capture pose (SO(3) log differences, the position's second
    differences), the base rows alone, from the Python API."""
    robot, d = quadruped
    chi = simulate_log(robot, d / "mocap.csv", seed=12, duration=15.0, fs=200.0,
                       contacts={"frame3": 3, "frame12": 12}, mocap=True)
    res = identify(robot.file, str(d / "mocap.csv"), kind="base", method="wls")
    assert res.to_dict()["floating"]["files"][0]["orientation"].startswith("pose")
    drive = {n for n in res.model.STANDARD_NAMES if n.rstrip("0123456789") in ("IA", "FV", "FS", "OFF")}
    assert set(res.fit.not_identifiable) == drive
    _check_within(res.to_dict(), chi)


def test_parquet_log_reads_as_the_csv(hopper_fit, tmp_path):
    """The same log as Parquet (pyarrow, columns by name) reads to the same arrays as the CSV."""
    pa = pytest.importorskip("pyarrow")
    pq = pytest.importorskip("pyarrow.parquet")
    _, d, _, _ = hopper_fit
    csv = read_floating(d / "walk.csv", 2)
    names = (d / "walk.csv").read_text().split("\n", 1)[0].split(",")
    table = np.loadtxt(d / "walk.csv", delimiter=",", skiprows=1)
    pq.write_table(pa.table({n: table[:, i] for i, n in enumerate(names)}), tmp_path / "walk.parquet")
    par = read_floating(tmp_path / "walk.parquet", 2)
    assert set(par.contacts) == set(csv.contacts) == {"frame2", "foot"}
    for field in ("t", "quaternion", "q", "gyro", "accel"):
        assert np.array_equal(getattr(par, field), getattr(csv, field)), field
    assert par.tau is None and par.position is None


@pytest.mark.slow
def test_diagnose_names_a_sensor_offset_and_a_gain(hopper, cli):
    """The loop on a floating base: contacts at the thigh (frame 1) and the foot; the thigh's sensor reads 5 N too
    much along its z, the foot's 5 % too much (16 s log: the loop accepts on the last share of the log, and a 12 s
    one leaves too few rows there). With joint torques the sensors' offsets and gains are candidates of the loop's
    own selection, on the rows their wrench reaches, against the drive effects: ``diagnose`` names the thigh's
    offset (absolute: the torques fix the scale) and the foot's gain, each within 4 sigma, and no drive effect; on
    the same log without the errors it names nothing."""
    robot, d = hopper
    clean = d / "sensors.csv"
    simulate_log(robot, clean, seed=3, duration=16.0, fs=200.0, contacts={"frame1": 1, "foot": 3})
    names = clean.read_text().split("\n", 1)[0].split(",")
    table = np.loadtxt(clean, delimiter=",", skiprows=1)
    table[:, names.index("frame1_fz")] += 5.0
    for c in ("fx", "fy", "fz", "mx", "my", "mz"):
        table[:, names.index(f"foot_{c}")] *= 1.05
    bad = d / "sensors_bad.csv"
    np.savetxt(bad, table, delimiter=",", header=",".join(names), comments="")
    out = d / "diag.json"
    cli("diagnose", str(robot.file), str(bad), "--json", str(out))
    res = json.loads(out.read_text())["floating"]
    assert res["checks"] == []
    loop = res["loop"]
    assert sorted(loop["found"]) == ["foot:contact_gain", "frame1:contact_offset"]
    by = {e["frame"]: e for e in loop["effects"]}
    off = by["frame1"]
    est = np.array([off["params"][f"contact_offset[frame1].{c}"] for c in ("fx", "fy", "fz", "mx", "my", "mz")])
    std = np.array([off["std"][f"contact_offset[frame1].{c}"] for c in ("fx", "fy", "fz", "mx", "my", "mz")])
    assert np.all(np.abs(est - [0, 0, 5.0, 0, 0, 0]) < 4 * std), (est, std)
    gain = by["foot"]
    assert abs(gain["physical"]["g"] - 0.05) < 4 * gain["physical"]["g_std"]
    plain = diagnose(robot.file, [str(clean)])
    assert plain.to_dict()["floating"]["loop"]["effects"] == [] and plain.found == []
