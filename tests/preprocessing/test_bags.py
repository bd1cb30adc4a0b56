"""ROS bags as recordings (readers/bag.py): bags written with the rosbags library from simulated recordings
(truth known), read back through the front door and identified like the same recording read as CSV."""
from __future__ import annotations

import json
import re
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from symoro_gen.description import load_robot
from symoro_gen.errors import DataFileError, OptionError, OutputError, RobotFileError
from symoro_gen.loader import model_for
from symoro_gen.preprocessing.readers import LogFormat, read_recording
from symoro_gen.preprocessing.readers.bag import (
    ImuMessage,
    JointStateMessage,
    JointTrajectoryMessage,
    WrenchMessage,
    joint_state_messages,
    read_imu,
    read_wrench,
    robot_joint_names,
    write_bag,
    write_messages,
)
from symoro_gen.simulate import write_recording_csv
from symoro_gen.simulate.parameters import random_physical_parameters
from symoro_gen.simulate.recording import simulate_recording
from symoro_gen.simulate.trajectories import fourier_trajectory

ROOT = Path(__file__).resolve().parents[2]
NAMES = ("shoulder", "elbow", "lift", "wrist")


def _named_robot_file(path: Path) -> Path:
    """robots/scara.toml with the URDF joint names ``import-urdf`` keeps in the frames' comments."""
    text = (ROOT / "robots" / "scara.toml").read_text()
    for j, nm in enumerate(NAMES, 1):
        text = text.replace(f"[[frames]]\nj = {j}\n", f"[[frames]]  # URDF joint {nm} (revolute), link l{j}\nj = {j}\n",
                            1)
    path.write_text(text)
    return path


def _recording(seed: int, duration: float = 1.0):
    robot, model = model_for("scara")
    rng = np.random.default_rng(seed)
    chi = random_physical_parameters(robot, rng)
    chi = getattr(chi, "chi_std", chi)
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, duration, 0.002, rng)
    t = np.round(t * 1e9) * 1e-9  # stamps are integer nanoseconds: the CSV gets the same times
    tr = simulate_recording(model, t, q, dq, ddq, chi, noise_q=1e-5, noise_tau=0.05, rng=rng)
    return replace(tr, dq=dq)


@pytest.fixture(scope="module")
def rec(tmp_path_factory):
    d = tmp_path_factory.mktemp("bags")
    tr = _recording(5)
    csv = d / "rec.csv"
    write_recording_csv(csv, tr)
    robot_file = _named_robot_file(d / "scara_named.toml")
    return {"dir": d, "tr": tr, "csv": csv, "robot_file": robot_file, "robot": load_robot(str(robot_file))}


def _read(path, robot, **kw):
    fmt = LogFormat(**{k: v for k, v in kw.items() if k in LogFormat.__dataclass_fields__})
    return read_recording(path, fmt, robot=robot)


def test_robot_file_keeps_urdf_joint_names(rec):
    assert robot_joint_names(rec["robot"]) == NAMES
    assert robot_joint_names(load_robot("scara")) is None


@pytest.mark.parametrize("name", ["rec.mcap", "rec.db3", "rec.bag", "rec_folder"])
def test_each_storage_reads_the_recording_exactly(rec, name):
    """ROS 2 MCAP, ROS 2 sqlite3, ROS 1, a rosbag2 folder: the samples come back bit for bit."""
    tr = rec["tr"]
    p = rec["dir"] / name
    write_bag(tr, p, NAMES, storage="sqlite3" if name == "rec_folder" else "mcap")
    if name == "rec_folder":
        assert (p / "metadata.yaml").is_file()
    (got,), rep = read_recording(p, robot=rec["robot"])
    np.testing.assert_array_equal(got.q, tr.q)
    np.testing.assert_array_equal(got.tau, tr.tau)
    np.testing.assert_array_equal(got.dq, tr.dq)
    np.testing.assert_allclose(got.t, tr.t, rtol=0, atol=1e-12)
    assert rep.rows_read == tr.n_samples and rep.rows_dropped == 0
    assert any("URDF joint names of the robot file" in n for n in rep.notes)


def test_bag_and_csv_give_the_same_samples(rec):
    """What identification sees: the same recording read from a bag and from its CSV, sample for sample."""
    p = write_bag(rec["tr"], rec["dir"] / "same.db3", NAMES, velocity=False)
    (a,), _ = read_recording(p, robot=rec["robot"])
    (b,), _ = read_recording(rec["csv"], robot=rec["robot"])
    for f in ("q", "tau"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f))
    np.testing.assert_allclose(a.t, b.t, rtol=0, atol=1e-15)


@pytest.mark.slow  # the first identification of a session builds the model (~10 s)
def test_identified_parameters_equal_the_csvs(rec):
    """The same recording as a bag and as CSV: the same identified parameters (same stamps)."""
    import symoro_gen

    p = rec["dir"] / "ident.mcap"
    write_bag(rec["tr"], p, NAMES, velocity=False)
    a = symoro_gen.identify(str(rec["robot_file"]), [str(p)], method="ols")
    b = symoro_gen.identify(str(rec["robot_file"]), [str(rec["csv"])], method="ols")
    va, vb = (np.asarray(r.to_dict()["parameters"]["values"], float) for r in (a, b))
    np.testing.assert_allclose(va, vb, rtol=1e-9, atol=1e-9 * np.abs(vb).max())


def _msgs(tr, names=NAMES, **kw):
    return joint_state_messages(tr, names, **kw)


