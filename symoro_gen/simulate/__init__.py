"""Simulation for demos and tests (the truth is known): exciting trajectories, random physical
parameters and payloads, synthetic recordings with gains and noise."""
from .numeric_model import NumericModel, numeric_model
from .parameters import (
    ParameterSet,
    check_physical_consistency,
    random_link_inertial,
    random_payload,
    random_physical_parameters,
)
from .recording import simulate_recording, true_torques, write_recording_csv
from .trajectories import FourierSeries, Motion, double_s_times, fourier_trajectory, ptp_trajectory, random_states

__all__ = [
    "Motion", "FourierSeries", "fourier_trajectory", "ptp_trajectory", "double_s_times", "random_states", "ParameterSet",
    "random_physical_parameters", "random_payload", "random_link_inertial", "check_physical_consistency",
    "simulate_recording", "true_torques", "write_recording_csv", "NumericModel", "numeric_model",
]
