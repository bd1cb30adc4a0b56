"""Plausibility of identified bodies (symoro_gen.identification.plausibility) on simulated arms with known truth:
the truth gives no warning; an absurd body (nominal mass 10 x the truth, a far centre of mass, a negative rotor
inertia) is named; ``bounded_bodies`` keeps the centre of mass in the link's box; a solver status other than
optimal is a warning. On the real LWR4 recording, link 2's mass is measured and, when absurd, named."""
from __future__ import annotations

import dataclasses
import importlib
import json

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description.inertia import com_from_standard, standard_from_com
from symoro_gen.description.mdh import row_transform
from symoro_gen.identification.plausibility import (
    MASS_FACTOR,
    Plausibility,
    body_boxes,
    check_base,
    check_standard,
    slab_rows,
)
from symoro_gen.loader import model_for
from symoro_gen.params import INERTIAL_KINDS
from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording


def _truth(robot, seed, **kw):
    """Realistic bodies: centre of mass within 0.1 m of the frame origin, semi-axes up to 0.15 m."""
    rng = np.random.default_rng(seed)
    return rng, random_physical_parameters(robot, rng, com_radius=0.1, size_range=(0.03, 0.15), **kw).as_dict()


def _recordings(model, truth: dict, rng, n=2, duration=8.0):
    chi = np.array([truth[k] for k in model.STANDARD_NAMES])
    out = []
    for i in range(n):
        mo = fourier_trajectory(model.N_JOINTS, duration, 0.005, rng, vmax=1.5, amax=8.0)
        out.append(simulate_recording(model, mo.t, mo.q, mo.dq, mo.ddq, chi, noise_q=1e-5, noise_tau=0.02, rng=rng,
                                      source=f"sim{i}"))
    return out


# ---- geometry ---------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["scara", "lwr4", "rx90"])
def test_boxes_contain_the_children_origins(name):
    """Independent of the box code: the origin of every child frame, from the MDH transform T(j, k)."""
    robot, _ = model_for(name)
    boxes = body_boxes(robot)
    subs = robot.geometry_subs()
    for r in robot.joints:
        box = boxes[r.j]
        assert np.all(box.lo <= -box.margin + 1e-12) and np.all(box.hi >= box.margin - 1e-12)
        for k in robot.children(r.j):
            o = row_transform(robot.row(k), subs, 0.0)[:3, 3]
            assert box.outside(o) == 0.0, (r.j, k, o)
            assert np.all(o - box.lo >= box.margin - 1e-9) and np.all(box.hi - o >= box.margin - 1e-9)


def test_scara_link1_box_spans_its_arm():
    robot, _ = model_for("scara")
    b = body_boxes(robot)[1]
    D2 = robot.values["D2"]
    assert b.hi[0] - b.lo[0] == pytest.approx(D2 + 2 * b.margin)


def test_slab_rows_are_the_integrals_over_point_masses():
    """tr(Q_i P) = sum m (x_i - lo_i)(hi_i - x_i) for point masses (an independent sum); >= 0 inside the box."""
    robot, _ = model_for("lwr4")
    box = body_boxes(robot)[2]
    rng = np.random.default_rng(0)
    pts = rng.uniform(box.lo, box.hi, size=(50, 3))
    masses = rng.uniform(0.1, 1.0, 50)
    p = sum(standard_from_com(m, x, np.zeros((3, 3))) for m, x in zip(masses, pts))
    A, _ = slab_rows(box)
    direct = [(masses * (pts[:, i] - box.lo[i]) * (box.hi[i] - pts[:, i])).sum() for i in range(3)]
    assert np.allclose(A @ p, direct, rtol=1e-10)
    assert np.all(A @ p >= 0)
    out = standard_from_com(1.0, box.hi + 0.1, np.zeros((3, 3)))
    assert np.all(A @ out < 0)


# ---- checks on standard sets -----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", ["scara", "lwr4"])
def test_truth_gives_no_finding_and_a_tenfold_nominal_mass_is_named(name):
    robot, _ = model_for(name)
    _, truth = _truth(robot, 11)
    assert check_standard(robot, truth, nominal=truth) == []
    assert check_standard(robot, truth, nominal={}) == []
    nominal = dict(truth, M2=10 * truth["M2"])
    found = check_standard(robot, truth, nominal=nominal)
    assert [(f.body, f.quantity) for f in found] == [("link 2", "mass")]
    assert found[0].message.startswith(f"link 2: mass {truth['M2']:.3g} kg, 0.1 x its nominal")
    assert found[0].bound == pytest.approx(10 * truth["M2"] / MASS_FACTOR)


def test_far_centre_of_mass_is_named():
    robot, _ = model_for("lwr4")
    _, truth = _truth(robot, 12)
    far = dict(truth)
    m, c, Ic = com_from_standard([truth[f"{k}6"] for k in INERTIAL_KINDS])
    far.update(zip([f"{k}6" for k in INERTIAL_KINDS], standard_from_com(m, c + [0.0, 0.0, 0.57], Ic)))
    found = check_standard(robot, far, nominal=truth)
    assert {(f.body, f.quantity) for f in found} == {("link 6", "com"), ("link 6", "com_shift")}
    assert any("lies" in f.message and "outside the link's box" in f.message for f in found)