def test_out_of_order_messages_sorted_and_counted(rec):
    tr = rec["tr"]
    msgs = _msgs(tr)
    for i in (10, 200, 331):  # three pairs of neighbours received (logged) in the wrong order
        msgs[i], msgs[i + 1] = msgs[i + 1], msgs[i]
    msgs = [replace(m, log_time=float(tr.t[i])) for i, m in enumerate(msgs)]
    p = write_messages(rec["dir"] / "swapped.mcap", {"/joint_states": msgs})
    (got,), rep = read_recording(p, robot=rec["robot"])
    np.testing.assert_array_equal(got.q, tr.q)
    np.testing.assert_array_equal(got.tau, tr.tau)
    assert "3 message(s) out of order in the bag: sorted by stamp" in rep.notes


def test_missing_joint_names_the_joint_and_topic(rec):
    tr = rec["tr"]
    names = ("shoulder", "elbo", "lift", "wrist")  # a typo in the driver's configuration
    p = write_bag(tr, rec["dir"] / "typo.mcap", names)
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"])
    msg = str(e.value)
    assert f"{p}, topic /joint_states, field 'name': joint 'elbow' is in no message" in msg
    assert "elbo" in msg.split("joints published:")[1]
    assert "--joint-names" in e.value.hint and "--topic" in e.value.hint


def test_two_robots_in_one_bag_by_prefix(rec):
    left, right = rec["tr"], _recording(11)
    msgs = []
    for a, b in zip(_msgs(left, [f"left_{x}" for x in NAMES]), _msgs(right, [f"right_{x}" for x in NAMES])):
        msgs.append(JointStateMessage(a.stamp, a.names + b.names, a.position + b.position, a.velocity + b.velocity,
                                      a.effort + b.effort))
    p = write_messages(rec["dir"] / "two.bag", {"/joint_states": msgs})
    (r,), rep = _read(p, rec["robot"], prefix="right_")
    np.testing.assert_array_equal(r.q, right.q)
    np.testing.assert_array_equal(r.tau, right.tau)
    assert any("joints ignored (not the robot's): left_elbow" in n for n in rep.notes)
    assert "--prefix right_" in rep.options
    import symoro_gen

    (lft,), _ = symoro_gen.read_recording(p, robot=rec["robot"], prefix="left_")  # the package-level front door
    np.testing.assert_array_equal(lft.q, left.q)
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"])
    msg = str(e.value)
    assert "field 'name': joints shoulder, elbow, lift, wrist are in no message (joints published: left_elbow" in msg
    assert msg.endswith("right_wrist); --prefix left_ or --prefix right_ would match 'shoulder'")


def test_extra_joints_and_per_message_order(rec):
    """Gripper fingers ignored (listed), each message with its own joint order."""
    tr = rec["tr"]
    rng = np.random.default_rng(0)
    msgs = []
    for m in _msgs(tr):
        names = m.names + ("finger_left", "finger_right")
        pos = m.position + (0.01, 0.01)
        vel = m.velocity + (0.0, 0.0)
        eff = m.effort + (1.0, 1.0)
        o = rng.permutation(len(names))
        msgs.append(JointStateMessage(m.stamp, tuple(names[i] for i in o), tuple(pos[i] for i in o),
                                      tuple(vel[i] for i in o), tuple(eff[i] for i in o)))
    p = write_messages(rec["dir"] / "fingers.db3", {"/joint_states": msgs})
    (got,), rep = read_recording(p, robot=rec["robot"])
    np.testing.assert_array_equal(got.q, tr.q)
    np.testing.assert_array_equal(got.tau, tr.tau)
    np.testing.assert_array_equal(got.dq, tr.dq)
    assert "joints ignored (not the robot's): finger_left, finger_right" in rep.notes


def _split(msgs, first=2):
    a = [JointStateMessage(m.stamp, m.names[:first], m.position[:first], m.velocity[:first], m.effort[:first])
         for m in msgs]
    b = [JointStateMessage(m.stamp, m.names[first:], m.position[first:], m.velocity[first:], m.effort[first:])
         for m in msgs]
    return a, b


def test_publishers_merged_by_stamp(rec):
    """Two publishers (arm, wrist) on one topic and on two topics: merged by stamp."""
    tr = rec["tr"]
    a, b = _split(_msgs(tr))
    inter = [m for pair in zip(a, b) for m in pair]
    p1 = write_messages(rec["dir"] / "merged1.mcap", {"/joint_states": inter})
    p2 = write_messages(rec["dir"] / "merged2.mcap", {"/arm/joint_states": a, "/wrist/joint_states": b})
    for p in (p1, p2):
        (got,), rep = read_recording(p, robot=rec["robot"])
        np.testing.assert_array_equal(got.q, tr.q)
        np.testing.assert_array_equal(got.tau, tr.tau)
        assert rep.rows_read == 2 * tr.n_samples
    # the wrist publisher misses one time: an error naming the joints, the time and the message
    p3 = write_messages(rec["dir"] / "hole.mcap", {"/joint_states": inter[:101] + inter[102:]})
    with pytest.raises(DataFileError) as e:
        read_recording(p3, robot=rec["robot"])
    t50 = tr.t[50] - tr.t[0]
    assert (f"{p3}, joint lift, field 'position': missing at 1 of {tr.n_samples} time(s): {t50:.6g} s "
            "(/joint_states message 101)") in str(e.value)
    assert "--drop-bad-rows" in e.value.hint
    p4 = write_messages(rec["dir"] / "hole_end.mcap", {"/joint_states": inter[:-1]})  # the last time, no gap
    (got,), rep = _read(p4, rec["robot"], drop_bad_rows=True)
    assert rep.rows_dropped == 1 and got.n_samples == tr.n_samples - 1
    np.testing.assert_array_equal(got.q, tr.q[:-1])
    assert rep.dropped[0].startswith(f"joint lift, position: missing at 1 of {tr.n_samples} time(s): ")


