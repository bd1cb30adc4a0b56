"""The plain expert model of issue 10 against the current ``diagnose`` loop, on the real recordings.

For each recording of ``../shared/data`` (LWR4: identify on files 1 and 3, validate on file 2; TX40: the
split CSVs through the drive chain of ``robots/tx40.toml``, last 30 % held out; LBR Med 7:
``measurements.csv`` read with numpy at dt = 0.01 s, model imported from ``urdf/med7dock.urdf`` and built
in memory, last 30 % held out) it prints, per joint, the validation relative error norms
``||rho_j|| / ||Y_j||`` of

* the declared model fitted by LS ("declared", diagnose's "before"),
* the expert model: declared base parameters + Fc tanh(dq/v) (v by time-blocked CV) + Fv dq + offset,
* the declared model with the friction law of each joint chosen by time-blocked CV
  (:func:`symoro_gen.diagnostics.friction.select_friction`; "declared+laws"),
* the loop's final model ("loop after"),

on the filtered, decimated system (``filt``) and, where available, at full rate against the raw measured
torque (``raw``; the loop's report has no raw metric yet: ``-``), then the share of the loop's final
identification residual that boosted trees predict out of fold (:mod:`symoro_gen.diagnostics.unexplained`).

Usage (from the project root)::

    PYTHONPATH=$PWD python bench/expert_vs_loop.py [--data ../shared/data] [--method ols|wls] [--only lwr4,tx40,med7]
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
from symoro_gen.diagnostics import diagnose
from symoro_gen.diagnostics.expert import (
    filtered_data,
    fit_declared,
    fit_expert,
    fit_linear,
)
from symoro_gen.diagnostics.friction import (
    friction_column_indices,
    replaced_friction_columns,
    select_friction,
    velocity_grid,
)
from symoro_gen.diagnostics.unexplained import (
    rows_to_samples,
    signal_matrix,
    unexplained_structure,
)
from symoro_gen.preprocessing.filtering import estimate_dynamics_bandwidth
from symoro_gen.preprocessing.load import load_trajectories, load_trajectory
from symoro_gen.preprocessing.trajectory import Trajectory

HOLDOUT = 0.3
#: sign(dq) is smoothed at this many standard deviations of the velocity noise
V_FLOOR_NOISE = 3.0


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


def run(name, model, ident, valid, method: str) -> None:
    print(f"\n== {name}: {model.N_JOINTS} joints, {len(model.BASE_NAMES)} base parameters "
          f"({', '.join(n for n in model.BASE_NAMES if n[:2] in ('FS', 'FV', 'OF')) or 'no friction/offset columns'})")
    fdyn = max(estimate_dynamics_bandwidth(tr.q, 1.0 / tr.dt) for tr in ident)
    t0 = time.perf_counter()
    data = filtered_data(ident, dynamics_bandwidth_hz=fdyn)
    vdata = filtered_data(valid, dynamics_bandwidth_hz=fdyn)
    dec = fit_declared(model, data, method=method)
    ex = fit_expert(model, data, method=method)
    d_f, d_r = dec.errors(model, vdata)
    e_f, e_r = ex.errors(model, vdata)
    t_ex = time.perf_counter() - t0
    # friction-law selection per joint (item 1), on the declared model's decimated columns
    t0 = time.perf_counter()
    W = data.columns(lambda ex: np.asarray(model.regressor(ex.q, ex.dq, ex.ddq), float))
    blocks = data.blocks()
    choices = []
    for j in range(model.N_JOINTS):
        fs, fv = friction_column_indices(model.BASE_NAMES, j)
        if not fs or not fv:
            continue
        ch = select_friction(np.delete(W, fs + fv, axis=1), data.Y, data.joint, j, np.zeros(data.Y.size), blocks,
                             columns=lambda f, p, j=j: data.joint_columns(j, f, p),
                             v_grid=velocity_grid(np.concatenate([e.dq[:, j] for e in data.experiments])),
                             v_floor=V_FLOOR_NOISE * max(float(data.dq_noise[j]), 1e-9))
        choices.append(ch)
    _, cols = replaced_friction_columns(model, choices)
    fl = fit_linear(cols, data, method=method)
    l_f, l_r = fl.errors(vdata)
    t_fr = time.perf_counter() - t0
    t0 = time.perf_counter()
    rep = diagnose(model, ident, validation=valid, method=method, dynamics_bandwidth_hz=fdyn)
    t_loop = time.perf_counter() - t0
    st = data.experiments[0].settings
    print(f"filter: f_dyn {fdyn:.3g} Hz, cut-off {st.cutoff_hz:.3g} Hz, n_d {st.n_d}; "
          f"expert {t_ex:.1f} s, diagnose {t_loop:.1f} s ({len(rep.effects)} effect(s): "
          + ", ".join(f"{e.kind}{'' if e.joint is None else e.joint + 1}" for e in rep.effects) + ")")
    print("expert v [rad/s]: " + " ".join(f"{v:.3g}" for v in ex.v))
    print(f"friction laws by time-blocked CV ({t_fr:.1f} s):")
    for ch in choices:
        print("  " + ch.describe())
    raw_after = getattr(rep, "after_validation_rel_err_raw", None)
    rows = [
        ("declared (ours)      filt", d_f),
        ("diagnose before      filt", rep.before_validation_rel_err),
        ("expert               filt", e_f),
        ("declared+laws        filt", l_f),
        ("loop after           filt", rep.after_validation_rel_err),
        ("declared (ours)      raw ", d_r),
        ("expert               raw ", e_r),
        ("declared+laws        raw ", l_r),
        ("loop after           raw ", raw_after),
    ]
    n = model.N_JOINTS
    print(f"{'validation ||rho_j||/||Y_j||':28s}" + "".join(f"    j{j + 1:<3d}" for j in range(n)))
    for label, vals in rows:
        print(f"{label:28s}" + "".join(f" {fmt(None if vals is None else float(vals[j]))}" for j in range(n)))
    worse = [j + 1 for j in range(n) if rep.after_validation_rel_err[j] > e_f[j]]
    print(f"loop worse than the expert (filtered) on joints: {worse or 'none'}")
    unexplained(rep)


def unexplained(rep) -> None:
    """Structure left in the loop's final identification residual (issue 10 item 4), from the report's
    plot data (frame and residual of the last round)."""
    try:
        F = rep.plot_data["frame"]
        resid = rep.plot_data["round_resid"][-1][0]
    except (AttributeError, KeyError, IndexError, TypeError):
        print("unexplained: the report has no frame/residual to analyse")
        return
    t0 = time.perf_counter()
    E, e_exp, e_idx = rows_to_samples(resid, F.system.joint, F.row_experiment, F.row_index)
    S = F.samples()
    X, names = signal_matrix(S["q"], S["dq"], S["ddq"], S.get("tau_hat"), S["t"])
    out = unexplained_structure(E, X, names, experiment=e_exp, order=e_idx)
    print(f"structure left that no candidate explains ({time.perf_counter() - t0:.1f} s; out-of-fold R^2 of "
          "boosted trees on q, dq, ddq, tau_hat, t; threshold from block-permuted residuals):")
    for u in out:
        print(f"  joint {u.joint}: share {u.share:.2f} (threshold {u.threshold:.2f})"
              + (f"  FLAGGED, depends on {', '.join(u.signals)}" if u.flagged else ""))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=str(ROOT.parent / "shared" / "data"))
    ap.add_argument("--method", default="ols", choices=("ols", "wls"))
    ap.add_argument("--only", default="lwr4,tx40,med7")
    args = ap.parse_args(argv)
    data = Path(args.data)
    if not data.is_dir():
        print(f"no data folder {data}: nothing to compare", file=sys.stderr)
        return 2
    for key in args.only.split(","):
        run(*{"lwr4": lwr4, "tx40": tx40, "med7": med7}[key.strip()](data), method=args.method)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
