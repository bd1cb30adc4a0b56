"""A floating-base robot's contact sensors as candidates of the fixed-base loop on its rows (docs/floating-base.md,
"Contact sensors and drives in one selection").

:class:`ContactRows` is :class:`~symoro_gen.identification.floating.RowsAsJoints` (the ``6 + n`` rows of each sample as
the "joints" of a fixed-base model) with the logs' contact wrenches, so that the loop
(:func:`symoro_gen.diagnostics.diagnose`, whose :func:`~symoro_gen.diagnostics.candidates.make_families` asks the
model for ``candidate_families``) offers, besides the drive effects of the joint rows:

* per contact frame ``c``, an **offset** of its sensor (``f_measured = f + o``, six components in its axes): the
  measured side of the rows ``S^T tau + sum_c J_c^T f_c`` gains ``J_c^T o``, columns ``J_c^T e_i``;
* per contact frame, a **gain** error of its sensor (``f_measured = (1 + g) f``): the rows gain
  ``gamma J_c^T f_measured``, ``gamma = g / (1 + g)``, column ``J_c^T f_measured``;

each on every row its wrench reaches ([AVN2014]: the base-link rows always, the joint rows of the joints between the
base and the contact frame), and competing with the drive effects in the same rounds, the same held-out acceptance
and the same plausibility verdicts. On a joint row a contact wrench reaches, the drive's ``gain`` and ``time_delay``
columns are built on the drive's own torque ``tau_j = (Y chi)_j - (J_c^T f_c)_j`` (the model torque of the row minus
the measured contact term, both low-passed alike), not on the row's model torque ``tau_j + (J_c^T f_c)_j``: a drive's
gain or delay acts on ``tau_j`` alone.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..diagnostics.candidates import CONTACT_KINDS, Family, FitContext
from ..diagnostics.frame import MODEL_TORQUE_BANDWIDTH_FACTOR, Experiment, Frame
from ..errors import IdentificationError
from ..identification.floating import RowsAsJoints
from ..preprocessing.filtering import filter_and_differentiate

__all__ = ["ContactLog", "ContactRows", "COMPONENTS"]

#: the six components of a contact sensor's offset (its frame's axes)
COMPONENTS = ("fx", "fy", "fz", "mx", "my", "mz")


@dataclass(frozen=True, eq=False)
class ContactLog:
    """One log's contact columns at full rate, on the samples of its loop trajectory.

    ``source``: the trajectory's source (the loop's experiments are named from it, their held-out parts with a
    suffix); ``t`` (N,) its times; ``columns``: per contact frame (N, 6 + n, 7), ``J_c^T e_i`` then ``J_c^T f_c``."""

    source: str
    t: NDArray[np.float64]
    columns: Mapping[str, NDArray[np.float64]]

    def rows_of(self, ex: Experiment) -> NDArray[np.intp]:
        """The samples of this log an experiment of the loop holds: its times (counted from the trajectory's
        first) matched to the log's, to a tenth of a sample interval."""
        tl = self.t - self.t[0]
        i = np.clip(np.searchsorted(tl, ex.t), 1, max(tl.size - 1, 1))
        i = np.where(np.abs(tl[i - 1] - ex.t) <= np.abs(tl[i] - ex.t), i - 1, i)
        dt = float(np.min(np.diff(tl))) if tl.size > 1 else 1.0
        if np.max(np.abs(tl[i] - ex.t), initial=0.0) > 0.1 * dt:
            raise IdentificationError(f"{ex.source}: its samples are not those of the log {self.source}")
        out: NDArray[np.intp] = i.astype(np.intp)
        return out


