"""Benchmark: ``diagnose`` against ``identify`` on the same data (target: diagnose <= 10x identify's wall
time, peak RSS of diagnose <= 0.5 GB).

Two simulated recordings (as in ``bench/bench_diagnose.py``: random physical parameters, Fourier excitation,
noise on q and torque, effects the declared model lacks injected with :func:`symoro_gen.diagnostics.inject_effect`):

* ``rx90``: 150 s of 6-joint data at 100 Hz, Stribeck friction on joint 2 and a 10 ms torque lag on joint 1;
* ``lwr4``: 120 s of 7-joint data at 1 kHz (LWR-like friction), Stribeck friction on joint 2, a 10 ms torque
  lag on joint 1 and a position ripple on joint 6.

Each run (``identify`` with OLS, then ``diagnose`` with its defaults: every stage) is a fresh subprocess
that loads the recording from a temporary ``.npz``; its wall and CPU time are printed by the child and its
peak resident memory is read by the parent from ``resource.getrusage(RUSAGE_CHILDREN).ru_maxrss`` (one
intermediate process per run, so the figure is that run's own).

    PYTHONPATH=. python bench/bench_diagnose_speed.py [--case rx90 lwr4] [--scale 1.0] [--stages]
        [--commands [--anchor-tree DIR]]

``--scale`` shortens the recordings (e.g. 0.2 for a quick look). ``--stages`` also prints the CPU time of
each stage of ``diagnose``, the peak resident memory a stage raised (``ru_maxrss`` before and after each call:
the stage listed with the run's peak is where it is made), and its counts of model fits (a second diagnose run, with the stage functions of
:mod:`symoro_gen.diagnostics.core` wrapped by timers; nested stages are listed under their parent): the
out-of-fold least-squares solves (``BlockedLS.oof_residual``, one per candidate and fold set), the
friction-law stage's simulated-noise placebos and its law selections (the placebo's re-runs included), and
the unexplained stage's tree fits (``FoldFits.step``, one fold each), against the one least-squares solve of
``identify``.

``--commands`` also times the two commands as a user runs them (``python -m symoro_gen identify NAME
rec.npz --method ols`` and ``python -m symoro_gen diagnose NAME rec.npz``, interpreter start, imports, loading
and printed report included; wall time, best of ``--repeat`` runs each after one warm-up run that fills the
bytecode caches). ``--anchor-tree DIR`` runs ``identify`` from another checkout of the project (e.g. a
``git worktree`` of the commit the target was stated on), so the anchor is measured in the same run. CPU
time (user + system of the command's process) is printed beside the wall time: on a shared machine it is
the steadier of the two.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TARGET_RATIO = 10.0
TARGET_RSS_GB = 0.5
CASES = {
    # robot, seconds, rate [Hz], effects (kind, 0-based joint, parameters)
    "rx90": ("rx90", 150.0, 100.0, [("stribeck", 1, dict(Fst=0.5, vs=0.05)), ("time_delay", 0, dict(delay=0.01))]),
    "lwr4": ("lwr4", 120.0, 1000.0, [("stribeck", 1, dict(Fst=0.5, vs=0.05)), ("time_delay", 0, dict(delay=0.01)),
                                     ("position_ripple", 5, dict(amplitude=0.2, k=8))]),
}


def simulate(case: str, scale: float, path: Path, seed: int = 1) -> str:
    """Write the case's recording (t, q, tau) to ``path``; return a one-line description."""
    import symoro_gen
    from symoro_gen.description import load_robot
    from symoro_gen.diagnostics import inject_effect
    from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, true_torques

    name, seconds, rate, effects = CASES[case]
    seconds *= scale
    rng = np.random.default_rng(seed)
    model, robot = symoro_gen.load_model(name), load_robot(name)
    n = model.N_JOINTS
    t, q, dq, ddq = fourier_trajectory(n, seconds, 1.0 / rate, rng, base_frequency_hz=0.1)
    kw = dict(fs_range=(0.1, 0.5), fv_range=(0.1, 1.0)) if name == "lwr4" else {}
    chi = np.asarray(random_physical_parameters(robot, rng, **kw))
    tau = true_torques(model, q, dq, ddq, chi)
    for kind, j, params in effects:    # torque effects (the measured q stays the true one)
        _, tau = inject_effect(kind, t, q, dq, ddq, tau, joint=j, **params)
    qm = q + 1e-5 * rng.standard_normal(q.shape)
    tau = tau + 0.05 * rng.standard_normal(q.shape)
    np.savez(path, t=t, q=qm, tau=tau, name=name)
    return (f"{name}: {t.size} samples x {n} joints at {rate:g} Hz ({seconds:g} s), injected "
            + ", ".join(f"{k} joint {j + 1}" for k, j, _ in effects))