def test_joint_on_two_topics_needs_topic(rec):
    tr = rec["tr"]
    msgs = _msgs(tr)
    p = write_messages(rec["dir"] / "twice.mcap", {"/joint_states": msgs, "/joint_states_filtered": msgs})
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"])
    assert "topics /joint_states, /joint_states_filtered, field 'name': joint 'shoulder' is published on several" \
        in str(e.value)
    (got,), rep = read_recording(p, robot=rec["robot"], topic="/joint_states_filtered")
    np.testing.assert_array_equal(got.q, tr.q)
    with pytest.raises(DataFileError, match="topic /nope, field '--topic': no such topic in the bag"):
        read_recording(p, robot=rec["robot"], topic="/nope")


def test_stamps_header_log_and_zero(rec):
    tr = rec["tr"]
    # header stamps all zero (a driver that does not stamp): the log times, said in the report
    zero = [replace(m, zero_stamp=True) for m in _msgs(tr)]
    p = write_messages(rec["dir"] / "zero.mcap", {"/joint_states": zero})
    (got,), rep = read_recording(p, robot=rec["robot"])
    np.testing.assert_allclose(got.t, tr.t, atol=1e-12)
    assert any("every header stamp of /joint_states is zero: the bag's log times are used" in n for n in rep.notes)
    # some zero: an error naming the messages, the option that fixes it
    some = _msgs(tr)
    some[7] = replace(some[7], zero_stamp=True)
    p = write_messages(rec["dir"] / "somezero.mcap", {"/joint_states": some})
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"])
    assert f"{p}, 1 message(s): /joint_states message 8, field 'header.stamp': zero while other" in str(e.value)
    assert "--stamp log" in e.value.hint
    (got,), _ = read_recording(p, robot=rec["robot"], stamp="log")
    np.testing.assert_array_equal(got.q, tr.q)
    # log times delayed by a jittery transport: --stamp header (default) keeps the sensor's times
    rng = np.random.default_rng(1)
    late = [replace(m, log_time=m.stamp + 0.001 + 2e-4 * rng.random()) for m in _msgs(tr)]
    p = write_messages(rec["dir"] / "late.mcap", {"/joint_states": late})
    (h,), _ = read_recording(p, robot=rec["robot"])
    np.testing.assert_allclose(h.t, tr.t, atol=1e-12)
    (lg,), _ = read_recording(p, robot=rec["robot"], stamp="log")
    lt = np.array([m.log_time for m in late])
    np.testing.assert_allclose(lg.t, lt - lt[0], atol=1e-9)


def test_empty_velocity_and_effort(rec):
    tr = rec["tr"]
    p = write_bag(tr, rec["dir"] / "novel.mcap", NAMES, velocity=False)
    (got,), rep = read_recording(p, robot=rec["robot"])
    assert got.dq is None and "velocity empty in the messages: velocities computed from the positions" in rep.notes
    p = write_bag(tr, rec["dir"] / "noeff.mcap", NAMES, effort=False)
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"])
    assert (f"{p}, topic /joint_states, field 'effort': empty in every message for joint(s) shoulder, elbow, lift, "
            "wrist: the torque is needed") in str(e.value)


def test_currents_scaled_by_tau_scale(rec):
    tr = rec["tr"]
    k = np.array([2.0, 4.0, 0.5, 8.0])
    p = write_bag(replace(tr, tau=tr.tau / k), rec["dir"] / "currents.mcap", NAMES)
    (got,), rep = _read(p, rec["robot"], tau_scale=tuple(k))
    np.testing.assert_allclose(got.tau, tr.tau, rtol=1e-15)


def test_no_joint_names_matched_by_order(rec):
    tr = rec["tr"]
    p = write_bag(tr, rec["dir"] / "order.mcap", ("a", "b", "c", "d"))
    (got,), rep = read_recording(p, robot=load_robot("scara"))
    np.testing.assert_array_equal(got.q, tr.q)
    assert any(n.startswith("topic(s) /joint_states: ") and "joints matched by order (the robot file names no joints)"
               in n for n in rep.notes)
    # --joint-names overrides the robot file's names
    (got,), rep = read_recording(p, robot=rec["robot"], joint_names=["d", "c", "b", "a"])
    np.testing.assert_array_equal(got.q, tr.q[:, ::-1])


def test_reference_topic_as_recorded_reference(rec):
    tr = rec["tr"]
    ref = tr.q + 1e-3 * np.sin(tr.t)[:, None]
    p = write_bag(tr, rec["dir"] / "ref.mcap", NAMES, reference=ref, reference_topic="/commanded")
    (got,), rep = read_recording(p, robot=rec["robot"], reference_topic="/commanded")
    np.testing.assert_allclose(got.meta["q_ref"], ref, atol=1e-15)
    np.testing.assert_array_equal(got.q, tr.q)  # the reference topic is not a measured one
    assert any(n.startswith("reference positions from /commanded") for n in rep.notes)


def test_imu_and_wrench_topics(rec):
    t = np.arange(20) * 0.01
    rng = np.random.default_rng(2)
    w = rng.normal(size=(20, 3))
    a = rng.normal(size=(20, 3))
    f = rng.normal(size=(20, 6))
    quat = np.tile([0.0, 0.0, np.sin(0.2), np.cos(0.2)], (20, 1))
    imu = [ImuMessage(float(ti), tuple(quat[i]), tuple(w[i]), tuple(a[i])) for i, ti in enumerate(t)]
    wr = [WrenchMessage(float(ti), tuple(f[i, :3]), tuple(f[i, 3:])) for i, ti in enumerate(t)]
    p = write_messages(rec["dir"] / "base.mcap", {"/imu": imu[::-1], "/ft": wr})
    d = read_imu(p)
    np.testing.assert_allclose(d["t"], t, atol=1e-12)  # sorted by stamp
    np.testing.assert_array_equal(d["angular_velocity"], w)
    np.testing.assert_array_equal(d["linear_acceleration"], a)
    np.testing.assert_array_equal(d["orientation"], quat)
    e = read_wrench(p, "/ft")
    np.testing.assert_array_equal(e["force"], f[:, :3])
    np.testing.assert_array_equal(e["torque"], f[:, 3:])
    with pytest.raises(DataFileError, match="no sensor_msgs/msg/Imu topic"):
        read_imu(p, "/ft")


