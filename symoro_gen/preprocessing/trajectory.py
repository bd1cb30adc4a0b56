"""Measured (or simulated) joint trajectories: the value type data loaders return, and
:func:`hold_back` (each experiment split in time, the last part held back for validation)."""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np


def _frozen_array(x, name, ndim):
    """A read-only float array: copied, unless it already is a read-only float64 array (for
    example a memory-mapped file opened read-only), which nobody can change through us."""
    if x is None:
        return None
    if isinstance(x, np.ndarray) and x.dtype == np.float64 and not x.flags.writeable:
        a = x
    else:
        a = np.array(x, dtype=float, copy=True)
    if a.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {a.shape}")
    a.setflags(write=False)
    return a


@dataclass(frozen=True)
class Trajectory:
    """One experiment (one file): joint-side samples.

    Attributes
    ----------
    t : ndarray, shape (N,)
        Time [s], strictly increasing.
    q : ndarray, shape (N, n)
        Joint positions [rad or m], joint side, MDH convention.
    tau : ndarray, shape (N, n)
        Joint torques/forces [N m or N] (or the raw signal v_tau whose gain is identified).
    dq, ddq : ndarray, shape (N, n), optional
        Velocities and accelerations when the file provides them.
    source : str
        File name (used in messages).
    loaded : bool
        True when the payload is mounted during this experiment.
    meta : dict
        Free-form provenance.
    deflection : ndarray, shape (N, n), optional
        Measured joint deflection [rad or m] of a recording with two position sources (motor- and
        link-side encoders): motor position mapped to the joint side (motor / ratio) minus the
        link-side position ``q``. A signal for the diagnosis (elasticity seen directly).
    """

    t: np.ndarray
    q: np.ndarray
    tau: np.ndarray
    dq: np.ndarray | None = None
    ddq: np.ndarray | None = None
    source: str = "<memory>"
    loaded: bool = False
    meta: dict = field(default_factory=dict)
    deflection: np.ndarray | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", _frozen_array(self.t, "t", 1))
        for k in ("q", "tau", "dq", "ddq", "deflection"):
            object.__setattr__(self, k, _frozen_array(getattr(self, k), k, 2))
        N = self.t.shape[0]
        for k in ("q", "tau", "dq", "ddq", "deflection"):
            a = getattr(self, k)
            if a is not None and a.shape[0] != N:
                raise ValueError(f"{self.source}: {k} has {a.shape[0]} samples, t has {N}")
        if self.tau.shape[1] != self.q.shape[1]:
            raise ValueError(f"{self.source}: q has {self.q.shape[1]} joints, tau has {self.tau.shape[1]}")

    @property
    def n_samples(self) -> int:
        return self.t.shape[0]

    @property
    def n_joints(self) -> int:
        return self.q.shape[1]

    @property
    def dt(self) -> float:
        """Median sampling period [s]."""
        return float(np.median(np.diff(self.t)))


#: fewest samples of a part :func:`hold_back` cuts from a piece of a file split in several (shorter: the whole
#: piece goes to the other side); the fewest samples filtering takes (``readers.common.MIN_SAMPLES``)
MIN_PART = 32


def _recording(tr: Trajectory, k: int) -> str:
    """The file (or split-file spec) an experiment was read from with the data options: experiments of one
    file share it; any other experiment (the plain reading, arrays) is a recording of its own."""
    rec = tr.meta.get("recording")
    return f"file {rec}" if rec is not None else f"experiment {k}"