@dataclass(frozen=True, eq=False)
class ContactRows(RowsAsJoints):
    """:class:`~symoro_gen.identification.floating.RowsAsJoints` with the logs' contact wrenches: the model
    offers the loop the contact sensors' offsets and gains and builds the drive gain and delay columns of the joint
    rows a contact reaches on the drive's torque alone (module docstring)."""

    logs: tuple[ContactLog, ...] = ()
    #: per contact frame, the rows (0-based positions) its wrench reaches in the logs
    reach: Mapping[str, tuple[int, ...]] = field(default_factory=dict)

    @classmethod
    def with_contacts(cls, rows: RowsAsJoints, logs: Sequence[ContactLog]) -> ContactRows:
        """``rows`` with the contact columns of ``logs``; a frame reaches a row where its Jacobian's column is not
        zero on some sample (the base rows always)."""
        reach: dict[str, tuple[int, ...]] = {}
        for log in logs:
            for name, C in log.columns.items():
                hit = set(np.flatnonzero(np.any(C[:, :, :6] != 0, axis=(0, 2))).tolist()) | set(range(6))
                reach[name] = tuple(sorted(set(reach.get(name, ())) | hit))
        return cls(rows.model, rows.kept, rows.names, tuple(logs), reach)

    def log_of(self, ex: Experiment) -> ContactLog:
        """The log an experiment of the loop comes from (the longest source its own begins with)."""
        best = [log for log in self.logs if ex.source.startswith(log.source)]
        if not best:
            raise IdentificationError(f"{ex.source}: no contact log of that source")
        return max(best, key=lambda log: len(log.source))

    def _sensor_family(self, name: str, kind: str) -> Family:
        cols = slice(0, 6) if kind == "contact_offset" else slice(6, 7)
        params = COMPONENTS if kind == "contact_offset" else ("gamma",)
        rows = self.reach[name]

        def columns(ex: Experiment) -> dict[int, NDArray[np.float64]]:
            log = self.log_of(ex)
            C = log.columns[name][log.rows_of(ex)]
            return {r: C[:, r, cols] for r in rows}

        def build(fr: Frame, ctx: FitContext) -> list[NDArray[np.float64]]:
            return [fr.full_rate_columns(columns, len(params))]
        return Family(kind, None, params, build, variant=name, reveal="t", rows=rows)

    def contact_torque(self, ex: Experiment, r: int) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """Row ``r``'s measured contact term ``sum_c (J_c^T f_c)_r`` of experiment ``ex`` and its time derivative,
        low-passed as the model torque ``tau_hat`` (:func:`symoro_gen.diagnostics.frame.attach_model_torque`: the
        same zero-phase Butterworth), so that ``tau_hat - it`` is the drive's torque with the smoothing of both."""
        log = self.log_of(ex)
        idx = log.rows_of(ex)
        c = sum((log.columns[nm][idx, r, 6] for nm in log.columns), np.zeros(idx.size))
        st = ex.settings
        fc = min(st.cutoff_hz, MODEL_TORQUE_BANDWIDTH_FACTOR * st.dynamics_bandwidth_hz)
        tf, d1, _ = filter_and_differentiate(c[:, None], st.fs, fc, st.order, source=ex.source)
        return np.asarray(tf, float)[:, 0], np.asarray(d1, float)[:, 0]

    def _drive_family(self, fam: Family) -> Family:
        """``fam`` (a ``gain`` or ``time_delay`` of joint row ``r``) built on the drive's torque alone: the row's
        model torque minus its contact term (``gain``: ``tau_hat_r - c_r``; ``time_delay``: ``-(dtau_hat_r -
        dc_r)``, [GB-gains] eq. 4 with the contact wrench on the measured side)."""
        r = fam.joint
        assert r is not None
        delay = fam.kind == "time_delay"

        def columns(ex: Experiment) -> dict[int, NDArray[np.float64]]:
            c, dc = self.contact_torque(ex, r)
            assert ex.tau_hat is not None and ex.dtau_hat is not None   # attached before the candidates are built
            col = -(ex.dtau_hat[:, r] - dc) if delay else ex.tau_hat[:, r] - c
            return {r: col[:, None]}

        def build(fr: Frame, ctx: FitContext) -> list[NDArray[np.float64]]:
            return [fr.full_rate_columns(columns, 1)]
        return Family(fam.kind, r, fam.params, build, reveal=fam.reveal, depends_on_fit=True,
                      info=(("on", "drive torque"),))

    def candidate_families(self, frame: Frame, kinds: set[str], families: Sequence[Family]) -> list[Family]:
        """The loop's families on these rows (:func:`symoro_gen.diagnostics.candidates.make_families`): the drive
        ``gain`` and ``time_delay`` of a joint row a contact reaches rebuilt on the drive's torque
        (:meth:`_drive_family`), and each contact sensor's offset and gain (:data:`CONTACT_KINDS`) on the rows its
        wrench reaches."""
        reached = {r for rows in self.reach.values() for r in rows if r >= 6}
        out = [self._drive_family(f) if f.kind in ("gain", "time_delay") and f.joint in reached else f
               for f in families]
        for name in self.reach:
            out += [self._sensor_family(name, kind) for kind in CONTACT_KINDS]
        return out
