"""What ``identify``'s assembly of 1 h of 7-joint 1 kHz data costs, before and after the assembly engine, against
the fleet's per-log kernel measured in the same run.

One hour (``SYMORO_BENCH_KERNEL_HOURS``) of simulated LWR4 data at 1 kHz (3.6 M samples, noise on q and tau,
the simulation of ``bench/bench_fleet.py``) is written once as an uncompressed ``.npz`` and memory-mapped.
For each code tree (``--before``: the ``main`` branch exported by ``git archive`` unless a folder is given;
``--after``: this checkout) and each of

* ``assemble``: ``observations.assemble(model, log, AssemblyOptions())``, exactly as ``identify`` calls it
  (the filters' rule inside, the full-rate filtered signals kept for ``rel_err_raw``, the whole ``W``);
* ``streamed``: ``accumulate(iter_chunks(model, log, AssemblyOptions(keep_signals=False)))``, the assembly in
  bounded memory (the per-joint QR factors of the same rows);
* ``fleet``: ``fleet.fused.fold_trajectory(model, log)``, the fleet's kernel (the reference),

a fresh process measures CPU time (best of ``SYMORO_BENCH_KERNEL_RUNS`` runs, 1 by default; the machine is
shared, CPU time is the figure that does not depend on its load), wall time and peak resident memory above
the start. Printed: the figures, the ratio of each assembly to the fleet kernel of the same tree, and the
speed-up of the assembly from ``--before`` to ``--after``.

Run: ``python bench/bench_engine_assembly.py [--before DIR|REF] [--after DIR] [--what assemble streamed fleet]``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

from benchlog import simulate_lwr4_log

ROOT = Path(__file__).resolve().parents[1]
FS = 1000.0
HOURS = float(os.environ.get("SYMORO_BENCH_KERNEL_HOURS", "1.0"))
RUNS = int(os.environ.get("SYMORO_BENCH_KERNEL_RUNS", "1"))

#: the measurement, run in a fresh process with PYTHONPATH set to the tree under test
_CHILD = r"""
import json, sys, time
from pathlib import Path
import numpy as np

def peak_mb():
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")

path, what, runs = sys.argv[1], sys.argv[2], int(sys.argv[3])
from symoro_gen import load_model
from symoro_gen.observations import AssemblyOptions, assemble, iter_chunks
from symoro_gen.identification.accumulate import accumulate
from symoro_gen.fleet.fused import fold_trajectory
from symoro_gen.preprocessing.trajectory import Trajectory

m = load_model("lwr4")
z = np.zeros((1, 7))
m.regressor(z, z, z)                                   # the C library loaded: not timed
small = Trajectory(t=np.arange(20000) * 1e-3, q=np.sin(np.arange(20000)[:, None] * 1e-3 * np.arange(1, 8)),
                   tau=np.zeros((20000, 7)), source="warm-up")
fold_trajectory(m, small)                              # compiled helpers built, column map cached: not timed
assemble(m, small, AssemblyOptions(), progress=False)
with np.load(path, mmap_mode="r") as f:
    tr = Trajectory(t=f["times"], q=f["positions"], tau=f["torques"], source=path)
    rss0 = peak_mb()
    best = None
    for _ in range(runs):
        t0, c0 = time.perf_counter(), time.process_time()
        if what == "assemble":
            asm = assemble(m, tr, AssemblyOptions(), progress=False)
            rows, st = asm.system.Y.size, asm.experiments[0].settings
            del asm
        elif what == "streamed":
            reps = []
            acc = accumulate(iter_chunks(m, tr, AssemblyOptions(keep_signals=False), on_experiment=reps.append,
                                         progress=False))
            rows, st = acc.n_rows, reps[0].settings
        else:
            acc = fold_trajectory(m, tr)
            rows, st = acc.n_rows, None
        cpu, wall = time.process_time() - c0, time.perf_counter() - t0
        if best is None or cpu < best[0]:
            best = (cpu, wall)
    print(json.dumps({"cpu": best[0], "wall": best[1], "rss": peak_mb() - rss0, "rows": int(rows),
                      "n_d": None if st is None else int(st.n_d),
                      "cutoff": None if st is None else float(st.cutoff_hz), "samples": int(tr.n_samples)}))
"""


def simulate_hour(path: Path) -> None:
    """HOURS of simulated LWR4 data at 1 kHz (:func:`benchlog.simulate_lwr4_log`, the log of
    ``bench/bench_fleet.py``)."""
    simulate_lwr4_log(path, HOURS * 3600, FS)


def _export(ref: str, dest: Path) -> Path:
    tar = dest / "src.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", "-o", str(tar), ref], check=True)
    with tarfile.open(tar) as t:
        t.extractall(dest / "tree", filter="data")
    return dest / "tree"


def _measure(tree: Path, log: Path, what: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": os.environ.get("OPENBLAS_NUM_THREADS", "1")}
    r = subprocess.run([sys.executable, "-c", _CHILD, str(log), what, str(RUNS)], env=env, cwd=tree,
                       capture_output=True, text=True, check=False)
    if r.returncode != 0:
        raise SystemExit(f"{what} failed in {tree}:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", default="main", help="a code folder or a git ref of this repository (default: main)")
    ap.add_argument("--after", default=str(ROOT), help="a code folder (default: this checkout)")
    ap.add_argument("--what", nargs="+", default=["assemble", "streamed", "fleet"],
                    choices=["assemble", "streamed", "fleet"])
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        log = tmp / "hour.npz"
        simulate_hour(log)
        trees = {"before": Path(a.before) if Path(a.before).is_dir() else _export(a.before, tmp),
                 "after": Path(a.after)}
        res: dict[str, dict[str, dict]] = {}
        for label, tree in trees.items():
            res[label] = {}
            for what in a.what:
                r = res[label][what] = _measure(tree, log, what)
                print(f"  {label:6s} {what:8s}: {r['cpu']:6.1f} s CPU, {r['wall']:6.1f} s wall, peak RSS "
                      f"+{r['rss']:5.0f} MB, {r['samples']:,} samples -> {r['rows']:,} rows (n_d {r['n_d']}, "
                      f"cut-off {r['cutoff']})", flush=True)
            fl = res[label].get("fleet")
            if fl:
                for what in ("assemble", "streamed"):
                    if what in res[label]:
                        print(f"  {label:6s} {what} / fleet kernel (same tree, same run): "
                              f"x{res[label][what]['cpu'] / fl['cpu']:.2f} CPU")
        for what in ("assemble", "streamed", "fleet"):
            if what in res["before"] and what in res["after"]:
                b, f = res["before"][what]["cpu"], res["after"][what]["cpu"]
                print(f"[engine assembly] {what}: {b:.1f} s CPU before, {f:.1f} s after (x{b / f:.2f} faster); "
                      f"{HOURS:g} h of 7-joint 1 kHz data; os.getloadavg() = {os.getloadavg()[0]:.1f} on "
                      f"{os.cpu_count()} cores")


if __name__ == "__main__":
    main()
