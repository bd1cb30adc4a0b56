"""Fleet identification (issue 12): many robots of one model, one log per robot and day, identified on
Dask distributed with exact TSQR reductions, pooled into a fleet model, and the robots whose parameters
drift away from the fleet flagged (random-effects distance and trend over days, Holm-corrected).

Needs the ``fleet`` extra (``dask[distributed]``, ``pyarrow``). See docs/fleet.md.
"""
from .engine import DEFAULT_ALPHA, Estimate, FleetResult, identify_fleet, open_client
from .files import (
           FleetError,
           LogFile,
           compile_pattern,
           discover,
           read_log,
           write_parquet,
)
from .kernel import Partial, merge_accumulators, merge_partials, process_file
from .simulate import Drift, FleetTruth, simulate_fleet

__all__ = ["DEFAULT_ALPHA", "Drift", "Estimate", "FleetError", "FleetResult", "FleetTruth", "LogFile", "Partial",
           "compile_pattern", "discover", "identify_fleet", "merge_accumulators", "merge_partials", "open_client",
           "process_file", "read_log", "simulate_fleet", "write_parquet"]
