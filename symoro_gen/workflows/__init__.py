"""The library's use cases, one module each: a function taking a robot, data and named options and returning a
frozen results object (``summary()``, ``to_dict()``, ``report(path)``, ``plot()``). The commands of
``symoro-gen`` are thin leaves over them (:mod:`symoro_gen.commands`).

======================  ==================================================================
``identify``            recordings -> base parameters, gains, validation errors
======================  ==================================================================
"""
from .base import SCHEMA_VERSION, Options, Results
from .identify import IdentifyOptions, IdentifyResults, identify

__all__ = ["SCHEMA_VERSION", "IdentifyOptions", "IdentifyResults", "Options", "Results", "identify"]
