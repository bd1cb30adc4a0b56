"""ROS bags (``rosbags`` library, pure Python, no ROS; the ``bags`` extra): ROS 2 bags (a ``.mcap`` or
sqlite3 ``.db3`` file, or a rosbag2 folder with ``metadata.yaml``) and ROS 1 ``.bag`` files.

The joints come from ``sensor_msgs/JointState`` messages (``name``, ``position``, ``velocity``,
``effort``; REP 103 units: rad, m, rad/s, N m, N). The messages are read as they were published:

* the topics: those named by ``--topic`` (several separated by commas), else every ``JointState`` topic that
  carries one of the robot's joints (a joint published on two topics is an error: name one with ``--topic``);
* the joints, matched by name to the robot's (``--joint-names``, else the URDF joint names the robot file's
  ``[[frames]]`` comments keep from ``import-urdf``, else by order of the first message -- said in the
  report), with ``--prefix`` (``left_``: several robots in one bag) before each name; other joints
  (gripper fingers) are ignored and listed in the report;
* the time: the header stamps (``--stamp header``, the default; the bag's log times when every header
  stamp is zero, said in the report) or the log times (``--stamp log``), relative to the first one;
* each message's own joint order; several publishers each giving some joints, merged by stamp (publishers
  on their own clocks: interpolated on the times of the joint published most with ``--resample``); messages
  out of order, sorted by stamp (counted in the report); ``velocity``/``effort`` arrays left empty (no
  velocity in some or all messages: every velocity computed by the filter, said in the report; no effort:
  an error, the torque is needed);
* ``effort`` is the torque (``--tau-scale`` turns a logged current into N m).

The messages are read column-wise: those sharing a layout (byte length, frame id, joint names, array
sizes) have their stamps and arrays at the same byte offsets (ROS 1 serialization, or the OMG CDR 1.0 of
ROS 2 as rosbags' ``serde`` reads it), read as numpy views of one buffer; each layout is checked once against
the library's own deserialization (a message it does not match is deserialized by the library).
``bench/bench_bag_speed.py`` measures the speed against the same data as CSV.

Problems name the file, the topic, the message (index in its topic, 1-based) or its time, and the field.
The samples then go through the data options like any other format (:mod:`.logs`).

Optionally the commanded positions of ``--reference-topic`` (a ``JointState``; a
``trajectory_msgs/JointTrajectory``, its points at the header stamp plus their ``time_from_start``, a later
trajectory replacing the rest of an earlier one; or a controller state / trajectory point with
``joint_names`` and ``reference``/``desired``/``positions``) are interpolated on the samples' times as ``Trajectory.meta['q_ref']``: the recorded reference IV and DIDIM use
(:mod:`symoro_gen.identification.iv`, :mod:`symoro_gen.identification.didim`).

:func:`read_imu` and :func:`read_wrench` read ``sensor_msgs/Imu`` and ``geometry_msgs/WrenchStamped``
topics into arrays (for a floating base); :func:`write_bag` writes a recording as a bag (tests,
simulators), never over an existing file unless ``force`` (:func:`~symoro_gen.atomic.check_replaceable`).
"""
from __future__ import annotations

import os
import re
import shutil
import struct
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import scipy.interpolate

from ...atomic import check_replaceable
from ...errors import DataFileError, Problem
from ..trajectory import Trajectory
from .common import ABSURD_VALUE, DROP_HINT, Column, RawColumns, fmt_names
from .logs import log_trajectories
from .options import LoadReport, LogFormat

__all__ = ["BAG_SUFFIXES", "BAGS_EXTRA", "JOINT_STATE", "is_bag", "robot_joint_names", "read_bag", "read_imu",
           "read_wrench", "JointStateMessage", "joint_state_messages", "write_bag", "write_messages",
           "ImuMessage", "WrenchMessage", "JointTrajectoryMessage"]

BAG_SUFFIXES = (".mcap", ".db3", ".bag")
BAGS_EXTRA = "pip install 'symoro_gen[bags]'"
JOINT_STATE = "sensor_msgs/msg/JointState"
IMU = "sensor_msgs/msg/Imu"
WRENCH = "geometry_msgs/msg/WrenchStamped"
TRAJECTORY = "trajectory_msgs/msg/JointTrajectory"
TRAJECTORY_POINT = "trajectory_msgs/msg/JointTrajectoryPoint"
#: epoch of the stamps written by :func:`write_bag` (a plausible wall-clock time, 2023-11-14) [ns]
EPOCH_NS = 1_700_000_000 * 10**9
STAMP_HINT = "give --stamp log to use the bag's log times (when each message was recorded)"
TOPIC_HINT = "name the joint-state topic(s) with --topic (several separated by commas)"
SHOWN = 3


def is_bag(path: str | os.PathLike) -> bool:
    """A ``.mcap``/``.db3``/``.bag`` file or a rosbag2 folder (``metadata.yaml`` inside)."""
    p = Path(path)
    return p.suffix.lower() in BAG_SUFFIXES or (p.is_dir() and (p / "metadata.yaml").is_file())


def _rosbags(path: str) -> None:
    """Check that the ``rosbags`` library is installed, or fail naming the extra."""
    try:
        import rosbags.highlevel  # noqa: F401 - only whether it is installed
    except ImportError:
        raise DataFileError([Problem(path, "", "", f"ROS bags are read with the rosbags library: {BAGS_EXTRA}")]
                            ) from None


def _typestore(ros1: bool) -> Any:
    from rosbags.typesys import Stores, get_typestore
    return get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)


@contextmanager
def _open(path: str) -> Iterator[Any]:
    """An open ``AnyReader`` (bags without type definitions: the ROS 2 Humble / ROS 1 Noetic types)."""
    _rosbags(path)
    from rosbags.highlevel import AnyReader
    p = Path(path)
    if not p.exists():
        raise DataFileError([Problem(path, "", "", "file not found")])
    try:
        reader = AnyReader([p], default_typestore=_typestore(p.suffix.lower() == ".bag"))
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises several types on a damaged bag
        raise DataFileError([Problem(path, "", "", f"cannot read as a ROS bag ({type(exc).__name__}: {exc})")]
                            ) from None
    try:
        yield reader
    finally:
        reader.close()


# ---------------------------------------------------------------------------------------------
# joint names
# ---------------------------------------------------------------------------------------------
_URDF_FRAME = re.compile(r"^\[\[frames\]\]\s*#\s*URDF joint (\S+) \((\w+)\)")
_J = re.compile(r"^\s*j\s*=\s*(\d+)")


def robot_joint_names(robot) -> tuple[str, ...] | None:
    """The names of the robot's model joints: the ``name`` of their ``[[frames]]`` entries (written by
    ``import-urdf``), else the URDF joint names older ``import-urdf`` files keep in the frames' comments
    (``# URDF joint NAME (type), link ...``); None when the file has neither."""
    if robot is None:
        return None
    named = getattr(robot, "joint_names", None)
    if named:
        return tuple(named)
    path = Path(getattr(robot, "file", "") or "")
    if not path.is_file():
        return None
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    by_frame: dict[int, str] = {}
    pending = None
    for line in text.splitlines():
        m = _URDF_FRAME.match(line.strip())
        if m:
            pending = m.group(1)
            continue
        mj = _J.match(line)
        if mj and pending is not None:
            by_frame[int(mj.group(1))] = pending
            pending = None
    names = [by_frame.get(r.j) for r in robot.model_joints]
    if not names or any(n is None for n in names):
        return None
    return tuple(str(n) for n in names)


