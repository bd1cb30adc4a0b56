"""An independent simulator of measured robot recordings, the "truth" of the loop-truth bench.

Nothing here uses the project's simulator (``symoro_gen.simulate``) or its effect injection
(``symoro_gen.diagnostics.inject``):

* the rigid-body torques are Pinocchio's recursive Newton-Euler algorithm (``pin.rnea``; Featherstone,
  *Rigid Body Dynamics Algorithms*, 2008, ch. 5) on a Pinocchio model built from the MDH table by the
  test oracle ``tests/oracles/pinocchio_model.py`` (its own rotations, Pinocchio's own inertia
  conversion); only the parsed robot file (the MDH table, nominal values, joint limits) is shared;
* the excitation is a sum of sines per joint (a finite Fourier series, Swevers, Ganseman, Tukel,
  De Schutter & Van Brussel 1997, "Optimal robot excitation and identification", eq. 9) scaled into
  the robot file's position, velocity and acceleration limits, evaluated analytically at any time
  (so a delayed recording is the exact torque at ``t - d``, not an interpolation);
* each effect is written from its physics in :class:`Truth` (friction laws after Armstrong-Helouvry,
  Dupont & Canudas de Wit 1994, "A survey of models, analysis tools and compensation methods for the
  control of machines with friction", eq. 5 for Stribeck; the elastic joint after Spong 1987,
  "Modeling and control of elastic joint robots": ``tau = K (q_motor - q_link)``).
"""
from __future__ import annotations

import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pinocchio as pin  # type: ignore[import-untyped]

ROOT = Path(__file__).resolve().parents[1]
for _p in (ROOT, ROOT / "tests"):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

from oracles.pinocchio_model import build_pinocchio_model, random_parameters  # type: ignore[import-not-found]

from symoro_gen.description.model import RobotDescription
from symoro_gen.preprocessing.trajectory import Trajectory

#: share of each limit the excitation may use (position half-range, velocity, acceleration)
LIMIT_SHARE = 0.8
#: the position amplitude is also capped at this [rad] (a +-170 deg joint need not sweep it all)
MAX_AMPLITUDE = 1.2


