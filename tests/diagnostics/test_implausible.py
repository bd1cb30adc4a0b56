"""Physical plausibility of an effect's identified parameters (``candidates.implausible``): the rules,
at and across their limits."""
from __future__ import annotations

import math

import numpy as np
import pytest

from symoro_gen.diagnostics.candidates import GAIN_SCALE_RANGE, MAX_DELAY_PHASE, Family, implausible


def _fam(kind, params, variant=None, joint=4):
    return Family(kind, joint, tuple(params), lambda fr, ctx: [np.zeros((1, len(params)))], variant=variant)


@pytest.mark.parametrize("gamma, bad", [(0.0, False), (0.1, False), (-0.49, False), (0.99, False),
                                        (-0.51, True), (1.01, True), (-2.102, True), (1.26, True)])
def test_gain_scale_range(gamma, bad):
    why = implausible(_fam("gain", ["gamma"]), [gamma], f_dyn=1.0)
    assert (why is not None) == bad, why
    if bad:
        assert f"{1 + gamma:.3g}" in why and "joint 5" in why


@pytest.mark.parametrize("f_dyn", [0.5, 1.0, 4.0])
def test_delay_bound_scales_with_the_dynamics_bandwidth(f_dyn):
    d_max = MAX_DELAY_PHASE / (2 * math.pi * f_dyn)
    fam = _fam("time_delay", ["d"])
    for d in (0.0, 0.5 * d_max, -0.99 * d_max, 0.99 * d_max):
        assert implausible(fam, [d], f_dyn=f_dyn) is None
    for d in (1.01 * d_max, -1.01 * d_max, -0.413 if d_max < 0.413 else -2 * d_max):
        assert "first-order" in implausible(fam, [d], f_dyn=f_dyn)
    # the LWR4's measured 70 ms torque lag is possible at its 1 Hz dynamics bandwidth; -0.41 s is not
    assert implausible(fam, [0.0697], f_dyn=1.0) is None
    assert implausible(fam, [-0.413], f_dyn=1.0) is not None


def test_shared_motor_friction_must_dissipate():
    fam = _fam("coupling", ["IAm", "FVm", "FSm"], variant="shared")
    assert implausible(fam, [0.012, 0.589, 2.06], f_dyn=1.0) is None
    assert implausible(fam, [-0.01, 0.589, 2.06], f_dyn=1.0) is None     # inertia: a correction, any sign
    assert "FSm" in implausible(fam, [0.012, 0.589, -0.2], f_dyn=1.0)
    assert "FVm" in implausible(fam, [0.012, -0.1, 2.06], f_dyn=1.0)
    # a one-way coupling's terms are corrections of the joint's own model: no sign rule
    assert implausible(_fam("coupling", ["IA", "FV"], variant="one-way"), [0.0, -0.5], f_dyn=1.0) is None


def test_other_kinds_have_no_rule():
    assert implausible(_fam("stribeck", ["Fst"]), [-2.46], f_dyn=1.0) is None
    assert GAIN_SCALE_RANGE[0] < 1 < GAIN_SCALE_RANGE[1]