@pytest.mark.parametrize("name", ["clobber.mcap", "clobber.bag", "clobber_folder"])
def test_write_bag_never_replaces_without_force(rec, name):
    tr = rec["tr"]
    short = replace(tr, t=tr.t[:40], q=tr.q[:40], tau=tr.tau[:40], dq=tr.dq[:40])
    p = rec["dir"] / name
    write_bag(short, p, NAMES)
    before = sorted(x.name for x in p.iterdir()) if p.is_dir() else p.read_bytes()
    with pytest.raises(OutputError, match="exists; not overwritten"):
        write_bag(short, p, NAMES)
    after = sorted(x.name for x in p.iterdir()) if p.is_dir() else p.read_bytes()
    assert before == after
    longer = replace(tr, t=tr.t[:60], q=tr.q[:60], tau=tr.tau[:60], dq=tr.dq[:60])
    write_bag(longer, p, NAMES, force=True)
    (got,), _ = read_recording(p, robot=rec["robot"])
    assert got.n_samples == 60
    assert not [x for x in p.parent.iterdir() if x.name.startswith(f".{name}.")]  # no temporary left


def test_without_rosbags_the_error_names_the_extra(rec, monkeypatch):
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
    with pytest.raises(DataFileError, match=re.escape("pip install 'symoro_gen[bags]'")):
        read_recording(rec["dir"] / "rec.mcap", robot=rec["robot"])


# --- the command line ------------------------------------------------------------------------------------
@pytest.mark.slow  # the first identification of a session builds the model (~10 s)
def test_cli_identify_bag_same_as_csv(rec, cli):
    p = rec["dir"] / "cli.mcap"
    write_bag(rec["tr"], p, NAMES)
    outs = []
    for data in (p, rec["csv"]):
        out = rec["dir"] / f"res_{Path(data).suffix[1:]}.json"
        cli("--quiet", "identify", rec["robot_file"], data, "--method", "ols", "--json", out, rc=0)
        outs.append(json.loads(out.read_text()))
    a, b = (np.array(d["parameters"]["values"]) for d in outs)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.abs(b).max())
    assert any("URDF joint names" in n for n in outs[0]["data"][0]["notes"])


def test_cli_errors_name_file_message_field_and_option(rec, cli):
    tr = rec["tr"]
    some = _msgs(tr)
    some[3] = replace(some[3], zero_stamp=True)
    p = write_messages(rec["dir"] / "cli_zero.db3", {"/joint_states": some})
    err = cli("inspect", "scara", p, rc=2).err
    assert f"{p}, 1 message(s): /joint_states message 4, field 'header.stamp': zero while other messages" in err
    assert "hint: give --stamp log to use the bag's log times" in err
    p = write_bag(tr, rec["dir"] / "cli_typo.bag", ("shoulder", "elbow", "lift", "wrist2"))
    err = cli("inspect", "scara", p, "--joint-names", ",".join(NAMES), rc=2).err
    assert (f"{p}, topic /joint_states, field 'name': joint 'wrist' is in no message (joints published: elbow, lift, "
            "shoulder, wrist2)") in err
    assert "--joint-names a,b,c (and --prefix) say which joints are the robot's" in err
    out = cli("inspect", "scara", p, "--joint-names", "shoulder,elbow,lift,wrist2", rc=0).out
    assert "--joint-names shoulder,elbow,lift,wrist2" in out


@pytest.mark.slow  # closed-loop IV iterations
def test_reference_topic_is_the_iv_reference(rec, cli):
    """--reference-topic: IV's recorded reference (without it IV uses the filtered measured positions), the
    held-back part keeping its share of it."""
    p = write_bag(rec["tr"], rec["dir"] / "iv_ref.mcap", NAMES, reference=rec["tr"].q, reference_topic="/commanded")
    out = cli("identify", "scara", p, "--method", "iv", "--joint-names", ",".join(NAMES), "--reference-topic",
              "/commanded", "--validate-fraction", "0.3").out
    assert "reference: recorded" in out


def test_fleet_finds_bag_files_and_rosbag2_folders(rec, tmp_path):
    """A rosbag2 folder found in a folder is one log (its metadata.yaml and storage file are not logs)."""
    from symoro_gen.fleet.files import discover, read_experiments

    tr = rec["tr"]
    short = replace(tr, t=tr.t[:50], q=tr.q[:50], tau=tr.tau[:50], dq=tr.dq[:50])
    write_bag(short, tmp_path / "arm1" / "day1", NAMES, storage="sqlite3")   # a rosbag2 folder
    write_bag(short, tmp_path / "arm2" / "day1.mcap", NAMES)
    write_bag(short, tmp_path / "arm3" / "day2.bag", NAMES)
    logs = discover([tmp_path], "{robot}/{day}")
    assert [(f.robot, f.day) for f in logs] == [("arm1", "day1"), ("arm2", "day1.mcap"), ("arm3", "day2.bag")]
    assert Path(logs[0].path).is_dir()
    assert [(f.robot, f.day) for f in discover([tmp_path / "arm1" / "day1"], "{robot}/{day}")] == [("arm1", "day1")]
    for lf in logs:
        (got,) = read_experiments(lf.path, 4, fmt=LogFormat(joint_names=NAMES))
        np.testing.assert_array_equal(got.q, short.q)


