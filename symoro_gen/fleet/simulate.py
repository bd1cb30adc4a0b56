"""A simulated fleet with known truth (tests, demo, benchmark): N robots of one model, each with its own
parameters (a common physically consistent set scattered by a few % per robot, more in friction), a
few robots whose friction or torque-sensor gain drifts linearly over the days, and one log per robot
and day written as Parquet ``ROOT/<robot>/<day>.parquet`` (read with ``--by "{robot}/{day}.parquet"``).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..atomic import check_replaceable
from ..loader import model_for
from ..simulate import (
    fourier_trajectory,
    random_physical_parameters,
    simulate_recording,
)
from .files import write_parquet

__all__ = ["Drift", "FleetTruth", "simulate_fleet"]


@dataclass(frozen=True)
class Drift:
    """A robot whose standard parameter ``parameter`` (e.g. ``"FV2"``) or torque gain of joint ``joint``
    (``parameter="gain"``) changes by ``rate`` (relative) per day, from ``offset`` (relative) away from its
    own value on the first day: ``x_d = x_0 (1 + offset + rate d)`` (``rate=0``: a unit that is off from
    the start, e.g. a gearbox that was never like the others)."""

    robot: str
    parameter: str
    rate: float
    joint: int | None = None
    offset: float = 0.0


@dataclass(frozen=True, eq=False)
class FleetTruth:
    """What was simulated: files, per-robot standard parameters on day 0, the drifts."""

    root: Path
    robots: tuple[str, ...]
    days: tuple[str, ...]
    files: tuple[Path, ...]
    chi: dict[str, np.ndarray]
    drifts: tuple[Drift, ...] = ()
    standard_names: tuple[str, ...] = field(default=())

    @property
    def drifting(self) -> set[str]:
        return {d.robot for d in self.drifts}


def simulate_fleet(root, robot: str = "scara", *, n_robots: int = 6, n_days: int = 5, duration: float = 20.0,
                   fs: float = 1000.0, drifts: tuple[Drift, ...] | None = None, friction_scatter: float = 0.03,
                   inertia_scatter: float = 0.01, noise: tuple[float, float] = (0.02, 1e-5),
                   seed: int = 0, force: bool = False) -> FleetTruth:
    """Write one Parquet log per robot and day and return the truth.

    Parameters
    ----------
    root : path
        Output folder (``root/<robot>/<day>.parquet``; robots ``r00``, ``r01``..., days ``d00``...).
    robot : str
        Robot model (name of robots/ or a robot file).
    n_robots, n_days : int
    duration, fs : float
        Seconds per log and sampling frequency [Hz].
    drifts : tuple of Drift, optional
        Default: robot ``r01`` viscous friction of the last joint +6 %/day and robot ``r03`` torque gain
        of joint 1 -3 %/day (when the fleet has them).
    friction_scatter, inertia_scatter : float
        Relative standard deviation of the per-robot scatter of the drive (``IA FV FS OFF``) and link
        inertial parameters around the common set.
    noise : (float, float)
        Standard deviations of the white noise on the logged torques [N m] and positions [rad].
    seed : int
    force : bool
        Replace existing logs symoro-gen did not write (a log it wrote is replaced without it: see
        :func:`~symoro_gen.fleet.write_parquet`).

    Returns
    -------
    FleetTruth

    Raises
    ------
    OutputError
        A log exists that symoro-gen did not write and ``force`` is false (checked before any is written).
    """
    desc, model = model_for(robot)
    n = int(model.N_JOINTS)
    rng = np.random.default_rng(seed)
    base = random_physical_parameters(desc, rng)
    names = base.names
    drive = np.array([nm.rstrip("0123456789") in ("IA", "FV", "FS", "OFF") for nm in names])
    robots = tuple(f"r{i:02d}" for i in range(n_robots))
    days = tuple(f"d{i:02d}" for i in range(n_days))
    if drifts is None:
        drifts = tuple(d for d in (Drift("r01", f"FV{n}", 0.06), Drift("r03", "gain", -0.03, joint=1))
                       if d.robot in robots)
    chi, files = {}, []
    root = Path(root)
    for r in robots:
        for d in days:
            check_replaceable(root / r / f"{d}.parquet", force, label="Parquet log")
    for r in robots:
        c = np.asarray(base, float).copy()
        c[drive] *= 1.0 + friction_scatter * rng.standard_normal(drive.sum())
        c[~drive] *= 1.0 + inertia_scatter * rng.standard_normal((~drive).sum())
        chi[r] = c
        for di, d in enumerate(days):
            cd, gains = c.copy(), np.ones(n)
            for dr in drifts:
                if dr.robot != r:
                    continue
                if dr.parameter == "gain":
                    gains[(dr.joint or 1) - 1] *= 1.0 + dr.offset + dr.rate * di
                else:
                    cd[names.index(dr.parameter)] *= 1.0 + dr.offset + dr.rate * di
            mo = fourier_trajectory(n, duration, 1.0 / fs, rng, vmax=1.5, amax=8.0)
            rec = simulate_recording(model, mo.t, mo.q, mo.dq, mo.ddq, cd, gains=gains, noise_q=noise[1],
                                     noise_tau=noise[0], rng=rng, source=f"{r}/{d}")
            path = root / r / f"{d}.parquet"
            write_parquet(path, rec, force=force)
            files.append(path)
    return FleetTruth(root=root, robots=robots, days=days, files=tuple(files), chi=chi, drifts=tuple(drifts),
                      standard_names=tuple(names))
