"""How likely an effect the loop found is, physically: the band between *possible* and *likely*.

:func:`.candidates.implausible` rejects what cannot be (a gain of the wrong sign, a delay beyond its
first-order column). An effect can fit, be possible, and still be unlikely for the arm it is found on:
a 48 ms delay of one joint of a torque-controlled arm sampled at 1 kHz (a drive or bus delay shows on
every joint of the bus, a few sampling periods), a gain of ×1.33 where the declared gain is known to a
few per cent, a Stribeck velocity of 0.4 mrad/s (below what a differentiated encoder resolves). This
module rates every effect kind and every friction-law replacement against stated priors
(``docs/loop-plausibility.md`` gives each with its source) and turns the rating, with the evidence of
the round, into a *verdict*:

``cause``
    fits, beats its alternatives, plausible (score >= :data:`PLAUSIBLE`);
``doubtful``
    fits but implausible, or an eligible alternative of its round on its joints fits almost as well (leaves
    at most :data:`CLOSE_REMAINING` times its squared validation error there);
``rejected``
    implausible and an eligible alternative explains the same residual (leaves at most
    :data:`EXPLAINS_REMAINING` times its squared validation error), or physically impossible; a time delay
    only when impossible or absurd (:func:`delay_is_absurd`), otherwise at worst ``doubtful``.

An alternative that is the same physical effect under another name of the library (:data:`SYNONYMS`) is
no rival.

Scores
------
Each prior is a *band* ``[lo, hi]`` of a positive magnitude ``x`` (delay, ``|log scale|``, deflection,
Stribeck velocity...): inside it the factor is 1; outside it falls as a log-normal,
``exp(-(log(x / hi) / w)^2 / 2)`` above ``hi`` (``lo`` below), ``w`` the band's log-width (at ``x = hi
e^w`` the factor is 0.61, at ``hi e^{2w}`` 0.14). A qualitative prior (a delay on one joint only, a
negative stiffness) is a fixed factor. The score of an effect is the product of its factors, in
[0, 1]; each factor below 1 comes with its reason.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

__all__ = [
    "ALTERNATIVE_EXPLAINS", "CLOSE_ALTERNATIVE", "CLOSE_REMAINING", "COMPOSED_TORQUE_SHARE", "CROSSTALK_TYPICAL", "DEFLECTION_BAND",
    "DELAY_ABSURD_PERIOD_SHARE",
    "DELAY_TYPICAL_PERIODS", "DELAY_TYPICAL_S", "EXPLAINS_REMAINING", "GAIN_TOLERANCE", "LAW_GAIN_MIN", "PLAUSIBLE",
    "POWER_BAND", "STRIBECK_BAND", "STRIBECK_EXCESS_SHARE", "STRIBECK_SPEED_SHARE", "SYNONYMS", "VELOCITY_RESOLUTION",
    "VERDICTS", "ZERO_OFFSET_TYPICAL_DEG", "ZERO_OFFSET_WIDTH", "ArmScales", "Plausibility", "alternatives_of",
    "band_factor", "delay_is_absurd", "effect_plausibility", "explains_same", "fits_like", "law_alternatives", "law_plausibility",
    "own_candidate", "rate_effects", "remaining_error", "verdict",
]

#: an effect (or law) rated below this is not called a cause
PLAUSIBLE = 0.5
#: an eligible alternative of the same round makes the effect doubtful when it leaves at most this factor of
#: the effect's squared validation error on the effect's joints (it "fits almost as well": what it misses
#: is within 10 % of what the effect leaves); without the errors, when its score reaches this share of the
#: effect's
CLOSE_ALTERNATIVE = 0.9
CLOSE_REMAINING = 1.1
#: an implausible effect is rejected when an eligible alternative explains the same residual: leaves at most
#: EXPLAINS_REMAINING times the effect's squared validation error on its joints (without the errors: reaches
#: ALTERNATIVE_EXPLAINS of its score)
ALTERNATIVE_EXPLAINS = 0.5
EXPLAINS_REMAINING = 1.5
VERDICTS = ("cause", "doubtful", "rejected")
#: alternatives listed per effect
N_ALTERNATIVES = 3

#: transport delay of a torque-controlled arm: a few sampling periods of the drive bus (KUKA LWR4 FRI and
#: EtherCAT drives: 1-3 cycles at 1 kHz; Albu-Schaffer et al. 2007, sec. V), at most ~10 ms
DELAY_TYPICAL_S = 0.01
#: ... or this many sampling periods of the recording, whichever is larger
DELAY_TYPICAL_PERIODS = 4.0
#: log-width of the delay band (a factor 2 beyond it gives 0.61)
DELAY_WIDTH = math.log(2.0)
#: a delay on one joint only (the others none): a bus or drive delay is common to the joints of the bus
ONE_JOINT_DELAY_FACTOR = 0.4
#: a delay longer than this share of the excitation's shortest period (``1 / f_max``) is absurd as a transport
#: delay: the torque is then shifted by a quarter cycle of the fastest motion (90 degrees of phase), what no
#: bus or drive does; shorter delays found on one joint are doubtful, not rejected (an elastic joint, a
#: filter on that torque channel or its own time stamping look the same)
DELAY_ABSURD_PERIOD_SHARE = 0.25
#: a negative delay (the torque leads the motion) longer than a sampling period: not a transport delay
LEAD_FACTOR = 0.3
#: relative tolerance of a declared torque gain (torque constant, sensor calibration): a few per cent
#: (motor datasheets give the torque constant to +-5-10 %; calibrated joint torque sensors to 1-2 %)
GAIN_TOLERANCE = 0.05
GAIN_WIDTH = math.log(1.1)
#: deflection [rad] of a joint at its 98th-percentile torque: harmonic drives deflect 0.5-10 mrad at rated
#: torque (Harmonic Drive CSG/CSD catalogues, torsional stiffness K1-K3: 1e3-1e6 N m/rad by size);
#: LWR-type joints with torque sensors 1-20 mrad (Albu-Schaffer et al. 2007)
DEFLECTION_BAND = (1e-4, 0.02)
DEFLECTION_WIDTH = math.log(3.0)
NEGATIVE_STIFFNESS_FACTOR = 0.1
#: Stribeck velocity [rad/s]: 0.001-0.1 rad/s at the joint of a drive (Armstrong-Helouvry, Dupont & Canudas
#: de Wit 1994, sec. 2 and Table 2; Olsson et al. 1998, sec. 2 and Table 1: 0.001-0.1 for sliding contacts)
STRIBECK_BAND = (0.001, 0.1)
STRIBECK_WIDTH = math.log(3.0)
#: a Stribeck dip lives at low speed: a ``vs`` above this share of the joint's 98th-percentile speed spans the
#: motion itself - the law is then a reshaped Coulomb law, not a Stribeck effect (Armstrong-Helouvry et al.
#: 1994, sec. 2: the Stribeck curve falls to the Coulomb level within a small fraction of the operating speeds)
STRIBECK_SPEED_SHARE = 0.3
STRIBECK_SPEED_WIDTH = math.log(2.0)
#: static excess ``Fs - Fc`` of a Stribeck law against the joint's 98th-percentile torque: the static friction
#: of geared joints exceeds the Coulomb level by 10-50 % of it, i.e. by about 1-15 % of the torque range (LWR4
#: paper, Table II; Armstrong-Helouvry et al. 1994, sec. 2); below 0.5 % it is within the noise of the fit
STRIBECK_EXCESS_SHARE = 0.005
STRIBECK_EXCESS_WIDTH = math.log(2.0)
#: a shape law (Stribeck, power viscous) must lower the out-of-fold error norm of its joint by at least this
#: share to be named a cause: a gain of a few % is what a delay or a gain error seen through the friction
#: columns leaves (engineering choice, docs/loop-plausibility.md)
LAW_GAIN_MIN = 0.05
LAW_GAIN_WIDTH = math.log(2.0)
#: velocity resolution [rad/s] of a differentiated encoder at 1 kHz: a 19-bit encoder step (1.2e-5 rad) per
#: period is 0.012 rad/s raw; filtered over ~10 periods, ~1e-3 rad/s. Below it a velocity scale is noise
VELOCITY_RESOLUTION = 1e-3
BELOW_RESOLUTION_FACTOR = 0.05
#: exponent of a power viscous law ``|dq|^delta``: close to 1 for a lubricated contact (Olsson et al. 1998,
#: viscous friction is linear in the velocity; Bittencourt & Gunnarsson 2012 fit 0.7-1.4 on robot joints)
POWER_BAND = (0.7, 1.4)
POWER_WIDTH = math.log(1.5)
#: friction magnitudes against the joint's 98th-percentile torque: dry friction of a geared joint is
#: 2-30 % of its torque range (LWR4 paper, Table II; RX-90 paper, Table 3), above half of it it is unusual
FRICTION_SHARE = 0.5
#: ... and the Coulomb coefficient of a friction law at most the torque range itself (a friction-dominated
#: wrist joint has most of its torque in friction)
COULOMB_SHARE = 1.0
#: load-dependent friction ``mu |tau|``: 0-0.3 (harmonic-drive efficiency 70-90 %, HD catalogues)
LOAD_FRICTION_BAND = (0.0, 0.3)
#: a torque (offset, drift over the recording, ripple amplitude, spring at the range's end) against the
#: 98th-percentile torque of its joint: above this share it is unusual for an unmodelled effect
TORQUE_SHARE = 0.3
#: a once-per-turn ripple (order 1): the misalignment torque of a strain-gauge torque sensor built into a
#: harmonic drive, periodic in the rotation (Taghirad & Belanger 1998, "Torque ripple and misalignment torque
#: compensation for the built-in torque sensor of harmonic drive systems", IEEE Trans. Instrum. Meas. 47(1)),
#: the eccentricity of an output-side sensor or bearing, or a cable wound over the joint: a few % of the
#: rated torque at most (engineering choice). The loop knows no rated torque: the amplitude is judged, as
#: for the other orders, against TORQUE_SHARE of the joint's 98th-percentile torque, and no gear-ratio factor
ONCE_PER_TURN_NOTE = "once per turn: a torque sensor's or output bearing's eccentricity, or a cable"
SHARE_WIDTH = math.log(2.0)
NEGATIVE_FRICTION_FACTOR = 0.2
#: encoder zero offset of a calibrated arm: typically below 1-2 deg (Hollerbach & Wampler 1996, the calibration
#: index and taxonomy for robot kinematic calibration methods, IJRR 15(6): joint offsets are the dominant
#: kinematic errors; Khalil & Dombre 2002, ch. 11, geometric calibration: the identified offsets of arms);
#: with ZERO_OFFSET_WIDTH = ln 2, 4 deg gives 0.61, 5 deg 0.42 (doubtful); beyond
#: :data:`.candidates.MAX_ZERO_OFFSET_DEG` (20 deg) the offset is rejected as impossible for a zero error
#: (a wrong MDH theta convention of the robot file, rather)
ZERO_OFFSET_TYPICAL_DEG = 2.0
ZERO_OFFSET_WIDTH = math.log(2.0)
#: link-length (MDH d, r) error of a machined and assembled arm: a few mm (ISO 2768-1 general tolerances:
#: +-0.8 mm "medium", +-4 mm "very coarse" for 400-1000 mm; Mooring, Roth & Driels 1991, *Fundamentals of
#: Manipulator Calibration*, ch. 1, link-length errors of a few mm); with LENGTH_ERROR_WIDTH = ln 2, 16 mm gives
#: 0.61, 20 mm 0.42 (doubtful); beyond :data:`.candidates.MAX_LINK_LENGTH_M` (50 mm) it is rejected as impossible
LENGTH_ERROR_TYPICAL_MM = 8.0
LENGTH_ERROR_WIDTH = math.log(2.0)
#: cross-talk into a joint's torque channel: strain-gauge joint torque sensors' datasheets specify a
#: cross-sensitivity (cross-talk) of about 1-3 % of the reading; up to 10 % of a neighbouring joint's torque
#: is plausible, beyond it the factor falls (20 %: 0.61) - a larger share is a mixed channel, not cross-talk
CROSSTALK_TYPICAL = 0.10
CROSSTALK_WIDTH = math.log(2.0)


@dataclass(frozen=True)
class Plausibility:
    """The rating of one effect: ``score`` in [0, 1] (product of the factors) and a reason per factor
    below 1; ``check`` says what to look at."""

    score: float
    reasons: tuple[str, ...] = ()
    check: str = ""

    def to_dict(self) -> dict:
        return {"score": float(self.score), "reasons": list(self.reasons)}


@dataclass(frozen=True)
class ArmScales:
    """What the priors are judged against, per joint (0-based arrays) and for the recording.

    Attributes
    ----------
    dt : float
        Sampling period of the recording [s].
    tau98, v98, dq_noise : ndarray
        98th percentiles of |tau_j| [N m] and |dq_j| [rad/s], standard deviation of the velocity noise.
    n_joints : int
    gear_ratios : mapping joint -> ratio, optional
        Known gear ratios (ripple orders are compared with them).
    f_max : float, optional
        Highest frequency of the excitation [Hz] (a delay beyond a quarter of its period is absurd).
    """

    dt: float
    tau98: np.ndarray
    v98: np.ndarray
    dq_noise: np.ndarray
    n_joints: int
    gear_ratios: Mapping[int, float] = field(default_factory=dict)
    f_max: float | None = None   # highest frequency of the excitation [Hz] (the assembly's f_dyn), when known

    @classmethod
    def of_frame(cls, frame, gear_ratios: Mapping[int, float] | None = None) -> ArmScales:
        """The scales of a :class:`.frame.Frame` (its experiments' time, velocity noise; its samples' torque and
        velocity)."""
        S = frame.samples()
        tau98 = np.quantile(np.abs(np.asarray(S["tau"], float)), 0.98, axis=0)
        v98 = np.quantile(np.abs(np.asarray(S["dq"], float)), 0.98, axis=0)
        dq_noise = np.max([np.asarray(ex.dq_noise, float) for ex in frame.experiments], axis=0)
        dts = [float(np.median(np.diff(ex.t))) for ex in frame.experiments if np.size(ex.t) > 1]
        return cls(dt=min(dts) if dts else 0.001, tau98=tau98, v98=v98, dq_noise=dq_noise,
                   n_joints=int(frame.n_joints), gear_ratios=dict(gear_ratios or {}))

    def velocity_resolution(self, j: int) -> float:
        """The smallest velocity scale the data resolve on joint j: :data:`VELOCITY_RESOLUTION` or 3 velocity
        noise standard deviations, whichever is larger."""
        return max(VELOCITY_RESOLUTION, 3.0 * float(self.dq_noise[j]))


def band_factor(x: float, lo: float, hi: float, width: float) -> float:
    """1 inside ``[lo, hi]``, a log-normal fall ``exp(-(log(x/hi)/width)^2/2)`` above (``lo`` below; ``lo <= 0``:
    no lower bound)."""
    x = abs(float(x))
    if not math.isfinite(x):
        return 0.0
    if x > hi > 0:
        return math.exp(-0.5 * (math.log(x / hi) / width) ** 2)
    if lo > 0 and x < lo:
        if x <= 0:
            return 0.0
        return math.exp(-0.5 * (math.log(lo / x) / width) ** 2)
    return 1.0


class _Rating:
    def __init__(self) -> None:
        self.score = 1.0
        self.reasons: list[str] = []
        self.checks: list[str] = []

    def factor(self, f: float, reason: str, check: str = "") -> None:
        f = min(max(float(f), 0.0), 1.0)
        if f < 0.999:
            self.score *= f
            self.reasons.append(f"{reason} (factor {f:.2f})")
            if check:
                self.checks.append(check)

    def done(self, note: str = "") -> Plausibility:
        reasons = tuple(self.reasons) + ((note,) if note and not self.reasons else ())
        return Plausibility(float(self.score), reasons, "; ".join(self.checks))


def _who(joint: int | None) -> str:
    return "all joints" if joint is None else f"joint {joint + 1}"


def effect_plausibility(kind: str, joint: int | None, params: Mapping[str, float], physical: Mapping[str, float],
                        scales: ArmScales, *, variant: str = "", modulation: str | None = None,
                        delay_joints: Sequence[int | None] = ()) -> Plausibility:
    """The plausibility of one effect the loop added (its final parameters ``params``, by short name: ``d``,
    ``gamma``, ``c``, ``Fst``, ``mu``, ``a_sin``..., and its physical reading ``physical``).

    ``delay_joints``: the joints (None: all) of every ``time_delay`` effect of the diagnosis (a delay on one
    joint only is rated down, :data:`ONE_JOINT_DELAY_FACTOR`).
    """
    r = _Rating()
    j = joint
    tau = float(np.max(scales.tau98)) if j is None else float(scales.tau98[j])
    tau = tau if tau > 0 else 1.0
    if modulation is not None:
        return _rate_composed(r, kind, j, physical, scales, tau)
    if kind == "time_delay":
        _rate_delay(r, j, physical, params, scales, delay_joints)
    elif kind == "gain":
        s = float(physical.get("scale", 1.0 + params.get("gamma", 0.0)))
        if s > 0:
            r.factor(band_factor(math.exp(abs(math.log(s))), 0.0, 1.0 + GAIN_TOLERANCE, GAIN_WIDTH),
                     f"a torque scale of ×{s:.3g} on {_who(j)} is beyond the few-% tolerance of a declared gain "
                     f"(±{100 * GAIN_TOLERANCE:g} %)",
                     f"the torque constant / gear ratio of {_who(j)} in the data conversion, a payload or inertia "
                     "error of the links it carries")
    elif kind == "contact_gain":
        s = float(physical.get("scale", 1.0))
        if s > 0:
            r.factor(band_factor(math.exp(abs(math.log(s))), 0.0, 1.0 + GAIN_TOLERANCE, GAIN_WIDTH),
                     f"a wrench scale of ×{s:.3g} of the sensor at {variant} is beyond the few-% tolerance of a "
                     f"calibrated force-torque sensor (±{100 * GAIN_TOLERANCE:g} %)",
                     f"the sensor at {variant} against a known load")
    elif kind == "contact_offset":
        return r.done(f"offset of the sensor at {variant}: no prior on its magnitude (a force-torque sensor's zero "
                      "drifts with temperature and mounting)")
    elif kind == "elasticity":
        _rate_stiffness(r, j, physical, tau)
    elif kind == "stribeck":
        vs = physical.get("vs")
        if vs is not None and j is not None:
            _velocity_scale(r, float(vs), scales.velocity_resolution(j), "Stribeck velocity vs")
        fst = float(params.get("Fst", 0.0))
        r.factor(band_factor(fst / tau, 0.0, FRICTION_SHARE, SHARE_WIDTH),
                 f"a Stribeck excess of {fst:.3g} N m is large against the torque range {tau:.3g} N m")
        if fst < 0:
            r.factor(0.5, "a negative Stribeck excess (friction rising out of standstill) is unusual",
                     "the velocity filter's phase at reversals")
    elif kind == "load_friction":
        mu = float(params.get("mu", 0.0))
        if mu < 0:
            r.factor(NEGATIVE_FRICTION_FACTOR if abs(mu) > 0.02 else 1.0,
                     f"friction decreasing with the load (mu = {mu:.3g}) is unusual", "a gain error of the joint")
        else:
            r.factor(band_factor(mu, 0.0, LOAD_FRICTION_BAND[1], SHARE_WIDTH),
                     f"a load-dependent friction of {100 * mu:.3g} % of the torque is large (gear efficiency "
                     "70-90 %)", "a gain error of the joint")
    elif kind == "position_ripple":
        amp = float(physical.get("amplitude", 0.0))
        r.factor(band_factor(amp / tau, 0.0, TORQUE_SHARE, SHARE_WIDTH),
                 f"a ripple of {amp:.3g} N m is large against the torque range {tau:.3g} N m")
        k = physical.get("k")
        g = scales.gear_ratios.get(j) if j is not None else None
        # order 1 is once per turn of the joint's output: an eccentric or tilted torque sensor or output
        # bearing, a cable (ONCE_PER_TURN_NOTE), not a tooth order of the gear - no gear-ratio factor
        if k is not None and g and float(k) != 1.0:
            ok = any(abs(float(k) - m * g) < 0.5 or abs(float(k) * m - g) < 0.5 for m in (1, 2))
            r.factor(1.0 if ok else 0.7, f"order {float(k):g} is not a multiple or divisor of the gear ratio {g:g}")
    elif kind == "spring":
        a = abs(float(params.get("k1", 0.0))) + abs(float(params.get("k2", 0.0))) + abs(float(params.get("k3", 0.0)))
        r.factor(band_factor(a / tau, 0.0, 1.0, SHARE_WIDTH),
                 f"a spring torque of {a:.3g} N m at the range's end exceeds the torque range {tau:.3g} N m",
                 "a gravity compensation spring or cable in the robot file")
    elif kind == "drift":
        a = abs(float(params.get("a1", 0.0))) + abs(float(params.get("a2", 0.0)))
        r.factor(band_factor(a / tau, 0.0, TORQUE_SHARE, SHARE_WIDTH),
                 f"a drift of {a:.3g} N m over the recording is large against the torque range {tau:.3g} N m",
                 "the sensor's temperature, a slipping offset")
    elif kind == "offset":
        a = abs(float(params.get("OFF", 0.0)))
        r.factor(band_factor(a / tau, 0.0, TORQUE_SHARE, SHARE_WIDTH),
                 f"an offset of {a:.3g} N m is large against the torque range {tau:.3g} N m",
                 "the torque sensor's zero, a missing gravity term")
    elif kind == "rotor_inertia":
        ia = float(params.get("IA", 0.0))
        if ia < 0:
            r.factor(0.5, f"a negative rotor inertia ({ia:.3g}) corrects a declared inertia, it is no rotor",
                     "the declared rotor inertia")
    elif kind == "joint_zero":
        if "offset_deg" in physical:
            deg = float(physical["offset_deg"])
            r.factor(band_factor(deg, 0.0, ZERO_OFFSET_TYPICAL_DEG, ZERO_OFFSET_WIDTH),
                     f"a zero offset of {deg:.3g} deg on {_who(j)} is large for a calibrated arm (typical: below "
                     f"{ZERO_OFFSET_TYPICAL_DEG:g} deg)",
                     f"the encoder zero / reference position of {_who(j)}, the theta offset of its row in the robot "
                     "file")
        else:
            return r.done("zero offset of a prismatic joint (a length): no prior on its magnitude")
    elif kind == "link_length" and "length_mm" in physical:
        mm, frame = float(physical["length_mm"]), int(physical.get("frame", 0))
        r.factor(band_factor(mm, 0.0, LENGTH_ERROR_TYPICAL_MM, LENGTH_ERROR_WIDTH),
                 f"a length error of {mm:.3g} mm of link {frame} is large for a machined arm (typical: below "
                 f"{LENGTH_ERROR_TYPICAL_MM:g} mm)", f"the d/r of frame {frame} in the robot file")
    elif kind == "held_friction":
        fh = float(params.get("Fh", 0.0))
        r.factor(band_factor(fh / tau, 0.0, FRICTION_SHARE, SHARE_WIDTH),
                 f"a held friction of {fh:.3g} N m is large against the torque range {tau:.3g} N m",
                 f"a load held by {_who(j)}'s brake, a gravity term missing at the rest poses")
    elif kind == "crosstalk":
        c = float(physical.get("share", params.get("c", 0.0)))
        src = "another joint" if j is None else "a neighbouring joint"
        r.factor(band_factor(c, 0.0, CROSSTALK_TYPICAL, CROSSTALK_WIDTH),
                 f"{100 * abs(c):.3g} % of {src}'s torque in {_who(j)}'s channel is large for the cross-sensitivity "
                 f"of a torque sensor (datasheets: 1-3 %; plausible up to {100 * CROSSTALK_TYPICAL:g} %)",
                 f"the wiring and the channel assignment of {_who(j)}'s torque in the data conversion")
    elif kind == "coupling" and variant == "shared":
        for nm in ("FVm", "FSm"):
            if float(params.get(nm, 0.0)) < 0:
                r.factor(NEGATIVE_FRICTION_FACTOR, f"negative friction of the shared motor ({nm})")
    return r.done()


#: composed effects (:mod:`.compose`) rated on their magnitude like their plain kind: a ripple's local amplitude as a
#: ``position_ripple``'s, a constant's torque as an ``offset``'s (TORQUE_SHARE), a Coulomb or viscous term's torque as
#: a friction torque (FRICTION_SHARE, as ``held_friction`` and the Stribeck excess); an inertia term has no
#: magnitude prior (a ``rotor_inertia`` only a sign one)
COMPOSED_TORQUE_SHARE = {"constant": TORQUE_SHARE, "coulomb": FRICTION_SHARE, "viscous": FRICTION_SHARE}


def _rate_composed(r: _Rating, kind: str, j: int | None, physical: Mapping[str, float], scales: ArmScales,
                   tau: float) -> Plausibility:
    """A composed effect (``kind`` its effect: ``ripple``, ``constant``, ``coulomb``, ``viscous``, ``inertia``) rated
    on its magnitude (:meth:`.compose.Composed.magnitude`: ``amplitude`` or ``torque`` in ``physical``) with the
    prior of its plain kind (:data:`COMPOSED_TORQUE_SHARE`): a modulated term the data would have named as an
    implausible plain term is no more plausible for its modulation. Without a magnitude, rated on its evidence."""
    if kind == "ripple" and "amplitude" in physical:
        amp = float(physical["amplitude"])
        r.factor(band_factor(amp / tau, 0.0, TORQUE_SHARE, SHARE_WIDTH),
                 f"a ripple of {amp:.3g} N m (its largest local amplitude) is large against the torque range "
                 f"{tau:.3g} N m", f"a position-dependent torque of {_who(j)} the robot file lacks")
        k = physical.get("order")
        g = scales.gear_ratios.get(j) if j is not None else None
        if k is not None and g and float(k) != 1.0:
            ok = any(abs(float(k) - m * g) < 0.5 or abs(float(k) * m - g) < 0.5 for m in (1, 2))
            r.factor(1.0 if ok else 0.7, f"order {float(k):g} is not a multiple or divisor of the gear ratio {g:g}")
        return r.done()
    share = COMPOSED_TORQUE_SHARE.get(kind)
    if share is not None and "torque" in physical:
        t = float(physical["torque"])
        r.factor(band_factor(t / tau, 0.0, share, SHARE_WIDTH),
                 f"a modulated {kind} torque of {t:.3g} N m is large against the torque range {tau:.3g} N m")
        return r.done()
    return r.done("composed effect: no prior on its magnitude, rated on its evidence only")


def _rate_delay(r: _Rating, j: int | None, physical: Mapping[str, float], params: Mapping[str, float],
                scales: ArmScales, delay_joints: Sequence[int | None]) -> None:
    """The ``time_delay`` prior: against a few sampling periods, a lead, and a delay on one joint only."""
    d = float(physical.get("delay_s", params.get("d", 0.0)))
    hi = max(DELAY_TYPICAL_S, DELAY_TYPICAL_PERIODS * scales.dt)
    r.factor(band_factor(d, 0.0, hi, DELAY_WIDTH),
             f"a {1e3 * abs(d):.3g} ms delay is long for a torque-controlled arm (typical: up to "
             f"{1e3 * hi:.3g} ms, a few {1e3 * scales.dt:.3g} ms sampling periods)",
             "the time stamps of the torque against the positions, the drive's torque filter")
    if d < -scales.dt:
        r.factor(LEAD_FACTOR, f"the torque leads the motion by {1e3 * -d:.3g} ms: not a transport delay",
                 "the sign convention of the time stamps, a velocity feed-forward in the torque")
    if j is not None and scales.n_joints > 1 and not any(x is None or x != j for x in delay_joints):
        r.factor(ONE_JOINT_DELAY_FACTOR, f"a delay on joint {j + 1} only is unusual: a drive or bus delay "
                 "shows on every joint of the bus",
                 f"what else looks like it: an elastic joint {j + 1} (a motor-side encoder), a filter on joint "
                 f"{j + 1}'s torque channel (its drive's current/torque filter), its own time stamping, a torque "
                 "computed from a delayed current")


def _rate_stiffness(r: _Rating, j: int | None, physical: Mapping[str, float], tau: float) -> None:
    """The ``elasticity`` prior: the deflection at the joint's torque range against harmonic drives'."""
    K = float(physical.get("K_Nm_per_rad", math.inf))
    if K < 0:
        r.factor(NEGATIVE_STIFFNESS_FACTOR, f"a negative stiffness ({K:.3g} N m/rad) is not a compliance",
                 "a position offset or a delay correlated with the torque")
    elif math.isfinite(K) and K > 0:
        defl = tau / K
        lo, hi = DEFLECTION_BAND
        r.factor(band_factor(defl, lo, hi, DEFLECTION_WIDTH),
                 f"K = {K:.3g} N m/rad deflects {_who(j)} by {1e3 * defl:.3g} mrad at its torque range "
                 f"({tau:.3g} N m); harmonic drives: {1e3 * lo:g}-{1e3 * hi:g} mrad",
                 "the gear's catalogue stiffness")


def _velocity_scale(r: _Rating, v: float, res: float, what: str) -> None:
    lo, hi = STRIBECK_BAND
    if v < res:
        r.factor(BELOW_RESOLUTION_FACTOR, f"{what} = {1e3 * v:.3g} mrad/s is below the velocity resolution "
                 f"({1e3 * res:.3g} mrad/s): a shape of the noise or of a delay at reversals, not friction",
                 "a time delay of the torque, the velocity filter")
    else:
        r.factor(band_factor(v, lo, hi, STRIBECK_WIDTH),
                 f"{what} = {v:.3g} rad/s is outside the usual {lo:g}-{hi:g} rad/s")


def law_plausibility(choice, scales: ArmScales, *, priors_only: bool = False) -> Plausibility:
    """The plausibility of a friction-law replacement (a :class:`.friction.FrictionChoice`: its joint, its laws
    with their shape parameters, its coefficients ``Fc``, ``Fs``, ``Fv``). The declared law (``sign`` +
    ``linear``) and a ``tanh`` rounding of the sign carry no shape prior: only the Stribeck velocity, the
    exponent of a power viscous law and the Coulomb coefficient are rated.

    Besides these priors, three factors weigh the *evidence* that a shape law is friction and not another
    effect seen through the friction columns (a delay or a gain error leaves its largest residual at the
    velocity reversals): a Stribeck velocity above :data:`STRIBECK_SPEED_SHARE` of the joint's typical
    speed (a reshaped Coulomb law), a static excess ``Fs - Fc`` below :data:`STRIBECK_EXCESS_SHARE` of the
    torque range, an out-of-fold gain below :data:`LAW_GAIN_MIN`. ``priors_only`` leaves them out (the
    friction-law stage applies no law that contradicts the priors; one that only lacks the evidence competes
    in the loop's rounds and is rated with them)."""
    j = int(choice.joint)
    coulomb, coulomb_param = choice.coulomb.law, choice.coulomb.param
    viscous, viscous_param = choice.viscous.law, choice.viscous.param
    coefficients = dict(choice.coefficients or {})
    r = _Rating()
    tau = float(scales.tau98[j]) if float(scales.tau98[j]) > 0 else 1.0
    if coulomb == "stribeck" and coulomb_param is not None:
        vs = float(coulomb_param)
        _velocity_scale(r, vs, scales.velocity_resolution(j), "Stribeck velocity vs")
        v98 = float(scales.v98[j])
        if v98 > 0 and vs >= scales.velocity_resolution(j) and not priors_only:
            r.factor(band_factor(vs / v98, 0.0, STRIBECK_SPEED_SHARE, STRIBECK_SPEED_WIDTH),
                     f"vs = {vs:.3g} rad/s is {100 * vs / v98:.0f} % of the joint's typical speed ({v98:.3g} rad/s): "
                     "the dip spans the motion, a reshaped Coulomb law rather than a Stribeck effect",
                     "a time delay or a gain error of the joint, seen through the friction columns")
        fs = coefficients.get("Fs")
        fc0 = coefficients.get("Fc")
        if fs is not None and fc0 is not None and math.isfinite(float(fs) - float(fc0)) and not priors_only:
            ex = float(fs) - float(fc0)
            if ex > 0:
                r.factor(band_factor(ex / tau, STRIBECK_EXCESS_SHARE, math.inf, STRIBECK_EXCESS_WIDTH),
                         f"a static excess Fs - Fc of {ex:.3g} N m is tiny against the torque range {tau:.3g} N m",
                         "the velocity filter's phase at reversals")
    if (coulomb == "stribeck" or viscous == "power") and not priors_only:
        d0, d1 = getattr(choice, "declared_cv_rel_err", None), getattr(choice, "cv_rel_err", None)
        if d0 is not None and d1 is not None and float(d0) > 0 and math.isfinite(float(d1)):
            g = 1.0 - float(d1) / float(d0)
            r.factor(band_factor(max(g, 1e-12), LAW_GAIN_MIN, math.inf, LAW_GAIN_WIDTH),
                     f"the law lowers the joint's cross-validated error by {100 * g:.1f} % only (a shape law "
                     f"is named with {100 * LAW_GAIN_MIN:g} % or more)",
                     "a time delay or a gain error of the joint")
    if viscous == "power" and viscous_param is not None:
        lo, hi = POWER_BAND
        r.factor(band_factor(float(viscous_param), lo, hi, POWER_WIDTH),
                 f"a viscous law |dq|^{float(viscous_param):.3g} is far from linear (usual exponent {lo:g}-{hi:g})",
                 "a load-dependent friction, a gain error of the joint")
    fc = coefficients.get("Fc")
    if fc is not None and math.isfinite(float(fc)):
        if float(fc) < 0:
            r.factor(NEGATIVE_FRICTION_FACTOR, f"a negative Coulomb friction ({float(fc):.3g} N m)")
        else:
            r.factor(band_factor(float(fc) / tau, 0.0, COULOMB_SHARE, SHARE_WIDTH),
                     f"a Coulomb friction of {float(fc):.3g} N m is large against the torque range {tau:.3g} N m")
    return r.done()


def _close(a: Mapping, s: float | None, remaining: float | None, factor: float = CLOSE_REMAINING,
           share: float = CLOSE_ALTERNATIVE) -> bool:
    """An eligible alternative ``a`` fits almost as well as the effect (score ``s``, validation error
    ``remaining`` left on its joints): it leaves at most ``factor`` times the effect's squared error, or
    (errors not recorded) reaches ``share`` of its score (:data:`CLOSE_REMAINING`, :data:`EXPLAINS_REMAINING`)."""
    if not a.get("eligible") or a.get("score") is None or a.get("same_effect"):
        return False
    ra = a.get("remaining")
    if remaining is not None and remaining > 0 and ra is not None and math.isfinite(float(ra)):
        return float(ra) ** 2 <= factor * remaining ** 2
    return s is not None and float(a["score"]) >= share * s


def verdict(plaus: Plausibility, score: float | None, alternatives: Sequence[Mapping], *,
            impossible: str | None = None, remaining: float | None = None) -> tuple[str, str]:
    """``(verdict, why)`` of an effect from its plausibility, its score, the validation error it leaves on its
    joints (``remaining``, RMS of the per-joint relative error norms) and its round's alternatives (dicts with
    ``score``, ``eligible`` and ``remaining``; see :func:`alternatives_of`)."""
    if impossible:
        return "rejected", f"its parameters are physically impossible ({impossible})"
    s = float(score) if score is not None and math.isfinite(float(score)) else None
    if plaus.score < PLAUSIBLE:
        if any(_close(a, s, remaining, EXPLAINS_REMAINING, ALTERNATIVE_EXPLAINS) for a in alternatives):
            return "rejected", "it is implausible and an alternative explains the same residual"
        return "doubtful", "it is implausible"
    if any(_close(a, s, remaining) for a in alternatives):
        return "doubtful", "an alternative fits almost as well"
    return "cause", "fits, beats its alternatives, plausible"


def explains_same(kind: str, variant: str, joint: int | None, partner: int | None, score: float | None, own,
                  other, round: int) -> bool:
    """An eligible candidate ``other`` (:class:`.report.CandidateScore`) of round ``round`` explains the same
    residual as the effect of kind ``kind`` whose own candidate is ``own``: it overlaps the effect's joints, is
    not the same physical effect under another name (:data:`SYNONYMS`) and leaves at most
    :data:`EXPLAINS_REMAINING` times the effect's squared validation error on its joints - the rule by which
    :func:`verdict` rejects an implausible effect, applied before the effect is added."""
    rem = None if own is None else remaining_error(own, joint, partner)
    s = float(score) if score is not None and math.isfinite(float(score)) else None
    return any(_close(a, s, rem, EXPLAINS_REMAINING, ALTERNATIVE_EXPLAINS)
               for a in alternatives_of(kind, variant, joint, partner, score, [other], round, k=None))


def _overlap(kind_joint: int | None, partner: int | None, other_joint: int | None, other_partner: int | None) -> bool:
    if kind_joint is None or other_joint is None:
        return True
    a = {kind_joint} | ({partner} if partner is not None else set())
    b = {other_joint} | ({other_partner} if other_partner is not None else set())
    return bool(a & b)


def remaining_error(c, joint: int | None, partner: int | None) -> float | None:
    """RMS over the joints of an effect (all for ``joint`` None) of the validation relative error norms a candidate
    (:class:`.report.CandidateScore`) leaves (None when not recorded)."""
    after = np.asarray(getattr(c, "val_rel_err_after", ()) or (), float)
    if after.size == 0:
        return None
    js = list(range(after.size)) if joint is None else [j for j in (joint, partner) if j is not None and j < after.size]
    return float(np.sqrt(np.mean(after[js] ** 2))) if js else None


#: one physical effect under two names of the library: a composed candidate whose columns are a plain kind's
#: (``sign(dq_j) |tau_hat_j|`` is the load-dependent friction, a constant changing with ``tau_hat_j`` the gain
#: column); as alternatives of each other they are the same explanation, not a competing one
SYNONYMS = (frozenset({("coulomb", "abs_tau"), ("load_friction", "")}), frozenset({("constant", "tau"), ("gain", "")}))


def _named(kind: str, variant: str) -> tuple[str, str]:
    """The physical effect a (kind, variant) of the library stands for: a friction-law replacement whose Coulomb
    law is Stribeck's is the Stribeck effect of its joint (the loop's ``stribeck`` kind at another ``vs``)."""
    if kind in ("load_friction", "gain", "stribeck"):
        return kind, ""
    if kind == "friction_law" and variant.startswith("stribeck"):
        return "stribeck", ""
    return kind, variant


def _same_effect(kind: str, variant: str, other_kind: str, other_variant: str) -> bool:
    a, b = _named(kind, variant), _named(other_kind, other_variant)
    return (a == b and a[0] == "stribeck") or any(a in g and b in g for g in SYNONYMS)


def own_candidate(kind: str, joint: int | None, partner: int | None, variant: str, tried: Sequence, round: int):
    """The effect's own entry among the candidates of its round (same kind, joints and variant; None when not
    found)."""
    return next((c for c in tried if c.round == round and c.kind == kind and c.joint == joint
                 and c.partner == partner and c.variant == variant), None)


def alternatives_of(kind: str, effect_variant: str, joint: int | None, partner: int | None,
                    score: float | None, tried: Sequence, round: int, k: int | None = N_ALTERNATIVES) -> list[dict]:
    """The next candidates of round ``round`` (``tried``: :class:`.report.CandidateScore`) on the joints of an
    effect of kind ``kind``, best score first, without the effect itself and without a candidate tying its
    score (the same fit under another name); ``remaining``: the validation error each leaves on the effect's
    joints (:func:`remaining_error`); ``same_effect``: the same physical effect under another name of the
    library (:data:`SYNONYMS`, not a competing explanation). ``k``: at most so many."""
    out = []
    for c in tried:
        if c.round != round or c.score is None or not math.isfinite(float(c.score)):
            continue
        if c.kind == kind and c.joint == joint and c.partner == partner and c.variant == effect_variant:
            continue
        if not _overlap(joint, partner, c.joint, c.partner):
            continue
        if score is not None and math.isfinite(float(score)) and abs(float(c.score) - float(score)) <= 1e-9 * abs(
                float(score)):
            continue
        out.append(c)
    out.sort(key=lambda c: -float(c.score))
    return [{"label": c.label + (f" {c.variant}" if c.variant and c.kind != "coupling" else ""), "kind": c.kind,
             "joint": None if c.joint is None else int(c.joint) + 1, "score": float(c.score),
             "eligible": bool(c.eligible), "search": dict(c.search),
             "remaining": remaining_error(c, joint, partner),
             "same_effect": _same_effect(kind, effect_variant, c.kind, c.variant)}
            for c in (out if k is None else out[:k])]


def fits_like(kind: str, joint: int | None, physical: Mapping[str, float], description: str, *,
              one_joint_delay: bool = False) -> str:
    """What an effect fits like, in words: ``"a 48 ms delay on joint 7 only"``, ``"a torque scale ×1.33 on joint 5"``."""
    who = _who(joint)
    if kind == "time_delay" and "delay_s" in physical:
        return f"a {1e3 * float(physical['delay_s']):.3g} ms delay on {who}" + (" only" if one_joint_delay else "")
    if kind == "gain" and "scale" in physical:
        return f"a torque scale ×{float(physical['scale']):.3g} on {who}"
    if kind == "contact_gain" and "scale" in physical:
        return f"a wrench scale ×{float(physical['scale']):.4g} of a contact sensor ({description})"
    if kind == "contact_offset":
        return f"a constant offset of a contact sensor ({description})"
    if kind == "elasticity" and "K_Nm_per_rad" in physical:
        return f"a stiffness of {float(physical['K_Nm_per_rad']):.3g} N m/rad of {who}"
    if kind == "stribeck" and "vs" in physical:
        return f"Stribeck friction with vs = {float(physical['vs']):.3g} rad/s on {who}"
    if kind == "held_friction" and "Fh_Nm" in physical:
        return f"a friction of {float(physical['Fh_Nm']):.3g} N m held at rest on {who} (the last sliding direction's)"
    if kind == "crosstalk" and "percent" in physical:
        fj = physical.get("from_joint")
        src = "a neighbouring joint" if fj is None else f"joint {int(fj)}"
        return f"cross-talk: {float(physical['percent']):.3g} % of {src}'s torque read in {who}'s torque channel"
    if kind == "link_length" and "length_mm" in physical:
        frame, fld = int(physical.get("frame", 0)), "r" if physical.get("field_r") else "d"
        return f"link {frame} length {float(physical['length_mm']):+.1f} mm ({fld}{frame})"
    if kind == "joint_zero" and "offset_deg" in physical:
        return f"an encoder zero offset of {float(physical['offset_deg']):.3g} deg on {who}"
    if kind == "joint_zero" and "offset_m" in physical:
        return f"an encoder zero offset of {1e3 * float(physical['offset_m']):.3g} mm on {who}"
    if kind == "position_ripple" and float(physical.get("k", 0.0)) == 1.0:
        return (f"a torque once per turn (order 1, {float(physical.get('amplitude', math.nan)):.3g} N m) on {who} "
                f"({ONCE_PER_TURN_NOTE})")
    if kind == "position_ripple" and "k" in physical:
        return f"a ripple of order {float(physical['k']):g} ({float(physical.get('amplitude', math.nan)):.3g} N m) on {who}"
    return description or f"{kind} on {who}"


def rate_effects(effects: Sequence, scales: ArmScales, tried: Sequence, *,
                 impossible: Mapping[str, str] | None = None,
                 law_ratings: Mapping[int, tuple[Plausibility, list[dict]]] | None = None) -> list:
    """``effects`` (:class:`.report.Effect`) with their ``verdict``, ``plausibility``, ``alternatives`` and
    ``verdict_reason`` set.

    ``tried``: every candidate of every round (the alternatives of an effect are those of its round);
    ``impossible``: label -> why its final parameters are impossible (:func:`.candidates.implausible`);
    ``law_ratings``: joint -> (rating, alternatives) of the friction-law stage's replacements (a law that won a
    round of the loop has that round's candidates as alternatives too).
    """
    impossible = dict(impossible or {})
    law_ratings = dict(law_ratings or {})
    delay_joints = [e.joint for e in effects if e.kind == "time_delay" and e.modulation is None]
    out = []
    for e in effects:
        if e.kind == "friction_law":
            pl, alts = law_ratings.get(e.joint, (Plausibility(1.0), []))
            if e.round > 0:   # a law that won a round of the loop: its rivals are that round's candidates too
                alts = alternatives_of(e.kind, e.variant, e.joint, e.partner, None, tried, e.round, k=None) + list(alts)
        else:
            short = {nm.split(".")[-1]: float(v) for nm, v in zip(e.names, e.values)}
            pl = effect_plausibility(e.kind, e.joint, short, e.physical or {}, scales, variant=e.variant,
                                     modulation=e.modulation, delay_joints=delay_joints)
            alts = alternatives_of(e.kind, e.variant, e.joint, e.partner, e.score, tried, e.round, k=None)
        own = own_candidate(e.kind, e.joint, e.partner, e.variant, tried, e.round)
        rem = None if own is None else remaining_error(own, e.joint, e.partner)
        v, why = verdict(pl, e.score, alts, impossible=impossible.get(e.label), remaining=rem)
        if e.kind == "time_delay" and e.modulation is None and not impossible.get(e.label):
            v, why = _delay_verdict(v, why, e, scales)
        alts = alts[:N_ALTERNATIVES]
        one = (e.kind == "time_delay" and e.joint is not None and scales.n_joints > 1
               and not any(x is None or x != e.joint for x in delay_joints))
        like = fits_like(e.kind, e.joint, e.physical or {}, e.description, one_joint_delay=one)
        if v == "cause":
            text = f"{like}; {why}"
        else:
            text = f"fits like {like}, but {why}"
            if pl.reasons and pl.score < 1.0:   # the priors it contradicts (not a note that there is none)
                text += ": " + "; ".join(pl.reasons)
            if pl.check:
                text += f"; check {pl.check}"
            text += "; not named the cause"
        out.append(replace(e, verdict=v, plausibility=pl, alternatives=tuple(alts), verdict_reason=text))
    return out


def delay_is_absurd(delay_s: float, scales: ArmScales) -> bool:
    """A delay longer than :data:`DELAY_ABSURD_PERIOD_SHARE` of the excitation's shortest period (``scales.f_max``;
    never absurd when unknown)."""
    f = scales.f_max
    return bool(f is not None and f > 0 and abs(float(delay_s)) > DELAY_ABSURD_PERIOD_SHARE / float(f))


def _delay_verdict(v: str, why: str, e, scales: ArmScales) -> tuple[str, str]:
    """The verdict of a delay effect: *rejected* only when absurd (:func:`delay_is_absurd`); an implausible delay
    that fits (on one joint only, or long for the bus) is *doubtful*, even when an alternative explains part of
    the same residual - it was found, and an elastic joint or a filter on the channel can look the same."""
    d = float((e.physical or {}).get("delay_s", e.values[0] if len(e.values) else 0.0))
    if delay_is_absurd(d, scales):
        f = float(scales.f_max or 0.0)
        return "rejected", (f"a {1e3 * abs(d):.3g} ms delay is longer than a quarter of the excitation's shortest "
                            f"period ({1e3 * DELAY_ABSURD_PERIOD_SHARE / f:.3g} ms at {f:.3g} Hz): no transport delay")
    if v == "rejected":
        return "doubtful", "it is implausible, and an alternative explains part of the same residual"
    return v, why


def law_alternatives(choice, k: int = N_ALTERNATIVES) -> list[dict]:
    """The other laws the friction-law stage tried on a joint (a :class:`.friction.FrictionChoice`), with the
    share of the declared law's out-of-fold squared error each removes as ``score`` (informational: the stage
    chose by cross-validation, they are not ``eligible`` candidates of a round)."""
    chosen = {choice.coulomb.label, choice.viscous.label}
    d0 = float(choice.declared_cv_rel_err)
    alts = [{"label": c.label, "kind": "friction_law", "joint": int(choice.joint) + 1,
             "score": (1.0 - (float(c.cv_rel_err) / d0) ** 2) if d0 > 0 else None, "eligible": False, "search": {}}
            for c in choice.candidates if c.label not in chosen and c.law not in ("sign", "linear")]
    return sorted(alts, key=lambda a: -(a["score"] if a["score"] is not None else -math.inf))[:k]