def test_bag_options_checked_and_in_a_format_file(rec, tmp_path):
    f = tmp_path / "cell.toml"
    f.write_text('prefix = "right_"\njoint_names = ["shoulder", "elbow", "lift", "wrist"]\nstamp = "log"\n')
    from symoro_gen.preprocessing.readers import make_format

    fmt = make_format(format_file=f)
    assert (fmt.prefix, fmt.joint_names, fmt.stamp) == ("right_", NAMES, "log")
    assert fmt.options() == ("--stamp log", "--prefix right_", "--joint-names shoulder,elbow,lift,wrist")
    with pytest.raises(DataFileError, match="field 'stamp': 'arrival': expected header or log"):
        make_format(bag={"stamp": "arrival"})
    tr = rec["tr"]
    p = write_bag(replace(tr, t=tr.t[:40], q=tr.q[:40], tau=tr.tau[:40], dq=tr.dq[:40]), tmp_path / "o.mcap", NAMES)
    with pytest.raises(OptionError, match="read_recording: unknown option 'topics'; did you mean 'topic'"):
        read_recording(p, robot=rec["robot"], topics="/joint_states")
    with pytest.raises(DataFileError, match="a ROS bag has no columns"):
        read_recording(p, LogFormat(columns=(("q", "1:5"), ("tau", "5:9"))), robot=rec["robot"])


def test_load_trajectory_reads_a_bag(rec, tmp_path):
    from symoro_gen.preprocessing.readers import load_trajectory

    tr = rec["tr"]
    p = write_bag(tr, tmp_path / "plain.bag", NAMES)
    got = load_trajectory(p, robot=rec["robot"])
    np.testing.assert_array_equal(got.q, tr.q)
    np.testing.assert_array_equal(got.tau, tr.tau)


def test_bad_values_and_malformed_messages_named_by_message(rec, tmp_path):
    tr = rec["tr"]
    msgs = _msgs(tr)
    m = msgs[20]
    msgs[20] = replace(m, effort=(m.effort[0], float("nan")) + m.effort[2:])
    p = write_messages(tmp_path / "nan.mcap", {"/joint_states": msgs})
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"])
    assert (f"{p}, topic /joint_states, message 21 (t = {tr.t[20] - tr.t[0]:.6g} s), joint elbow, field 'effort': "
            "nan: not a finite value") in str(e.value)
    assert "--drop-bad-rows" in e.value.hint
    (got,), rep = _read(p, rec["robot"], drop_bad_rows=True, resample=True)
    assert rep.rows_dropped == 1 and rep.resampled and tr.n_samples - 1 <= got.n_samples <= tr.n_samples
    np.testing.assert_allclose(got.q[20], tr.q[20], atol=1e-4)  # the dropped time, interpolated back
    msgs[20] = replace(m, velocity=m.velocity[:3])  # 3 velocities for 4 names
    p = write_messages(tmp_path / "short.mcap", {"/joint_states": msgs})
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"])
    assert (f"{p}, topic /joint_states, message 21 (logged {tr.t[20] - tr.t[0]:.6g} s into the bag), field "
            "'velocity': 3 values for 4 joint names") in str(e.value)


# --- commanded trajectories, partial velocities, the library's own reading -----------------------------------
def _commanded(t):
    """The commanded positions of the trajectory tests (a smooth function of time, one phase per joint)."""
    return 0.3 * np.sin(2 * np.pi * 0.7 * np.asarray(t)[:, None] + np.arange(4))


def _trajectory_messages(t_end, period=0.1, step=0.01, span=0.25):
    """A JointTrajectory every ``period`` with points every ``step`` over ``span``: each overlaps the next one,
    whose start replaces it; the replaced points (after the next start) carry a 1 rad offset that must not
    show."""
    starts = np.arange(0.0, t_end, period)
    out = []
    for k, s0 in enumerate(starts):
        tf = np.arange(0.0, span, step)
        pos = _commanded(s0 + tf)
        if k + 1 < starts.size:
            pos[s0 + tf > starts[k + 1] + step / 2] += 1.0
        out.append(JointTrajectoryMessage(float(s0), NAMES, tuple(map(float, tf)), tuple(map(tuple, pos))))
    return out, np.arange(0.0, starts[-1] + span - step / 2, step)


@pytest.mark.parametrize("name", ["traj.mcap", "traj.bag"])
def test_joint_trajectory_reference_multi_point(rec, name):
    """A trajectory_msgs/JointTrajectory topic as the reference: every point at stamp + time_from_start, a later
    trajectory replacing the rest of the earlier one; the reference is the commanded function's samples
    interpolated on the recording's times."""
    tr = rec["tr"]
    traj, grid = _trajectory_messages(float(tr.t[-1]))
    p = write_messages(rec["dir"] / name, {"/joint_states": _msgs(tr), "/arm_controller/joint_trajectory": traj})
    (got,), rep = read_recording(p, robot=rec["robot"], reference_topic="/arm_controller/joint_trajectory")
    want = np.column_stack([np.interp(tr.t, grid, _commanded(grid)[:, j]) for j in range(4)])
    np.testing.assert_allclose(got.meta["q_ref"], want, atol=1e-9)
    assert np.abs(got.meta["q_ref"] - _commanded(tr.t)).max() < 1e-4  # no replaced point (1 rad off) kept
    np.testing.assert_array_equal(got.q, tr.q)
    assert (f"reference positions from /arm_controller/joint_trajectory ({len(traj)} messages, {grid.size} "
            "trajectory points), interpolated on the samples") in rep.notes


