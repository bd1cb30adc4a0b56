"""Data in and pre-processing: readers of recordings (:mod:`.readers`), drive-chain mapping, band-pass
derivatives, parallel decimation."""
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
from .readers import (
    DataSpec,
    DataWarning,
    LoadReport,
    LogFormat,
    load_trajectories,
    load_trajectory,
    make_format,
    parse_data_spec,
    read_recording,
    read_recordings,
)
from .trajectory import Trajectory, hold_back, note_hold_back

__all__ = [
    "Trajectory", "load_trajectory", "load_trajectories", "parse_data_spec", "DataSpec", "DataWarning",
    "motor_to_joint", "joint_to_motor", "FilterSettings", "choose_filter_settings", "estimate_dynamics_bandwidth",
    "lowpass_positions", "differentiate", "filter_and_differentiate", "decimate", "parallel_decimate",
    "LogFormat", "LoadReport", "make_format", "read_recording", "read_recordings", "hold_back",
    "note_hold_back",
]
