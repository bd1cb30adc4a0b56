"""Tree-structured robots: generation time and operation counts, and how the time grows.

The SDA10F dual-arm torso of ``robots/sda10f.toml`` (a waist carrying two 7-joint arms, 15 frames)
and the same torso cut to ``k`` joints per arm (1 + 2k frames, k = 1..7): each generated end to end
(parse, Newton-Euler, base parameters, emission of NumPy + C source + CasADi, as ``symoro-gen
generate``) into a scratch folder. Prints per size the standard / base parameter counts, the base
regressor's operation count, the generation time (CPU seconds of this process, best of
``SYMORO_BENCH_REPEAT`` runs, default 1: the machine is shared, CPU time is what compares), and the
exponent ``p`` of a least-squares fit ``time ~ frames^p`` over the sizes.

Run: ``python bench/bench_trees.py`` (part of ``make bench``).
"""
from __future__ import annotations

import os
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from symoro_gen.description import parse_robot_text
from symoro_gen.emit.package import emit_robot

REPEAT = int(os.environ.get("SYMORO_BENCH_REPEAT", "1"))


def torso_text(k: int) -> str:
    """``robots/sda10f.toml`` with k joints per arm (frames 1, 2..1+k, 9..8+k renumbered)."""
    text = (ROOT / "robots" / "sda10f.toml").read_text()
    head, *frames = re.split(r"\n(?=\[\[frames\]\])", text.split("\n[limits]")[0])
    keep = [1] + list(range(2, 2 + k)) + list(range(9, 9 + k))
    new = {old: i + 1 for i, old in enumerate(keep)}
    out = [head.replace('name = "sda10f"', f'name = "torso{k}"')]
    for fr in frames:
        j = int(re.search(r"^j = (\d+)$", fr, re.M).group(1))
        if j not in new:
            continue
        ant = int(re.search(r"^ant = (\d+)$", fr, re.M).group(1))
        fr = re.sub(r"^j = \d+$", f"j = {new[j]}", fr, flags=re.M)
        out.append(re.sub(r"^ant = \d+$", f"ant = {new.get(ant, 0)}", fr, flags=re.M))
    return "\n".join(out) + "\n"


def main() -> int:
    out = Path(tempfile.mkdtemp(prefix="symoro_bench_trees_"))
    rows = []
    print("[trees] SDA10F torso cut to k joints per arm; generation end to end (CPU s, this process)")
    print(f"  {'k':>2} {'frames':>6} {'std':>4} {'base':>4} {'mul':>5} {'add':>5} {'CPU s':>6} {'wall s':>6}")
    for k in range(1, 8):
        text = torso_text(k)
        best_cpu, best_wall, em = float("inf"), float("inf"), None
        for _ in range(REPEAT):
            c0, w0 = time.process_time(), time.perf_counter()
            em = emit_robot(parse_robot_text(text, file=f"torso{k}.toml"), out, force=True)
            best_cpu = min(best_cpu, time.process_time() - c0)
            best_wall = min(best_wall, time.perf_counter() - w0)
        assert em is not None
        n = 1 + 2 * k
        rows.append((n, best_cpu))
        print(f"  {k:>2} {n:>6} {em.n_standard:>4} {em.n_base:>4} {em.base_ops.mul + em.base_ops.div:>5} "
              f"{em.base_ops.add:>5} {best_cpu:>6.2f} {best_wall:>6.2f}")
    n, t = np.array(rows).T
    sel = n >= 5  # below, imports and fixed costs dominate
    p = np.polyfit(np.log(n[sel]), np.log(t[sel]), 1)[0]
    print(f"  growth: CPU time ~ frames^{p:.2f} (least squares over {int(n[sel].min())}..{int(n[sel].max())} frames)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
