"""Former home of the assembly stage; it lives in :mod:`symoro_gen.observations` now.

These keyword-style entry points are kept for scripts written against them: each builds an
:class:`~symoro_gen.observations.AssemblyOptions` from its keywords (unknown ones raise ``TypeError``)
and calls :func:`symoro_gen.observations.assemble` / :func:`~symoro_gen.observations.iter_chunks`.
"""
from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

from ..model import IdentificationModel
from ..observations.assembly import (
    Assembly,
    ExperimentReport,
    ExperimentSignals,
    assemble,
    iter_chunks,
)
from ..observations.assembly import (
    observation_settings as _observation_settings,
)
from ..observations.options import AssemblyOptions
from ..observations.system import ObservationSystem
from ..preprocessing.filtering import FilterSettings
from ..preprocessing.trajectory import Trajectory

__all__ = [
    "ExperimentReport",
    "ExperimentSignals",
    "Assembly",
    "AssemblyOptions",
    "observation_settings",
    "assemble_observation",
    "build_observation",
    "iter_observation_chunks",
]


def observation_settings(trajectory: Trajectory, **kw: Any) -> FilterSettings:
    """The :class:`FilterSettings` the assembly uses for ``trajectory`` (keywords of :class:`AssemblyOptions`)."""
    return _observation_settings(trajectory, AssemblyOptions.from_keywords(**kw))


def iter_observation_chunks(model: IdentificationModel, trajectories: Trajectory | Iterable[Trajectory], *,
                            on_experiment: Callable[[ExperimentReport], None] | None = None, progress=None,
                            **kw: Any) -> Iterator[ObservationSystem]:
    """:func:`symoro_gen.observations.iter_chunks` with the options as keywords."""
    return iter_chunks(model, trajectories, AssemblyOptions.from_keywords(**kw), on_experiment=on_experiment,
                       progress=progress)


def assemble_observation(model: IdentificationModel, trajectories, *, progress=None, **kw: Any) -> Assembly:
    """:func:`symoro_gen.observations.assemble` with the options as keywords."""
    return assemble(model, trajectories, AssemblyOptions.from_keywords(**kw), progress=progress)


def build_observation(model: IdentificationModel, trajectories, *, progress=None, **kw: Any) -> ObservationSystem:
    """The observation system ``Y = W chi`` of the experiments (:func:`assemble_observation` ``.system``;
    no full-rate signals kept)."""
    kw.setdefault("keep_signals", False)
    return assemble_observation(model, trajectories, progress=progress, **kw).system