#: stage functions of ``symoro_gen.diagnostics.core`` timed by ``--stages`` (name shown, function name; the
#: indented ones run inside the one above them)
STAGES = (("assemble", "_stage_assemble"), ("friction laws", "_stage_friction"),
          ("  of which the law's noise placebo", "_law_beats_noise"), ("baseline", "_stage_baseline"),
          ("loop", "_stage_loop"), ("  of which scoring", "_stage_score"),
          ("    of which the composed library", "_score_composed_round"), ("stability", "_stage_stability"),
          ("report", "_stage_report"), ("  of which unexplained", "_unexplained"))
#: methods whose calls ``--stages`` counts (shown name, module, class, method)
COUNTED = (("out-of-fold LS solves", "symoro_gen.diagnostics.stability", "BlockedLS", "oof_residual"),
           ("noise placebos (<= 19 selections each)", "symoro_gen.diagnostics.stability", None,
            "simulated_noise_placebo"),
           ("friction-law selections", "symoro_gen.diagnostics.friction", None, "select_friction"),
           ("tree fits (one fold)", "symoro_gen.diagnostics.unexplained", "FoldFits", "step"))


def _instrument() -> tuple[dict, dict, dict]:
    """Wrap the stage functions (:data:`STAGES`) by CPU timers and the counted methods (:data:`COUNTED`) by
    counters; return the three dicts they fill (CPU per stage, calls, and for each stage during which the
    process's peak resident memory rose, the highest peak it reached: where the run's peak RSS is made)."""
    import functools
    import importlib
    import resource

    import symoro_gen.diagnostics.core as core

    cpu: dict = {}
    calls: dict = {}
    peak: dict = {}   # stage -> most of the process's peak resident memory [kB] a call of it raised

    def timer(name, fn):
        @functools.wraps(fn)
        def run(*a, **k):
            c, m = time.process_time(), resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            try:
                return fn(*a, **k)
            finally:
                cpu[name] = cpu.get(name, 0.0) + time.process_time() - c
                m2 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                if m2 > m:
                    peak[name] = max(peak.get(name, 0), m2)
        return run

    def counter(name, fn):
        @functools.wraps(fn)
        def run(*a, **k):
            calls[name] = calls.get(name, 0) + 1
            return fn(*a, **k)
        return run

    for shown, fn_name in STAGES:
        setattr(core, fn_name, timer(shown, getattr(core, fn_name)))
    for shown, mod, cls, meth in COUNTED:
        owner = getattr(importlib.import_module(mod), cls) if cls else importlib.import_module(mod)
        setattr(owner, meth, counter(shown, getattr(owner, meth)))
        if cls is None and hasattr(core, meth):   # a module function: also where core imported it
            setattr(core, meth, getattr(owner, meth))
    return cpu, calls, peak


def worker(command: str, path: str) -> None:
    """Run ``identify`` or ``diagnose`` on the recording; print a JSON line with the times."""
    import symoro_gen
    from symoro_gen.preprocessing.trajectory import Trajectory

    d = np.load(path)
    model = symoro_gen.load_model(str(d["name"]))
    tr = Trajectory(t=d["t"], q=d["q"], tau=d["tau"], source=f"simulated {d['name']}")
    w0, c0 = time.perf_counter(), time.process_time()
    info: dict = {}
    stages = None
    if command == "diagnose-stages":
        stages = _instrument()
        w0, c0 = time.perf_counter(), time.process_time()
    if command == "identify":
        symoro_gen.identify(model, tr, method="ols")
    else:
        rep = symoro_gen.diagnose(model, tr).residual
        info["effects"] = [e.label for e in rep.effects]
        info["unexplained"] = [u.joint for u in rep.unexplained if u.flagged]
    info.update(wall=time.perf_counter() - w0, cpu=time.process_time() - c0)
    if stages is not None:
        info.update(stage_cpu=stages[0], counts=stages[1], stage_peak_kb=stages[2])
    print("RESULT " + json.dumps(info))


