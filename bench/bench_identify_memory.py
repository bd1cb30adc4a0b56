"""Peak memory of ``identify`` on long recordings, against the size of the recording itself.

10 and 60 minutes (``SYMORO_BENCH_MEMORY_MINUTES``, e.g. ``"10 60"``) of simulated LWR4 data at 1 kHz (7 joints,
noise on q and tau, the motion of ``bench/bench_engine_assembly.py``) are written once as uncompressed ``.npz``
files. For each, a fresh process loads the recording into memory (``t``, ``q``, ``tau``: the anchor, its array
size measured in the same run), then runs ``symoro_gen.identify(model, recording, method=...)`` (WLS, the
default) and measures the memory ``identify`` needs above the loaded recording:

* ``tracemalloc``: the peak of the Python and NumPy allocations during the call (NumPy reports its buffers);
* ``RSS``: the peak resident set above the one before the call (``VmHWM`` after resetting it through
  ``/proc/self/clear_refs``; not reported where the kernel does not allow the reset).

Each figure is printed in MB and as a ratio to the recording's own array size; the target is a peak below
2x the recording (the recording itself may be in memory), i.e. a ratio of the extra memory below 1, that
does not grow with the length. ``--in-memory`` also measures the whole-system path (``identify`` before the
streaming: ``W`` and the full-rate signals kept) in the same run.

Run: ``python bench/bench_identify_memory.py [--minutes 10 60] [--method wls] [--in-memory]``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from benchlog import simulate_lwr4_log

ROOT = Path(__file__).resolve().parents[1]
FS = 1000.0

_CHILD = r"""
import json, sys, time, tracemalloc
from pathlib import Path
import numpy as np

def status(key):
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(key + ":"):
            return int(line.split()[1]) / 1024
    return float("nan")

def reset_peak():
    try:
        Path("/proc/self/clear_refs").write_text("5")
        return True
    except OSError:
        return False

path, method, streamed = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
import symoro_gen
import symoro_gen.workflows.identify
from symoro_gen.preprocessing.trajectory import Trajectory
wf = sys.modules["symoro_gen.workflows.identify"]
if not streamed:
    wf.streams = lambda opts: False
m = symoro_gen.load_model("lwr4")
n = 20000
small = Trajectory(t=np.arange(n) * 1e-3, q=np.sin(np.arange(n)[:, None] * 1e-3 * np.arange(1, 8)) * 0.5,
                   tau=np.cos(np.arange(n)[:, None] * 1e-3 * np.arange(1, 8)), source="warm-up")
try:
    symoro_gen.identify(m, small, method=method)     # libraries loaded, helpers compiled: not measured
except Exception:
    pass
with np.load(path) as f:
    tr = Trajectory(t=np.array(f["times"]), q=np.array(f["positions"]), tau=np.array(f["torques"]), source=path)
anchor = (tr.t.nbytes + tr.q.nbytes + tr.tau.nbytes) / 2 ** 20
rss0 = status("VmRSS")
can_reset = reset_peak()
tracemalloc.start()
t0, c0 = time.perf_counter(), time.process_time()
res = symoro_gen.identify(m, tr, method=method)
cpu, wall = time.process_time() - c0, time.perf_counter() - t0
_, peak = tracemalloc.get_traced_memory()
tracemalloc.stop()
rss = status("VmHWM") - rss0 if can_reset else float("nan")
d = res.to_dict()
print(json.dumps({"anchor_mb": anchor, "traced_mb": peak / 2 ** 20, "rss_mb": rss, "cpu": cpu, "wall": wall,
                  "samples": int(tr.n_samples), "rows": int(d["rel_err_basis"]["rows"]),
                  "values": d["parameters"]["values"], "rel_err_raw": d["rel_err_raw"]}))
"""


def simulate(path: Path, minutes: float) -> None:
    """``minutes`` of simulated LWR4 data at 1 kHz (:func:`benchlog.simulate_lwr4_log`, the motion of
    ``bench/bench_engine_assembly.py``)."""
    simulate_lwr4_log(path, minutes * 60, FS)


def measure(log: Path, method: str, streamed: bool) -> dict:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1")}
    r = subprocess.run([sys.executable, "-c", _CHILD, str(log), method, "1" if streamed else "0"], env=env,
                       cwd=ROOT, capture_output=True, text=True, check=False)
    if r.returncode != 0:
        raise SystemExit(f"identify failed on {log}:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    default = [float(x) for x in os.environ.get("SYMORO_BENCH_MEMORY_MINUTES", "10 60").split()]
    ap.add_argument("--minutes", nargs="+", type=float, default=default)
    ap.add_argument("--method", default="wls", choices=["ols", "wls"])
    ap.add_argument("--in-memory", action="store_true", help="also measure the whole-system path")
    a = ap.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as td:
        for minutes in a.minutes:
            log = Path(td) / f"log_{minutes:g}min.npz"
            simulate(log, minutes)
            paths = [("streamed", True)] + ([("in memory", False)] if a.in_memory else [])
            got = {}
            for label, streamed in paths:
                r = got[label] = measure(log, a.method, streamed)
                rows.append((minutes, label, r))
                print(f"  {minutes:4g} min, {label:9s}: recording {r['anchor_mb']:6.0f} MB; identify's peak above it: "
                      f"tracemalloc {r['traced_mb']:6.0f} MB (x{r['traced_mb'] / r['anchor_mb']:.2f} the recording), "
                      f"RSS {r['rss_mb']:6.0f} MB (x{r['rss_mb'] / r['anchor_mb']:.2f}); {r['cpu']:.1f} s CPU, "
                      f"{r['samples']:,} samples -> {r['rows']:,} rows", flush=True)
            if len(got) == 2:
                va, vb = (np.array(got[k]["values"]) for k in ("in memory", "streamed"))
                print(f"  {minutes:4g} min: streamed vs in memory, max |d chi| / max |chi| = "
                      f"{np.max(np.abs(va - vb)) / np.max(np.abs(va)):.1e}")
            log.unlink()
    streamed = [(mi, r) for mi, lab, r in rows if lab == "streamed"]
    if len(streamed) >= 2:
        (m0, r0), (m1, r1) = streamed[0], streamed[-1]
        print(f"[identify memory] {a.method}: peak above the recording x{r0['traced_mb'] / r0['anchor_mb']:.2f} "
              f"({m0:g} min) and x{r1['traced_mb'] / r1['anchor_mb']:.2f} ({m1:g} min) of the recording's size "
              f"(tracemalloc); {r1['traced_mb']:.0f} MB for {m1 / m0:g}x the data against {r0['traced_mb']:.0f} MB; "
              f"os.getloadavg() = {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
