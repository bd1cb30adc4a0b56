"""Generator benchmarks.

Prints each figure and its ratio to its anchor or target:
* generation end to end for every robot of robots/ (parse, Newton-Euler, base parameters, emit NumPy +
  CasADi + C source; in process, after imports): wall and CPU seconds, base count, operation counts;
* generation time against the number of frames, 2..14, for two families of serial chains with the
  14 parameters per joint (random non-zero d and r): "industrial" (alpha in {0, -pi/2, pi/2}, as in
  the robots people build) and "general" (arbitrary alpha), with the exponent p of t ~ n^p fitted by
  least squares on log t against log n; targets: any 14-frame structure <= 5 s, LWR4 <= 0.5 s
  (OpenSYMORO's range), growth <= n^1.5;
* the LWR4 with all 14 parameters per joint, as before:
  compiling the C kernels (`build()`, done once; importing compiles nothing);
  anchors: SymPyBotics 3.2 s, OpenSYMORO 0.4-0.6 s (measured on this machine class; not re-run);
* operation count of the emitted base regressor; anchors SymPyBotics 730 mul / 458 add,
  OpenSYMORO 801 / 456;
* batch evaluation of the base regressor for 100,000 samples from Python, against
  Pinocchio's computeJointTorqueRegressor timed in the same run.
Targets: <= 2 s, <= 600 multiplications, <= 0.5 us per sample.

Usage: ``python bench/bench_generator.py [--frames 2-14] [--families industrial,general] [--no-eval]``
(``--no-eval`` skips the C build and the evaluation timings). The machine is shared: CPU seconds
(``time.process_time``) are printed beside wall seconds and are the figures to compare.
"""
from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

T0 = time.perf_counter()
from symoro_gen import load_model
from symoro_gen.description import parse_robot_text
from symoro_gen.emit.package import emit_robot

IMPORT_S = time.perf_counter() - T0
N_SAMPLES = 100_000
PIN_ANCHOR_US = 2.8


def lwr4_full_text() -> str:
    text = (ROOT / "robots" / "lwr4.toml").read_text()
    return text.replace('drive = ["FV", "FS", "OFF"]', 'drive = ["IA", "FV", "FS", "OFF"]').replace(
        'name = "lwr4"', 'name = "lwr4_full"'
    )


def best_of(fn, repeat=3):
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return min(ts)


def chain_text(n: int, family: str, seed: int = 0) -> str:
    """A serial chain of ``n`` revolute frames with the 14 parameters per joint, as a robot file.

    d and r: random, non-zero, in mm steps (|x| in [0.05, 0.5] m). alpha: ``industrial`` cycles through
    0, -pi/2, pi/2 (after the first frame); ``general``: arbitrary, |alpha| in [0.2, 1.3] rad in mrad steps.
    """
    rng = np.random.default_rng(seed)
    lines = [f'name = "{family}{n}"', "gravity = [0, 0, -9.81]", 'drive = ["IA", "FV", "FS", "OFF"]', ""]
    special = ("0", '"-pi/2"', '"pi/2"')
    for j in range(1, n + 1):
        d, r = (float(rng.integers(50, 500)) / 1000 * float(rng.choice([-1, 1])) for _ in range(2))
        if family == "industrial":
            alpha = special[j % 3] if j > 1 else "0"
        else:
            alpha = repr(float(rng.integers(200, 1300)) / 1000 * float(rng.choice([-1, 1])))
        lines += ["[[frames]]", f"j = {j}", f"ant = {j - 1}", "sigma = 0", f"alpha = {alpha}", f"d = {d!r}",
                  'theta = "q"', f"r = {r!r}", ""]
    return "\n".join(lines)


def timed(fn):
    """(wall s, CPU s, result) of one call."""
    w, c = time.perf_counter(), time.process_time()
    res = fn()
    return time.perf_counter() - w, time.process_time() - c, res


def generate_text(text: str, file: str, out: Path):
    return emit_robot(parse_robot_text(text, file=file), out, force=True)


