"""What a recording can and cannot give, before identifying (the ``inspect`` workflow's computation).

Per file: sampling rate and jitter, gaps, dropped rows (from :class:`LoadReport`); the time steps as logged
(percentiles, the outlier steps by row, what ``--max-gap`` does with them: :class:`~.readers.StepStats`); per experiment and
joint: standstill fraction, saturation (samples stuck at the column's bound), the low-pass cut-off and
decimation factor the papers' rules choose (:func:`~symoro_gen.preprocessing.filtering.choose_filter_settings`);
for all experiments: the condition number of ``W`` assembled by the identification code
(:func:`~symoro_gen.identification.assemble.build_observation`) and the base parameters whose
predicted relative standard deviation ``%sigma`` (Gautier 1990; LWR4 paper eq. 11) exceeds
``REL_STD_WARN_PCT``: the parameters this recording cannot identify.

The use case is :func:`symoro_gen.workflows.inspect.inspect`, the command :mod:`symoro_gen.commands.inspect`
(exit 0, with warnings, when the recording is usable; 2 with the reason when it is not).
"""
from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..atomic import mark_png
from ..errors import IdentificationError
from ..identification.assemble import build_observation
from ..identification.estimators import REL_STD_WARN_PCT
from ..identification.method import identify
from ..model import IdentificationModel
from ..report import Figure, Heading, ItemList, Preformatted, Report, Table, require_matplotlib
from .cli import data_block, data_text
from .filtering import choose_filter_settings, filter_and_differentiate
from .motion import motion_rms, noise_level_joints, noise_sigma
from .readers import LoadReport
from .trajectory import Trajectory

__all__ = ["JointStats", "ExperimentStats", "Inspection", "inspect_recordings", "inspection_report", "signal_figures"]

#: |dq| below which a joint is at a standstill [rad/s or m/s]
STANDSTILL_VELOCITY = 0.01
#: share of the samples at a column's extreme value above which it is reported saturated
SATURATION_FRACTION = 0.02
#: standstill share above which a joint is reported (the recording hardly excites it)
STANDSTILL_WARN = 0.5
#: cond(W) (columns scaled) above which the recording is reported ill-conditioned
COND_WARN = 1e3


@dataclass(frozen=True)
class JointStats:
    """One joint of one experiment."""

    joint: int
    standstill: float        # share of samples with |dq| < STANDSTILL_VELOCITY
    q_saturated: float       # share of samples at min or max of q
    tau_saturated: float     # share of samples at min or max of tau
    q_range: float
    tau_peak: float


@dataclass(frozen=True)
class ExperimentStats:
    source: str
    n_samples: int
    fs: float
    duration: float
    cutoff_hz: float
    n_d: int
    joints: tuple[JointStats, ...]


