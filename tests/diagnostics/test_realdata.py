"""The loop on the real recordings of ../shared/data (skipped when absent).

* KUKA LWR4+ (FloBaRoID): identify on measurements 1 and 3, validate on 2. The declared model is the
  paper's (Coulomb + viscous + offset, no rotor inertia). The loop must run, name what it adds, and
  the validation error of the joints it works on must drop.
* Staubli TX40 (figaroh), declared *without* the coupled-wrist motor terms (Iam6, fvm6, fsm6 of
  TX40_config.yaml): the loop must trace the wrist residual to a shared coupling of joints 5 and 6,
  with values near the published priors.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.realdata

LWR4 = Path("kuka_lwr4_flobaroid") / "data" / "KUKA" / "HW"
TX40 = Path("staubli_tx40_figaroh") / "data"


@pytest.fixture(scope="module")
def lwr4_report(shared_data):
    import symoro_gen
    from symoro_gen.diagnostics import DiagnoseSettings, diagnose
    from symoro_gen.preprocessing.readers import load_trajectory

    paths = [shared_data / LWR4 / f"measurements_{i}.npz" for i in (1, 2, 3)]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"LWR4 recordings not found: {missing}")
    tr = [load_trajectory(p, n_joints=7) for p in paths]
    return diagnose(symoro_gen.load_model("lwr4"), [tr[0], tr[2]], DiagnoseSettings(method="ols"), validation=[tr[1]])


@pytest.mark.slow
def test_lwr4_loop_runs_and_names_what_it_adds(lwr4_report):
    rep = lwr4_report
    from symoro_gen.diagnostics import KINDS
    from symoro_gen.diagnostics.compose import EFFECTS

    assert rep.effects, rep.summary()
    assert all(e.kind in KINDS + EFFECTS + ("friction_law",) for e in rep.effects)
    # the declared model's validation errors (plain OLS, Coulomb + viscous + offset): the large wrist and
    # joint-1 errors the issue quotes, and joints 2 and 4 well modelled
    b = rep.before_validation_rel_err
    assert b[1] < 0.05 and b[3] < 0.05 and b[6] > 0.5 and b[0] > 0.15, b
    # every effect's own joint(s) predict the unseen file no worse than the declared model beyond that joint's
    # 95 % block-bootstrap band (the loop accepts on the end of files 1 and 3 and never reads file 2, so it
    # cannot promise a strict decrease there: the ripple of joint 3 modulated by q5 lowers the acceptance
    # error 0.108 -> 0.087 and moves file 2's 0.087 -> 0.091, inside its band [0.063, 0.111]); most improve
    a = rep.after_validation_rel_err
    band = rep.before_validation_rel_err_band
    own = {e.joint for e in rep.effects if e.joint is not None}
    for j in own:
        assert a[j] <= band[j, 1], (j, b, a, band[j])
    assert sum(a[j] < b[j] for j in own) > len(own) / 2, (b, a)
    assert rep.acceptance["validation_worse"] == []
    assert a[6] < 0.5 * b[6], (b, a)          # the wrist joint 7 error is at least halved
    assert np.mean(a) < np.mean(b)
    d = rep.to_dict()
    assert [e["kind"] for e in d["effects"]] == [e.kind for e in rep.effects]


@pytest.mark.slow
def test_tx40_finds_the_coupled_wrist(shared_data):
    from symoro_gen.diagnostics import DiagnoseSettings, diagnose
    from symoro_gen.loader import model_for
    from symoro_gen.preprocessing.readers import load_trajectory

    folder = shared_data / TX40
    if not (folder / "pos_read_data.csv").is_file():
        pytest.skip(f"TX40 recording not found in {folder}")
    robot, model = model_for("tx40")
    tr = load_trajectory("q=pos_read_data.csv,tau=curr_data.csv,dt=0.0002", robot=robot,
                         drive_chain=robot.drive_chain, base_dir=folder)
    rep = diagnose(model, tr, DiagnoseSettings(max_effects=2))
    first = next(e for e in rep.effects if e.kind != "friction_law")   # after the friction-law stage
    assert (first.kind, first.variant, first.joint, first.partner) == ("coupling", "shared", 4, 5), rep.summary()
    # published priors (TX40_config.yaml): Iam6 = 0.00964 kg m^2, fvm6 = 0.616 N m s/rad, fsm6 = 1.95 N m
    iam, fvm, fsm = first.values
    assert iam == pytest.approx(0.00964, rel=0.5)
    assert fvm == pytest.approx(0.616, rel=0.25)
    assert fsm == pytest.approx(1.95, rel=0.25)
    assert rep.after_validation_rel_err[4] < 0.5 * rep.before_validation_rel_err[4]
    assert rep.after_validation_rel_err[5] < rep.before_validation_rel_err[5]


@pytest.mark.slow
def test_lwr4_ten_effects_are_physically_possible(shared_data):
    """With ``max_effects = 10`` the loop used to report a gain of joint 5 of scale -1.10 and a joint-5 delay of
    -0.41 s (a torque-scaling column and the delay's first-order column fitted jointly, far outside the
    expansion's validity): every effect reported must now be physically possible, the candidates passed over
    for it are listed in ``implausible`` and the warnings."""
    import symoro_gen
    from symoro_gen.diagnostics import DiagnoseSettings, diagnose
    from symoro_gen.diagnostics.candidates import GAIN_SCALE_RANGE, MAX_DELAY_PHASE
    from symoro_gen.preprocessing.readers import load_trajectory

    paths = [shared_data / LWR4 / f"measurements_{i}.npz" for i in (1, 2, 3)]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"LWR4 recordings not found: {missing}")
    tr = [load_trajectory(p, n_joints=7) for p in paths]
    rep = diagnose(symoro_gen.load_model("lwr4"), [tr[0], tr[2]], DiagnoseSettings(method="ols", max_effects=10),
                   validation=[tr[1]])
    d_max = MAX_DELAY_PHASE / (2 * np.pi * rep.settings["dynamics_bandwidth_hz"])
    for e in rep.effects:
        if e.kind == "time_delay":
            assert abs(e.physical["delay_s"]) <= d_max, rep.summary()
        if e.kind == "gain":
            assert GAIN_SCALE_RANGE[0] <= e.physical["scale"] <= GAIN_SCALE_RANGE[1], rep.summary()
    # the joint-5 lag (a delay on one joint only, rated down by the plausibility priors) is named, or it is an
    # alternative of what was named instead (a torque-proportional constant of joint 5 fits it almost as well)
    assert any(e.kind == "time_delay" or any(a.get("kind") == "time_delay" for a in e.alternatives)
               for e in rep.effects), rep.summary()
    d = rep.to_dict()
    assert d["implausible"], rep.summary()   # on this recording a joint-5 gain of scale 2.26 is passed over
    assert all(x["reasons"] for x in d["implausible"])