# ---------------------------------------------------------------------------------------------
# reading joint states, column-wise
# ---------------------------------------------------------------------------------------------
#: the fields of a JointState's arrays, in the order of the message definition (sensor_msgs/msg/JointState)
ARRAYS = ("position", "velocity", "effort")


@dataclass(frozen=True)
class _Layout:
    """Where the fields lie in the serialized messages sharing a byte length and a header-and-names prefix:
    joint names, and for each array its (byte offset, count); ``dtype`` the float64 of the encoding."""

    names: tuple[str, ...]
    arrays: tuple[tuple[int, int], ...]
    prefix_end: int
    dtype: str
    counts: tuple[int, ...]              # byte offsets of the arrays' element counts

    def key(self, raw: bytes) -> tuple[int, bytes, bytes]:
        """What messages of this layout share: the length; the frame id, names and position count (one slice);
        the velocity count (the length then fixes the effort count)."""
        return len(raw), bytes(raw[12:self.counts[0] + 4]), bytes(raw[self.counts[1]:self.counts[1] + 4])


def _decode_layout(raw: bytes, ros1: bool) -> _Layout:
    """The layout of one serialized ``sensor_msgs/JointState``: ROS 1 (little endian, no alignment; header seq,
    stamp, frame_id) or ROS 2 CDR (4-byte encapsulation header, then fields aligned to their size counted from
    byte 4; OMG CDR 1.0 as rosbags' ``serde.cdr``). Raises ValueError on a message that does not parse."""
    view = memoryview(raw)
    if ros1:
        base, le = 0, True
    else:
        if len(raw) < 4 or raw[1] not in (0, 1):
            raise ValueError("not a CDR encapsulation header")
        base, le = 4, raw[1] == 1
    u32 = struct.Struct("<I" if le else ">I")

    def align(p: int, k: int) -> int:
        return p if ros1 else base + ((p - base + k - 1) & -k)

    def u(p: int) -> int:
        if p + 4 > len(raw):
            raise ValueError("truncated")
        return u32.unpack_from(view, p)[0]

    pos = 12 if ros1 else base + 8       # ROS 1: seq, sec, nsec; ROS 2: sec, nanosec
    nul = 0 if ros1 else 1               # CDR strings count their NUL byte
    pos += 4 + u(pos)                    # frame_id
    pos = align(pos, 4)
    count = u(pos)
    pos += 4
    if count > len(raw):
        raise ValueError("name count larger than the message")
    names = []
    for _ in range(count):
        pos = align(pos, 4)
        k = u(pos)
        if k < nul or pos + 4 + k > len(raw):
            raise ValueError("bad name")
        names.append(bytes(view[pos + 4:pos + 4 + k - nul]).decode())
        pos += 4 + k
    prefix_end = pos
    arrays, counts = [], []
    for _ in ARRAYS:
        pos = align(pos, 4)
        counts.append(pos)
        k = u(pos)
        pos += 4
        if k:
            pos = align(pos, 8)
        if pos + 8 * k > len(raw):
            raise ValueError("truncated array")
        arrays.append((pos, k))
        pos += 8 * k
    return _Layout(tuple(names), tuple(arrays), prefix_end, "<f8" if le else ">f8", tuple(counts))


@dataclass
class _Msgs:
    """The messages of the joint topics, one entry per message in the bag's order: ``topic`` (code into
    ``topics``), ``index`` (1-based, in its topic), ``log_ns``, ``stamp_ns``, ``layout`` (code into
    ``names``/``arrays``: messages with the same joint names and array sizes) and ``row`` (the message's row in
    its layout's arrays ``arrays[layout][field]``, (messages, joints), empty arrays of zero columns)."""

    topics: list[str]
    topic: np.ndarray
    index: np.ndarray
    log_ns: np.ndarray
    stamp_ns: np.ndarray
    layout: np.ndarray
    row: np.ndarray
    names: list[tuple[str, ...]]
    arrays: list[dict[str, np.ndarray]]

    @property
    def size(self) -> int:
        return int(self.topic.size)

    def take(self, keep: np.ndarray) -> _Msgs:
        return replace(self, topic=self.topic[keep], index=self.index[keep], log_ns=self.log_ns[keep],
                       stamp_ns=self.stamp_ns[keep], layout=self.layout[keep], row=self.row[keep])

    def label(self, i: int) -> str:
        return f"{self.topics[int(self.topic[i])]} message {int(self.index[i])}"

    def topic_names(self) -> set[str]:
        return {self.topics[int(c)] for c in np.unique(self.topic)}

    def layouts_used(self) -> list[int]:
        """The layouts of the messages, in the order they first appear."""
        codes, first = np.unique(self.layout, return_index=True)
        return [int(c) for c in codes[np.argsort(first)]]

    def published(self) -> set[str]:
        return {nm for k in self.layouts_used() for nm in self.names[k]}


def _stamp_ns(msg) -> int:
    st = msg.header.stamp
    return int(st.sec) * 10**9 + int(getattr(st, "nanosec", getattr(st, "nsec", 0)))


def _joint_topics(reader, path: str, fmt: LogFormat) -> list[Any]:
    """The connections of the joint-state topics (``fmt.topic`` or every ``JointState`` topic but the reference)."""
    conns = list(reader.connections)
    if fmt.topic:
        want = [t.strip() for t in fmt.topic.split(",") if t.strip()]
        known = sorted({c.topic for c in conns})
        out = []
        for t in want:
            cs = [c for c in conns if c.topic == t]
            if not cs:
                raise DataFileError([Problem(path, f"topic {t}", "--topic", f"no such topic in the bag (topics: "
                                             f"{fmt_names(known)})")])
            bad = [c for c in cs if c.msgtype != JOINT_STATE]
            if bad:
                raise DataFileError([Problem(path, f"topic {t}", "--topic", f"a {bad[0].msgtype} topic, not "
                                             f"{JOINT_STATE}")])
            out += cs
        return out
    out = [c for c in conns if c.msgtype == JOINT_STATE and c.topic != fmt.reference_topic]
    if not out:
        types = sorted({f"{c.topic} ({c.msgtype})" for c in conns})
        raise DataFileError([Problem(path, "", "--topic", f"no {JOINT_STATE} topic in the bag (topics: "
                                     f"{', '.join(types) or 'none'})")])
    return out


def _layout(raw: bytes, ros1: bool) -> _Layout | None:
    """:func:`_decode_layout`, None when the message does not parse."""
    try:
        return _decode_layout(raw, ros1)
    except (ValueError, UnicodeDecodeError, struct.error):
        return None