def test_joint_trajectory_reference_errors_name_message_and_point(rec, tmp_path):
    tr = rec["tr"]
    traj, _ = _trajectory_messages(float(tr.t[-1]))
    m = traj[2]
    traj[2] = replace(m, positions=m.positions[:4] + (m.positions[4][:3],) + m.positions[5:])
    p = write_messages(tmp_path / "badtraj.mcap", {"/joint_states": _msgs(tr), "/traj": traj})
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"], reference_topic="/traj")
    assert f"{p}, topic /traj, message 3, point 5, field 'positions': 3 positions for 4 joint names" in str(e.value)
    traj, _ = _trajectory_messages(float(tr.t[-1]))
    traj = [replace(m, joint_names=("shoulder", "elbow", "lift", "wrist_roll")) for m in traj]
    p = write_messages(tmp_path / "namestraj.bag", {"/joint_states": _msgs(tr), "/traj": traj})
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"], reference_topic="/traj")
    assert f"{p}, topic /traj, message 1, field 'joint_names': joint(s) wrist missing" in str(e.value)


def test_velocity_empty_in_some_messages(rec):
    """A publisher that leaves velocity empty in a few messages (or one of two publishers that never fills it):
    every velocity is computed from the positions, said with the count and the first message."""
    tr = rec["tr"]
    msgs = _msgs(tr)
    for i in range(5, 10):
        msgs[i] = replace(msgs[i], velocity=())
    p = write_messages(rec["dir"] / "somevel.mcap", {"/joint_states": msgs})
    (got,), rep = read_recording(p, robot=rec["robot"])
    assert got.dq is None
    np.testing.assert_array_equal(got.q, tr.q)
    assert (f"velocity empty in 5 of {tr.n_samples} messages (the first: /joint_states message 6): velocities "
            "computed from the positions") in rep.notes
    a, b = _split(_msgs(tr))
    b = [replace(m, velocity=()) for m in b]  # the wrist driver publishes no velocity
    p = write_messages(rec["dir"] / "wristnovel.db3", {"/arm/joint_states": a, "/wrist/joint_states": b})
    (got,), rep = read_recording(p, robot=rec["robot"])
    assert got.dq is None and any(n.startswith(f"velocity empty in {tr.n_samples} of {2 * tr.n_samples} messages")
                                  for n in rep.notes)
    np.testing.assert_array_equal(got.tau, tr.tau)


@pytest.mark.parametrize("name,forced", [("lib.mcap", "_decode_layout"), ("lib.db3", "_agrees"),
                                         ("lib.bag", "_decode_layout"), ("lib2.bag", "_agrees")])
def test_column_wise_reading_equals_the_librarys(rec, name, forced, monkeypatch):
    """The fields read at fixed offsets equal rosbags' own deserialization of every message (the reader's
    fallback, forced here: a message that does not parse, or a layout the library reads otherwise), with
    per-message joint orders, extra joints and empty arrays mixed."""
    from symoro_gen.preprocessing.readers import bag

    tr = rec["tr"]
    rng = np.random.default_rng(3)
    msgs = []
    for i, m in enumerate(_msgs(tr)):
        names = m.names + (("finger",) if i % 3 else ())
        pos, vel, eff = (x + ((0.01,) if i % 3 else ()) for x in (m.position, m.velocity, m.effort))
        o = rng.permutation(len(names)) if i % 2 else np.arange(len(names))
        msgs.append(JointStateMessage(m.stamp, tuple(names[k] for k in o), tuple(pos[k] for k in o),
                                      tuple(vel[k] for k in o) if i % 5 else (), tuple(eff[k] for k in o)))
    p = write_messages(rec["dir"] / name, {"/joint_states": msgs})
    (fast,), rep_f = read_recording(p, robot=rec["robot"])

    def refuse(*args):
        if forced == "_agrees":
            return False
        raise ValueError("forced")

    monkeypatch.setattr(bag, forced, refuse)
    (slow,), rep_s = read_recording(p, robot=rec["robot"])
    for f in ("t", "q", "tau"):
        np.testing.assert_array_equal(getattr(fast, f), getattr(slow, f))
    np.testing.assert_array_equal(fast.q, tr.q)
    assert fast.dq is None and slow.dq is None and rep_f.notes == rep_s.notes


