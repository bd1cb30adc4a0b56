"""Files of a closed-loop robot's package beside the tree's: the base parameters its loops bring.

The package of a robot with ``[[loops]]`` or coupled (mimic) joints is its tree's model (``symoro_gen.closedloop`` projects it
on the actuated joints). When the loop closure is linear in the joint variables (parallelograms),
``closed_loop_base_parameters.md`` gives the closed-loop base parameters in closed form
(:func:`symoro_gen.closedloop.grouping.closed_form_base`, [KB1995]) and ``_closed_loop.py`` the
closed-loop base regressor as NumPy code in the actuated ``q, dq, ddq`` only (Lagrange's equations of
the energy functions, :func:`symoro_gen.closedloop.grouping.closed_loop_regressor`); otherwise the
Markdown file says that the groupings stay numeric and the model stays the numeric projection.
"""
from __future__ import annotations

from ..baseparams.regroup import BaseParameterMap
from ..closedloop.grouping import closed_form_base, closed_form_markdown, closed_loop_kernel_source
from ..description.model import RobotDescription
from ..errors import ModelError

__all__ = ["closed_loop_files"]


def closed_loop_files(robot: RobotDescription, bp: BaseParameterMap) -> dict[str, str]:
    """``{file name: text}`` for the package of ``robot`` (empty without ``[[loops]]`` or coupled joints)."""
    if not robot.constrained:
        return {}
    try:
        cf = closed_form_base(robot, bp.base_names, bp.kept, bp.relations, bp.gravity)
    except ModelError as e:  # the tree package is still written; the closed-loop model reports it at load
        return {"closed_loop_base_parameters.md": closed_form_markdown(robot, None, len(bp.base_names), reason=str(e))}
    files = {"closed_loop_base_parameters.md": closed_form_markdown(robot, cf, len(bp.base_names))}
    if cf is not None:
        files["_closed_loop.py"] = closed_loop_kernel_source(robot, cf)[0]
    return files