def fit_exponent(ns, ts) -> float:
    """p of t ~ c n^p, least squares on log t against log n (nan with fewer than two points)."""
    if len(ns) < 2:
        return float("nan")
    return float(np.polyfit(np.log(np.asarray(ns, float)), np.log(np.asarray(ts, float)), 1)[0])


def robots_table(out: Path) -> None:
    print("[generation per robot] robots/*.toml, in process after imports (best of 3; CPU s beside wall s)")
    print(f"  {'robot':<8} {'wall s':>7} {'CPU s':>7} {'std':>4} {'base':>4} {'mul':>5} {'add':>5} {'func':>4}")
    for f in sorted((ROOT / "robots").glob("*.toml")):
        text = f.read_text()
        runs = [timed(lambda text=text, f=f: generate_text(text, f.name, out)) for _ in range(3)]
        w, c = min(r[0] for r in runs), min(r[1] for r in runs)
        em = runs[-1][2]
        o = em.base_ops
        note = f"  (target <= 0.5 s: {'met' if c <= 0.5 else 'NOT met'})" if f.stem == "lwr4" else ""
        print(f"  {f.stem:<8} {w:7.2f} {c:7.2f} {em.n_standard:4d} {em.n_base:4d} {o.mul + o.div:5d} {o.add:5d} {o.func:4d}{note}")


