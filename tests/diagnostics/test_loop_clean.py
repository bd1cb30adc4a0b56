"""Clean simulated data (the declared model is the truth, realistic noise on q and torque): over 30
seeds the closed loop (friction-law stage, plain and composed candidates, stability, unexplained
structure) adds nothing and flags nothing. Small recordings keep it fast."""
from __future__ import annotations

import pytest

from symoro_gen.diagnostics import DiagnoseSettings, diagnose

from .simdata import recording

pytest.importorskip("sklearn", reason="scikit-learn (extra 'diagnose') is needed for the unexplained stage")

SEEDS = range(500, 530)
#: three chunks of ten seeds (each chunk one test, so no single test runs long)
CHUNKS = [SEEDS[i:i + 10] for i in range(0, len(SEEDS), 10)]


# the friction-law stage used to put a Stribeck law on seed 510 (joint 1) and 539 (joint 2): a law whose shape
# is searched on the folds that judge it claims CV gains on pure noise (the null replicates reach 0.46); it
# now has to beat the simulated-noise placebo (core._law_beats_noise). Seeds 530-559 pass too (run once).


@pytest.mark.slow
@pytest.mark.parametrize("seeds", CHUNKS, ids=[f"seeds{c[0]}-{c[-1]}" for c in CHUNKS])
def test_clean_data_nothing_added_nothing_flagged_over_30_seeds(seeds):
    added, flagged = {}, {}
    for seed in seeds:
        model, tr = recording("scara", seed, duration=10.0, dt=0.01)
        rep = diagnose(model, tr, DiagnoseSettings(structure=False))
        d = rep.to_dict()
        # a smoothing of sign(dq) at the velocity noise floor that passes the acceptance test is listed as an
        # effect (it changes the model), but it is a processing matter, not a physical effect the clean truth
        # lacks: allowed, as long as no joint ends worse on the validation data beyond its band
        physical = [e for e in d["effects"] if e["kind"] != "sign_smoothing"]
        if physical:
            added[seed] = [(e["kind"], e["joint"], e["modulation"]) for e in physical]
        assert d["acceptance"]["validation_worse"] == [], (seed, d["acceptance"])
        if d["unexplained"]:
            flagged[seed] = d["unexplained"]
    assert sum(len(c) for c in CHUNKS) >= 30
    assert not added, f"effects added on clean data: {added}"
    assert not flagged, f"structure flagged on clean data: {flagged}"