def _agrees(reader, raw: bytes, lay: _Layout) -> bool:
    """The layout decoded from a message gives what the library's deserialization of it gives (a bag whose
    JointState definition is not the standard one reads through the library)."""
    try:
        msg = reader.deserialize(raw, JOINT_STATE)
    except Exception:  # noqa: BLE001 - the library's own errors on a malformed message
        return False
    if tuple(str(x) for x in msg.name) != lay.names:
        return False
    for f, (off, k) in zip(ARRAYS, lay.arrays):
        a = np.asarray(getattr(msg, f), float).ravel()
        b = np.frombuffer(raw, lay.dtype, count=k, offset=off)
        if a.size != k or not np.array_equal(a, b, equal_nan=True):
            return False
    return True


def _read_messages(reader, conns, path: str) -> _Msgs:
    """Every message of ``conns``, column-wise. Messages are grouped by layout (:meth:`_Layout.key`: byte
    length, frame id, joint names, array sizes): the stamps and arrays of a group are read at fixed offsets
    from one buffer (one numpy view per field instead of a Python object per message); a message that does
    not match the last layout is decoded (:func:`_decode_layout`) and looked up, a new layout checked once
    against the library's deserialization (:func:`_agrees`); a message the decoder cannot read, or of a
    layout the library reads otherwise, is deserialized by the library."""
    ros1 = not getattr(reader, "is2", Path(path).suffix.lower() != ".bag")
    topics = sorted({c.topic for c in conns})
    code = {t: k for k, t in enumerate(topics)}
    layouts: list[_Layout | None] = []           # None: a message deserialized by the library
    keys: dict[tuple[int, bytes, bytes], int] = {}
    rejected: set[tuple[int, bytes, bytes]] = set()     # layouts the library reads otherwise
    raws: list[list[bytes]] = []
    lib: dict[int, tuple[tuple[str, ...], dict[str, np.ndarray], int]] = {}
    topic, index, log, layout, row = [], [], [], [], []
    count = [0] * len(topics)
    probs: list[Problem] = []
    start = int(reader.start_time)
    last_key: tuple[int, bytes, bytes] = (-1, b"", b"")
    head = vel = 0                               # the slices of the last layout's key
    last_k = -1
    for conn, log_ns, raw in reader.messages(connections=conns):
        c = code[conn.topic]
        count[c] += 1
        if len(raw) == last_key[0] and raw[12:head] == last_key[1] and raw[vel:vel + 4] == last_key[2]:
            k = last_k
        else:
            lay = _layout(raw, ros1)
            key = lay.key(raw) if lay is not None else (0, b"", b"")
            k = keys.get(key, -1) if lay is not None else -1
            if lay is not None and k < 0:  # a new layout: checked once against the library
                if key not in rejected and _agrees(reader, raw, lay):
                    k = keys[key] = len(layouts)
                    layouts.append(lay)
                    raws.append([])
                else:
                    rejected.add(key)
                    lay = None
            if lay is not None:
                last_key, last_k, head, vel = key, k, lay.counts[0] + 4, lay.counts[1]
            else:
                try:
                    msg = reader.deserialize(raw, conn.msgtype)
                except Exception as exc:  # noqa: BLE001 - the library's errors on a malformed message
                    probs.append(Problem(path, f"topic {conn.topic}, message {count[c]} (logged "
                                         f"{(log_ns - start) * 1e-9:.6g} s into the bag)", "",
                                         f"cannot deserialize ({type(exc).__name__}: {exc})"))
                    continue
                k = len(layouts)
                layouts.append(None)
                raws.append([])
                lib[k] = (tuple(str(x) for x in msg.name),
                          {f: np.asarray(getattr(msg, f), float).ravel()[None, :] for f in ARRAYS}, _stamp_ns(msg))
        topic.append(c)
        index.append(count[c])
        log.append(int(log_ns))
        layout.append(k)
        row.append(len(raws[k]))
        if layouts[k] is not None:
            raws[k].append(raw)
    names: list[tuple[str, ...]] = []
    arrays: list[dict[str, np.ndarray]] = []
    stamp = np.zeros(len(topic), np.int64)
    lay_arr = np.asarray(layout, np.int64)
    for k, lay in enumerate(layouts):
        mine = np.flatnonzero(lay_arr == k)
        if lay is None:
            nm, arrs, stamp[mine] = lib[k]
        else:
            nm = lay.names
            buf = np.frombuffer(b"".join(raws[k]), np.uint8).reshape(len(raws[k]), -1)
            i32 = "<i4" if lay.dtype[0] == "<" else ">i4"
            u32 = "<u4" if lay.dtype[0] == "<" else ">u4"
            sec = np.ascontiguousarray(buf[:, 4:8]).view(u32 if ros1 else i32)[:, 0].astype(np.int64)
            nsec = np.ascontiguousarray(buf[:, 8:12]).view(u32)[:, 0].astype(np.int64)
            stamp[mine] = sec * 10**9 + nsec
            arrs = {f: np.ascontiguousarray(buf[:, off:off + 8 * cnt]).view(lay.dtype).astype(float)
                    for f, (off, cnt) in zip(ARRAYS, lay.arrays)}
        i = int(mine[0])
        where = f"topic {topics[topic[i]]}, message {index[i]} (logged {(log[i] - start) * 1e-9:.6g} s into the bag)"
        names.append(nm)
        arrays.append(arrs)
        for f, a in arrs.items():
            size = a.shape[-1]
            if size not in (0, len(nm)):
                probs.append(Problem(path, where, f, f"{size} values for {len(nm)} joint names"
                                     + (f" (and {mine.size - 1} more message(s) alike)" if mine.size > 1 else "")))
        if arrs["position"].shape[-1] == 0 and nm:
            probs.append(Problem(path, where, "position", "empty: every message must give the joints' positions"))
    if probs:
        raise DataFileError(probs[:20])
    return _Msgs(topics, np.asarray(topic, np.int64), np.asarray(index, np.int64), np.asarray(log, np.int64),
                 stamp, lay_arr, np.asarray(row, np.int64), names, arrays)


def _wanted_names(msgs: _Msgs, n: int, fmt: LogFormat, robot, path: str, topics: str) -> tuple[list[str], str]:
    """The bag's names of the robot's joints (prefix included) and how they were matched."""
    pre = fmt.prefix or ""
    if fmt.joint_names:
        names = list(fmt.joint_names)
        if len(names) != n:
            raise DataFileError([Problem(path, "", "--joint-names", f"{len(names)} names given, the robot has {n} "
                                         "joints")])
        return [pre + x for x in names], "by the names of --joint-names"
    named = getattr(robot, "joint_names", None)
    if named:
        return [pre + x for x in named], "by the joint names of the robot file (the name of its frames)"
    rn = robot_joint_names(robot)
    if rn is not None:
        return [pre + x for x in rn], "by the URDF joint names of the robot file"
    first: list[str] = []
    for k in msgs.layouts_used():
        first += [x for x in msgs.names[k] if x.startswith(pre) and x not in first]
        if len(first) >= n:
            break
    if len(first) < n:
        raise DataFileError([Problem(path, f"topic {topics}", "name", f"the robot has {n} joints and no joint names; "
                                     f"the messages name only {len(first)} joint(s){' starting with ' + repr(pre) if pre else ''}"
                                     f" ({fmt_names(first)}): give the bag's names with --joint-names a,b,c")])
    return first[:n], (f"by order (the robot file names no joints): the first {n} joint names of the messages "
                       f"{fmt_names(first[:n])}; --joint-names a,b,c gives them")