@dataclass(frozen=True)
class Inspection:
    """What :func:`inspect_recordings` found.

    ``warnings`` are the findings that may spoil an identification (bad rows, irregular steps, standstill,
    saturation, conditioning); what reading a file did (rows skipped, a dump reshaped, a file split, joints
    ignored) is in the load reports' ``notes`` (``files``), printed once under ``Data:``, not repeated here.
    """

    files: tuple[LoadReport, ...]
    experiments: tuple[ExperimentStats, ...]
    cond: float | None
    cond_scaled: float | None
    names: tuple[str, ...] = ()
    rel_std_pct: tuple[float, ...] = ()
    warnings: tuple[str, ...] = ()
    errors: tuple[str, ...] = ()

    @property
    def usable(self) -> bool:
        return not self.errors

    @property
    def unidentifiable(self) -> tuple[tuple[str, float], ...]:
        return tuple((n, p) for n, p in zip(self.names, self.rel_std_pct) if not (p <= REL_STD_WARN_PCT))

    def to_dict(self) -> dict:
        def f(x):
            return None if x is None or not np.isfinite(x) else float(x)

        return {
            "usable": self.usable, "errors": list(self.errors), "warnings": list(self.warnings),
            "data": data_block(self.files),
            "steps": [{"file": r.file, **r.steps.to_dict(), "max_gap_effect": r.steps.max_gap_effect(r.resampled)}
                      for r in self.files if r.steps is not None],
            "experiments": [{"source": e.source, "n_samples": e.n_samples, "fs": e.fs, "duration": e.duration,
                             "cutoff_hz": e.cutoff_hz, "n_d": e.n_d,
                             "joints": [{"joint": j.joint, "standstill": j.standstill, "q_saturated": j.q_saturated,
                                         "tau_saturated": j.tau_saturated, "q_range": j.q_range,
                                         "tau_peak": j.tau_peak} for j in e.joints]} for e in self.experiments],
            "cond": f(self.cond), "cond_scaled": f(self.cond_scaled),
            "parameters": {"names": list(self.names), "rel_std_pct": [f(p) for p in self.rel_std_pct]},
            "unidentifiable": [{"name": n, "rel_std_pct": f(p)} for n, p in self.unidentifiable],
        }

    def summary(self) -> str:
        lines = [data_text(self.files), ""]
        for r in self.files:
            assert r.step_from is not None  # every file read has a time step
            st = r.steps
            if st is None or not st.n_outliers:
                lines.append(f"{r.file}: step {r.step_from:.6g} s ({1 / r.step_from:.5g} Hz), jitter "
                             f"{100 * r.step_jitter:.3g} % of the step, {r.gaps} gap(s) split, {r.rows_dropped} row(s) "
                             "dropped")
                continue
            lines.append(f"{r.file}: step {r.step_from:.6g} s ({1 / r.step_from:.5g} Hz), jitter {100 * st.jitter:.3g} "
                         f"% of the step but for {st.n_outliers} outlier step(s), {r.gaps} gap(s) split, "
                         f"{r.rows_dropped} row(s) dropped")
            lines.append(f"  steps: p50 {st.p50:.6g} s, p99 {st.p99:.6g} s, max {st.max:.6g} s")
            shown = ", ".join(f"row {row}" + (f" (line {ln})" if ln is not None else "") + f": {h:.6g} s"
                              for row, ln, h in st.outliers)
            more = f" and {st.n_outliers - len(st.outliers)} more" if st.n_outliers > len(st.outliers) else ""
            lines.append(f"  {st.n_outliers} outlier step(s) (more than {100 * st.tol:g} % off the median): {shown}"
                         f"{more}")
            lines.append(f"  {st.max_gap_effect(r.resampled)}")
        for e in self.experiments:
            lines.append(f"{e.source}: {e.n_samples} samples, {e.duration:.4g} s at {e.fs:.5g} Hz; the papers' rule "
                         f"chooses a cut-off of {e.cutoff_hz:.3g} Hz and decimation n_d = {e.n_d}")
            lines.append("  joint  standstill  q at bound  tau at bound   q range   |tau| max")
            for j in e.joints:
                lines.append(f"  {j.joint:5d}  {100 * j.standstill:9.1f}%  {100 * j.q_saturated:9.1f}%  "
                             f"{100 * j.tau_saturated:11.1f}%  {j.q_range:8.4g}  {j.tau_peak:10.4g}")
        if self.cond is not None:
            lines.append(f"cond(W) = {self.cond:.4g} (columns scaled: {self.cond_scaled:.4g}); "
                         f"{len(self.names)} base parameters")
            un = self.unidentifiable
            if un:
                lines.append(f"{len(un)} base parameter(s) this recording cannot identify (predicted %sigma > "
                             f"{REL_STD_WARN_PCT:g}): " + ", ".join(f"{n} ({p:.3g} %)" for n, p in un))
            else:
                lines.append(f"every base parameter has a predicted %sigma <= {REL_STD_WARN_PCT:g}")
        lines += [f"warning: {w}" for w in self.warnings]
        lines += [f"not usable: {e}" for e in self.errors]
        return "\n".join(lines)


def _at_bound(x: np.ndarray) -> float:
    """Share of the samples stuck at the column's minimum or maximum: the samples at an extreme that more than
    one sample reaches (a plateau, as a clipped signal makes); a single sample at each extreme, as every signal
    has, counts as none."""
    lo, hi = x.min(), x.max()
    if hi - lo <= 0:
        return 1.0
    tol = 1e-9 * (hi - lo)
    at_lo, at_hi = x <= lo + tol, x >= hi - tol
    stuck = (at_lo if at_lo.sum() > 1 else False) | (at_hi if at_hi.sum() > 1 else False)
    return float(np.mean(stuck))