def scaling(out: Path, frames: list[int], families: list[str]) -> None:
    print(f"[scaling] generation time against the number of frames ({frames[0]}..{frames[-1]}), one run each; "
          "targets: 14 frames <= 5 s, growth <= n^1.5")
    for fam in families:
        ns, cpu, ops = [], [], []
        print(f"  {fam}: {'n':>3} {'wall s':>7} {'CPU s':>7} {'base':>4} {'mul':>6} {'add':>6}")
        for n in frames:
            w, c, em = timed(lambda n=n, fam=fam: generate_text(chain_text(n, fam), f"{fam}{n}.toml", out))
            ns.append(n)
            cpu.append(c)
            o = em.base_ops
            ops.append(o.mul + o.div + o.add)
            print(f"  {'':{len(fam)}}  {n:3d} {w:7.2f} {c:7.2f} {em.n_base:4d} {o.mul + o.div:6d} {o.add:6d}", flush=True)
        p_all = fit_exponent(ns, cpu)
        tail = [k for k, n in enumerate(ns) if n >= 6]
        p_tail = fit_exponent([ns[k] for k in tail], [cpu[k] for k in tail])
        largest = cpu[-1]
        print(f"  {fam}: fitted exponent (CPU s, log-log least squares) {p_all:.2f} over n = {ns[0]}..{ns[-1]}, "
              f"{p_tail:.2f} over n >= 6 (target <= 1.5: {'met' if p_all <= 1.5 else 'NOT met'}); "
              f"{ns[-1]} frames: {largest:.2f} s CPU (target <= 5 s: {'met' if largest <= 5 else 'NOT met'})")
        print(f"  {fam}: the emitted base regressor itself grows as n^{fit_exponent(ns, ops):.2f} (operations, "
              f"{ns[0]}..{ns[-1]}); n^{fit_exponent([ns[k] for k in tail], [ops[k] for k in tail]):.2f} over n >= 6: "
              "writing it out is a floor for the time's growth")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", default="2-14", help="range of frame counts for the scaling, e.g. 2-14")
    ap.add_argument("--families", default="industrial,general")
    ap.add_argument("--no-eval", action="store_true", help="skip the C build and the evaluation timings")
    args = ap.parse_args(argv)
    lo, hi = (int(x) for x in args.frames.split("-"))
    out = Path(tempfile.mkdtemp(prefix="symoro_bench_"))
    print(f"imports {IMPORT_S:.2f} s; load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    robots_table(out)
    scaling(out, list(range(lo, hi + 1)), [f for f in args.families.split(",") if f])
    if args.no_eval:
        return 0
    text = lwr4_full_text()
    results = {}

    def gen():
        robot = parse_robot_text(text, file="lwr4_full.toml")
        return emit_robot(robot, out)

    t_gen = best_of(gen, 3)
    em = gen()
    print(f"[generation] LWR4 with IA, {em.n_standard} standard -> {em.n_base} base parameters")
    print(f"  end to end (in process, after imports): {t_gen:.2f} s  (target <= 2 s; "
          f"ratio to SymPyBotics 3.2 s: {t_gen / 3.2:.2f}; to OpenSYMORO 0.5 s: {t_gen / 0.5:.2f}); imports {IMPORT_S:.2f} s")
    ops = em.base_ops
    print(f"[operations] base regressor: {ops.mul + ops.div} mul+div ({ops.mul} mul, {ops.div} div), {ops.add} add, "
          f"{ops.func} sin/cos/sign  (target <= 600; ratio to SymPyBotics 730: {(ops.mul + ops.div) / 730:.2f}, "
          f"to OpenSYMORO 801: {(ops.mul + ops.div) / 801:.2f})")
    results["gen_s"] = t_gen
    results["mul"] = ops.mul + ops.div

    m = load_model(out / "lwr4_full")
    t = time.perf_counter()
    built = m.build()  # importing compiled nothing: compile the C kernels now (symoro-gen build)
    print(f"[build] C kernels compiled in {time.perf_counter() - t:.1f} s -> {built.path.name} "
          f"({(out / 'lwr4_full' / 'regressor_lwr4_full.c').stat().st_size / 1e3:.0f} kB of C)")
    rng = np.random.default_rng(0)
    n = m.N_JOINTS
    q = rng.uniform(-np.pi, np.pi, (N_SAMPLES, n))
    dq = rng.normal(0, 1, (N_SAMPLES, n))
    ddq = rng.normal(0, 3, (N_SAMPLES, n))
    buf = np.empty((N_SAMPLES, n, len(m.BASE_NAMES)))
    m.regressor(q[:10], dq[:10], ddq[:10])
    t_out = best_of(lambda: m.regressor(q, dq, ddq, out=buf))
    t_alloc = best_of(lambda: m.regressor(q, dq, ddq))

    # Pinocchio reference, same robot, same states, one call per sample from Python
    sys.path.insert(0, str(ROOT / "tests"))
    import pinocchio as pin
    from oracles.pinocchio_model import build_pinocchio_model

    robot = parse_robot_text(text, file="lwr4_full.toml")
    chi = np.abs(rng.normal(size=len(robot.standard_names)))
    pmodel, pdata = build_pinocchio_model(robot, chi)[:2]
    Np = 20_000
    qs, dqs, ddqs = q[:Np].copy(), dq[:Np].copy(), ddq[:Np].copy()

    def pin_loop():
        for k in range(Np):
            pin.computeJointTorqueRegressor(pmodel, pdata, qs[k], dqs[k], ddqs[k])

    t_pin = best_of(pin_loop, 2) / Np * N_SAMPLES
    us = lambda t: t / N_SAMPLES * 1e6  # noqa: E731
    print(f"[evaluation] base regressor, {N_SAMPLES} samples, backend {m.BACKEND}:")
    print(f"  into a preallocated array: {us(t_out):.3f} us/sample; allocating the (N, n, nb) result: {us(t_alloc):.3f} us/sample"
          f"  (target <= 0.5)")
    print(f"  Pinocchio computeJointTorqueRegressor, same run: {us(t_pin):.3f} us/sample -> ratio {t_out / t_pin:.3f} "
          f"(preallocated), {t_alloc / t_pin:.3f} (allocating)")
    # the machine is shared: express the figure on the scale of the Pinocchio anchor (2.8 us/sample here when quiet)
    norm = t_out / t_pin * PIN_ANCHOR_US
    print(f"  normalised by the same-run Pinocchio time to its 2.8 us anchor: {norm:.3f} us/sample (target <= 0.5)")
    results["eval_us"] = norm
    try:
        print(f"  load average during the run: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    except OSError:
        pass
    ok = t_gen <= 2.0 and results["mul"] <= 600 and results["eval_us"] <= 0.5
    print(f"[generator targets] {'met' if ok else 'NOT met'} (evaluation judged on the same-run Pinocchio ratio; "
          f"absolute figure {us(t_out):.3f} us/sample {'<=' if us(t_out) <= 0.5 else '>'} 0.5)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