def test_cli_bag_problems_named_with_the_option(rec, cli, tmp_path):
    """From the command line: what each bag problem prints (file, topic/joint, message, field, option)."""
    tr = rec["tr"]
    jn = ("--joint-names", ",".join(NAMES))
    msgs = _msgs(tr)
    msgs[10], msgs[11] = msgs[11], msgs[10]
    msgs = [replace(m, log_time=float(tr.t[i])) for i, m in enumerate(msgs)]  # logged in order, stamps not
    p = write_messages(tmp_path / "ooo.mcap", {"/joint_states": msgs})
    assert "note: 1 message(s) out of order in the bag: sorted by stamp" in cli("inspect", "scara", p, *jn).out
    fingers = [JointStateMessage(m.stamp, m.names + ("finger",), m.position + (0.0,), m.velocity + (0.0,),
                                 m.effort + (0.0,)) for m in _msgs(tr)]
    p = write_messages(tmp_path / "fingers.bag", {"/joint_states": fingers})
    assert "note: joints ignored (not the robot's): finger" in cli("inspect", "scara", p, *jn).out
    a, b = _split(_msgs(tr))
    p = write_messages(tmp_path / "hole.db3", {"/arm": a, "/wrist": b[:30] + b[31:]})
    r = cli("inspect", "scara", p, *jn, rc=2)
    assert f"{p}, joint lift, field 'position': missing at 1 of {tr.n_samples} time(s): " in r.err
    assert "(/arm message 31)" in r.err and "hint: give --drop-bad-rows to drop these times" in r.err
    assert f"{tr.n_samples} rows read, 1 dropped" not in r.out
    r = cli("inspect", "scara", p, *jn, "--drop-bad-rows", rc=2)  # a time dropped mid-file: a step of 2 dt
    assert f"{p}, rows 31, field 'stamp': irregular sampling" in r.err and "hint: give --resample" in r.err
    out = cli("inspect", "scara", p, *jn, "--drop-bad-rows", "--resample").out
    assert f"{2 * tr.n_samples - 1} rows read, 1 dropped, resampled" in out
    assert "dropped joint lift, position: missing at 1" in out
    somevel = [replace(m, velocity=()) if i in (7, 8) else m for i, m in enumerate(_msgs(tr))]
    p = write_messages(tmp_path / "somevel.bag", {"/joint_states": somevel})
    assert (f"note: velocity empty in 2 of {tr.n_samples} messages (the first: /joint_states message 8): velocities "
            "computed from the positions") in cli("inspect", "scara", p, *jn).out
    p = write_bag(tr, tmp_path / "noeff.mcap", NAMES, effort=False)
    r = cli("inspect", "scara", p, *jn, rc=2)
    assert (f"{p}, topic /joint_states, field 'effort': empty in every message for joint(s) shoulder, elbow, lift, "
            "wrist: the torque is needed (effort, or a current with --tau-scale)") in r.err
    traj, grid = _trajectory_messages(float(tr.t[-1]))
    p = write_messages(tmp_path / "cmd.mcap", {"/joint_states": _msgs(tr), "/cmd": traj})
    out = cli("inspect", "scara", p, *jn, "--reference-topic", "/cmd").out
    assert f"note: reference positions from /cmd ({len(traj)} messages, {grid.size} trajectory points)" in out
    r = cli("inspect", "scara", p, *jn, "--reference-topic", "/command", rc=2)
    assert f"{p}, topic /command, field '--reference-topic': no such topic in the bag (topics: /cmd, /joint_states)" \
        in r.err


def _sines(t):
    """Known smooth joint signals (positions, velocities, torques) of the four joints at times ``t``."""
    f = np.array([0.4, 0.7, 1.1, 0.9])
    w = 2 * np.pi * f
    ph = np.arange(4.0)
    return (0.5 * np.sin(w * t[:, None] + ph), 0.5 * w * np.cos(w * t[:, None] + ph),
            10.0 * np.cos(w * t[:, None] + 2 * ph))


def test_publishers_on_their_own_clocks_interpolated_with_resample(rec, cli, tmp_path):
    """An arm driver (shoulder, elbow) and a wrist driver (lift, wrist) each stamping its own times (0.7 ms
    apart): refused naming the joints and --resample; with it, the wrist's own samples interpolated on the
    arm's times, equal to the known signals at those times."""
    t_arm = np.arange(500) * 0.002
    t_wr = t_arm + 0.0007
    qa, va, ea = _sines(t_arm)
    qw, vw, ew = _sines(t_wr)
    arm = [JointStateMessage(float(t), NAMES[:2], tuple(qa[i, :2]), tuple(va[i, :2]), tuple(ea[i, :2]))
           for i, t in enumerate(t_arm)]
    wrist = [JointStateMessage(float(t), NAMES[2:], tuple(qw[i, 2:]), tuple(vw[i, 2:]), tuple(ew[i, 2:]))
             for i, t in enumerate(t_wr)]
    p = write_messages(tmp_path / "clocks.mcap", {"/arm/joint_states": arm, "/wrist/joint_states": wrist})
    jn = ("--joint-names", ",".join(NAMES))
    r = cli("inspect", "scara", p, *jn, rc=2)
    assert (f"{p}, joint lift, field 'header.stamp': joint(s) lift, wrist published at other times than shoulder, "
            "elbow (at 0 of their 500 times): publishers on their own clocks are not merged by stamp") in r.err
    assert "hint: give --resample to interpolate them on the times of shoulder" in r.err
    (got,), rep = read_recording(p, LogFormat(resample=True, joint_names=NAMES), n_joints=4)
    # the arm's times but the first (before the wrist's first sample), the wrist interpolated on them
    assert got.n_samples == 499
    np.testing.assert_allclose(got.t, t_arm[1:] - t_arm[1], atol=1e-12)
    q, v, e = _sines(t_arm[1:])
    np.testing.assert_array_equal(got.q[:, :2], qa[1:, :2])
    np.testing.assert_allclose(got.q[:, 2:], q[:, 2:], atol=1e-7)        # cubic spline, 2 ms steps
    np.testing.assert_allclose(got.tau[:, 2:], e[:, 2:], atol=2e-3)      # linear: |e''| h^2 / 8
    np.testing.assert_allclose(got.dq[:, 2:], v[:, 2:], atol=1e-3)
    assert ("joint(s) lift, wrist published at other times than shoulder, elbow (at 0 of their 500 times): "
            "interpolated on the 499 times of shoulder (--resample); 1 time(s) before or after their own left out"
            in rep.notes)


@pytest.mark.parametrize("name", ["swap.mcap", "swap.bag"])
def test_layouts_of_equal_length_told_apart(rec, name):
    """Messages of one length and joint names whose velocity and effort sizes are swapped (velocity without
    effort, then effort without velocity): two layouts, so the effort is missing at every other time (an error
    naming it), never read from the velocity's bytes."""
    tr = rec["tr"]
    msgs = [replace(m, effort=()) if i % 2 else replace(m, velocity=()) for i, m in enumerate(_msgs(tr))]
    p = write_messages(rec["dir"] / name, {"/joint_states": msgs})
    with pytest.raises(DataFileError) as e:
        read_recording(p, robot=rec["robot"])
    assert f"{p}, joint shoulder, field 'effort': missing at {tr.n_samples // 2} of {tr.n_samples} time(s)" \
        in str(e.value)


