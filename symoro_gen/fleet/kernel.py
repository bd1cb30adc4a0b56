"""The per-file task of a fleet run and the merge of its results (TSQR tree reduction).

One task reads one log, band-pass filters and decimates it block by block and folds every block of the
base regressor into the per-joint QR factors of :class:`~symoro_gen.identification.accumulate.Accumulator`
(:mod:`symoro_gen.fleet.fused`, the assembly engine's rows, those of :func:`~symoro_gen.observations.iter_chunks`: the full-rate
``W`` of a whole log never exists; memory is the log's ``t, q, tau`` plus one Butterworth block of
``AssemblyOptions.chunk_samples`` or 64k samples, and ~2 MB of regressor buffers).
Two partial results merge exactly: the factor of ``[R_a; R_b]`` is the factor of all the rows of both
(Demmel et al., "Communication-optimal parallel and sequential QR", SIAM J. Sci. Comput. 2012: TSQR).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from typing import cast

import numpy as np

from ..errors import IdentificationError
from ..identification.accumulate import Accumulator
from ..loader import load_model
from ..model import IdentificationModel
from ..observations import AssemblyOptions
from ..observations.fused import model_column_map
from ..preprocessing.filtering import blas_threads
from ..preprocessing.motion import saturation_text, still_text
from .files import LogFile, read_experiments
from .fused import fold_trajectories

__all__ = ["Partial", "error_line", "log_warnings", "merge_accumulators", "merge_partials", "process_file", "resolve_model"]


@dataclass(frozen=True, eq=False)
class Partial:
    """The factors of the logs of one group (a file, a robot-day, a robot, the fleet).

    Attributes
    ----------
    files : tuple of str
        Logs folded in.
    acc : Accumulator or None
        None when no log of the group could be used.
    samples : int
        Full-rate samples read.
    skipped : tuple of (str, str)
        ``(file, reason)`` of the logs that could not be used.
    warnings : tuple of str
        The warnings on the logs folded in (:func:`log_warnings`: a joint at its noise level, a saturated torque),
        each naming the robot, the day and the log.
    """

    files: tuple[str, ...]
    acc: Accumulator | None
    samples: int = 0
    skipped: tuple[tuple[str, str], ...] = ()
    warnings: tuple[str, ...] = ()


def log_warnings(log: LogFile, trajs, tau_max=None) -> tuple[str, ...]:
    """The warnings ``identify`` and ``diagnose`` give on a recording (:mod:`symoro_gen.preprocessing.motion`: a
    joint that does not move beyond its encoder noise, a torque at its limit), for one log of a fleet: each names
    the robot, the day, the log and the joints. ``fleet`` has neither ``--drop-unexcited`` nor ``--drop-saturated``:
    the advice is to identify that log alone with the option, or to leave it out."""
    out = []
    for tr in trajs:
        head = f"robot {log.robot}, day {log.day}: {log.label}"
        if len(trajs) > 1 and tr.source and tr.source != log.path:
            head += f" ({tr.source})"
        what = still_text(tr.q)
        if what is not None:
            out.append(f"{head}: {what} does not move beyond its noise: the parameters of its own motion (rotor "
                       "inertia, friction...) in this robot-day's estimate are fitted to noise; fleet cannot hold it "
                       "still: leave the log out, or identify it with `symoro-gen identify ROBOT LOG "
                       "--drop-unexcited`")
        what = saturation_text(tr.tau, tau_max)
        if what is not None:
            out.append(f"{head}: {what}: a clipped torque biases this robot-day's estimate; fleet cannot leave those "
                       "rows out: leave the log out, or identify it with `symoro-gen identify ROBOT LOG "
                       "--drop-saturated`")
    return tuple(out)


def error_line(exc: BaseException) -> str:
    """One line for an error: its problems joined (a :class:`~symoro_gen.errors.DataFileError` is ``N problems in
    data:`` and the problems on the lines below), else its first line."""
    problems = getattr(exc, "problems", None)
    if problems:
        return "; ".join(str(p) for p in problems)
    return (str(exc).strip().splitlines() or [type(exc).__name__])[0]


def resolve_model(ref) -> IdentificationModel:
    """A model from what a task received: a name or path, or the model.

    A name or path goes through :func:`~symoro_gen.loader.load_model` on every call: its import is kept
    per process under the package's path *and content hash* (0.35 ms when cached), so a worker that lives
    on while ``generated/<robot>/`` is regenerated picks up the new model instead of a stale one; the
    column map follows the module object (:func:`~symoro_gen.observations.fused.model_column_map`).
    """
    if isinstance(ref, (str, os.PathLike)):
        return load_model(os.fspath(ref))
    return ref


def merge_accumulators(a: Accumulator, b: Accumulator) -> Accumulator:
    """The accumulator of the rows of ``a`` and of ``b`` (per joint, ``R`` of ``[R_a; R_b]``; exact).

    Raises
    ------
    IdentificationError
        The two have different columns or weighting.
    """
    if a.names != b.names or a.weighted != b.weighted:
        raise IdentificationError("merge_accumulators: the two accumulators have different columns or weighting")
    c1 = a.n_params + 1
    nj = max(a.n_joints, b.n_joints)
    Rs, rows, yy = [], [], []
    for j in range(nj):
        parts = [x.R[j] for x in (a, b) if j < x.n_joints]
        R = cast(np.ndarray, np.linalg.qr(np.vstack(parts), mode="r")) if len(parts) > 1 else parts[0]
        if R.shape[0] < c1:
            R = np.vstack([R, np.zeros((c1 - R.shape[0], c1))])
        Rs.append(R)
        rows.append(sum(x.rows[j] for x in (a, b) if j < x.n_joints))
        yy.append(sum(x.yy[j] for x in (a, b) if j < x.n_joints))
    return Accumulator(a.names, tuple(Rs), tuple(rows), tuple(yy), a.weighted)


def merge_partials(*parts: Partial) -> Partial:
    """Merge partial results (files, samples and skipped logs concatenated; factors merged; one BLAS
    thread: the QR of a ``2(c+1) x (c+1)`` stack gains nothing from more and a multi-threaded OpenBLAS
    spends far more in synchronisation)."""
    acc = None
    with blas_threads(1):
        for p in parts:
            if p.acc is not None:
                acc = p.acc if acc is None else merge_accumulators(acc, p.acc)
    return Partial(files=tuple(f for p in parts for f in p.files), acc=acc,
                   samples=sum(p.samples for p in parts), skipped=tuple(s for p in parts for s in p.skipped),
                   warnings=tuple(w for p in parts for w in p.warnings))


def process_file(model_ref, log: LogFile, options: AssemblyOptions | None = None, load_kw: dict | None = None
                 ) -> Partial:
    """Read one log, filter, decimate, evaluate the base regressor block by block and fold it into the
    per-joint QR factors (the kernel of a fleet run, :func:`~symoro_gen.fleet.fused.fold_trajectory`;
    RX-90 paper eq. 14-16 for the filters).

    A log that cannot be read or used (damaged file, wrong columns, too short...) does not raise: it
    comes back in ``skipped`` with the reason, so that it cannot stop the rest of the fleet.

    Parameters
    ----------
    model_ref : str or IdentificationModel
        Robot name / package folder (loaded once per worker) or a model object.
    log : LogFile
    options : AssemblyOptions, optional
        Filters and block size (``keep_signals`` is ignored); ``tau_limits``: the robot file's torque limits, for
        the saturation warnings (:func:`log_warnings`).
    load_kw : dict, optional
        Keywords of :func:`~symoro_gen.fleet.files.read_experiments`: ``fmt`` (a
        :class:`~symoro_gen.preprocessing.readers.LogFormat`, the command line's data options, for every
        format), ``drive_chain`` (motor-side logs), ``loaded``.
    """
    model = resolve_model(model_ref)
    opts = AssemblyOptions(keep_signals=False) if options is None else options
    try:
        trajs = read_experiments(log.path, int(model.N_JOINTS), start=log.start, stop=log.stop, **(load_kw or {}))
        acc = fold_trajectories(model, trajs, opts, cmap=model_column_map(model))
        notes = log_warnings(log, trajs, opts.tau_limits)
    except Exception as exc:  # noqa: BLE001 - any failure of one log is reported, never fatal to the fleet
        msg = error_line(exc)
        if log.path not in msg:
            msg = f"{log.label}: {msg}"
        return Partial(files=(), acc=None, samples=0, skipped=((log.label, msg),))
    return Partial(files=(log.label,), acc=acc, samples=int(sum(t.n_samples for t in trajs)), warnings=notes)
