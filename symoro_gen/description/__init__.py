"""Robot descriptions: MDH rows, robot files (TOML), SYMORO .par import, validation."""
from .model import FIXED, PRISMATIC, REVOLUTE, DriveChain, MdhRow, RobotDescription, ddq_symbol, dq_symbol, q_symbol
from .par import export_par, import_par, write_robot_toml
from .parse import load_robot, parse_robot, parse_robot_text, resolve_robot_path, robots_dir

__all__ = [
    "FIXED", "PRISMATIC", "REVOLUTE", "DriveChain", "MdhRow", "RobotDescription",
    "q_symbol", "dq_symbol", "ddq_symbol", "load_robot", "parse_robot", "parse_robot_text",
    "resolve_robot_path", "robots_dir", "import_par", "export_par", "write_robot_toml",
]
