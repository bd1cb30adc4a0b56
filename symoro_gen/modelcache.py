"""Get a generated model for a robot name or robot file, generating it when needed."""
from __future__ import annotations

import os
from pathlib import Path

from .description import load_robot
from .description.model import RobotDescription
from .loader import generated_dir, load_model


def cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "symoro_gen" / "models"


def model_for(robot_or_name) -> tuple[RobotDescription, object]:
    """(robot description, generated model) for a robot name in robots/ or a robot .toml path.

    Uses ``generated/<name>/`` when it was generated from the same file (same hash); otherwise
    generates into a user cache folder keyed by the file hash.
    """
    robot = robot_or_name if isinstance(robot_or_name, RobotDescription) else load_robot(robot_or_name)
    cand = generated_dir() / robot.name
    if (cand / "__init__.py").exists():
        m = load_model(cand)
        if getattr(m, "ROBOT_FILE_SHA256", None) == robot.file_hash:
            return robot, m
    target = cache_dir() / robot.file_hash[:16]
    if not (target / robot.name / "__init__.py").exists():
        from .emit.package import emit_robot

        emit_robot(robot, target)
    return robot, load_model(target / robot.name)