# ---- the workflow: unconstrained and --physical ------------------------------------------------------------------
@pytest.fixture(scope="module")
def scara_truth():
    robot, model = model_for("scara")
    rng, truth = _truth(robot, 7)
    return robot, model, rng, truth


def test_simulated_scara_gives_no_body_warning(scara_truth):
    pytest.importorskip("cvxpy")
    robot, model, rng, truth = scara_truth
    data = _recordings(model, truth, rng)
    desc = dataclasses.replace(robot, nominal=truth)
    for physical in (False, True):
        res = symoro_gen.identify(desc, data, physical=physical)
        assert res.plausibility is not None and res.plausibility.findings == (), res.plausibility.warnings
        assert "Plausibility of the bodies" not in res.summary()
        d = res.to_dict()
        assert d["plausibility"]["findings"] == [] and not any("fit:" in w for w in d["warnings"])
        assert len(d["plausibility"]["boxes"]) == 4


def test_negative_rotor_inertia_is_named(scara_truth):
    """Drives whose IA2 and IA4 are negative (both base parameters alone): the unconstrained fit recovers them,
    each named by its joint. IA3R = IA3 + OFF3/G3 has no sign (the offset has none): not reported."""
    robot, model, rng, truth = scara_truth
    bad = dict(truth, IA2=-0.2, IA4=-0.1, IA3=-0.3)
    res = symoro_gen.identify(robot, _recordings(model, bad, rng))
    found = {f.quantity: f for f in res.plausibility.findings}
    assert set(found) == {"IA2", "IA4"}, res.plausibility.warnings
    assert found["IA2"].body == "joint 2" and found["IA4"].body == "joint 4"
    v2, v4 = found["IA2"].value, found["IA4"].value
    assert v2 == pytest.approx(-0.2, abs=0.01) and v4 == pytest.approx(-0.1, abs=0.01)
    assert found["IA2"].message.startswith(f"joint 2: rotor inertia IA2 = {v2:.3g} kg m^2 < 0 (2 sigma ")
    assert "beyond 2 sigma" in found["IA2"].message
    assert f"warning: unconstrained fit: joint 2: rotor inertia IA2 = {v2:.3g}" in res.summary()
    assert any(w.startswith(f"unconstrained fit: joint 4: rotor inertia IA4 = {v4:.3g}") for w in res.to_dict()["warnings"])


def test_check_base_signs_only_sums_of_nonnegative_terms():
    """Every base parameter at -1: reported exactly when its relation (independently: the model's regrouping
    of unit vectors) has positive coefficients on XX, YY, ZZ, M, IA, FV, FS only. On the SCARA, ZZ1R and IA3R
    hold OFF3/G3 (no sign); on the LWR4, ZZ1R = ZZ1 + YY2 is signed."""
    for name in ("scara", "lwr4", "rx90"):
        _, model = model_for(name)
        names = list(model.BASE_NAMES)
        found = {f.quantity for f in check_base(model, names, -np.ones(len(names)))}
        st = list(model.STANDARD_NAMES)
        for n in names:
            img = np.array([model.base_parameters(np.eye(len(st))[k])[names.index(n)] for k in range(len(st))])
            terms = [(c, st[k]) for k, c in enumerate(img) if abs(c) > 1e-9]
            signed = all(c > 0 and m.rstrip("0123456789") in ("XX", "YY", "ZZ", "M", "IA", "FV", "FS")
                         for c, m in terms)
            assert (n in found) == signed, (name, n, terms)
    _, scara = model_for("scara")
    found = {f.quantity for f in check_base(scara, scara.BASE_NAMES, -np.ones(len(scara.BASE_NAMES)))}
    assert {"IA2", "FV1", "FS1", "ZZ4"} <= found and not {"ZZ1R", "IA3R", "MX4", "OFF1"} & found
    _, lwr4 = model_for("lwr4")
    (f,) = [f for f in check_base(lwr4, lwr4.BASE_NAMES, -np.ones(len(lwr4.BASE_NAMES))) if f.quantity == "ZZ1R"]
    assert f.body == "link 1" and "ZZ1R = ZZ1 + YY2" in f.message


@pytest.fixture(scope="module")
def far_com_fits():
    """SCARA whose terminal link 4 has its centre of mass 0.6 m out along x (MX4, MY4 are base parameters
    alone, so the data see it), fitted --physical with and without bounded bodies."""
    pytest.importorskip("cvxpy")
    robot, model = model_for("scara")
    rng, truth = _truth(robot, 8)
    m, c, Ic = com_from_standard([truth[f"{k}4"] for k in INERTIAL_KINDS])
    truth.update(zip([f"{k}4" for k in INERTIAL_KINDS], standard_from_com(m, np.array([0.6, 0.0, c[2]]), Ic)))
    data = _recordings(model, truth, rng)
    desc = dataclasses.replace(robot, nominal=truth)
    return robot, [symoro_gen.identify(desc, data, physical=True, bounded_bodies=b) for b in (False, True)]


