"""Benchmark: the ``excite`` command's default effort against the long settings it ran before.

``symoro-gen excite ROBOT -o t.csv --duration 20 --seed 1`` used to run 4 IPOPT starts (the best 4 of 40 random
feasible designs), each through two IPOPT stages of at most 200 iterations (the smooth criterion's powers 8 and
64) and 20 SDP iterations on the true cond: more than 15 minutes on a loaded 2-core machine. Those settings are
now ``--effort thorough``; the default, ``--effort quick``, runs one start through the first stage and a few SDPs.
This bench runs the same command both ways, one after the other in this process's machine (the thorough run is
the anchor), and prints their wall times and the ratio of their conds (target: the quick cond at most 10 %
above the thorough one). The commands run as ``python -m symoro_gen`` in a fresh process each, exactly as a
user types them (``--quiet``, the CSV and the JSON in a temporary folder).

    PYTHONPATH=. python bench/bench_excite_defaults.py [--robots lwr4 rx90] [--duration 20] [--seed 1]
        [--efforts thorough quick] [--keep DIR]

The load average (1 min) before and after each run is printed: the machine is shared, wall times are as
measured under it.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from symoro_gen.excite import EFFORTS

#: the quick cond may be at most this much above the thorough one
TARGET_RATIO = 1.10


def run(robot: str, effort: str, duration: float, seed: int, folder: Path) -> dict:
    """One ``symoro-gen excite`` run: its wall time, cond and starts (from its JSON)."""
    csv, js = folder / f"{robot}_{effort}.csv", folder / f"{robot}_{effort}.json"
    cmd = [sys.executable, "-m", "symoro_gen", "--quiet", "excite", robot, "-o", str(csv), "--duration", f"{duration:g}",
           "--seed", str(seed), "--effort", effort, "--json", str(js), "--force"]
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed ({r.returncode}):\n{r.stderr[-2000:]}")
    out = json.loads(js.read_text())
    return {"robot": robot, "effort": effort, "wall": wall, "cond": out["cond"], "limits_ok": out["limits_ok"],
            "starts": out["starts"], "load": (load0, os.getloadavg()[0]), "command": " ".join(cmd[2:])}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--robots", nargs="+", default=["lwr4"])
    ap.add_argument("--duration", type=float, default=20.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--efforts", nargs="+", choices=tuple(EFFORTS), default=["thorough", "quick"],
                    help="the first is the anchor the others' cond and time are compared with")
    ap.add_argument("--keep", type=Path, default=None, help="write the CSVs and JSONs here (default: a temporary folder)")
    a = ap.parse_args(argv)
    for name in a.efforts:
        print(f"--effort {name}: {EFFORTS[name]}")
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = a.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        for robot in a.robots:
            for effort in a.efforts:
                res = run(robot, effort, a.duration, a.seed, folder)
                rows.append(res)
                per = "; ".join(f"{st['cond_start']:.4g} -> " + "/".join(f"{c:.4g}" for c in st["cond_stages"]) +
                                (f" -> {st['cond']:.4g} ({st['refine_sdps']} SDPs)" if "refine_sdps" in st else "")
                                for st in res["starts"])
                print(f"{robot} --effort {effort}: cond {res['cond']:.4f}, {res['wall']:.1f} s wall, limits_ok "
                      f"{res['limits_ok']}, load {res['load'][0]:.1f} -> {res['load'][1]:.1f}; starts: {per}",
                      flush=True)
    ok = True
    print(f"\n| robot | effort | wall [s] | cond | cond / {a.efforts[0]} | time / {a.efforts[0]} | load (1 min) |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for robot in a.robots:
        mine = [r for r in rows if r["robot"] == robot]
        anchor = mine[0]
        for r in mine:
            ratio = r["cond"] / anchor["cond"]
            ok &= bool(ratio <= TARGET_RATIO and r["limits_ok"])
            print(f"| {robot} | {r['effort']} | {r['wall']:.1f} | {r['cond']:.4f} | {ratio:.3f} | "
                  f"{r['wall'] / anchor['wall']:.3f} | {r['load'][0]:.1f} -> {r['load'][1]:.1f} |")
    print(f"\ncond ratio target <= {TARGET_RATIO:g} (and every limit held): {'met' if ok else 'NOT met'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