@dataclass
class _Samples:
    t_ns: np.ndarray                     # (N,) stamps, sorted
    q: np.ndarray
    dq: np.ndarray | None
    tau: np.ndarray
    first_msg: np.ndarray                # (N,) the first message at each time (index into the messages)
    notes: list[str] = field(default_factory=list)
    dropped: list[str] = field(default_factory=list)
    n_dropped: int = 0                   # times dropped (a joint missing, --drop-bad-rows)


def _times(msgs: _Msgs, fmt: LogFormat, path: str, topics: str, notes: list[str]) -> np.ndarray:
    """Each message's time [ns]: the header stamp or the log time (``fmt.stamp``)."""
    if fmt.stamp == "log":
        return msgs.log_ns
    zero = np.flatnonzero(msgs.stamp_ns == 0)
    if zero.size and zero.size == msgs.size:
        notes.append(f"every header stamp of {topics} is zero: the bag's log times are used (--stamp log)")
        return msgs.log_ns
    if zero.size:
        where = ", ".join(msgs.label(i) for i in zero[:SHOWN]) + (", ..." if zero.size > SHOWN else "")
        raise DataFileError([Problem(path, f"{zero.size} message(s): {where}", "header.stamp",
                                     "zero while other messages are stamped")], hint=STAMP_HINT)
    return msgs.stamp_ns


def _out_of_order(msgs: _Msgs, times: np.ndarray) -> int:
    """Messages earlier than one before them in their topic (each publisher's own sequence)."""
    back = 0
    for c in np.unique(msgs.topic):
        tt = times[msgs.topic == c]
        if tt.size > 1:
            back += int((tt[1:] < np.maximum.accumulate(tt)[:-1]).sum())
    return back


def _samples(msgs: _Msgs, names: list[str], fmt: LogFormat, path: str, topics: str) -> _Samples:
    """Per-stamp samples of the wanted joints (messages of several publishers merged by stamp), column-wise:
    every (message, joint) value in one array, sorted by (time, message), the first of each (time, joint) kept."""
    notes: list[str] = []
    times = _times(msgs, fmt, path, topics, notes)
    want = {nm: j for j, nm in enumerate(names)}
    back = _out_of_order(msgs, times)
    if back:
        notes.append(f"{back} message(s) out of order in the bag: sorted by "
                     f"{'log time' if fmt.stamp == 'log' else 'stamp'}")
    present = msgs.published()
    missing = [nm for nm in names if nm not in present]
    if missing:
        what = f"joint {missing[0]!r} is" if len(missing) == 1 else f"joints {fmt_names(missing)} are"
        bare = missing[0][len(fmt.prefix):] if missing[0].startswith(fmt.prefix) else missing[0]
        prefixes = sorted({x[:-len(bare)] for x in present if x.endswith(bare) and x != bare})
        tip = (f"; --prefix {' or --prefix '.join(prefixes)} would match {bare!r}" if prefixes and not fmt.prefix
               else "")
        raise DataFileError([Problem(path, f"topic {topics}", "name", f"{what} in no message (joints published: "
                                     f"{fmt_names(sorted(present))}){tip}")],
                            hint=TOPIC_HINT + "; --joint-names a,b,c (and --prefix) say which joints are the robot's")
    extra = sorted(present - set(names))
    if extra:
        notes.append(f"joints ignored (not the robot's): {fmt_names(extra)}")
    stamps, row_of = np.unique(times, return_inverse=True)
    N, n = stamps.size, len(names)
    # every value of a wanted joint: (message, joint, q, dq, tau), NaN where the message's array is empty
    e_msg: list[np.ndarray] = []
    e_j: list[np.ndarray] = []
    e_q: list[np.ndarray] = []
    e_v: list[np.ndarray] = []
    e_e: list[np.ndarray] = []
    for k in msgs.layouts_used():
        cols = [(c, want[nm]) for c, nm in enumerate(msgs.names[k]) if nm in want]
        if not cols:
            continue
        mine = np.flatnonzero(msgs.layout == k)
        rows = msgs.row[mine]
        c_idx = np.array([c for c, _ in cols])
        arr = msgs.arrays[k]
        e_msg.append(np.repeat(mine, len(cols)))
        e_j.append(np.tile([j for _, j in cols], mine.size))
        for f, acc in (("position", e_q), ("velocity", e_v), ("effort", e_e)):
            a = arr[f]
            acc.append(a[rows][:, c_idx].ravel() if a.shape[1] else np.full(mine.size * len(cols), np.nan))
    m_all, j_all = np.concatenate(e_msg), np.concatenate(e_j)
    vals = {"position": np.concatenate(e_q), "velocity": np.concatenate(e_v), "effort": np.concatenate(e_e)}
    empty = {f: _empty_mask(msgs, m_all, f) for f in ARRAYS}  # NaN from an empty array, not a bad value
    o = np.lexsort((m_all, times[m_all]))              # by time, then bag order: the first published kept
    key = row_of[m_all[o]] * n + j_all[o]
    uniq, first = np.unique(key, return_index=True)
    dup = o.size - uniq.size
    keep = o[first]
    r, j = row_of[m_all[keep]], j_all[keep]
    t_first = times.min()
    bad: list[Problem] = []
    out: dict[str, np.ndarray] = {}
    for f in ARRAYS:
        x = vals[f][keep].copy()
        ok = empty[f][keep] | (np.isfinite(x) & (np.abs(x) <= ABSURD_VALUE))
        for i in np.flatnonzero(~ok)[:max(0, 20 - len(bad))]:
            mi = int(m_all[keep[i]])
            bad.append(Problem(path, f"topic {msgs.topics[int(msgs.topic[mi])]}, message {int(msgs.index[mi])} "
                               f"(t = {(times[mi] - t_first) * 1e-9:.6g} s), joint {names[int(j[i])]}", f,
                               f"{x[i]:g}: not a finite value of at most {ABSURD_VALUE:g}"))
        x[~ok] = np.nan  # dropped with --drop-bad-rows (the time is incomplete)
        grid = np.full((N, n), np.nan)
        grid[r, j] = x
        out[f] = grid
        if f != "position":
            has = np.zeros((N, n), bool)
            has[r, j] = ~empty[f][keep]
            out[f + "_has"] = has
    if bad and not fmt.drop_bad_rows:
        raise DataFileError(bad[:20], hint=DROP_HINT)
    if dup:
        notes.append(f"{dup} joint sample(s) published twice at the same time: the first kept")
    has_e = np.asarray(out["effort_has"].any(axis=0), bool)
    no_e = [names[jj] for jj in range(n) if not has_e[jj]]
    if no_e:
        raise DataFileError([Problem(path, f"topic {topics}", "effort", f"empty in every message for joint(s) "
                                     f"{fmt_names(no_e)}: the torque is needed (effort, or a current with "
                                     "--tau-scale)")])
    got_q = ~np.isnan(out["position"])
    has_v = out["velocity_has"]
    dq: np.ndarray | None = out["velocity"]
    if not has_v.any():
        dq = None
        notes.append("velocity empty in the messages: velocities computed from the positions")
    elif not has_v[got_q].all():
        dq = None
        no_v = np.unique(m_all[keep][empty["velocity"][keep]])
        notes.append(f"velocity empty in {no_v.size} of {msgs.size} messages (the first: {msgs.label(int(no_v[0]))}): "
                     "velocities computed from the positions")
    o_msg = np.lexsort((np.arange(msgs.size), times))
    _, first_row = np.unique(row_of[o_msg], return_index=True)
    return _complete(_Samples(stamps.astype(np.int64), out["position"], dq, out["effort"], o_msg[first_row], notes),
                     names, fmt, path, msgs)