# ------------------------------------------------------------------------------------------------
# excitation
# ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class SumOfSines:
    """``q_j(t) = c_j + sum_k a_jk sin(2 pi k f0 t + phi_jk)`` (Swevers et al. 1997, eq. 9, sine form).

    Evaluated analytically with its first two derivatives. ``pauses`` (list of ``(start, end)`` in
    seconds) stop the motion: the series is evaluated at a phase ``s(t)`` whose rate ``s'(t)`` falls
    smoothly (cosine ramps of ``ramp`` seconds) to 0 inside each pause, so the robot is exactly at rest
    there and the motion resumes where it stopped.
    """

    f0: float
    center: np.ndarray      # (n,)
    amp: np.ndarray         # (n, K)
    phase: np.ndarray       # (n, K)
    pauses: tuple = ()
    ramp: float = 0.5

    def _rate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Phase rate ``s'(t)`` and its derivative ``s''(t)``."""
        r = np.ones_like(t)
        dr = np.zeros_like(t)
        for a, b in self.pauses:
            # 1 -> 0 over [a - ramp, a], 0 on [a, b], 0 -> 1 over [b, b + ramp]
            for lo, hi, down in ((a - self.ramp, a, True), (b, b + self.ramp, False)):
                m = (t >= lo) & (t < hi)
                x = (t[m] - lo) / self.ramp
                w = 0.5 * (1 + np.cos(np.pi * x)) if down else 0.5 * (1 - np.cos(np.pi * x))
                dw = (-0.5 * np.pi * np.sin(np.pi * x) if down else 0.5 * np.pi * np.sin(np.pi * x)) / self.ramp
                r[m] *= w
                dr[m] = dw
            r[(t >= a) & (t < b)] = 0.0
        return r, dr

    def phase_of(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``s(t), s'(t), s''(t)`` (``s`` by the exact integral of the cosine ramps)."""
        t = np.asarray(t, float)
        r, dr = self._rate(t)
        if not self.pauses:
            return t.copy(), r, dr
        s = t.copy()
        for a, b in self.pauses:
            # time lost by t: the integral of (1 - s') up to t
            for lo, _hi, down in ((a - self.ramp, a, True), (b, b + self.ramp, False)):
                x = np.clip((t - lo) / self.ramp, 0.0, 1.0)
                # integral over [lo, t] of (1 - w): down ramp 1 - w = (1 - cos)/2, up ramp (1 + cos)/2
                lost = self.ramp * (0.5 * x - 0.5 * np.sin(np.pi * x) / np.pi) if down else \
                    self.ramp * (0.5 * x + 0.5 * np.sin(np.pi * x) / np.pi)
                s -= lost
            s -= np.clip(t - a, 0.0, b - a)
        return s, r, dr

    def at(self, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``q, dq, ddq`` at times ``t`` (shape (N, n))."""
        s, r, dr = self.phase_of(np.asarray(t, float))
        w = 2 * np.pi * self.f0 * np.arange(1, self.amp.shape[1] + 1)             # (K,)
        arg = s[:, None, None] * w[None, None, :] + self.phase[None]               # (N, n, K)
        sn, cs = np.sin(arg), np.cos(arg)
        q = self.center[None] + np.einsum("njk,jk->nj", sn, self.amp)
        dqs = np.einsum("njk,jk->nj", cs, self.amp * w)
        ddqs = -np.einsum("njk,jk->nj", sn, self.amp * w ** 2)
        return q, dqs * r[:, None], ddqs * (r ** 2)[:, None] + dqs * dr[:, None]


def sum_of_sines(robot: RobotDescription, rng: np.random.Generator, *, f0: float = 0.1, harmonics: int = 5,
                 pauses: Sequence[tuple[float, float]] = (), ramp: float = 0.5) -> SumOfSines:
    """A random sum of sines inside the robot file's ``[limits]`` (each at :data:`LIMIT_SHARE`).

    Amplitudes decay like ``1/k`` (smooth motion), random phases; then each joint's amplitudes are scaled
    by one factor so that the bounds ``sum |a_k|``, ``sum |a_k| w_k`` and ``sum |a_k| w_k^2`` meet the
    position half-range (and :data:`MAX_AMPLITUDE`), velocity and acceleration limits; the centre is drawn
    in the room left. A pause's ramps add at most ``pi/2 |dq| / ramp`` to the acceleration (kept under
    the limit by ``ramp >= 0.5 s`` here).
    """
    lim = robot.limits
    n = robot.n_joints
    if lim is None or lim.q_min is None:
        raise ValueError(f"robot {robot.name}: the excitation needs [limits] q_min/q_max in the robot file")
    qmin, qmax = np.asarray(lim.q_min, float), np.asarray(lim.q_max, float)
    vmax = np.asarray(lim.dq_max, float) if lim.dq_max is not None else np.full(n, np.inf)
    amax = np.asarray(lim.ddq_max, float) if lim.ddq_max is not None else np.full(n, np.inf)
    k = np.arange(1, harmonics + 1)
    w = 2 * np.pi * f0 * k
    amp = rng.uniform(0.5, 1.0, (n, harmonics)) / k[None, :] * rng.choice([-1.0, 1.0], (n, harmonics))
    phase = rng.uniform(0, 2 * np.pi, (n, harmonics))
    half = 0.5 * (qmax - qmin)
    a_pos = np.minimum(LIMIT_SHARE * half, MAX_AMPLITUDE)
    s_pos = a_pos / np.abs(amp).sum(1)
    s_vel = LIMIT_SHARE * vmax / (np.abs(amp) * w).sum(1)
    s_acc = LIMIT_SHARE * amax / (np.abs(amp) * w ** 2 * (1 + (np.pi / (2 * ramp * w) if pauses else 0))).sum(1)
    amp = amp * np.minimum(np.minimum(s_pos, s_vel), s_acc)[:, None]
    span = np.abs(amp).sum(1)
    room = np.maximum(LIMIT_SHARE * half - span, 0.0)
    center = 0.5 * (qmax + qmin) + rng.uniform(-1, 1, n) * room
    return SumOfSines(f0=f0, center=center, amp=amp, phase=phase, pauses=tuple(pauses), ramp=ramp)


# ------------------------------------------------------------------------------------------------
# rigid body + friction + effects
# ------------------------------------------------------------------------------------------------
class Rigid:
    """Pinocchio's RNEA on the robot's MDH table with standard parameters ``chi`` (no drive terms)."""

    def __init__(self, robot: RobotDescription, chi_std: np.ndarray, chi_payload: np.ndarray | None = None):
        self.robot = robot
        self.model, self.data = build_pinocchio_model(robot, chi_std, chi_payload)

    def __call__(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> np.ndarray:
        out = np.empty_like(q)
        for i in range(q.shape[0]):
            out[i] = pin.rnea(self.model, self.data, q[i], dq[i], ddq[i])
        return out


def drive_values(robot: RobotDescription, chi_std: np.ndarray, kind: str) -> np.ndarray:
    """The drive term ``kind`` (FV, FS, IA, OFF) of every joint from a standard vector (0 when absent)."""
    vals = dict(zip(robot.standard_names, np.asarray(chi_std, float)))
    return np.array([vals.get(f"{kind}{r.j}", 0.0) for r in robot.joints])


@dataclass
class Truth:
    """What the simulated robot does that a recording shows. Joints 0-based; every field optional.

    Friction per joint ``j`` (sliding velocity ``v``, transmitted rigid-body torque ``tau_r``):
    ``FS_j sign(v) + FV_j (1 + viscous_growth_j t/T) v + stribeck_j exp(-(v/vs_j)^2) sign(v)
    + load_mu_j |tau_r,j| sign(v)`` (Coulomb + viscous, RX-90 paper eq. 2; Stribeck, Armstrong-Helouvry et
    al. 1994 eq. 5; load-dependent Coulomb friction, ibid. sec. 2.1: the normal force in the gear teeth
    grows with the transmitted torque), ``T`` the recording's length. With ``coulomb_v`` the sign is
    ``tanh(v / coulomb_v)``.

    Measurement (applied in this order): an encoder offset (``q_meas = q - q_offset``), a motor-side
    encoder on an elastic joint (``q_meas = q + tau_r/K``, Spong 1987), cogging torque
    ``A sin(k q + phi)`` added to the drive's torque, a torque delay (``tau_meas(t) = tau(t - d)``),
    cross-talk (``tau_meas,j+1 += c tau_j``), a gain error (``tau_meas,j = g_j tau_j``), a current
    reading (``tau / k_t``), white noise.
    """

    FV: np.ndarray
    FS: np.ndarray
    OFF: np.ndarray
    coulomb_v: float | None = None
    viscous_growth: dict = field(default_factory=dict)    # j -> relative growth over the recording
    stribeck: dict = field(default_factory=dict)          # j -> (Fs - Fc [N m], vs [rad/s])
    load_mu: dict = field(default_factory=dict)           # j -> mu [-]
    cogging: dict = field(default_factory=dict)           # j -> (A [N m], k [periods/rev], phase)
    delay: dict = field(default_factory=dict)             # j -> d [s]
    crosstalk: dict = field(default_factory=dict)         # j -> (c, into joint)
    gain: dict = field(default_factory=dict)              # j -> g
    stiffness: dict = field(default_factory=dict)         # j -> K [N m/rad] (motor-side encoder)
    q_offset: dict = field(default_factory=dict)          # j -> offset [rad] (encoder reads q - offset)
    lugre_sigma0: float | None = None                     # bristle stiffness [N m/rad]: Coulomb part by LuGre
    k_t: np.ndarray | None = None                         # recorded value tau / k_t per joint
    sigma_q: float = 1e-5
    sigma_tau: float = 0.05

    def sgn(self, v: np.ndarray) -> np.ndarray:
        return np.sign(v) if self.coulomb_v is None else np.tanh(v / self.coulomb_v)

    def bristles(self, t: np.ndarray, dq: np.ndarray) -> np.ndarray:
        """Coulomb part of the LuGre model (Canudas de Wit, Olsson, Astrom & Lischinsky 1995, "A new model
        for control of systems with friction", eq. 1-3, without Stribeck and bristle damping):
        ``dz/dt = v - sigma0 |v| z / Fc``, friction ``sigma0 z``. Integrated exactly for a velocity constant
        over each sample interval (``z`` relaxes to ``Fc sign(v) / sigma0`` at the rate
        ``sigma0 |v| / Fc``); at rest ``z`` holds, so the friction keeps the value of the last sliding
        direction (static friction of a stopped drive, sec. 2 of the same paper)."""
        if self.lugre_sigma0 is None:
            raise ValueError("Truth.bristles needs lugre_sigma0 (the bristle stiffness) [N m/rad]")
        s0 = float(self.lugre_sigma0)
        fc = np.maximum(self.FS, 1e-9)
        z = np.zeros(dq.shape)
        zk = fc * np.sign(dq[0]) / s0
        dt = np.diff(t, prepend=t[0])
        for k in range(dq.shape[0]):
            v = dq[k]
            target = fc * np.sign(v) / s0
            zk = target + (zk - target) * np.exp(-s0 * np.abs(v) * dt[k] / fc)
            z[k] = zk
        return s0 * z

    def friction(self, t: np.ndarray, dq: np.ndarray, tau_r: np.ndarray, T: float) -> np.ndarray:
        s = self.sgn(dq)
        coulomb = self.FS[None] * s if self.lugre_sigma0 is None else self.bristles(t, dq)
        f = coulomb + self.FV[None] * dq + self.OFF[None]
        for j, g in self.viscous_growth.items():
            f[:, j] += self.FV[j] * g * (t / T) * dq[:, j]
        for j, (dfs, vs) in self.stribeck.items():
            f[:, j] += dfs * np.exp(-(dq[:, j] / vs) ** 2) * s[:, j]
        for j, mu in self.load_mu.items():
            f[:, j] += mu * np.abs(tau_r[:, j]) * s[:, j]
        return f


def record(robot: RobotDescription, rigid: Rigid, exc: SumOfSines, truth: Truth, seconds: float, rate: float,
           rng: np.random.Generator, source: str, growth_time: float | None = None) -> tuple[Trajectory, dict]:
    """One recording of ``seconds`` at ``rate`` Hz: the measured ``q`` and ``tau`` (a :class:`Trajectory`)
    and the noise-free signals (``q``, ``dq``, ``ddq``, ``tau_rigid``, ``tau``: the drive torque before the
    measurement chain). ``growth_time``: the ``T`` of ``Truth.viscous_growth`` (default the recording's
    length; give one value to every file so the growth per second is the same in all)."""
    t = np.arange(int(round(seconds * rate))) / rate
    T = float(t[-1]) if growth_time is None else float(growth_time)

    def drive_torque(tt: np.ndarray) -> tuple[np.ndarray, ...]:
        q, dq, ddq = exc.at(tt)
        tau_r = rigid(q, dq, ddq)
        tau = tau_r + truth.friction(tt, dq, tau_r, T)
        for j, (a, k, ph) in truth.cogging.items():
            tau[:, j] += a * np.sin(k * q[:, j] + ph)
        return q, dq, ddq, tau_r, tau

    q, dq, ddq, tau_r, tau = drive_torque(t)
    if truth.stiffness:
        # motor-side encoder: the friction acts on the motor velocity dq + d(tau_r/K)/dt
        q_m = q.copy()
        for j, K in truth.stiffness.items():
            q_m[:, j] = q[:, j] + tau_r[:, j] / K
        dq_m = np.gradient(q_m, t, axis=0)
        tau = tau_r + truth.friction(t, dq_m, tau_r, T)
        for j, (a, k, ph) in truth.cogging.items():
            tau[:, j] += a * np.sin(k * q_m[:, j] + ph)
    else:
        q_m = q.copy()
    tau_meas = tau.copy()
    for j, d in truth.delay.items():
        tau_meas[:, j] = drive_torque(t - d)[4][:, j]
    for j, (c, into) in truth.crosstalk.items():
        tau_meas[:, into] += c * tau[:, j]
    for j, g in truth.gain.items():
        tau_meas[:, j] = g * tau_meas[:, j]
    for j, off in truth.q_offset.items():
        q_m[:, j] = q_m[:, j] - off
    tau_meas = tau_meas + truth.sigma_tau * rng.standard_normal(tau_meas.shape)
    if truth.k_t is not None:
        tau_meas = tau_meas / truth.k_t[None]
    q_meas = q_m + truth.sigma_q * rng.standard_normal(q_m.shape)
    tr = Trajectory(t=t, q=q_meas, tau=tau_meas, source=source)
    return tr, dict(t=t, q=q, dq=dq, ddq=ddq, tau_rigid=tau_r, tau=tau)


def nominal_parameters(robot: RobotDescription, rng: np.random.Generator | None = None
                       ) -> tuple[np.ndarray, np.ndarray | None]:
    """The robot file's ``[nominal]`` standard parameters (payload left off: unloaded recordings); a robot
    without nominal link values gets random physically consistent ones (the oracle's
    ``random_parameters``, friction redrawn as FS in [0.2, 1], FV in [0.2, 1.5])."""
    nom = robot.nominal_vector()
    if nom is not None and any(abs(v) > 0 for n, v in zip(robot.standard_names, nom) if n.startswith("M")):
        return np.asarray(nom, float), None
    rng = np.random.default_rng(0) if rng is None else rng
    chi, _ = random_parameters(robot, rng)
    vals = dict(zip(robot.standard_names, chi))
    for r in robot.joints:
        for kind, lo, hi in (("FS", 0.2, 1.0), ("FV", 0.2, 1.5), ("OFF", -0.5, 0.5), ("IA", 0.0, 0.0)):
            if f"{kind}{r.j}" in vals:
                vals[f"{kind}{r.j}"] = rng.uniform(lo, hi)
    return np.array([vals[n] for n in robot.standard_names]), None


def rest_share(dq: np.ndarray) -> float:
    """Share of the samples at which every joint is exactly at rest."""
    return float(np.mean(np.all(np.abs(dq) < 1e-12, axis=1)))


def pauses_for(seconds: float, share: float, rng: np.random.Generator, *, ramp: float = 0.5,
               length: tuple[float, float] = (1.5, 3.0)) -> list[tuple[float, float]]:
    """Pause intervals covering about ``share`` of ``seconds`` (plateaus of ``length`` s, apart by more than
    two ramps, none in the first or last 2 s)."""
    want = share * seconds
    out: list[tuple[float, float]] = []
    got = 0.0
    tries = 0
    while got < want and tries < 1000:
        tries += 1
        d = min(rng.uniform(*length), want - got)
        if d < 0.3:
            break
        a = rng.uniform(2.0, seconds - 2.0 - d)
        if all(a > b0 + 3 * ramp or a + d < a0 - 3 * ramp for a0, b0 in out):
            out.append((a, a + d))
            got += d
    return sorted(out)


def time_of_rest(exc: SumOfSines, t: np.ndarray) -> float:
    """Share of ``t`` inside a pause plateau."""
    m = np.zeros(t.shape, bool)
    for a, b in exc.pauses:
        m |= (t >= a) & (t < b)
    return float(m.mean())


__all__ = ["SumOfSines", "sum_of_sines", "Rigid", "Truth", "record", "drive_values", "nominal_parameters",
           "pauses_for", "rest_share", "time_of_rest"]
