"""``symoro-gen generate ROBOT``: an MDH robot file -> ``generated/<robot>/`` (NumPy, C and CasADi regressors).

A leaf: the robot file is read, its package folder checked (never over the robot file; only a package
``generate`` wrote from this file is replaced), then Newton-Euler, the base parameters and the emission run
under one progress bar.
"""
from __future__ import annotations

from pathlib import Path

from .. import progress
from ..atomic import Target, check_outputs
from ..baseparams.regroup import group_base_parameters
from ..description import load_robot
from ..emit.package import check_name, check_replaceable, emit_from, model_regressor
from ..loader import generated_dir
from ..progress import stage_callback
from .common import ROBOT_HELP

__all__ = ["add_parser", "generation_steps", "run"]


def generation_steps(robot) -> int:
    """Steps of the generation bar: Newton-Euler forward (per frame) and backward (per moving or
    payload frame) passes, base parameters, emission."""
    backward = sum(1 for r in robot.rows if r.is_moving or (robot.payload is not None and r.j == robot.payload))
    return len(robot.rows) + backward + 2


def run(args) -> int:
    """Generate the package; 0 on success."""
    robot = load_robot(args.robot)
    out = Path(args.out) if args.out else generated_dir()
    check_name(robot)
    # the package folder is replaced whole: never over the robot file; and only a package generate wrote
    # from this robot file (emit.package.check_replaceable), before the (long) generation
    check_outputs({"--out": Target(out / robot.name, folder=True, owner="caller")}, [("ROBOT", robot.file)])
    check_replaceable(out / robot.name, robot.name, args.force, robot_file=robot.file)
    # the steps of emit_robot, one bar over them; through the module: tests replace progress.progress_bar
    with progress.progress_bar(generation_steps(robot), f"{robot.name}", unit="step") as bar:
        reg = model_regressor(robot, progress=stage_callback(bar, prefix=f"{robot.name}: newton-euler "))
        bar.set_description(f"{robot.name}: base parameters")
        bp = group_base_parameters(reg)
        bar.update(1)
        bar.set_description(f"{robot.name}: emission (NumPy, C, CasADi)")
        m = emit_from(reg, bp, out, force=args.force)
        bar.update(1)
    if not args.quiet:
        print(
            f"{m.robot}: {m.n_standard} standard -> {m.n_base} base parameters; base regressor "
            f"{m.base_ops.mul} mul, {m.base_ops.div} div, {m.base_ops.add} add -> {m.path}"
        )
        if robot.floating:
            contacts = ", ".join(robot.row(j).name or f"frame{j}" for j in robot.contacts) or "none"
            print(f"{m.robot}: floating base: {6 + robot.n_joints} rows per sample (base wrench first); "
                  f"contact frames: {contacts}")
        if robot.constrained:
            print(f"{m.robot}: {len(robot.loops)} closed loop(s), {len(robot.couplings)} coupled joint(s): this "
                  f"package is the tree model; load_model() projects it on the {len(robot.actuated)} actuated joints "
                  "(its base parameters: model.base_parameters_text())")
    return 0


def add_parser(sub) -> None:
    """Register ``generate``."""
    g = sub.add_parser("generate", help="MDH robot file -> generated/<robot>/ (NumPy + CasADi regressors)")
    g.add_argument("robot", help=ROBOT_HELP)
    g.add_argument("--out", help="output folder (default: generated/ of the repository)")
    g.add_argument("--force", action="store_true",
                   help="replace OUT/<robot> even when it is not a package a previous `generate` wrote")
    g.set_defaults(func=run)