def _empty_mask(msgs: _Msgs, m_all: np.ndarray, f: str) -> np.ndarray:
    """Entries whose message has an empty ``f`` array."""
    empty_layout = np.array([msgs.arrays[k][f].shape[1] == 0 for k in range(len(msgs.names))], bool)
    return empty_layout[msgs.layout[m_all]]


#: a joint published at fewer than this share of the times of the joint published most is on another
#: publisher's clock (interpolated with ``--resample``), not from a publisher that missed a few times
SHARED_MIN = 0.5


def _other_clocks(s: _Samples, names: list[str], fmt: LogFormat, path: str) -> _Samples:
    """Joints whose publisher stamps other times than the joint published most (two drivers on their own
    clocks): an error naming them and ``--resample``; with it, each such joint's own samples interpolated on
    the times of the other (positions by a cubic spline, velocities and torques linearly, as
    :func:`.logs.resample`), the times outside its own first and last left out."""
    has = ~np.isnan(s.q) & ~np.isnan(s.tau)
    if has.all():
        return s
    j0 = int(np.argmax(has.sum(axis=0)))
    base = has[:, j0]
    shared = (has & base[:, None]).sum(axis=0) / base.sum()
    other = np.flatnonzero(shared < SHARED_MIN)
    if not other.size:
        return s
    ref = [names[j] for j in range(len(names)) if shared[j] >= SHARED_MIN]
    what = (f"joint(s) {fmt_names([names[j] for j in other])} published at other times than {fmt_names(ref)} "
            f"(at {int(round(shared[other].min() * base.sum()))} of their {int(base.sum())} times)")
    if not fmt.resample:
        raise DataFileError([Problem(path, f"joint {names[other[0]]}", "header.stamp", f"{what}: publishers on their "
                                     "own clocks are not merged by stamp")],
                            hint=f"give --resample to interpolate them on the times of {ref[0]} (then on a uniform "
                                 "grid)")
    tt = (s.t_ns - s.t_ns[0]) * 1e-9
    rows = np.flatnonzero(base)
    inside = np.ones(rows.size, bool)
    q, tau = s.q.copy(), s.tau.copy()
    dq = None if s.dq is None else s.dq.copy()
    for j in other:
        own = has[:, j]
        tj = tt[own]
        if tj.size < 2:
            raise DataFileError([Problem(path, f"joint {names[j]}", "position", f"published at {tj.size} time(s)")])
        inside &= (tt[rows] >= tj[0]) & (tt[rows] <= tj[-1])
        at = np.clip(tt[rows], tj[0], tj[-1])
        q[rows, j] = (scipy.interpolate.CubicSpline(tj, q[own, j])(at) if tj.size >= 4 else np.interp(at, tj, q[own, j]))
        tau[rows, j] = np.interp(at, tj, tau[own, j])
        if dq is not None:
            ok = own & ~np.isnan(dq[:, j])
            dq[rows, j] = np.interp(at, tt[ok], dq[ok, j]) if ok.sum() >= 2 else np.nan
    keep = rows[inside]
    if keep.size < 2:
        raise DataFileError([Problem(path, f"joint {names[other[0]]}", "header.stamp", f"{what}: their times do not "
                                     "overlap")])
    left = rows.size - keep.size
    note = (f"{what}: interpolated on the {keep.size} times of {ref[0]} (--resample)"
            + (f"; {left} time(s) before or after their own left out" if left else ""))
    return _Samples(s.t_ns[keep], q[keep], None if dq is None else dq[keep], tau[keep], s.first_msg[keep],
                    [*s.notes, note], s.dropped, s.n_dropped)


def _complete(s: _Samples, names: list[str], fmt: LogFormat, path: str, msgs: _Msgs) -> _Samples:
    """Stamps where a joint has no position or effort: joints on another publisher's clock interpolated
    (:func:`_other_clocks`), else an error naming them, or dropped (``--drop-bad-rows``)."""
    s = _other_clocks(s, names, fmt, path)
    hole = np.isnan(s.q) | np.isnan(s.tau)
    if s.dq is not None:
        hole |= np.isnan(s.dq) & ~np.isnan(s.q)
    bad = hole.any(axis=1)
    if not bad.any():
        return s
    t0 = s.t_ns[0]
    probs = []
    for j in np.flatnonzero(hole.any(axis=0)):
        rows = np.flatnonzero(hole[:, j])
        field_ = "position" if np.isnan(s.q[rows, j]).any() else "effort" if np.isnan(s.tau[rows, j]).any() else "velocity"
        at = ", ".join(f"{(s.t_ns[r] - t0) * 1e-9:.6g} s ({msgs.label(int(s.first_msg[r]))})" for r in rows[:SHOWN])
        probs.append(Problem(path, f"joint {names[j]}", field_, f"missing at {rows.size} of {len(bad)} time(s): {at}"
                             f"{', ...' if rows.size > SHOWN else ''} (joints published at other times are not "
                             "interpolated)"))
    if not fmt.drop_bad_rows:
        raise DataFileError(probs, hint="give --drop-bad-rows to drop these times (counted in the output); "
                            "publishers of some joints each are merged by equal stamps")
    keep = ~bad
    if keep.sum() < 2:
        raise DataFileError([Problem(path, "", "", "no time has every joint")])
    dropped = [f"{p.where}, {p.field}: {p.message}" for p in probs]
    return _Samples(s.t_ns[keep], s.q[keep], None if s.dq is None else s.dq[keep], s.tau[keep],
                    s.first_msg[keep], s.notes, dropped, int(bad.sum()))


def _duration_ns(d) -> int:
    return int(d.sec) * 10**9 + int(getattr(d, "nanosec", getattr(d, "nsec", 0)))


