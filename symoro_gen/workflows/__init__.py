"""The library's use cases, one module each: a function taking a robot, data and named options and returning a
frozen results object (``summary()``, ``to_dict()``, ``report(path)``, ``plot()``). The commands of
``symoro-gen`` are thin leaves over them (:mod:`symoro_gen.commands`).

======================  ==================================================================
``identify``            recordings -> base parameters, gains, validation errors
``diagnose``            recordings -> effects the model misses, added, re-identified
======================  ==================================================================
"""
from .base import SCHEMA_VERSION, Options, Results
from .diagnose import DiagnoseOptions, DiagnoseResults, diagnose
from .identify import IdentifyOptions, IdentifyResults, identify

__all__ = ["SCHEMA_VERSION", "DiagnoseOptions", "DiagnoseResults", "IdentifyOptions", "IdentifyResults", "Options",
           "Results", "diagnose", "identify"]