def _com4(res):
    st = res.physical.standard_map()
    return com_from_standard([st[f"{k}4"] for k in INERTIAL_KINDS])[1]


def test_far_com_is_warned_and_bounded_bodies_keep_it_in_the_box(far_com_fits):
    robot, (free, bounded) = far_com_fits
    box = body_boxes(robot)[4]
    assert box.outside(_com4(free)) > 0.3
    assert any(f.body == "link 4" and f.quantity == "com" for f in free.plausibility.findings)
    assert any(w.startswith("physical fit: link 4: centre of mass") for w in free.to_dict()["warnings"])
    assert box.outside(_com4(bounded)) <= 1e-4  # solver tolerance
    assert not any(f.body == "link 4" and f.quantity in ("com", "second_moments")
                   for f in bounded.plausibility.findings)
    assert bounded.physical.bounded and bounded.to_dict()["physical"]["bounded_bodies"] is True
    assert any(a.startswith("link 4: mass distribution at the boundary") for a in bounded.physical.active_constraints)
    assert "bodies bounded" in bounded.summary()


def test_bounded_bodies_needs_physical():
    with pytest.raises(symoro_gen.errors.IdentificationError, match="--bounded-bodies"):
        symoro_gen.workflows.IdentifyOptions(bounded_bodies=True)


def test_solver_status_other_than_optimal_is_a_warning():
    from symoro_gen.identification.physical import status_warnings

    assert status_warnings("CLARABEL", "optimal") == ()
    (w,) = status_warnings("CLARABEL", "optimal_inaccurate")
    assert "optimal_inaccurate" in w and "CLARABEL" in w
    p = Plausibility(notes=(w,))
    assert p.summary() == f"warning: {w}" and p.to_dict()["notes"] == [w]


def test_solver_status_reaches_the_text_and_json(far_com_fits, monkeypatch):
    from symoro_gen.identification.physical import status_warnings

    wf = importlib.import_module("symoro_gen.workflows.identify")
    robot, (free, _) = far_com_fits
    phys = dataclasses.replace(free.physical, status="optimal_inaccurate",
                               warnings=status_warnings("CLARABEL", "optimal_inaccurate"))
    res = dataclasses.replace(free, physical=phys, plausibility=wf._plausibility(robot, free.model, free.unconstrained, phys))
    assert "warning: conic solver CLARABEL ended with status 'optimal_inaccurate'" in res.summary()
    assert any("optimal_inaccurate" in w for w in json.loads(json.dumps(res.to_dict()))["warnings"])


# ---- the real LWR4 recording -------------------------------------------------------------------------------------
@pytest.mark.realdata
def test_real_lwr4_physical_link2_mass(shared_data):
    pytest.importorskip("cvxpy")
    d = shared_data / "kuka_lwr4_flobaroid" / "data" / "KUKA" / "HW"
    files = [d / f"measurements_{i}.npz" for i in (1, 3)]
    if not all(p.is_file() for p in files):
        pytest.skip(f"LWR4 recordings not found in {d}")
    res = symoro_gen.identify("lwr4", files, physical=True)
    m2 = res.physical.standard_map()["M2"]
    named = [f for f in res.plausibility.findings if f.body == "link 2" and f.quantity == "mass"]
    if m2 > MASS_FACTOR * 2.7:
        assert named and named[0].message.startswith(f"link 2: mass {m2:.3g} kg")
        assert any(w.startswith("physical fit: link 2: mass") for w in res.to_dict()["warnings"])
    else:
        assert not named


def test_rotor_inertia_against_its_nominal_value():
    """IA2 alone in the base parameters (unconstrained fit) and IA6 of a standard set (--physical): a value
    outside [1/3, 3] x a non-zero nominal IA is named by its joint; no nominal, no check."""
    _, scara = model_for("scara")
    names = list(scara.BASE_NAMES)
    vals = np.ones(len(names))
    vals[names.index("IA2")] = 0.5
    (f,) = check_base(scara, names, vals, nominal={"IA2": 0.05})
    assert (f.body, f.quantity, f.bound) == ("joint 2", "IA2", pytest.approx(0.15))
    assert f.message == "joint 2: rotor inertia IA2 = 0.5 kg m^2, 10 x its nominal 0.05 (plausible: 0.333 to 3 x)"
    assert check_base(scara, names, vals) == []
    robot, _ = model_for("rx90")
    _, truth = _truth(robot, 13)
    found = check_standard(robot, dict(truth, IA6=0.5), nominal=dict(truth, IA6=0.01))
    assert [(f.body, f.quantity) for f in found] == [("joint 6", "IA6")]
    assert "50 x its nominal 0.01" in found[0].message
