"""What an excitation design is written as: the trajectory CSV (:func:`write_trajectory_csv`), the figure of every
joint against its limits (:func:`plot_trajectory`, :func:`trajectory_figure_png`), the report
(:func:`excitation_report`), and the sentences the command and the report share (the passive joints' ranges of a
closed-loop robot, the floor's clearance)."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import __version__
from ..atomic import write_output_bytes, write_output_text
from ..model import IdentificationModel
from ..report import Figure, Heading, Paragraph, Report, Table
from ..report.plots import WIDTH_IN, figure_png, require_matplotlib
from .criterion import predicted_sigma
from .limits import Limits, Workspace
from .optimise import ExcitationResult

__all__ = [
    "excitation_report",
    "floor_text",
    "joint_label",
    "joint_numbers",
    "passive_ranges",
    "passive_text",
    "plot_trajectory",
    "trajectory_figure",
    "trajectory_figure_png",
    "write_trajectory_csv",
]


def write_trajectory_csv(path, t, q, dq, ddq, *, force: bool = False) -> None:
    """CSV with header ``t,q1..qn,dq1..dqn,ddq1..ddqn`` (SI units, full precision). An existing file is
    replaced only when it is such a trajectory (the header marks it), unless ``force``."""
    n = q.shape[1]
    head = ["t"] + [f"q{j}" for j in range(1, n + 1)] + [f"dq{j}" for j in range(1, n + 1)] + [f"ddq{j}" for j in range(1, n + 1)]
    data = np.column_stack([t, q, dq, ddq])
    lines = [",".join(head)] + [",".join(f"{v:.17g}" for v in row) for row in data]
    write_output_text(path, "\n".join(lines) + "\n", force=force)


def joint_numbers(model: IdentificationModel) -> tuple[int, ...]:
    """The robot joint of each design column ``q1..qn``: ``1..n``, or a closed-loop robot's actuated joints
    (``q3`` of a palletizer design is its joint 4)."""
    return tuple(getattr(model, "ACTUATED_JOINTS", range(1, int(model.N_JOINTS) + 1)))


def joint_label(j: int, joints: tuple[int, ...] | None) -> str:
    """``"q<j+1>"`` and, when it is another robot joint, ``" (joint k)"``: the suffix of ``q, dq, ddq``."""
    k = j + 1 if joints is None else joints[j]
    return f"{j + 1}" + (f" (joint {k})" if k != j + 1 else "")


def passive_ranges(model: IdentificationModel, q: np.ndarray) -> dict[int, tuple[float, float]]:
    """``{joint: (min, max)}`` of the passive joints of a closed-loop robot over the design's positions ``q``
    (from the loop closure; the design's limits constrain the actuated joints only); ``{}`` for an open one."""
    closed: Any = model  # a ClosedLoopModel (IdentificationModel does not declare its closure)
    if not hasattr(closed, "closure"):
        return {}
    act = set(joint_numbers(model))
    z = np.zeros_like(q)
    qt = closed.closure(q, z, z).q
    joints = list(closed.kinematics.tree_joints)
    return {j: (float(qt[:, c].min()), float(qt[:, c].max())) for c, j in enumerate(joints) if j not in act}


def floor_text(ws: Workspace, q: np.ndarray) -> str:
    """One sentence: the floor and the lowest height each moving frame origin reaches (m, base frame)."""
    low = ws.heights(q).min(0)
    return (f"floor z >= {ws.z_min:g} m (base frame): lowest frame origins " +
            ", ".join(f"{j}: {z:.3f}" for j, z in zip(ws.frames, low)) + " m")


def passive_text(model: IdentificationModel, passive: dict[int, tuple[float, float]], limits: Limits) -> str:
    """One sentence: which robot joints the design's columns are, and the passive joints' ranges against
    their ``[limits]`` ranges when given (deg or m)."""
    given = {p.joint: (p.lo, p.hi) for p in limits.passive}
    robot = getattr(model, "robot")  # noqa: B009 - a ClosedLoopModel's (IdentificationModel does not declare it)

    def rng(j: int, lo: float, hi: float) -> str:
        f, u, d = (1.0, "m", 4) if robot.row(j).sigma == 1 else (180.0 / math.pi, "deg", 1)
        lim = f" (limits {f * given[j][0]:.{d}f} .. {f * given[j][1]:.{d}f})" if j in given else ""
        return f"joint {j} {f * lo:.{d}f} .. {f * hi:.{d}f} {u}{lim}"
    joints = joint_numbers(model)
    free = "" if given else " ([limits] has no passive_q_min/passive_q_max: not constrained)"
    return (f"closed loop: q1..q{len(joints)} are the actuated joints {', '.join(map(str, joints))}; the passive "
            f"joints move over " + ", ".join(rng(j, *r) for j, r in passive.items()) + free)


def plot_trajectory(result: ExcitationResult, path, *, robot: str = "", joints: tuple[int, ...] | None = None,
                    force: bool = False) -> None:
    """PNG file of every joint's ``q, dq, ddq`` against its limits (dashed), titled with the robot, the
    kind of design and its cond (written atomically; an existing PNG symoro-gen did not write is replaced
    only with ``force``); ``joints``: :func:`joint_numbers` for the labels."""
    title = (f"{robot + ': ' if robot else ''}{result.basis.kind} excitation, cond = {result.cond:.4g}, limits "
             f"{'respected' if result.limits_ok else 'VIOLATED'}")
    write_output_bytes(path, trajectory_figure_png(result, dpi=90, title=title, joints=joints), force=force)


def trajectory_figure_png(result: ExcitationResult, *, dpi: int = 80, max_points: int = 2000, title: str = "",
                          joints: tuple[int, ...] | None = None) -> bytes:
    """PNG (report style) of :func:`trajectory_figure`."""
    return figure_png(trajectory_figure(result, dpi=dpi, max_points=max_points, title=title, joints=joints), dpi)


def trajectory_figure(result: ExcitationResult, *, dpi: int = 80, max_points: int = 2000, title: str = "",
                      joints: tuple[int, ...] | None = None):
    """Matplotlib figure of every joint's ``q, dq, ddq`` against its limits (dashed red), in deg or m;
    ``joints``: the robot joint of each column (:func:`joint_numbers`), named in the labels when it differs."""

    MplFigure, FigureCanvasAgg = require_matplotlib()
    lim, n = result.limits, result.limits.n
    ws = lim.workspace
    # a closed-loop robot's passive joints: one more row each (position only); a floor: one row of frame heights
    rows = n + len(lim.passive) + (ws is not None)
    base, head = 1.5 * rows + 0.9, (0.35 if title else 0.0)  # inches: the grid of axes, the title above it
    fig = MplFigure(figsize=(WIDTH_IN, base + head), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    axes = fig.subplots(rows, 3, squeeze=False, sharex=True)
    k = max(1, len(result.t) // max(max_points, 1))
    t = result.t[::k]
    passive = lim.passive_positions(result.q[::k])
    for i, p in enumerate(lim.passive):
        f, u = (1.0, "m") if p.prismatic else (180.0 / math.pi, "deg")
        ax = axes[n + i, 0]
        ax.plot(t, f * passive[:, i], lw=1, color="C1")
        for v in (p.lo, p.hi):
            ax.axhline(f * v, color="r", ls="--", lw=0.8)
        ax.set_ylabel(f"joint {p.joint}, passive [{u}]", fontsize=8)
        ax.tick_params(labelsize=7)
        for c in (1, 2):
            axes[n + i, c].set_visible(False)
    if ws is not None:
        ax = axes[-1, 0]
        for f, z in zip(ws.frames, ws.heights(result.q[::k]).T):
            ax.plot(t, z, lw=0.8, label=f"{f}")
        ax.axhline(ws.z_min, color="r", ls="--", lw=0.8)
        ax.set_ylabel("frame origins z [m]", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=6, ncol=2, loc="upper left", bbox_to_anchor=(1.02, 1.0), title="frame", title_fontsize=6)
        for c in (1, 2):
            axes[-1, c].set_visible(False)
    for j in range(n):
        f, u = (1.0, "m") if lim.is_prismatic(j) else (180.0 / math.pi, "deg")
        jl = joint_label(j, joints)
        panels = ((f * result.q[::k, j], f * lim.q_min[j], f * lim.q_max[j], f"q{jl} [{u}]"),
                  (f * result.dq[::k, j], -f * lim.dq_max[j], f * lim.dq_max[j], f"dq{jl} [{u}/s]"),
                  (f * result.ddq[::k, j], -f * lim.ddq_max[j], f * lim.ddq_max[j], f"ddq{jl} [{u}/s2]"))
        for c, (y, lo, hi, lab) in enumerate(panels):
            ax = axes[j, c]
            ax.plot(t, y, lw=1)
            for v in (lo, hi):
                ax.axhline(v, color="r", ls="--", lw=0.8)
            ax.set_ylabel(lab, fontsize=8)
            ax.tick_params(labelsize=7)
    extra = rows > n
    for c in range(3):
        axes[n - 1 if c and extra else -1, c].set_xlabel("t [s]", fontsize=8)
        if c and extra:
            axes[n - 1, c].tick_params(labelbottom=True)
    if title:
        fig.suptitle(title, fontsize=9, y=1 - 0.12 / (base + head))
    fig.subplots_adjust(left=0.07, right=0.99, top=1 - (0.03 * base + head) / (base + head), bottom=0.5 / (base + head),
                        wspace=0.3, hspace=0.25)
    return fig


def excitation_report(result: ExcitationResult, model: IdentificationModel, *, noise: float, chi_b=None,
                      title: str | None = None, plots: bool = True):
    """:class:`~symoro_gen.report.Report` of an excitation design: the figures, the joint
    trajectories against the limits, the peak use of every limit, and the predicted standard
    deviation (and %sigma with nominal base parameters) of every base parameter for i.i.d. torque
    noise ``noise`` (:func:`predicted_sigma`, Gautier 1997 eq. 9)."""

    lim, n = result.limits, result.limits.n
    sig, pct = predicted_sigma(model, result.q, result.dq, result.ddq, noise, chi_b)
    worst = max(max(v) for v in result.usage.values())
    blocks: list = [Paragraph(
        f"{model.ROBOT}: {result.basis.kind} excitation, {len(result.t)} samples over {result.t[-1]:g} s; "
        f"criterion {result.criterion}; cond = {result.cond:.6g} (2-norm condition number of the base regressor "
        f"stacked over the output samples, unscaled); limits {'respected' if result.limits_ok else 'VIOLATED'} "
        f"at every output sample and on a 10x denser resampling (peak usage {worst:.3f}); "
        f"{len(result.starts)} IPOPT start(s), {result.wall_time:.1f} s.")]
    if lim.defaulted:
        blocks.append(Paragraph(f"The robot file gives no {', '.join(lim.defaulted)} in [limits]: the design used "
                                f"{lim.defaulted_text()}."))
    joints = joint_numbers(model)
    passive = passive_ranges(model, result.q)
    if passive:
        blocks.append(Paragraph(passive_text(model, passive, lim)))
    if lim.workspace is not None:
        blocks.append(Paragraph(floor_text(lim.workspace, result.q) + " (frame origins only: the links' extent is "
                                "the clearance given in --z-min)"))
    blocks.append(Heading("Joint trajectories against the limits"))
    if plots:
        blocks.append(Figure("trajectory", trajectory_figure_png(result, joints=joints),
                             caption="q, dq, ddq per joint (rows) against the limits (dashed red)"
                                     + ("; below, the passive joints' positions (closed loop)" if lim.passive else "")
                                     + ("; last, the height of every moving frame origin above the floor (dashed)"
                                        if lim.workspace is not None else "")))
    rows = []
    for j in range(n):
        f, u, d = (1.0, "m", 4) if lim.is_prismatic(j) else (180.0 / math.pi, "deg", 1)
        rows.append((joint_label(j, joints), f"{f * result.q[:, j].min():.{d}f} .. {f * result.q[:, j].max():.{d}f} {u}",
                     f"{f * lim.q_min[j]:.{d}f} .. {f * lim.q_max[j]:.{d}f} {u}",
                     *(f"{result.usage[k][j]:.3f}" for k in ("q", "dq", "ddq")),
                     f"{result.usage['tau'][j]:.3f}" if "tau" in result.usage else "-"))
    qp = lim.passive_positions(result.q)
    for i, pr in enumerate(lim.passive):
        f, u, d = (1.0, "m", 4) if pr.prismatic else (180.0 / math.pi, "deg", 1)
        rows.append((f"joint {pr.joint} (passive)", f"{f * qp[:, i].min():.{d}f} .. {f * qp[:, i].max():.{d}f} {u}",
                     f"{f * pr.lo:.{d}f} .. {f * pr.hi:.{d}f} {u}", f"{result.usage['passive'][i]:.3f}", "-", "-", "-"))
    blocks.append(Table(("joint", "q range", "limits", "use q", "use dq", "use ddq", "use tau"),
                        tuple(rows), caption="Peak use of each limit (1 = at the limit; q about the range centre)"))
    blocks.append(Heading("Predicted precision of the base parameters"))
    cb = None if chi_b is None else np.asarray(chi_b, float)
    prow = []
    for i, name in enumerate(model.BASE_NAMES):
        nominal = "-" if cb is None else f"{cb[i]:.4g}"
        p = "-" if pct is None or not np.isfinite(pct[i]) else f"{pct[i]:.3g}"
        prow.append((name, nominal, f"{sig[i]:.4g}", p))
    blocks.append(Table(("parameter", "nominal", "sigma", "%sigma"), tuple(prow),
                        caption=f"sigma = noise sqrt(diag((W'W)^-1)) for torque noise {noise:g} N m "
                                f"(Gautier 1997 eq. 9); %sigma = 100 sigma / |nominal|"))
    if result.starts:
        blocks.append(Heading("Starts"))
        blocks.append(Table(("start", "cond at start", "cond optimised", "IPOPT status", "iterations"),
                            tuple((str(st["start"]), f"{st['cond_start']:.4g}", f"{st['cond']:.4g}", str(st["status"]),
                                   str(st["iterations"])) for st in result.starts),
                            caption="Random feasible starts (best of the pool) and IPOPT's result from each"))
    return Report(title or f"Excitation trajectory: {model.ROBOT}", tuple(blocks), footer=f"symoro_gen {__version__}")
