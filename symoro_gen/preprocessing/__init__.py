"""Data in and pre-processing: loaders, drive-chain mapping, band-pass derivatives, parallel decimation."""
from .drive_chain import joint_to_motor, motor_to_joint
from .filtering import (
    FilterSettings,
    choose_filter_settings,
    decimate,
    differentiate,
    estimate_dynamics_bandwidth,
    filter_and_differentiate,
    lowpass_positions,
    parallel_decimate,
)
from .load import DataSpec, DataWarning, load_trajectories, load_trajectory, parse_data_spec
from .logformat import LoadReport, LogFormat, hold_back, load_log, load_logs, make_format
from .trajectory import Trajectory

__all__ = [
    "Trajectory", "load_trajectory", "load_trajectories", "parse_data_spec", "DataSpec", "DataWarning",
    "motor_to_joint", "joint_to_motor", "FilterSettings", "choose_filter_settings", "estimate_dynamics_bandwidth",
    "lowpass_positions", "differentiate", "filter_and_differentiate", "decimate", "parallel_decimate",
    "LogFormat", "LoadReport", "make_format", "load_log", "load_logs", "hold_back",
]
