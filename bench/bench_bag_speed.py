"""Reading speed of ROS bags against CSV.

A 60 s recording of 7 joints at 1 kHz (60 000 ``sensor_msgs/JointState`` messages: 7 names, positions,
velocities, efforts; smooth sums of sines) is written as a ROS 2 MCAP bag, a ROS 2 sqlite3 bag and a ROS 1
bag (:func:`symoro_gen.preprocessing.readers.bag.write_bag`), and as the CSV of the same samples
(:func:`symoro_gen.simulate.write_recording_csv`). Each is read through the front door
(:func:`symoro_gen.preprocessing.readers.read_recording`, joints matched by name), best of RUNS; printed:
messages per second, and the time of each bag over the time of the CSV (the ratio: how much slower a bag
is to read than the same data as text). The samples read from each bag are checked equal to the CSV's.
Beside each bag, the floor and the former way: iterating over its raw messages alone (the library's
``AnyReader.messages``), and deserializing every message with the library (``AnyReader.deserialize``, one
Python object per message, as the reader did before it read the fields column-wise at fixed offsets).

Sizes: SYMORO_BENCH_BAG_SECONDS (60), SYMORO_BENCH_BAG_RUNS (2). Run: ``python bench/bench_bag_speed.py``
(or ``make bench``).
"""
from __future__ import annotations

import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SECONDS = float(os.environ.get("SYMORO_BENCH_BAG_SECONDS", "60"))
RUNS = int(os.environ.get("SYMORO_BENCH_BAG_RUNS", "2"))
FS = 1000.0
N = 7
NAMES = tuple(f"joint_a{j}" for j in range(1, N + 1))


def recording():
    """SECONDS of 7 joints at FS: positions, velocities (their derivatives) and torques, sums of sines."""
    from symoro_gen.preprocessing.trajectory import Trajectory

    rng = np.random.default_rng(0)
    t = np.round(np.arange(int(SECONDS * FS)) / FS * 1e9) * 1e-9  # integer nanoseconds, as bag stamps
    f = rng.uniform(0.1, 1.0, (2, N))
    ph = rng.uniform(0, 2 * np.pi, (2, N))
    q = 0.8 * np.sin(2 * np.pi * f[0] * t[:, None] + ph[0])
    dq = 0.8 * 2 * np.pi * f[0] * np.cos(2 * np.pi * f[0] * t[:, None] + ph[0])
    tau = 20.0 * np.sin(2 * np.pi * f[1] * t[:, None] + ph[1])
    return Trajectory(t=t, q=q, tau=tau, dq=dq, source="bench")


def best(fn, runs=RUNS):
    out, times = None, []
    for _ in range(runs):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return min(times), out


def library_times(path: Path) -> tuple[float, float]:
    """(iterating over the raw messages, iterating and deserializing each one) [s] with rosbags alone."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS1_NOETIC if path.suffix == ".bag" else Stores.ROS2_HUMBLE)

    def run(deserialize: bool) -> int:
        k = 0
        with AnyReader([path], default_typestore=store) as r:
            for c, _, raw in r.messages(connections=r.connections):
                if deserialize:
                    r.deserialize(raw, c.msgtype)
                k += 1
        return k

    return best(lambda: run(False))[0], best(lambda: run(True))[0]


def main() -> None:
    from symoro_gen.preprocessing.readers import LogFormat, read_recording
    from symoro_gen.preprocessing.readers.bag import write_bag
    from symoro_gen.simulate import write_recording_csv

    tr = recording()
    fmt = LogFormat(joint_names=NAMES)
    print(f"{SECONDS:g} s of {N} joints at {FS:g} Hz: {tr.n_samples} samples (best of {RUNS} runs)")
    with tempfile.TemporaryDirectory() as d:
        csv = Path(d) / "rec.csv"
        write_recording_csv(csv, tr)
        t_csv, ((ref,), _) = best(lambda: read_recording(csv, n_joints=N))
        print(f"  CSV            {t_csv:7.2f} s  {tr.n_samples / t_csv:10.0f} samples/s  (reference)")
        for name in ("rec.mcap", "rec.db3", "rec.bag"):
            p = Path(d) / name
            t0 = time.perf_counter()
            write_bag(tr, p, NAMES)
            t_w = time.perf_counter() - t0
            t_b, ((got,), rep) = best(lambda p=p: read_recording(p, fmt, n_joints=N))
            np.testing.assert_array_equal(got.q, tr.q)
            np.testing.assert_allclose(got.q, ref.q, rtol=0, atol=1e-9)  # the CSV holds 10+ digits
            np.testing.assert_array_equal(got.tau, tr.tau)
            kind = {".mcap": "ROS 2 MCAP", ".db3": "ROS 2 sqlite3", ".bag": "ROS 1"}[p.suffix]
            t_it, t_de = library_times(p)
            print(f"  {kind:14s} {t_b:7.2f} s  {rep.rows_read / t_b:10.0f} messages/s  {t_b / t_csv:5.2f} x the CSV"
                  f"  (written in {t_w:.1f} s; raw messages alone {t_it:.2f} s, deserialized one by one by the "
                  f"library {t_de:.2f} s = {t_de / t_csv:.2f} x the CSV)")


if __name__ == "__main__":
    main()
