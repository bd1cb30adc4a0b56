"""The loop's plausibility rating of a stiffness it finds (docs/loop-plausibility.md, ``elasticity``): the
deflection ``tau98 / K`` at the joint's torque range against the harmonic-drive band (Harmonic Drive CSG/CSD
catalogues: torsional stiffness 1e3-1e5 N m/rad for arm-size drives, deflections of a fraction of a mrad to
~20 mrad at rated torque). An injected elasticity moved from a plausible deflection (5 mrad) to an implausible one
(150 mrad) is found both times; its verdict goes from ``cause`` to ``doubtful`` with the reason stated."""
from __future__ import annotations

import numpy as np
import pytest

from symoro_gen.diagnostics.plausibility import DEFLECTION_BAND, PLAUSIBLE, ArmScales, effect_plausibility


def _scales(tau98: float, n: int = 4) -> ArmScales:
    return ArmScales(dt=0.004, tau98=np.full(n, tau98), v98=np.ones(n), dq_noise=np.full(n, 1e-4), n_joints=n)


@pytest.mark.parametrize("K", [1e3, 1e4, 1e5])
def test_catalogue_stiffnesses_are_plausible(K):
    """An arm-size joint (torque range 20 N m) with a catalogue stiffness deflects 0.2-20 mrad: no penalty."""
    pl = effect_plausibility("elasticity", 1, {"c": 1 / K}, {"K_Nm_per_rad": K}, _scales(20.0))
    assert pl.score == 1.0, pl.reasons


@pytest.mark.parametrize("defl", [0.2, 1.0, 1e-6])
def test_deflections_far_outside_the_band_are_implausible(defl):
    """A deflection of 0.2 rad (11 deg) or 1 rad at the torque range, or 1 urad (a stiffness beyond any gear),
    rates below PLAUSIBLE, and the reason gives the deflection in mrad and the band."""
    K = 20.0 / defl
    pl = effect_plausibility("elasticity", 1, {"c": 1 / K}, {"K_Nm_per_rad": K}, _scales(20.0))
    assert pl.score < PLAUSIBLE
    assert f"{1e3 * defl:.3g} mrad" in pl.reasons[0] and f"{1e3 * DEFLECTION_BAND[1]:g} mrad" in pl.reasons[0]


@pytest.mark.slow
@pytest.mark.parametrize("defl, want", [(0.005, "cause"), (0.15, "doubtful")])
def test_verdict_follows_the_injected_stiffness(defl, want):
    from symoro_gen.diagnostics import diagnose
    from tests.diagnostics.simdata import recording

    j = 3
    _, clean = recording("lwr4", 11, None, None, duration=20.0)
    tau98 = float(np.quantile(np.abs(clean.tau[:, j]), 0.98))
    K = tau98 / defl
    model, tr = recording("lwr4", 11, "elasticity", j, K=K, duration=20.0)
    rep = diagnose(model, tr)
    e = next(x for x in rep.effects if x.kind == "elasticity")
    assert e.joint == j
    assert e.verdict == want, e.verdict_reason
    if want == "cause":
        assert e.plausibility.score >= PLAUSIBLE
        assert abs(e.physical["K_Nm_per_rad"] - K) < 0.1 * K
    else:
        assert e.plausibility.score < PLAUSIBLE
        assert "implausible" in e.verdict_reason and "mrad at its torque range" in e.verdict_reason
        assert "not named the cause" in e.verdict_reason
