"""The observation system ``Y = W chi + rho`` (re-exported: it lives in :mod:`symoro_gen.observations.system`)."""
from ..observations.system import ObservationSystem

__all__ = ["ObservationSystem"]
