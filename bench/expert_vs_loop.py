"""The plain expert model against the current ``diagnose`` loop, on the real recordings.

For each recording of ``../shared/data`` (LWR4: identify on files 1 and 3, validate on file 2; TX40: the
split CSVs through the drive chain of ``robots/tx40.toml``, last 30 % held out; LBR Med 7:
``measurements.csv`` read with numpy at dt = 0.01 s, model imported from ``urdf/med7dock.urdf`` and built
in memory, last 30 % held out) it prints, per joint, the validation relative error norms
``||rho_j|| / ||Y_j||`` of

* the declared model fitted by LS (diagnose's "before"),
* the expert model: declared base parameters + Fc tanh(dq/v) (v by time-blocked CV) + Fv dq + offset,
* the loop's final model (friction laws chosen, static in the rest segments of each joint - the share of
  samples at rest is printed - effects accepted and kept by the stability stage),

on the filtered, decimated system (``filt``) and at full rate against the raw measured torque (``raw``),
under OLS and WLS. "Worse" is decided per joint with :func:`symoro_gen.diagnostics.expert.no_worse`: the
loop is worse only when ``rel_loop^2 - rel_expert^2`` exceeds twice its standard error over 10 contiguous
time blocks of the validation data. It also prints the effects named under each method (they must be the
same) and the structure left that no candidate explains.

Usage (from the project root)::

    PYTHONPATH=$PWD python bench/expert_vs_loop.py [--data ../shared/data] [--method ols,wls] [--only lwr4,tx40,med7]
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import symoro_gen
from symoro_gen.description import load_robot, parse_robot_text
from symoro_gen.description.urdf import import_urdf
from symoro_gen.diagnostics import DiagnoseSettings, diagnose
from symoro_gen.diagnostics.expert import expert_residuals, filtered_data, fit_expert, no_worse
from symoro_gen.observations import AssemblyOptions
from symoro_gen.preprocessing.filtering import estimate_dynamics_bandwidth
from symoro_gen.preprocessing.readers import load_trajectories, load_trajectory
from symoro_gen.preprocessing.trajectory import Trajectory

HOLDOUT = 0.3


def split(tr: Trajectory, fraction: float = HOLDOUT) -> tuple[Trajectory, Trajectory]:
    """Leading part (identification) and trailing ``fraction`` (validation) of one recording."""
    k = round(tr.n_samples * (1.0 - fraction))
    parts = []
    for a, b in ((0, k), (k, tr.n_samples)):
        parts.append(Trajectory(t=tr.t[a:b], q=tr.q[a:b], tau=tr.tau[a:b], source=f"{tr.source}[rows {a + 1}-{b}]",
                                loaded=tr.loaded, meta=dict(tr.meta)))
    return parts[0], parts[1]


def lwr4(data: Path):
    d = data / "kuka_lwr4_flobaroid" / "data" / "KUKA" / "HW"
    tr = [load_trajectory(d / f"measurements_{i}.npz", n_joints=7) for i in (1, 2, 3)]
    return "KUKA LWR4 (files 1+3, validate 2)", symoro_gen.load_model("lwr4"), [tr[0], tr[2]], [tr[1]]


def tx40(data: Path):
    d = data / "staubli_tx40_figaroh" / "data"
    spec = f"q={d / 'pos_read_data.csv'},tau={d / 'curr_data.csv'},dt=0.0002"
    robot = load_robot("tx40")
    (tr,) = load_trajectories([spec], n_joints=robot.n_joints, drive_chain=robot.drive_chain)
    a, b = split(tr)
    return "Staubli TX40 (last 30 % held out)", symoro_gen.load_model("tx40"), [a], [b]


def med7(data: Path):
    from symoro_gen.emit.package import build_in_memory

    d = data / "kuka_lbr_med7_lbrstack"
    robot = parse_robot_text(import_urdf(d / "urdf" / "med7dock.urdf", name="med7"))
    model = build_in_memory(robot)
    # no time column: dt = 0.01 s (the authors' rate); q_0..q_6 then tau_0..tau_6
    arr = np.loadtxt(d / "data" / "measurements.csv", delimiter=",", skiprows=1)
    tr = Trajectory(t=0.01 * np.arange(arr.shape[0]), q=arr[:, 0:7], tau=arr[:, 7:14], source="measurements.csv")
    a, b = split(tr)
    return "KUKA LBR Med 7 (URDF import, last 30 % held out)", model, [a], [b]


def fmt(x) -> str:
    return "      -" if x is None else f"{x:7.3f}"


def run(name, model, ident, valid, methods) -> dict:
    """Expert model and the loop (each method of ``methods``) on one arm; prints the per-joint table and
    returns it (for the README)."""
    print(f"\n== {name}: {model.N_JOINTS} joints, {len(model.BASE_NAMES)} base parameters "
          f"({', '.join(n for n in model.BASE_NAMES if n[:2] in ('FS', 'FV', 'OF')) or 'no friction/offset columns'})")
    fdyn = max(estimate_dynamics_bandwidth(tr.q, 1.0 / tr.dt) for tr in ident)
    out = {}
    n = model.N_JOINTS
    for method in methods:
        t0 = time.perf_counter()
        data = filtered_data(ident, dynamics_bandwidth_hz=fdyn)
        vdata = filtered_data(valid, dynamics_bandwidth_hz=fdyn)
        ex = fit_expert(model, data, method=method)
        e_f, e_r = ex.errors(model, vdata)
        ex_filt, ex_raw = expert_residuals(model, ex, vdata)
        t_ex = time.perf_counter() - t0
        t0 = time.perf_counter()
        rep = diagnose(model, ident, DiagnoseSettings(method=method), validation=valid,
                       assembly=AssemblyOptions(dynamics_bandwidth_hz=fdyn))
        t_loop = time.perf_counter() - t0
        ok_f, d_f, se_f = no_worse(rep.plot_data["valid_filtered"], ex_filt, n)
        ok_r, d_r, se_r = no_worse(rep.plot_data["valid_raw"], ex_raw, n)
        effects = [(e.kind, None if e.joint is None else e.joint + 1, e.modulation) for e in rep.effects]
        print(f"\n-- method {method.upper()}: expert {t_ex:.1f} s (v = " + " ".join(f"{v:.3g}" for v in ex.v)
              + f" rad/s), diagnose {t_loop:.1f} s")
        for e in rep.effects:
            print(f"   {e.kind} j{'-' if e.joint is None else e.joint + 1}"
                  + (f" [{e.modulation}]" if e.modulation else "")
                  + (f" sel.freq {e.selection_frequency:.2f}" if e.selection_frequency is not None else "")
                  + f": {e.description or e.label}")
        for line in rep.settings.get("static_at_rest") or []:
            print(f"   static at rest: {line}")
        rows = [("declared (before)  filt", rep.before_validation_rel_err),
                ("expert             filt", e_f),
                ("loop (after)       filt", rep.after_validation_rel_err),
                ("declared (before)  raw ", rep.before_validation_rel_err_raw),
                ("expert             raw ", e_r),
                ("loop (after)       raw ", rep.after_validation_rel_err_raw)]
        print(f"{'validation ||rho_j||/||Y_j||':28s}" + "".join(f"    j{j + 1:<3d}" for j in range(n)))
        for label, vals in rows:
            print(f"{label:28s}" + "".join(f" {fmt(float(vals[j]))}" for j in range(n)))
        print("loop - expert (rel^2) filt / 2 SE: " + " ".join(f"{d:+.2e}/{2 * s:.1e}" for d, s in zip(d_f, se_f)))
        print("loop - expert (rel^2) raw  / 2 SE: " + " ".join(f"{d:+.2e}/{2 * s:.1e}" for d, s in zip(d_r, se_r)))
        worse_f = [j + 1 for j in range(n) if not ok_f[j]]
        worse_r = [j + 1 for j in range(n) if not ok_r[j]]
        print(f"loop worse than the expert beyond 2 SE: filtered {worse_f or 'none'}, raw {worse_r or 'none'}")
        un = rep.to_dict()["unexplained"]
        print("structure left that no candidate explains: "
              + ("; ".join(f"joint {u['joint']} share {u['share']:.2f} ({', '.join(u['signals'])})" for u in un)
                 or "none"))
        for w in rep.warnings:
            print("   warning: " + w[:300])
        out[method] = dict(rep=rep, expert=(e_f, e_r), ok=(ok_f, ok_r), effects=effects)
    if len(out) == 2:
        a, b = (out[m]["effects"] for m in methods)
        print(f"effects OLS: {a}\neffects WLS: {b}\nsame effects under OLS and WLS: {a == b}")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--method", default="ols,wls", help="ols, wls or ols,wls (both: the effect sets compared)")
    ap.add_argument("--only", default="lwr4,tx40,med7")
    args = ap.parse_args(argv)
    data = Path(args.data)
    if not data.is_dir():
        print(f"no data folder {data}: nothing to compare", file=sys.stderr)
        return 2
    for key in args.only.split(","):
        run(*{"lwr4": lwr4, "tx40": tx40, "med7": med7}[key.strip()](data), methods=args.method.split(","))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