def _reference(reader, path: str, fmt: LogFormat, names: list[str]) -> tuple[np.ndarray, np.ndarray, str] | None:
    """``(t_ns, q_ref, what)`` of ``--reference-topic``: a ``JointState``'s positions; a
    ``trajectory_msgs/JointTrajectory`` (every point at the header stamp, or the log time when it is zero, plus
    its ``time_from_start``; a later message replaces the points of earlier ones from its first point on, as a
    ``joint_trajectory_controller`` does); or a message with ``joint_names`` and ``reference``/``desired`` (a
    controller state) or ``positions`` (a trajectory point)."""
    if not fmt.reference_topic:
        return None
    conns = [c for c in reader.connections if c.topic == fmt.reference_topic]
    if not conns:
        raise DataFileError([Problem(path, f"topic {fmt.reference_topic}", "--reference-topic", "no such topic in "
                                     f"the bag (topics: {fmt_names(sorted({c.topic for c in reader.connections}))})")])
    if all(c.msgtype == JOINT_STATE for c in conns):
        msgs = _read_messages(reader, conns, path)
        times = msgs.log_ns if fmt.stamp == "log" else np.where(msgs.stamp_ns != 0, msgs.stamp_ns, msgs.log_ns)
        q = np.full((msgs.size, len(names)), np.nan)
        for k in msgs.layouts_used():
            idx = {x: i for i, x in enumerate(msgs.names[k])}
            mine = np.flatnonzero(msgs.layout == k)
            miss = [x for x in names if x not in idx]
            pos = msgs.arrays[k]["position"]
            if miss or pos.shape[1] == 0:
                raise DataFileError([Problem(path, f"topic {fmt.reference_topic}, message {int(msgs.index[mine[0]])}",
                                             "name" if miss else "position", f"joint(s) {fmt_names(miss)} missing"
                                             if miss else "empty: a reference needs positions")])
            q[mine] = pos[msgs.row[mine]][:, [idx[x] for x in names]]
        return _sorted_reference(path, fmt, times, q, f"{msgs.size} messages")
    segments: list[tuple[np.ndarray, np.ndarray]] = []
    n_msgs = 0
    for k, (conn, log_ns, raw) in enumerate(reader.messages(connections=conns), 1):
        n_msgs = k
        msg = reader.deserialize(raw, conn.msgtype)
        where = f"topic {fmt.reference_topic}, message {k}"
        stamp = _stamp_ns(msg) if hasattr(msg, "header") and fmt.stamp != "log" else 0
        t_msg = stamp or int(log_ns)
        jn = [str(x) for x in getattr(msg, "joint_names", [])]
        if hasattr(msg, "points"):  # trajectory_msgs/JointTrajectory: several points
            pts = list(msg.points)
            if not pts:
                continue
            pts_q = [np.asarray(p.positions, float) for p in pts]
            wrong = [i for i, p in enumerate(pts_q) if p.size != len(jn)]
            if not jn or wrong:
                i = wrong[0] if wrong else 0
                raise DataFileError([Problem(path, f"{where}, point {i + 1}", "positions",
                                             f"{pts_q[i].size} positions for {len(jn)} joint names")])
            ts = t_msg + np.array([_duration_ns(p.time_from_start) for p in pts], np.int64)
            if np.any(np.diff(ts) <= 0):
                raise DataFileError([Problem(path, where, "points.time_from_start", "not strictly increasing")])
            rows = np.vstack(pts_q)
        elif hasattr(msg, "name") and hasattr(msg, "position"):
            jn, rows = [str(x) for x in msg.name], np.asarray(msg.position, float)[None, :]
            ts = np.array([t_msg], np.int64)
        else:
            point = next((getattr(msg, a) for a in ("reference", "desired") if hasattr(msg, a)), msg)
            rows = np.asarray(getattr(point, "positions", []), float)[None, :]
            ts = np.array([t_msg], np.int64)
        if not jn or rows.shape[1] != len(jn):
            raise DataFileError([Problem(path, where, "positions", f"a {conn.msgtype} with {len(jn)} joint names and "
                                         f"{rows.shape[1]} positions: not a reference (a JointState, a "
                                         "JointTrajectory, or joint_names with reference/desired positions)")])
        idx = {x: i for i, x in enumerate(jn)}
        miss = [x for x in names if x not in idx]
        if miss:
            raise DataFileError([Problem(path, where, "joint_names", f"joint(s) {fmt_names(miss)} missing")])
        segments.append((ts, rows[:, [idx[x] for x in names]]))
    multi = any(s[0].size > 1 for s in segments)
    if multi:  # each trajectory replaces the earlier ones from its first point on
        segments.sort(key=lambda s: int(s[0][0]))
        cut = [s[0][0] for s in segments[1:]] + [np.iinfo(np.int64).max]
        segments = [(ts[ts < c], q[ts < c]) for (ts, q), c in zip(segments, cut)]
    times = np.concatenate([s[0] for s in segments]) if segments else np.zeros(0, np.int64)
    q = np.vstack([s[1] for s in segments]) if segments else np.zeros((0, len(names)))
    what = f"{n_msgs} messages" + (f", {times.size} trajectory points" if multi else "")
    return _sorted_reference(path, fmt, times, q, what)


def _sorted_reference(path: str, fmt: LogFormat, times: np.ndarray, q: np.ndarray, what: str
                      ) -> tuple[np.ndarray, np.ndarray, str]:
    if times.size < 2:
        raise DataFileError([Problem(path, f"topic {fmt.reference_topic}", "", "fewer than 2 reference points")])
    o = np.argsort(times, kind="stable")
    return np.asarray(times, np.int64)[o], np.asarray(q, float)[o], what


def _topics_label(conns) -> str:
    return ",".join(sorted({c.topic for c in conns}))


def _check_topics(msgs: _Msgs, names: list[str], path: str) -> None:
    """A joint published on two topics: the topics must be told apart with ``--topic``."""
    where: dict[str, set[str]] = {}
    wanted = set(names)
    pairs = np.unique(np.column_stack([msgs.layout, msgs.topic]), axis=0)
    for k, c in pairs:
        for nm in msgs.names[int(k)]:
            if nm in wanted:
                where.setdefault(nm, set()).add(msgs.topics[int(c)])
    both = {nm: ts for nm, ts in where.items() if len(ts) > 1}
    if both:
        nm, ts = next(iter(both.items()))
        raise DataFileError([Problem(path, f"topics {', '.join(sorted(ts))}", "name", f"joint {nm!r} is published "
                                     "on several JointState topics")], hint=TOPIC_HINT)


