"""Identification: observation systems, LS / WLS / TLS with statistics, essential parameters,
payload, drive gains, torque-sensor gains, streaming accumulation.

Every function takes :class:`ObservationSystem` values (or an :class:`Accumulator` of streamed
chunks for the plain estimators) and returns an immutable result with ``summary()`` and
``to_dict()`` (the JSON contract: ``parameters`` {names, values, std, rel_std_pct}, ``rel_err``,
``cond``, ``sigma``, ``gains`` {values, rel_std_pct} when identified).

How the ``symoro-gen identify`` options map onto the functions (``unloaded``/``loaded``: systems of
the DATA and --loaded files; or one combined system with ``loaded=None, payload_names=...``)::

    --method M [--essential]           identify(system, method=M, essential=...)
    --validate DATA                    result.rel_err_on(validation_system)        (Table III, filtered)
                                       result.rel_err_raw_on(model, assembly)      (raw measured torque)
    --loaded DATA --payload N=V        fit_with_known_payload(unloaded, loaded, {N: V}, method=M)
    --gains sensor                     sensor_gains(unloaded, loaded, {N: V}, essential=...)  (IDIM-TLS)
    --gains drive                      identify_with_drive_gains(unloaded, loaded, payload, method=M)
    payload mass with robot known      identify_payload(loaded, result, payload_names, gains=...)  (Table IV)
    streamed data                      fit_ols(accumulate(observations.iter_chunks(model, data, options)))

The systems come from the observations stage (:mod:`symoro_gen.observations`: ``assemble(model,
trajectories, AssemblyOptions(...))``); :mod:`.assemble` keeps the former keyword entry points.
"""
from .accumulate import Accumulator, accumulate
from .essential import EssentialResult, essential_parameters
from .estimators import drop_columns, drop_unexcited, fit_ols, fit_tls, fit_wls, unexcited_columns
from .gains import DriveGainsResult, drive_gains, identify_with_drive_gains, sensor_gains
from .method import identify
from .observation import ObservationSystem
from .payload import fit_with_known_payload, identify_payload
from .result import EliminationStep, Gains, IdentificationResult
from .systems import apply_gains, fix_parameters, select_rows, stack_systems

__all__ = [
    "Accumulator", "accumulate", "EssentialResult", "essential_parameters", "fit_ols", "fit_tls",
    "fit_wls", "identify", "DriveGainsResult", "drive_gains", "identify_with_drive_gains",
    "sensor_gains", "ObservationSystem", "fit_with_known_payload", "identify_payload",
    "EliminationStep", "Gains", "IdentificationResult", "apply_gains", "fix_parameters",
    "select_rows", "stack_systems", "drop_columns", "drop_unexcited", "unexcited_columns",
]
