"""The options of a fleet run (:class:`FleetOptions`), taken by :func:`symoro_gen.fleet.engine.identify_fleet` and
by the ``fleet`` workflow (:mod:`symoro_gen.workflows.fleet`), the flags of ``symoro-gen fleet`` without their
dashes. They live beside the engine, which takes them, and below the workflow, which re-exports them.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

from ..errors import OptionError
from ..observations import AssemblyOptions
from ..preprocessing.readers import LogFormat
from ..workflows.base import Options
from .files import FleetError

__all__ = ["CORRECTIONS", "DEFAULT_ALPHA", "DIAGNOSE_METHODS", "SCHEDULER_FORMS", "FleetOptions", "check_scheduler"]

#: family-wise error rate of the flags (Holm) or false-discovery rate (BH)
DEFAULT_ALPHA = 0.01
CORRECTIONS = ("holm", "bh")
DIAGNOSE_METHODS = ("ols", "wls", "tls")

#: the schedulers of :func:`~symoro_gen.fleet.engine.open_client` other than an address
LOCAL_SCHEDULER = re.compile(r"(local|processes|threads)(?::([+-]?\d+))?")
#: the address of a running scheduler: ``tcp://host:port`` (or tls, ucx), ``inproc://...``, or a bare
#: ``host:port`` whose host is ``localhost``, dotted (``10.0.0.2``, ``sched.lan``) or a bracketed IPv6 address
SCHEDULER_ADDRESS = re.compile(r"(tcp|tls|ucx)://[A-Za-z0-9._\[\]:-]*[A-Za-z0-9\]]:\d{1,5}/?|inproc://\S+"
                               r"|(localhost|[A-Za-z0-9-]+(\.[A-Za-z0-9-]+)+|\[[0-9A-Fa-f:]+\]):\d{1,5}")
SCHEDULER_FORMS = "local:N or processes:N (N >= 1 worker processes), threads:N (N >= 1 threads of this process) " \
                  "or the address of a running scheduler, tcp://host:port"


def check_scheduler(scheduler: str | None) -> None:
    """Refuse a ``--scheduler`` that is none of :data:`SCHEDULER_FORMS` before anything starts (a mistyped one, such
    as ``threads:-3``, would be tried as an address for 20 s)."""
    if scheduler is None:
        return
    s = scheduler.strip()
    m = LOCAL_SCHEDULER.fullmatch(s)
    if m:
        if m.group(2) is not None and int(m.group(2)) < 1:
            raise FleetError(f"--scheduler {s}: {m.group(1)}:N needs N >= 1 (the number of workers), "
                             f"got {m.group(2)}")
        return
    if not SCHEDULER_ADDRESS.fullmatch(s):
        raise FleetError(f"--scheduler {s}: not a scheduler: give {SCHEDULER_FORMS}")


@dataclass(frozen=True)
class FleetOptions(Options):
    """Every option of ``fleet`` (see ``symoro-gen fleet --help`` and docs/fleet.md).

    Attributes
    ----------
    scheduler : str, optional
        Dask scheduler address (``tcp://host:8786``), ``"local:N"`` (or ``"processes:N"``) worker processes or
        ``"threads:N"`` in this process, N >= 1 (anything else is refused: :func:`check_scheduler`; default: a
        local cluster of ``min(2, cpus)`` processes; :func:`~symoro_gen.fleet.open_client`).
    alpha : float
        Level of the flags after the multiple-testing correction (0 < alpha < 1).
    correction : {"holm", "bh"}
        Holm (family-wise error rate) or Benjamini-Hochberg (false-discovery rate).
    retries : int
        Times Dask re-runs a task that failed (worker lost, exception).
    cutoff, decimate : optional
        Butterworth cut-off of q [Hz] and decimation factor (default: Gautier's rules per log).
    segment_samples : int, optional
        Cut Parquet logs longer than this (>= 1000) into segments, one task each (a worker's memory is then
        bounded by the segment); only for logs read as they are (no data options).
    chunk_samples : int, optional
        Full-rate samples per block inside a task (bounds the memory of a worker).
    diagnose : bool
        Run the residual diagnosis on each flagged robot's logs of its last flagged day.
    diagnose_method : {"ols", "wls", "tls"}
        The estimator of those diagnoses.
    data_format : LogFormat
        How the logs are read (columns, time base, units, resampling: docs/data-files.md).
    """

    scheduler: str | None = None
    alpha: float = DEFAULT_ALPHA
    correction: str = "holm"
    retries: int = 2
    cutoff: float | None = None
    decimate: int | None = None
    segment_samples: int | None = None
    chunk_samples: int | None = None
    diagnose: bool = False
    diagnose_method: str = "wls"
    data_format: LogFormat = field(default_factory=LogFormat)

    def __post_init__(self) -> None:
        check_scheduler(self.scheduler)
        if not 0 < self.alpha < 1:
            raise FleetError(f"alpha must be in (0, 1), got {self.alpha!r}")
        if self.correction not in CORRECTIONS:
            raise OptionError(f"correction {self.correction!r}: 'holm' or 'bh'")
        if self.diagnose_method not in DIAGNOSE_METHODS:
            raise OptionError(f"diagnose_method {self.diagnose_method!r}: one of {', '.join(DIAGNOSE_METHODS)}")
        if self.retries < 0:
            raise OptionError(f"retries must be >= 0, got {self.retries!r}")
        if self.segment_samples is not None and self.segment_samples < 1000:
            raise FleetError(f"segment_samples must be >= 1000, got {self.segment_samples!r}")
        if self.data_format is None:
            object.__setattr__(self, "data_format", LogFormat())
        self.assembly()  # a bad cut-off, decimation or block size fails here, before any log is read

    def assembly(self) -> AssemblyOptions:
        """The assembly options of every task (filters and block size; no signals kept)."""
        return AssemblyOptions(keep_signals=False, cutoff_hz=self.cutoff, n_d=self.decimate,
                               chunk_samples=self.chunk_samples)
