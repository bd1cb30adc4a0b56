"""Closed-loop robots and robots with coupled (mimic) joints: loop-closure kinematics (coupling rows
included) and the identification model projected on the actuated joints (see
:mod:`symoro_gen.closedloop.kinematics` and :mod:`symoro_gen.closedloop.model`)."""
from .kinematics import ClosedState, ClosureError, LoopKinematics
from .model import ClosedLoopBase, ClosedLoopModel, closed_loop_base

__all__ = ["ClosedState", "ClosureError", "LoopKinematics", "ClosedLoopModel", "ClosedLoopBase", "closed_loop_base"]
