"""The library's use cases, one module each: a function taking a robot, data and named options and returning a
frozen results object (``summary()``, ``to_dict()``, ``report(path)``, ``plot()``). The commands of
``symoro-gen`` are thin leaves over them (:mod:`symoro_gen.commands`).

======================  ==================================================================
``identify``            recordings -> base parameters, gains, validation errors
``diagnose``            recordings -> effects the model misses, added, re-identified
``inspect``             recordings -> what they can give: sampling, gaps, standstill, cond(W), %sigma
``excite``              robot and its limits -> an optimal excitation trajectory
``fleet``               the logs of a fleet -> per-day and fleet estimates, drift flags (Dask)
``export_urdf``         robot (and an identification) -> URDF text, notes, sidecar
``export_mjcf``         robot (and an identification) -> MuJoCo MJCF text, notes, sidecar
``export_par``          robot -> SYMORO+/OpenSYMORO .par text
``read_recording``      one DATA file -> its experiments and what reading did (the readers' pair, a results object)
======================  ==================================================================

The names are imported on first use (PEP 562): each workflow loads only what it needs (the exports stay free
of SciPy, so the light commands start quickly), and the engines below a workflow (the fleet engine) may use
:mod:`symoro_gen.workflows.base` without an import circle through this package. ``identify``, ``diagnose``, ``inspect``, ``excite``
and ``fleet`` are the functions, as an eager ``from .identify import identify`` would bind them, even once their modules are
imported (:class:`_Package`).
"""
from __future__ import annotations

import importlib
import sys
import types
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from .base import SCHEMA_VERSION, Options, Results
    from .diagnose import DiagnoseOptions, DiagnoseResults, diagnose
    from .excite import ExciteOptions, ExciteResults, excite
    from .export import ExportResults, export_mjcf, export_par, export_urdf
    from .fleet import FleetOptions, FleetResults, fleet
    from .identify import IdentifyOptions, IdentifyResults, identify
    from .inspect import InspectOptions, InspectResults, inspect
    from .read import RecordingResults, read_recording

_WHERE = {
    "SCHEMA_VERSION": "base", "Options": "base", "Results": "base",
    "IdentifyOptions": "identify", "IdentifyResults": "identify", "identify": "identify",
    "DiagnoseOptions": "diagnose", "DiagnoseResults": "diagnose", "diagnose": "diagnose",
    "InspectOptions": "inspect", "InspectResults": "inspect", "inspect": "inspect",
    "ExciteOptions": "excite", "ExciteResults": "excite", "excite": "excite",
    "FleetOptions": "fleet", "FleetResults": "fleet", "fleet": "fleet",
    "ExportResults": "export", "export_urdf": "export", "export_mjcf": "export", "export_par": "export",
    "RecordingResults": "read", "read_recording": "read",
}

__all__ = ["SCHEMA_VERSION", "DiagnoseOptions", "DiagnoseResults", "ExciteOptions", "ExciteResults", "ExportResults",
           "FleetOptions", "FleetResults", "IdentifyOptions", "IdentifyResults", "InspectOptions", "InspectResults",
           "Options", "RecordingResults", "Results", "diagnose", "excite", "export_mjcf", "export_par", "export_urdf",
           "fleet", "identify", "inspect", "read_recording"]


def __getattr__(name: str) -> Any:
    mod = _WHERE.get(name)
    if mod is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{mod}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))


class _Package(types.ModuleType):
    """This package: the import system binds a submodule to its name here once it is loaded; a workflow whose
    module has its name (``identify.py`` and ``identify``) is bound instead."""

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, types.ModuleType) and _WHERE.get(name) == name and hasattr(value, name):
            value = getattr(value, name)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _Package