def read_bag(path: str | os.PathLike, fmt: LogFormat | None = None, *, n: int, robot=None, dt: float | None = None,
             loaded: bool = False, drive_chain=None, joint_types=None
             ) -> tuple[tuple[Trajectory, ...], LoadReport]:
    """The experiments of a ROS bag (see the module docstring), read with the data options ``fmt``.

    Raises
    ------
    DataFileError
        Naming the file, the topic, the message (index or time), the joint and the field.
    """
    fmt = fmt or LogFormat()
    path = os.fspath(path)
    if fmt.columns:
        raise DataFileError([Problem(path, "", "--columns", "a ROS bag has no columns: its joints are matched by "
                                     "name (--joint-names, --prefix, --topic)")])
    with _open(path) as reader:
        conns = _joint_topics(reader, path, fmt)
        msgs = _read_messages(reader, conns, path)
        topics = _topics_label(conns)
        if not msgs.size:
            raise DataFileError([Problem(path, f"topic {topics}", "", "no message")])
        names, how = _wanted_names(msgs, n, fmt, robot, path, topics)
        if not fmt.topic:  # only the topics that carry the robot's joints
            wanted = set(names)
            lay_mine = np.array([bool(set(nm) & wanted) for nm in msgs.names], bool)
            mine = np.unique(msgs.topic[lay_mine[msgs.layout]])
            if mine.size:  # else every topic, to name the joints they publish
                msgs = msgs.take(np.isin(msgs.topic, mine))
                topics = ",".join(sorted(msgs.topic_names()))
            _check_topics(msgs, names, path)
        s = _samples(msgs, names, fmt, path, topics)
        ref = _reference(reader, path, fmt, names)
    t0 = int(s.t_ns[0])
    t = (s.t_ns - t0) * 1e-9
    cols = {"t": Column(path, ["stamp"], t[:, None], None), "q": Column(path, [f"{x}.position" for x in names], s.q, None),
            "tau": Column(path, [f"{x}.effort" for x in names], s.tau, None)}
    if s.dq is not None:
        cols["dq"] = Column(path, [f"{x}.velocity" for x in names], s.dq, None)
    raw = RawColumns(path, "bag", cols)
    trajs, rep = log_trajectories(raw, fmt, n=n, dt=dt, loaded=loaded, drive_chain=drive_chain,
                                  joint_types=joint_types)
    for tr in trajs:
        tr.meta.update({"topics": topics.split(","), "joint_names": names, "t0_ns": t0})
        if ref is not None:
            tr.meta["q_ref"] = np.column_stack([np.interp(tr.t, (ref[0] - t0) * 1e-9, ref[1][:, j])
                                                for j in range(n)])
            tr.meta["q_ref_topic"] = fmt.reference_topic
    notes = [f"topic(s) {topics}: {msgs.size} messages, {s.t_ns.size} times; joints matched {how}"] + s.notes
    text_only = [o for o, on in (("--skip-rows", fmt.skip_rows), ("--reshape", fmt.reshape)) if on]
    if text_only:  # a command's options apply to all its files
        notes.append(f"{', '.join(text_only)}: options of text and array files, not used for a ROS bag (read by "
                     "message, its joints by name)")
    if ref is not None:
        notes.append(f"reference positions from {fmt.reference_topic} ({ref[2]}), interpolated on the samples")
    rep = replace(rep, rows_read=msgs.size, rows_dropped=rep.rows_dropped + s.n_dropped,
                  dropped=tuple(s.dropped) + rep.dropped, notes=tuple(notes) + rep.notes)
    return trajs, rep


# ---------------------------------------------------------------------------------------------
# IMU and wrench topics (floating base: read, not used by the commands yet)
# ---------------------------------------------------------------------------------------------
def _topic_arrays(path: str | os.PathLike, topic: str | None, msgtype: str, fields: Mapping[str, tuple[str, ...]],
                  stamp: str = "header") -> dict[str, np.ndarray]:
    path = os.fspath(path)
    with _open(path) as reader:
        conns = [c for c in reader.connections if c.msgtype == msgtype and (topic is None or c.topic == topic)]
        if not conns:
            raise DataFileError([Problem(path, f"topic {topic}" if topic else "", "topic", f"no {msgtype} topic "
                                         f"(topics: {fmt_names(sorted({c.topic for c in reader.connections}))})")])
        if topic is None and len({c.topic for c in conns}) > 1:
            raise DataFileError([Problem(path, "", "topic", f"several {msgtype} topics "
                                         f"({fmt_names(sorted({c.topic for c in conns}))}): name one")])
        ts: list[int] = []
        out: dict[str, list] = {k: [] for k in fields}
        for conn, log_ns, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            ts.append(_stamp_ns(msg) if stamp == "header" and _stamp_ns(msg) else int(log_ns))
            for k, attrs in fields.items():
                obj = msg
                for a in attrs[:-1]:
                    obj = getattr(obj, a)
                last = attrs[-1]
                if last == "xyzw":
                    out[k].append([obj.x, obj.y, obj.z, obj.w])
                elif last == "xyz":
                    out[k].append([obj.x, obj.y, obj.z])
                else:
                    out[k].append(np.asarray(getattr(obj, last), float).ravel())
    o = np.argsort(np.asarray(ts, np.int64), kind="stable")
    tn = np.asarray(ts, np.int64)[o]
    res = {"t": (tn - tn[0]) * 1e-9 if tn.size else np.zeros(0), "t0_ns": np.asarray(tn[0] if tn.size else 0)}
    res.update({k: np.asarray(v, float)[o] for k, v in out.items()})
    return res


def read_imu(path: str | os.PathLike, topic: str | None = None, *, stamp: str = "header") -> dict[str, np.ndarray]:
    """A ``sensor_msgs/Imu`` topic as arrays: ``t`` [s, from the first message], ``orientation`` (N, 4) quaternion
    x y z w, ``angular_velocity`` (N, 3) [rad/s], ``linear_acceleration`` (N, 3) [m/s^2] (REP 103/145)."""
    return _topic_arrays(path, topic, IMU, {"orientation": ("orientation", "xyzw"),
                                            "angular_velocity": ("angular_velocity", "xyz"),
                                            "linear_acceleration": ("linear_acceleration", "xyz")}, stamp)


def read_wrench(path: str | os.PathLike, topic: str | None = None, *, stamp: str = "header") -> dict[str, np.ndarray]:
    """A ``geometry_msgs/WrenchStamped`` topic as arrays: ``t`` [s], ``force`` (N, 3) [N], ``torque`` (N, 3) [N m]."""
    return _topic_arrays(path, topic, WRENCH, {"force": ("wrench", "force", "xyz"),
                                               "torque": ("wrench", "torque", "xyz")}, stamp)


# ---------------------------------------------------------------------------------------------
# writing
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class JointStateMessage:
    """One ``JointState`` to write: ``stamp`` [s] (header; ``zero_stamp``: a zero header stamp, as drivers that do
    not stamp write), ``log_time`` [s] (default the stamp), joint ``names`` and their ``position``, ``velocity``,
    ``effort`` (empty: an empty array)."""

    stamp: float
    names: tuple[str, ...]
    position: tuple[float, ...]
    velocity: tuple[float, ...] = ()
    effort: tuple[float, ...] = ()
    log_time: float | None = None
    zero_stamp: bool = False


@dataclass(frozen=True)
class ImuMessage:
    stamp: float
    orientation: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    angular_velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)
    linear_acceleration: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class WrenchMessage:
    stamp: float
    force: tuple[float, float, float] = (0.0, 0.0, 0.0)
    torque: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class JointTrajectoryMessage:
    """One ``trajectory_msgs/JointTrajectory`` (a commanded trajectory): header ``stamp`` [s], ``joint_names``,
    the points' ``times`` from the stamp [s] and their ``positions`` (one tuple per point)."""

    stamp: float
    joint_names: tuple[str, ...]
    times: tuple[float, ...]
    positions: tuple[tuple[float, ...], ...]


BagMessage = JointStateMessage | ImuMessage | WrenchMessage | JointTrajectoryMessage