def measured(command: str, path: str) -> dict:
    """``command`` in a child of a fresh intermediate process, which reports the child's peak RSS."""
    code = ("import resource, subprocess, sys, json\n"
            f"p = subprocess.run([sys.executable, {str(Path(__file__).resolve())!r}, '--worker', {command!r}, "
            f"{path!r}], capture_output=True, text=True)\n"
            "line = [x for x in p.stdout.splitlines() if x.startswith('RESULT ')]\n"
            "if p.returncode or not line:\n"
            "    sys.stderr.write(p.stderr); sys.exit(1)\n"
            "out = json.loads(line[-1][7:])\n"
            "out['maxrss_kb'] = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss\n"
            "print(json.dumps(out))\n")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=str(ROOT),
                       env={**__import__("os").environ, "PYTHONPATH": str(ROOT)})
    if p.returncode:
        raise RuntimeError(f"{command} failed:\n{p.stderr[-3000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def command_time(argv: list[str], tree: Path, repeat: int) -> tuple[float, float, float]:
    """Best wall and CPU time [s] of ``python -m symoro_gen *argv`` run from ``tree`` (after one warm-up run)
    and the largest peak RSS [GB] of those runs."""
    code = ("import resource, subprocess, sys, time\n"
            "w = time.perf_counter()\n"
            f"p = subprocess.run([sys.executable, '-m', 'symoro_gen', *{argv!r}], capture_output=True, text=True)\n"
            "w = time.perf_counter() - w\n"
            "if p.returncode not in (0, 3):\n"
            "    sys.stderr.write(p.stdout[-2000:] + p.stderr[-3000:]); sys.exit(1)\n"
            "u = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
            "print(w, u.ru_utime + u.ru_stime, u.ru_maxrss)\n")
    env = {**__import__("os").environ, "PYTHONPATH": str(tree), "OPENBLAS_NUM_THREADS": "1"}
    best, cpu, rss = float("inf"), float("inf"), 0.0
    for k in range(repeat + 1):
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=str(tree), env=env)
        if p.returncode:
            raise RuntimeError(f"{' '.join(argv)} failed in {tree}:\n{p.stderr[-3000:]}")
        w, c, kb = p.stdout.split()
        if k:                                   # the first run is the warm-up
            best, cpu, rss = min(best, float(w)), min(cpu, float(c)), max(rss, int(kb) / 2 ** 20)
    return best, cpu, rss


def commands(name: str, path: Path, anchor: Path, repeat: int) -> None:
    """Print the wall times of the two commands as a user runs them, and their ratio."""
    iw, ic, _ = command_time(["identify", name, str(path), "--method", "ols"], anchor, repeat)
    dw, dc, rss = command_time(["diagnose", name, str(path)], ROOT, repeat)
    where = "" if anchor.resolve() == ROOT else f" (from {anchor})"
    print(f"  commands: identify{where} {iw:.1f} s wall {ic:.1f} s CPU, diagnose {dw:.1f} s wall {dc:.1f} s CPU, "
          f"peak RSS {rss:.2f} GB; ratio {dw / iw:.1f} wall, {dc / ic:.1f} CPU (target <= {TARGET_RATIO:g})",
          flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--case", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--stages", action="store_true", help="also time each stage of diagnose (a second run)")
    ap.add_argument("--commands", action="store_true",
                    help="also time `python -m symoro_gen identify|diagnose` end to end, as a user runs them")
    ap.add_argument("--anchor-tree", type=Path, default=ROOT,
                    help="checkout whose `identify` is the anchor of --commands (default: this one)")
    ap.add_argument("--repeat", type=int, default=2, help="timed runs of each command (best kept)")
    ap.add_argument("--worker", nargs=2, metavar=("COMMAND", "NPZ"), help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.worker:
        worker(*a.worker)
        return 0
    ok = True
    with tempfile.TemporaryDirectory() as tmp:
        for case in a.case:
            path = Path(tmp) / f"{case}.npz"
            print(simulate(case, a.scale, path), flush=True)
            ident = measured("identify", str(path))
            diag = measured("diagnose", str(path))
            ratio = diag["wall"] / ident["wall"]
            rss = diag["maxrss_kb"] / 2 ** 20
            good = ratio <= TARGET_RATIO and rss <= TARGET_RSS_GB
            ok &= good
            print(f"  identify (ols): {ident['wall']:.1f} s wall, {ident['cpu']:.1f} s CPU, peak RSS "
                  f"{ident['maxrss_kb'] / 2 ** 20:.2f} GB")
            print(f"  diagnose:       {diag['wall']:.1f} s wall, {diag['cpu']:.1f} s CPU, peak RSS {rss:.2f} GB; "
                  f"effects {', '.join(diag['effects']) or 'none'}; unexplained joints {diag['unexplained'] or 'none'}")
            print(f"  ratio diagnose/identify (wall) {ratio:.1f} (target <= {TARGET_RATIO:g}), CPU ratio "
                  f"{diag['cpu'] / max(ident['cpu'], 1e-9):.1f}; peak RSS {rss:.2f} GB (target <= {TARGET_RSS_GB:g}) "
                  f"{'OK' if good else 'MISSED'}", flush=True)
            if a.commands:
                name = CASES[case][0]
                commands(name, path, a.anchor_tree, a.repeat)
            if a.stages:
                st = measured("diagnose-stages", str(path))
                print(f"  diagnose by stage ({st['cpu']:.1f} s CPU in all):")
                for shown, _ in STAGES:
                    if shown in st["stage_cpu"]:
                        pk = st["stage_peak_kb"].get(shown)
                        print(f"    {shown:<38} {st['stage_cpu'][shown]:7.1f} s CPU"
                              + (f", raised the peak RSS to {pk / 2 ** 20:.2f} GB" if pk else ""))
                print("  counts: " + ", ".join(f"{k} {v}" for k, v in st["counts"].items())
                      + "; identify: 1 least-squares solve", flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