def test_options_of_the_other_kind_of_file_said_not_used(rec, cli, tmp_path):
    """A command's data options apply to all its files: a bag option on a CSV, a text option on a bag, is
    said to be unused for that file (not silently dropped)."""
    tr = rec["tr"]
    p = write_bag(tr, tmp_path / "opts.mcap", NAMES)
    out = cli("inspect", "scara", p, rec["csv"], "--joint-names", ",".join(NAMES), "--topic", "/joint_states",
              "--skip-rows", "2").out
    assert ("note: --skip-rows: options of text and array files, not used for a ROS bag (read by message, its "
            "joints by name)") in out
    assert "note: --topic, --joint-names: options of ROS bags, not used for this file" in out
    (got,), rep = read_recording(rec["csv"], LogFormat(skip_rows=2, prefix="left_"), robot=rec["robot"])
    np.testing.assert_array_equal(got.q, tr.q[2:])
    assert rep.notes[-1] == "--prefix: options of ROS bags, not used for this file"


@pytest.mark.slow  # two identifications from the command line
@pytest.mark.parametrize("name", ["messy.db3", "messy.bag"])
def test_messy_bag_identified_like_the_csv(rec, cli, name):
    """A cell as recorded (ROS 2 sqlite3, ROS 1): two arms by prefix, gripper fingers, each arm's joints from
    two publishers on one topic in their own joint order, messages received out of order. The right arm
    identified from it equals the same recording identified from its CSV."""
    left, right = _recording(11), rec["tr"]
    msgs = []
    for a, b in zip(_msgs(left, [f"left_{x}" for x in NAMES]), _msgs(right, [f"right_{x}" for x in NAMES])):
        arm = JointStateMessage(a.stamp, a.names[:2] + b.names[:2], a.position[:2] + b.position[:2],
                                a.velocity[:2] + b.velocity[:2], a.effort[:2] + b.effort[:2])
        wrist = JointStateMessage(a.stamp, b.names[2:][::-1] + a.names[2:] + ("finger",),
                                  b.position[2:][::-1] + a.position[2:] + (0.01,),
                                  b.velocity[2:][::-1] + a.velocity[2:] + (0.0,),
                                  b.effort[2:][::-1] + a.effort[2:] + (2.0,))
        msgs += [arm, wrist]
    for i in (40, 400, 801):
        msgs[i], msgs[i + 2] = msgs[i + 2], msgs[i]
    log = np.repeat(right.t, 2)
    msgs = [replace(m, log_time=float(log[i])) for i, m in enumerate(msgs)]
    p = write_messages(rec["dir"] / name, {"/joint_states": msgs})
    outs = []
    for data, extra in ((p, ("--prefix", "right_")), (rec["csv"], ())):
        out = rec["dir"] / f"messy_{Path(str(data)).suffix[1:]}.json"
        cli("--quiet", "identify", rec["robot_file"], data, *extra, "--method", "ols", "--json", out, rc=0)
        outs.append(json.loads(out.read_text()))
    a, b = (np.array(d["parameters"]["values"]) for d in outs)
    np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * np.abs(b).max())
    notes = outs[0]["data"][0]["notes"]
    stamps = [m.stamp for m in msgs]
    late = sum(s < max(stamps[:i]) for i, s in enumerate(stamps) if i)  # stamped before one received earlier
    assert late >= 3 and f"{late} message(s) out of order in the bag: sorted by stamp" in notes
    assert any(n.startswith("joints ignored (not the robot's): finger, left_elbow") for n in notes)


def _frame_named_robot_file(path: Path, names=NAMES) -> Path:
    """robots/scara.toml whose frames carry a ``name`` field (no URDF comments)."""
    text = (ROOT / "robots" / "scara.toml").read_text()
    for j, nm in enumerate(names, 1):
        text = text.replace(f"[[frames]]\nj = {j}\n", f'[[frames]]\nj = {j}\nname = "{nm}"\n', 1)
    path.write_text(text)
    return path


def test_frame_names_match_the_bag_joints(rec, tmp_path):
    """A robot file naming its joints with the frames' ``name`` field reads the bag like the URDF-comment file:
    the same samples, matched by name."""
    robot = load_robot(str(_frame_named_robot_file(tmp_path / "named.toml")))
    assert robot.joint_names == NAMES
    assert robot_joint_names(robot) == NAMES
    bag = write_bag(rec["tr"], tmp_path / "frame_names.mcap", NAMES)
    (by_field,), rep = read_recording(bag, robot=robot)
    (by_comment,), _ = read_recording(bag, robot=rec["robot"])
    np.testing.assert_array_equal(by_field.q, by_comment.q)
    np.testing.assert_array_equal(by_field.tau, rec["tr"].tau)
    assert any("joint names of the robot file (the name of its frames)" in n for n in rep.notes)


@pytest.mark.parametrize("bad, message", [('"two words"', "without spaces"), ("3", "without spaces"),
                                          ('"shoulder"', "already the name of frame 1")])
def test_bad_frame_name_is_named(tmp_path, bad, message):
    p = _frame_named_robot_file(tmp_path / "bad.toml")
    text = p.read_text().replace('name = "elbow"', f"name = {bad}", 1)
    p.write_text(text)
    with pytest.raises(RobotFileError) as ei:
        load_robot(str(p))
    msg = str(ei.value)
    assert "bad.toml" in msg and "frame 2" in msg and "name" in msg and message in msg