def hold_back(trajectories: Sequence[Trajectory], fraction: float
              ) -> tuple[tuple[Trajectory, ...], tuple[Trajectory, ...]]:
    """Hold back the last ``fraction`` of each recording FILE for validation, the first ``1 - fraction`` for
    identification.

    A file that reading split into several experiments (gaps longer than ``--max-gap``, resets of the clock:
    the experiments share ``meta["recording"]``) is held back as a whole: the cut lies at ``1 - fraction`` of
    its samples counted in file order (of its recorded duration: the pieces are on one uniform grid),
    experiments entirely after the cut go to validation, those before it to identification, and the one
    spanning it is cut (a part shorter than ``MIN_PART`` samples goes with the rest of its piece). A file read
    as one experiment is cut at ``round(N (1 - fraction))``.
    """
    if not 0 < fraction < 1:
        raise ValueError(f"the held-back fraction must lie between 0 and 1, got {fraction:g}")
    groups: dict[str, list[Trajectory]] = {}
    for k, tr in enumerate(trajectories):
        groups.setdefault(_recording(tr, k), []).append(tr)
    first, last = f"first {100 * (1 - fraction):.3g} %", f"last {100 * fraction:.3g} %"
    ident, valid = [], []

    def part(tr, a, b, tag):
        cut = {f: (getattr(tr, f)[a:b] if getattr(tr, f) is not None else None)
               for f in ("t", "q", "tau", "dq", "ddq", "deflection")}
        meta = {**tr.meta, "part": tag, "held_from": tr.source}
        if meta.get("q_ref") is not None and len(meta["q_ref"]) == tr.n_samples:  # a recorded reference
            meta["q_ref"] = meta["q_ref"][a:b]
        return replace(tr, **cut, source=f"{tr.source} [{tag}]", meta=meta)

    for pieces in groups.values():
        if len(pieces) == 1:
            tr = pieces[0]
            k = int(round(tr.n_samples * (1 - fraction)))
            ident.append(part(tr, 0, k, first))
            valid.append(part(tr, k, tr.n_samples, last))
            continue
        total = sum(tr.n_samples for tr in pieces)
        cut = int(round(total * (1 - fraction)))
        start = 0
        tag_i, tag_v = f"{first} of the file", f"{last} of the file"
        for tr in pieces:
            k = cut - start  # samples of this piece before the cut
            start += tr.n_samples
            if k >= tr.n_samples or (k >= tr.n_samples - MIN_PART and k >= MIN_PART):
                ident.append(part(tr, 0, tr.n_samples, tag_i))
            elif k <= 0 or k < MIN_PART:
                valid.append(part(tr, 0, tr.n_samples, tag_v))
            else:
                ident.append(part(tr, 0, k, tag_i))
                valid.append(part(tr, k, tr.n_samples, tag_v))
    return tuple(ident), tuple(valid)


def note_hold_back(reports: Sequence, identification: Sequence[Trajectory], validation: Sequence[Trajectory],
                   fraction: float) -> tuple:
    """The load reports (:class:`~symoro_gen.preprocessing.readers.LoadReport`) with a note of what
    :func:`hold_back` did with each file: how many experiments went to validation and to identification, and
    why (the last ``fraction`` of the file's duration, whatever the experiments reading split it into)."""
    pct = f"{100 * fraction:.3g} %"
    out = []
    for r in reports:
        iv = [tr for tr in identification if _held_file(tr) == r.file]
        vv = [tr for tr in validation if _held_file(tr) == r.file]
        if not vv:
            out.append(r)
            continue
        sv, si = sum(tr.n_samples for tr in vv), sum(tr.n_samples for tr in iv)
        start = min(float(tr.t[0]) for tr in vv)
        if r.experiments <= 1:
            note = (f"--validate-fraction {fraction:g}: the last {pct} of the file held back for validation ({sv} of "
                    f"{sv + si} samples, from t = {start:.6g} s)")
        else:
            labels = ", ".join(_part_label(tr, r.samples, r.experiments) for tr in vv)
            note = (f"--validate-fraction {fraction:g}: the last {pct} of the file's duration held back for "
                    f"validation, not {pct} of each of the {r.experiments} experiments the file was split into: "
                    f"{len(vv)} validation experiment(s) (experiment {labels}; {sv} samples from t = {start:.6g} s), "
                    f"{len(iv)} identification experiment(s) ({si} samples)")
        out.append(replace(r, notes=(*r.notes, note)))
    return tuple(out)


def _held_file(tr: Trajectory):
    """The file a part cut by :func:`hold_back` comes from (the load report's ``file``)."""
    return tr.meta.get("recording", tr.meta.get("held_from"))


def _part_label(tr: Trajectory, samples: Sequence[int], experiments: int) -> str:
    """``4/5 (its last 499 samples)``: the experiment a part comes from, and how much of it."""
    e = int(tr.meta.get("experiment", 0))
    whole = samples[e - 1] if 0 < e <= len(samples) else tr.n_samples
    return f"{e}/{experiments}" + (f" (its last {tr.n_samples} samples)" if tr.n_samples < whole else "")
