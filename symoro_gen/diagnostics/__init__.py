"""Residual diagnosis: find the structure the declared model leaves in the residual, trace it to a
physical effect, add it, re-identify, and report the error before and after.

Typical use::

    from symoro_gen.diagnostics import DiagnoseSettings, diagnose
    rep = diagnose(model, [traj1, traj3], DiagnoseSettings(method="ols"), validation=[traj2])
    print(rep.summary()); json.dump(rep.to_dict(), f); rep.write_plots("plots/")
"""
from .candidates import ALL, KINDS
from .core import DiagnoseSettings, diagnose
from .inject import inject_effect
from .report import CandidateScore, Effect, ResidualReport
from .structure import StructureItem, residual_structure

__all__ = ["diagnose", "DiagnoseSettings", "ResidualReport", "Effect", "CandidateScore", "StructureItem", "residual_structure",
           "inject_effect", "KINDS", "ALL"]