def joint_state_messages(trajectory: Trajectory, joint_names: Sequence[str], *, velocity: bool = True,
                         effort: bool = True, positions=None) -> list[JointStateMessage]:
    """One ``JointState`` per sample of ``trajectory`` (``positions``: other positions, e.g. a reference)."""
    q = np.asarray(trajectory.q if positions is None else positions, float)
    if q.shape[1] != len(joint_names):
        raise ValueError(f"{len(joint_names)} joint names for {q.shape[1]} joints")
    dq = trajectory.dq if velocity else None
    out = []
    for i, t in enumerate(np.asarray(trajectory.t, float)):
        out.append(JointStateMessage(float(t), tuple(joint_names), tuple(map(float, q[i])),
                                     tuple(map(float, dq[i])) if dq is not None else (),
                                     tuple(map(float, trajectory.tau[i])) if effort else ()))
    return out


def _ns(t: float) -> int:
    return EPOCH_NS + int(round(float(t) * 1e9))


def _ros_message(ts: Any, m: BagMessage, ros1: bool) -> tuple[str, Any, int]:
    """(msgtype, message, log time ns)."""
    T = ts.types
    stamp = T["builtin_interfaces/msg/Time"](sec=0, nanosec=0)
    if not getattr(m, "zero_stamp", False):
        ns = _ns(m.stamp)
        stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)
    header = (T["std_msgs/msg/Header"](seq=0, stamp=stamp, frame_id="") if ros1
              else T["std_msgs/msg/Header"](stamp=stamp, frame_id=""))
    log = _ns(m.log_time if isinstance(m, JointStateMessage) and m.log_time is not None else m.stamp)
    if isinstance(m, JointStateMessage):
        msg = T[JOINT_STATE](header=header, name=list(m.names), position=np.asarray(m.position, float),
                             velocity=np.asarray(m.velocity, float), effort=np.asarray(m.effort, float))
        return JOINT_STATE, msg, log
    if isinstance(m, JointTrajectoryMessage):
        D, P = T["builtin_interfaces/msg/Duration"], T[TRAJECTORY_POINT]
        empty = np.zeros(0)
        pts = [P(positions=np.asarray(p, float), velocities=empty, accelerations=empty, effort=empty,
                 time_from_start=D(sec=int(round(tf * 1e9)) // 10**9, nanosec=int(round(tf * 1e9)) % 10**9))
               for tf, p in zip(m.times, m.positions)]
        return TRAJECTORY, T[TRAJECTORY](header=header, joint_names=list(m.joint_names), points=pts), log
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    if isinstance(m, ImuMessage):
        x, y, z, w = m.orientation
        cov = np.zeros(9)
        msg = T[IMU](header=header, orientation=Q(x=x, y=y, z=z, w=w), orientation_covariance=cov,
                     angular_velocity=V3(*m.angular_velocity), angular_velocity_covariance=cov,
                     linear_acceleration=V3(*m.linear_acceleration), linear_acceleration_covariance=cov)
        return IMU, msg, log
    wr = T["geometry_msgs/msg/Wrench"](force=V3(*m.force), torque=V3(*m.torque))
    return WRENCH, T[WRENCH](header=header, wrench=wr), log


def _write_into(tmp: Path, kind: str, topics: Mapping[str, Sequence[BagMessage]]) -> None:
    """Write a new bag at ``tmp`` (``kind``: ``ros1``, ``mcap`` or ``sqlite3``: a rosbag2 folder)."""
    ros1 = kind == "ros1"
    ts = _typestore(ros1)
    items = []
    for topic, msgs in topics.items():
        for i, m in enumerate(msgs):
            items.append((topic, i, *_ros_message(ts, m, ros1)))
    if ros1:
        from rosbags.rosbag1 import Writer as Writer1
        with Writer1(tmp) as w1:
            conns1 = {tp: w1.add_connection(tp, next(x[2] for x in items if x[0] == tp), typestore=ts)
                      for tp in topics if topics[tp]}
            for tp, _i, typ, msg, log in items:  # written in the given order (out-of-order messages stay so)
                w1.write(conns1[tp], log, ts.serialize_ros1(msg, typ))
        return
    from rosbags.rosbag2 import StoragePlugin, Writer
    plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
    with Writer(tmp, version=9, storage_plugin=plugin) as w:
        conns = {tp: w.add_connection(tp, next(x[2] for x in items if x[0] == tp), typestore=ts)
                 for tp in topics if topics[tp]}
        for tp, _i, typ, msg, log in items:
            w.write(conns[tp], log, ts.serialize_cdr(msg, typ))


def write_messages(path: str | os.PathLike, topics: Mapping[str, Sequence[BagMessage]], *, force: bool = False,
                   storage: str = "mcap") -> Path:
    """Write messages as a bag: ``.bag`` a ROS 1 bag, ``.mcap``/``.db3`` a ROS 2 storage file, any other path a
    rosbag2 folder (``storage``: ``mcap`` or ``sqlite3``). Messages are written in the order given (each
    topic's list, topics one after the other), with their log times.

    Written to a temporary sibling and renamed. An existing file or folder is never replaced unless ``force``
    (a bag is a recording, an input of other commands: :func:`~symoro_gen.atomic.check_replaceable`).

    Raises
    ------
    OutputError
        ``path`` exists and ``force`` is false (nothing written).
    DataFileError
        The ``rosbags`` library is missing (the ``bags`` extra).
    """
    out = Path(path)
    suffix = out.suffix.lower()
    # a path without a storage file's suffix is a rosbag2 folder (a folder output)
    check_replaceable(out, force, owner="never", label="bag", folder=suffix not in (".bag", ".mcap", ".db3"))
    _rosbags(str(out))
    kind = {".bag": "ros1", ".mcap": "mcap", ".db3": "sqlite3"}.get(suffix, storage)
    if kind not in ("ros1", "mcap", "sqlite3"):
        raise ValueError(f"storage {storage!r}: expected 'mcap' or 'sqlite3'")
    out.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        if kind == "ros1":
            made = work / out.name
            _write_into(made, kind, topics)
        else:
            folder = work / "bag"
            _write_into(folder, kind, topics)
            made = folder
            if suffix in (".mcap", ".db3"):  # the storage file alone (read without metadata.yaml)
                made = next(folder.glob(f"*{suffix}"))
        if out.is_dir() and not out.is_symlink():
            shutil.rmtree(out)
        elif out.exists() or out.is_symlink():
            out.unlink()
        os.replace(made, out)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return out


def write_bag(trajectory: Trajectory, path: str | os.PathLike, joint_names: Sequence[str], *,
              topic: str = "/joint_states", force: bool = False, velocity: bool = True, effort: bool = True,
              reference=None, reference_topic: str = "/reference", storage: str = "mcap") -> Path:
    """Write a recording as a bag of ``sensor_msgs/JointState`` messages on ``topic`` (one per sample,
    stamped ``t``), read back by :func:`read_bag`; ``reference`` (N, n) positions as JointStates on
    ``reference_topic``. Format by suffix, no-clobber rule and errors: :func:`write_messages`."""
    topics: dict[str, Sequence[BagMessage]] = {topic: joint_state_messages(trajectory, joint_names,
                                                                           velocity=velocity, effort=effort)}
    if reference is not None:
        topics[reference_topic] = joint_state_messages(trajectory, joint_names, velocity=False, effort=False,
                                                       positions=reference)
    return write_messages(path, topics, force=force, storage=storage)
