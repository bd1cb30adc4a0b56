"""symoro_gen: MDH robot table -> symbolic identification model -> identified parameters.

``load_model`` is imported with the package; the workflows (``identify``, ``fleet``, ``export_urdf``...) and
their option and result types load on first use, so that ``import symoro_gen`` stays light (no SymPy, no
SciPy)::

    import symoro_gen
    res = symoro_gen.identify("lwr4", ["a.csv", "c.csv"], validate=["b.csv"], method="wls")
    print(res.summary())

``symoro_gen.fleet`` is the fleet package (``symoro_gen.fleet.simulate_fleet``...), callable as the ``fleet``
workflow: ``symoro_gen.fleet("scara", ["logs"], by="{robot}/{day}.parquet")``; ``symoro_gen.excite`` likewise is
the excitation package, callable as the ``excite`` workflow. ``symoro_gen.read_recording`` is the readers' front
door (:func:`symoro_gen.preprocessing.readers.read_recording`: every format, ROS bags with ``topic=``, ``stamp=``...)
returning its pair ``(trajectories, load_report)`` as a results object (:mod:`symoro_gen.workflows.read`).
"""
import importlib

from .loader import load_model
from .version import __version__

#: names served by symoro_gen.workflows on first use
_WORKFLOWS = ("identify", "IdentifyOptions", "IdentifyResults", "diagnose", "DiagnoseOptions", "DiagnoseResults",
              "inspect", "InspectOptions", "InspectResults", "excite", "ExciteOptions", "ExciteResults",
              "fleet", "FleetOptions", "FleetResults", "export_urdf", "export_mjcf", "export_par", "ExportResults",
              "read_recording", "RecordingResults")

__all__ = ["load_model", "__version__", *_WORKFLOWS]


def __getattr__(name: str):
    if name in ("fleet", "excite"):  # the packages, callable as the workflows (their __init__)
        return importlib.import_module(f"symoro_gen.{name}")
    if name in _WORKFLOWS:
        return getattr(importlib.import_module("symoro_gen.workflows"), name)
    raise AttributeError(f"module 'symoro_gen' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(_WORKFLOWS))
