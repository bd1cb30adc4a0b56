"""The built-in example (``make demo``): torque-sensor gain calibration of a KUKA LWR4 by IDIM-TLS,
on simulated recordings whose truth is known (LWR4 paper, Sec. III-IV).

1. the generated LWR4 model (payload as link 8), nominal link values from the robot file (URDF);
2. exciting trajectories without and with a 4.6136 kg payload, torque sensors with gains != 1
   (the values of Table II), noise on positions and torques;
3. band-pass filtering, parallel decimation, observation matrix with the payload columns;
4. global IDIM-TLS of the 7 sensor gains, the base parameters and the unknown payload parameters,
   with only the payload mass known; statistics of eq. 14-16;
5. cross-validation on a third recording (relative error norms per joint, Table III).
"""
from __future__ import annotations

import os

import numpy as np

from .description.inertia import standard_from_com
from .errors import ModelError, OptionError
from .identification import sensor_gains
from .identification.assemble import build_observation
from .loader import model_for
from .simulate.recording import simulate_recording
from .simulate.trajectories import fourier_trajectory

TRUE_GAINS = np.array([1.02, 1.01, 1.02, 1.02, 1.02, 1.05, 0.99])  # Table II of the LWR4 paper
PAYLOAD_MASS = 4.6136
DT = 0.005  # 200 Hz, as the LWR4 recorder
N_RECORDINGS = 3
#: working memory of the demo per sample and joint of one recording [bytes]: measured 590 B for the
#: three recordings together (peak RSS of ``demo --duration 10`` and ``--duration 60``), i.e. about
#: 25 float64 per sample-joint-recording; 32 float64 leave a margin.
BYTES_PER_SAMPLE_JOINT = 32 * 8


def available_memory() -> int | None:
    """Memory the demo may use [bytes]: ``MemAvailable`` of ``/proc/meminfo`` (Linux), else the
    physical memory (``os.sysconf``), else None (unknown: no check)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):
        return None


def demo_memory(duration: float, n_joints: int = 7) -> float:
    """Estimated working memory [bytes] of the demo for ``duration`` seconds per recording:
    samples x joints x recordings x :data:`BYTES_PER_SAMPLE_JOINT`."""
    return (duration / DT + 1) * n_joints * N_RECORDINGS * BYTES_PER_SAMPLE_JOINT


def check_duration(duration: float, n_joints: int = 7, available: int | None = None) -> None:
    """Refuse, before any work, a ``--duration`` whose recordings would not fit in memory.

    Raises
    ------
    OptionError
        ``--duration D: ...`` with the estimated need, the memory available and the longest
        duration that fits (one line).
    """
    if not (np.isfinite(duration) and duration > 0):
        raise OptionError(f"--duration {duration:g}: must be a positive number of seconds")
    available = available_memory() if available is None else available
    if available is None:
        return
    need = demo_memory(duration, n_joints)
    if need > available:
        longest = max(int(available / demo_memory(1.0, n_joints)), 0)
        raise OptionError(f"--duration {duration:g}: the demo's {N_RECORDINGS} recordings at {1 / DT:.0f} Hz would need "
                          f"about {size_text(need)} of memory, {size_text(available)} is available; use --duration {longest} "
                          "or less")


def size_text(b: float) -> str:
    """A number of bytes in KiB, MiB, GiB or TiB (3 significant digits)."""
    for unit, k in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20)):
        if b >= k:
            return f"{b / k:.3g} {unit}"
    return f"{b / 2**10:.3g} KiB"


def demo_payload() -> np.ndarray:
    """Payload (frame 8) standard parameters: 4.6136 kg, centre of mass off the flange axis."""
    m = PAYLOAD_MASS
    c = np.array([0.0575, -0.059, 0.06])  # MX8, MY8 of Table II are about 0.265, -0.272
    Ic = np.diag([0.012, 0.012, 0.008])
    return standard_from_com(m, c, Ic)


def run_demo(args=None) -> int:
    check_duration(getattr(args, "duration", 20.0))  # before any work
    seed = getattr(args, "seed", 0)
    duration = getattr(args, "duration", 20.0)
    quiet = getattr(args, "quiet", False)
    rng = np.random.default_rng(seed)
    robot, model = model_for("lwr4")
    nominal = getattr(model, "nominal_parameters", None)  # generated packages have it (not in the contract)
    chi = nominal() if nominal is not None else None
    if chi is None:
        raise ModelError("lwr4: the demo needs the nominal parameters of the robot file")
    names = model.STANDARD_NAMES
    for k, n in enumerate(names):  # torque-sensor offsets, not in the URDF
        if n.startswith("OFF"):
            chi[k] = rng.uniform(-0.5, 0.5)
    pay = demo_payload()
    dt = DT
    say = (lambda *a: None) if quiet else print
    say(f"symoro_gen demo: {robot.name}, {len(model.BASE_NAMES)} base parameters + payload {model.PAYLOAD_NAMES[-1]}; "
        f"backend {getattr(model, 'BACKEND', '?')}")

    def record(kind, loaded):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, duration, dt, rng, vmax=1.5, amax=6.0)
        return simulate_recording(model, t, q, dq, ddq, chi, chi_payload=pay if loaded else None, gains=TRUE_GAINS,
                                  noise_q=2e-5, noise_tau=0.02, rng=rng, source=f"simulated {kind}", loaded=loaded)

    unloaded, loaded, validation = record("unloaded", False), record("loaded", True), record("validation", True)
    say(f"simulated 3 recordings of {duration:.0f} s at {1 / dt:.0f} Hz; sensor gains {TRUE_GAINS.tolist()}")
    sys_u = build_observation(model, [unloaded], payload_columns=False)
    sys_l = build_observation(model, [loaded], payload_columns=True)
    res = sensor_gains(sys_u, sys_l, {model.PAYLOAD_NAMES[-1]: PAYLOAD_MASS})
    sys_v = build_observation(model, [validation], payload_columns=True)
    val = res.rel_err_on(sys_v)
    say(res.summary())
    gains = res.gains
    assert gains is not None  # sensor_gains identifies them
    g = np.asarray(gains.values)
    say("\nSensor gains: true vs identified (IDIM-TLS, payload mass known)")
    for j in range(robot.n_joints):
        say(f"  g{j + 1}: true {TRUE_GAINS[j]:.4f}  identified {g[j]:.4f}  %sigma {gains.rel_std_pct[j]:.2f}  "
            f"error {100 * (g[j] / TRUE_GAINS[j] - 1):+.2f} %")
    say("Validation, relative error norm per joint: " + "  ".join(f"{x:.4f}" for x in val))
    worst = float(np.max(np.abs(g / TRUE_GAINS - 1)))
    say(f"largest gain error {100 * worst:.2f} %")
    return 0
