"""Closed-loop benchmark, on the palletizer (robots/palletizer.toml: 6 tree joints, 4 actuated,
one parallelogram).

Prints:
* generation of the package (parse, Newton-Euler, tree base parameters, emission, and for the loop the
  closed-form groupings and the emitted closed-loop regressor) and the tree's operation count;
* building the closed-loop model (the numeric base-parameter sweep on 120 closed states);
* the closed-form groupings of the parallelogram (symoro_gen.closedloop.grouping: linear closure
  detected, energy functions, exact solves), given the tree's base parameters;
* the loop closure (positions by Newton's method, velocities, accelerations, G) for 10,000 samples,
  with the largest constraint residual;
* the closed-loop base regressor for 10,000 samples (closure + tree regressor + projection);
* the emitted closed-loop regressor of the linear closure (NumPy code in the actuated state, no closure
  solve) for the same samples, and its largest difference from the numeric projection.
No anchor: no published figures for this robot.
"""
from __future__ import annotations

import json
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from symoro_gen.baseparams.regroup import group_base_parameters
from symoro_gen.closedloop import ClosedLoopModel
from symoro_gen.closedloop.grouping import closed_form_base, closed_loop_kernel_source
from symoro_gen.description import load_robot
from symoro_gen.dynamics.newton_euler import build_regressor
from symoro_gen.emit.package import emit_robot
from symoro_gen.loader import import_package

N = 10_000


def main() -> None:
    warnings.simplefilter("ignore")
    with tempfile.TemporaryDirectory() as tmp:
        t = time.perf_counter()
        robot = load_robot("palletizer")
        emit_robot(robot, tmp)
        gen = time.perf_counter() - t
        man = json.loads((Path(tmp) / "palletizer" / "manifest.json").read_text())
        ops = man["operations"]["base_regressor"]
        tree = import_package(Path(tmp) / "palletizer")
        tree.regressor(np.zeros(6), np.zeros(6), np.zeros(6))  # compile / load the C kernels once
        t = time.perf_counter()
        model = ClosedLoopModel(robot, tree)
        build = time.perf_counter() - t
        t = time.perf_counter()
        bp = group_base_parameters(build_regressor(robot))
        t_tree = time.perf_counter() - t
        t = time.perf_counter()
        cf = closed_form_base(robot, bp.base_names, bp.kept, bp.relations, bp.gravity, kinematics=model.kinematics)
        closed_form = time.perf_counter() - t
        assert cf is not None
        t = time.perf_counter()
        src, kops = closed_loop_kernel_source(robot, cf)
        kernel_gen = time.perf_counter() - t
        kernel: dict = {}
        exec(compile(src, "<closed_loop>", "exec"), kernel)  # noqa: S102 (the generator's own output)
    rng = np.random.default_rng(0)
    q, dq, ddq = rng.uniform(-0.6, 0.6, (N, 4)), rng.normal(size=(N, 4)), rng.normal(size=(N, 4))
    t = time.perf_counter()
    st = model.kinematics.solve(q, dq, ddq)
    closure = time.perf_counter() - t
    t = time.perf_counter()
    model.regressor(q + 1e-3, dq, ddq)  # new inputs: closure again + tree regressor + projection
    reg = time.perf_counter() - t
    t = time.perf_counter()
    Yk = kernel["regressor"](q + 1e-3, dq, ddq)
    kern = time.perf_counter() - t
    err = float(np.abs(Yk - model.regressor(q + 1e-3, dq, ddq)).max())
    print("| figure | value |")
    print("| --- | --- |")
    print(f"| package generated (6 tree joints, {man['counts']['base']} tree base parameters; with the loop's "
          f"closed-form files) | {gen:.2f} s |")
    print(f"| tree base regressor operations | {ops['mul']} mul, {ops['add']} add |")
    print(f"| closed-loop model built ({len(model.BASE_NAMES)} base parameters) | {build:.2f} s |")
    print(f"| closed-form loop groupings ({len(cf.groupings)} relations, energy method; after the tree's "
          f"symbolic model and base parameters, {t_tree:.2f} s) | {closed_form:.2f} s |")
    print(f"| loop closure, {N} samples | {closure:.2f} s ({closure / N * 1e6:.0f} us/sample), "
          f"max residual {st.residual.max():.1e} |")
    print(f"| closed-loop base regressor, {N} samples | {reg:.2f} s ({reg / N * 1e6:.0f} us/sample) |")
    print(f"| emitted closed-loop regressor (`_closed_loop.py`, {kops} operations; generated in {kernel_gen:.2f} s), "
          f"{N} samples | {kern:.3f} s ({kern / N * 1e6:.1f} us/sample), max difference {err:.1e} |")


if __name__ == "__main__":
    main()
