"""Files of a closed-loop robot's package beside the tree's: the base parameters its loops bring.

The package of a robot with ``[[loops]]`` is its tree's model (``symoro_gen.closedloop`` projects it
on the actuated joints). When the loop closure is linear in the joint variables (parallelograms),
``closed_loop_base_parameters.md`` gives the closed-loop base parameters in closed form
(:func:`symoro_gen.closedloop.grouping.closed_form_base`, [KB1995]); otherwise it says that the
groupings stay numeric.
"""
from __future__ import annotations

from ..baseparams.regroup import BaseParameterMap
from ..closedloop.grouping import closed_form_base, closed_form_markdown
from ..description.model import RobotDescription

__all__ = ["closed_loop_files"]


def closed_loop_files(robot: RobotDescription, bp: BaseParameterMap) -> dict[str, str]:
    """``{file name: text}`` for the package of ``robot`` (empty without ``[[loops]]``)."""
    if not robot.loops:
        return {}
    cf = closed_form_base(robot, bp.base_names, bp.kept, bp.relations, bp.gravity)
    return {"closed_loop_base_parameters.md": closed_form_markdown(robot, cf, len(bp.base_names))}
