"""Identification: observation systems, LS / WLS / TLS with statistics, essential parameters,
payload, drive gains, torque-sensor gains, streaming accumulation.

Typical use::

    from symoro_gen.identification import identify, sensor_gains
    res = identify(system, method="wls", essential=True)
    print(res.summary()); json.dump(res.to_dict(), f)
"""
from .accumulate import Accumulator, accumulate
from .essential import EssentialResult, essential_parameters
from .estimators import fit_ols, fit_tls, fit_wls, identify
from .gains import DriveGainsResult, drive_gains, identify_with_drive_gains, sensor_gains
from .observation import ObservationSystem
from .payload import fit_with_known_payload, identify_payload
from .result import EliminationStep, Gains, IdentificationResult
from .systems import apply_gains, fix_parameters, select_rows, stack_systems

__all__ = [
    "Accumulator", "accumulate", "EssentialResult", "essential_parameters", "fit_ols", "fit_tls",
    "fit_wls", "identify", "DriveGainsResult", "drive_gains", "identify_with_drive_gains",
    "sensor_gains", "ObservationSystem", "fit_with_known_payload", "identify_payload",
    "EliminationStep", "Gains", "IdentificationResult", "apply_gains", "fix_parameters",
    "select_rows", "stack_systems",
]
