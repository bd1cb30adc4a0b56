"""The observations stage: recorded trajectories -> the observation system ``Y = W chi`` (Gautier's
band-pass filtering and parallel decimation, RX-90 paper eq. 14-16) with the provenance of every row
and the filtered signals the later stages (identification errors, diagnosis) use.

* :class:`AssemblyOptions` - every filter, decimation, row-selection and chunking setting, validated once;
* :func:`assemble` (whole system, :class:`Assembly`) and :func:`iter_chunks` (streaming), one signature;
* :class:`ObservationSystem` - ``W``, ``Y``, column names, joint of each row;
* :func:`full_rate_torque`, :func:`raw_error_sums`, :func:`rel_err_raw` - the model at full rate on the
  filtered states against the raw measured torque (the ``rel_err_raw`` metric).
"""
from .assembly import (
           Assembly,
           ExperimentReport,
           ExperimentSignals,
           assemble,
           iter_chunks,
           observation_settings,
)
from .options import AssemblyOptions
from .raw import full_rate_torque, raw_error_sums, rel_err_raw
from .system import ObservationSystem

__all__ = [
           "Assembly",
           "AssemblyOptions",
           "ExperimentReport",
           "ExperimentSignals",
           "ObservationSystem",
           "assemble",
           "full_rate_torque",
           "iter_chunks",
           "observation_settings",
           "raw_error_sums",
           "rel_err_raw",
]