def _experiment_stats(tr: Trajectory, cutoff_hz, n_d) -> ExperimentStats:
    fs = 1.0 / tr.dt
    st = choose_filter_settings(fs, tr.q, cutoff_hz=cutoff_hz, n_d=n_d)
    _, dq, _ = filter_and_differentiate(tr.q, fs, st.cutoff_hz, source=tr.source)
    joints = []
    for j in range(tr.n_joints):
        joints.append(JointStats(
            joint=j + 1, standstill=float(np.mean(np.abs(dq[:, j]) < STANDSTILL_VELOCITY)),
            q_saturated=_at_bound(tr.q[:, j]), tau_saturated=_at_bound(tr.tau[:, j]),
            q_range=float(np.ptp(tr.q[:, j])), tau_peak=float(np.abs(tr.tau[:, j]).max())))
    return ExperimentStats(tr.source, tr.n_samples, fs, float(tr.t[-1] - tr.t[0]), st.cutoff_hz, st.n_d, tuple(joints))


def inspect_recordings(model: IdentificationModel, trajectories: Sequence[Trajectory],
                       reports: Sequence[LoadReport] = (), *, cutoff_hz: float | None = None,
                       n_d: int | None = None) -> Inspection:
    """Inspect recordings for ``model`` (see the module docstring).

    Parameters
    ----------
    model : IdentificationModel
    trajectories : sequence of Trajectory
    reports : sequence of LoadReport
        How the files were read (sampling, gaps, dropped rows).
    cutoff_hz, n_d : optional
        As for identification (default: the papers' rules).
    """
    warn: list[str] = []
    errs: list[str] = []
    exps = []
    for tr in trajectories:
        try:
            exps.append(_experiment_stats(tr, cutoff_hz, n_d))
        except ValueError as exc:  # too short to filter...
            errs.append(f"{tr.source}: {str(exc).splitlines()[0]}")
    for r in reports:
        if r.rows_dropped:
            warn.append(f"{r.file}: {r.rows_dropped} bad row(s) dropped")
        if r.step_jitter > 0.5 and not r.resampled:
            warn.append(f"{r.file}: irregular time steps (up to {100 * r.step_jitter:.3g} % of the median step)")
        # the load report's notes are printed once, under "Data:" (and in the JSON's data[].notes): not warnings
    n = model.N_JOINTS if hasattr(model, "N_JOINTS") else (trajectories[0].n_joints if trajectories else 0)
    for j in range(n):
        still = [e.joints[j].standstill for e in exps if j < len(e.joints)]
        if still and min(still) > STANDSTILL_WARN:
            warn.append(f"joint {j + 1} is at a standstill {100 * min(still):.0f} % of the time or more: "
                        "its friction and inertia are barely excited")
        sat = [(e.source, e.joints[j].tau_saturated) for e in exps if j < len(e.joints)]
        for src, s in sat:
            if SATURATION_FRACTION < s < 1.0:
                warn.append(f"{src}: tau of joint {j + 1} sits at its extreme value {100 * s:.1f} % of the time "
                            "(saturated torque or current limit?)")
            elif s >= 1.0:
                warn.append(f"{src}: tau of joint {j + 1} is constant")
        for e in exps:
            if j < len(e.joints) and e.joints[j].q_range == 0:
                warn.append(f"{e.source}: joint {j + 1} never moves")
    for tr in trajectories:  # moving at the noise level (preprocessing.motion; a constant joint is named above)
        q = np.asarray(tr.q, float)
        rms, sig = motion_rms(q), noise_sigma(q)
        for j in noise_level_joints(q):
            if np.ptp(q[:, j]) > 0:
                warn.append(f"{tr.source}: joint {j + 1} (position RMS {rms[j]:.2g}, noise {sig[j]:.2g}) does not move "
                            "beyond its noise: identify and diagnose would fit the parameters of its own motion "
                            "(rotor inertia, friction...) to noise: give --drop-unexcited to treat it as still")
    cond = cond_s = None
    names: tuple[str, ...] = ()
    pct: tuple[float, ...] = ()
    if not errs and trajectories:
        try:
            sys_ = build_observation(model, trajectories, cutoff_hz=cutoff_hz, n_d=n_d)
            res = identify(sys_, method="ols")
            cond, cond_s = float(res.cond), float(res.cond_scaled)
            names, pct = tuple(res.names), tuple(float(p) for p in res.rel_std_pct)
            warn.extend(w for w in res.warnings if "poorly identified" not in w)
            if cond_s > COND_WARN:
                warn.append(f"cond(W) = {cond_s:.3g} with scaled columns: the recording excites the parameters "
                            "poorly (essential parameters or a richer trajectory help)")
        except (IdentificationError, ValueError) as exc:
            errs.append(f"identification not possible on this recording: {str(exc).splitlines()[0]}")
    if not trajectories:
        errs.append("no data")
    return Inspection(tuple(reports), tuple(exps), cond, cond_s, names, pct, tuple(dict.fromkeys(warn)), tuple(errs))


def signal_figures(trajectories: Sequence[Trajectory]) -> list[tuple[str, Any, str]]:
    """One matplotlib figure per experiment and joint (q and tau against t): ``(name, figure, caption)``."""
    MplFigure, Canvas = require_matplotlib()
    out = []
    for k, tr in enumerate(trajectories):
        for j in range(tr.n_joints):
            fig = MplFigure(figsize=(8, 3.2), dpi=80)
            Canvas(fig)
            ax1, ax2 = fig.subplots(2, 1, sharex=True)
            step = max(1, tr.n_samples // 4000)
            ax1.plot(tr.t[::step], tr.q[::step, j], lw=0.8)
            ax1.set_ylabel(f"q{j + 1}")
            ax2.plot(tr.t[::step], tr.tau[::step, j], lw=0.8, color="C1")
            ax2.set_ylabel(f"tau{j + 1}")
            ax2.set_xlabel("t [s]")
            out.append((f"exp{k + 1}_joint{j + 1}", fig, f"{tr.source}, joint {j + 1}"))
    return out


def inspection_report(insp: Inspection, trajectories: Sequence[Trajectory], robot: str) -> Report:
    """An HTML/Markdown report: the summary tables and one plot per joint (q and tau against t)."""
    require_matplotlib()
    blocks: list = [Heading("Files", 2),
                    Table(("file", "rows read", "dropped", "resampled", "step [s]", "jitter [%]", "gaps", "experiments"),
                          tuple((r.file, str(r.rows_read), str(r.rows_dropped), "yes" if r.resampled else "no",
                                 f"{r.step_from:.6g}", f"{100 * r.step_jitter:.3g}", str(r.gaps), str(r.experiments))
                                for r in insp.files), caption="How each file was read")]
    odd = [r for r in insp.files if r.steps is not None and r.steps.n_outliers]
    if odd:
        blocks.append(Table(("file", "p50 step [s]", "p99 step [s]", "max step [s]", "outlier steps (row: step)",
                             "--max-gap"),
                            tuple((r.file, f"{r.steps.p50:.6g}", f"{r.steps.p99:.6g}", f"{r.steps.max:.6g}",
                                   f"{r.steps.n_outliers}: " + ", ".join(f"{row}: {h:.6g}" for row, _, h
                                                                        in r.steps.outliers),
                                   r.steps.max_gap_effect(r.resampled)) for r in odd if r.steps is not None),
                            caption="Time steps as logged, where some are more than 50 % off the median"))
    for e in insp.experiments:
        blocks.append(Table(("joint", "standstill [%]", "q at bound [%]", "tau at bound [%]", "q range", "|tau| max"),
                            tuple((str(j.joint), f"{100 * j.standstill:.1f}", f"{100 * j.q_saturated:.1f}",
                                   f"{100 * j.tau_saturated:.1f}", f"{j.q_range:.4g}", f"{j.tau_peak:.4g}")
                                  for j in e.joints),
                            caption=f"{e.source}: {e.fs:.5g} Hz, cut-off {e.cutoff_hz:.3g} Hz, n_d = {e.n_d}"))
    if insp.names:
        blocks.append(Heading("Predicted identifiability", 2))
        blocks.append(Table(("parameter", "predicted %sigma"),
                            tuple((n, f"{p:.3g}") for n, p in zip(insp.names, insp.rel_std_pct)),
                            caption=f"cond(W) = {insp.cond:.4g} (scaled {insp.cond_scaled:.4g})",
                            row_classes=tuple("poor" if not p <= REL_STD_WARN_PCT else "" for p in insp.rel_std_pct)))
    if insp.warnings or insp.errors:
        blocks.append(ItemList(tuple(insp.errors) + tuple(insp.warnings)))
    blocks.append(Heading("Signals per joint", 2))
    for name, fig, caption in signal_figures(trajectories):
        buf = io.BytesIO()
        fig.savefig(buf, format="png", metadata={"Software": None})
        blocks.append(Figure(name, mark_png(buf.getvalue()), caption=caption))
    blocks.append(Preformatted(insp.summary()))
    return Report(f"Inspection of recordings for {robot}", tuple(blocks))
