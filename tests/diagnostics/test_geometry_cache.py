"""The loop's geometry candidates kept across rounds: their decimated derivatives are built once per frame and
each fit's column is one product with them (the column and the decimation are both linear in the parameters).

* ``link_length``: the kept decimated entries of the emitted ``dY_std/dL`` times a changed fit equal a fresh
  full-rate evaluation of the columns at that fit (``length_columns``) to rounding, with no second full-rate
  pass, and the decimated central difference of Pinocchio's torque at the perturbed geometry;
* ``joint_zero``: the tangent kept on the rigid model's columns serves the model with a friction law in place of
  a joint's ``FS``/``FV`` (new parameter names) without a new full-rate pass, and equals a fresh evaluation on
  that model at a changed fit and the decimated central difference of Pinocchio's torque in the angle.
"""
from __future__ import annotations

import numpy as np
import pytest

import symoro_gen.diagnostics.candidates as candidates
import symoro_gen.diagnostics.geometry as dgeo
from symoro_gen.description import load_robot
from symoro_gen.diagnostics.candidates import FitContext, make_families
from symoro_gen.diagnostics.frame import build_frame, common_bandwidth
from symoro_gen.diagnostics.geometry import (
    LengthColumns,
    decimated_zero_matrix,
    description_of,
    length_columns,
    visible_lengths,
)
from symoro_gen.identification.friction_law import JointColumns, LawSplicedModel
from symoro_gen.identification.geometry import emitted_length_terms, perturbed_robot

from .simdata import recording

pin = pytest.importorskip("pinocchio")
from tests.oracles.pinocchio_model import pin_torque, random_parameters  # noqa: E402


@pytest.fixture(scope="module")
def rx90_frame():
    model, tr = recording("rx90", 31, noise_q=1e-4, duration=3.0)
    F = build_frame(model, [tr], dynamics_bandwidth_hz=common_bandwidth([tr]))
    return model, F


def _close(a: np.ndarray, b: np.ndarray, rel: float) -> float:
    err = float(np.abs(a - b).max()) / max(float(np.abs(b).max()), 1e-300)
    assert err <= rel, err
    return err


def test_kept_length_entries_give_a_changed_fits_columns(rx90_frame, monkeypatch):
    model, F = rx90_frame
    lengths = visible_lengths(model)
    rng = np.random.default_rng(5)
    shared = LengthColumns(model, lengths)
    theta = {nm: float(v) for nm, v in zip(model.BASE_NAMES, rng.normal(size=len(model.BASE_NAMES)))}
    first = np.hstack([shared.column(F, theta, i) for i in range(len(lengths))])
    _close(first, length_columns(F, model, theta, lengths), 1e-9)
    theta2 = {nm: v * (1.0 + rng.uniform(-0.5, 0.5)) for nm, v in theta.items()}   # another fit: entries kept
    again = np.hstack([shared.column(F, theta2, i) for i in range(len(lengths))])
    _close(again, length_columns(F, model, theta2, lengths), 1e-9)
    passes = []
    real = type(F).full_rate_columns_batched
    monkeypatch.setattr(type(F), "full_rate_columns_batched", lambda *a, **k: passes.append(1) or real(*a, **k))
    theta3 = {nm: -v for nm, v in theta.items()}
    third = shared.column(F, theta3, 1)
    next_round = LengthColumns(model, lengths).column(F, theta3, 0)   # the next round's families: new objects
    monkeypatch.undo()
    assert not passes   # the other fits' columns are products with the kept entries
    _close(next_round, length_columns(F, model, theta3, lengths[:1]), 1e-9)
    _close(third, length_columns(F, model, theta3, lengths[1:2]), 1e-9)
    assert float(np.abs(again - first).max()) > 1e-3 * float(np.abs(first).max())   # the fit did change them


def test_kept_length_entries_are_the_pinocchio_difference(rx90_frame):
    model, F = rx90_frame
    robot = description_of(model)
    assert robot is not None
    lengths = visible_lengths(model)[:3]
    terms = emitted_length_terms(model, robot, lengths)
    assert terms is not None and terms.standard.size > 0
    T = F.full_rate_columns_batched(lambda ex, a, b: terms.values(ex.q[a:b], ex.dq[a:b], ex.ddq[a:b]),
                                    terms.standard.size)
    chi, _ = random_parameters(load_robot("rx90"), np.random.default_rng(8))
    h = 1e-6
    for i, (f, fld) in enumerate(lengths):
        plus, minus = perturbed_robot(robot, f, fld, h), perturbed_robot(robot, f, fld, -h)

        def fd(ex, a, b, plus=plus, minus=minus):
            q, dq, ddq = ex.q[a:b], ex.dq[a:b], ex.ddq[a:b]
            return ((pin_torque(plus, q, dq, ddq, chi) - pin_torque(minus, q, dq, ddq, chi)) / (2 * h))[:, :, None]

        ref = F.full_rate_columns_batched(fd, 1)
        assert float(np.abs(ref).max()) > 0, (f, fld)
        _close((T @ terms.matrix(chi))[:, i:i + 1], ref, 1e-6)


def _law_model(model) -> LawSplicedModel:
    """Joint 2's FS/FV replaced by a tanh law of its speed (the columns the loop's friction stage swaps in)."""
    return LawSplicedModel(model, [JointColumns(1, ("law2_a", "law2_b"),
                                                lambda v: np.stack([np.tanh(v / 0.05), v * np.abs(v)], axis=1),
                                                ("FS2", "FV2"))])


def test_kept_zero_tangent_serves_a_friction_law_and_a_changed_fit(rx90_frame, monkeypatch):
    model, F = rx90_frame
    law = _law_model(model)
    assert set(law.BASE_NAMES) != set(model.BASE_NAMES)
    rng = np.random.default_rng(9)
    theta = {nm: float(v) for nm, v in zip(model.BASE_NAMES, rng.normal(size=len(model.BASE_NAMES)))}
    fams = {f.joint: f for f in make_families(F, ("joint_zero",), model=model)}
    assert fams
    for fam in fams.values():
        fam.build(F, FitContext(model, theta))   # the tangent decimated once per frame and joint
    calls = []
    real = candidates.decimated_zero_matrix
    monkeypatch.setattr(candidates, "decimated_zero_matrix", lambda *a, **k: calls.append(1) or real(*a, **k))
    theta2 = {nm: float(v) for nm, v in zip(law.BASE_NAMES, rng.normal(size=len(law.BASE_NAMES)))}
    for j, fam in fams.items():
        got = fam.build(F, FitContext(law, theta2))[0]
        monkeypatch.undo()
        th = np.array([theta2.get(nm, 0.0) for nm in (*law.BASE_NAMES, *law.PAYLOAD_NAMES)])
        fresh = (decimated_zero_matrix(F, law, j) @ th).reshape(-1, 1)
        monkeypatch.setattr(candidates, "decimated_zero_matrix", lambda *a, **k: calls.append(1) or real(*a, **k))
        _close(got, fresh, 1e-9)
    assert not calls   # the law renamed the parameters: the kept tangents served it


def test_kept_zero_tangent_is_the_pinocchio_difference(rx90_frame):
    model, F = rx90_frame
    robot = load_robot("rx90")
    chi, _ = random_parameters(robot, np.random.default_rng(10))
    theta = dict(zip(model.BASE_NAMES, model.base_parameters(chi)))
    h = 1e-5
    fams = {f.joint: f for f in make_families(F, ("joint_zero",), model=model)}
    for j in sorted(fams)[:2]:
        col = fams[j].build(F, FitContext(_law_model(model), theta))[0]

        def fd(ex, a, b, j=j):
            q, dq, ddq = ex.q[a:b], ex.dq[a:b], ex.ddq[a:b]
            e = np.zeros(q.shape[1])
            e[j] = h
            return ((pin_torque(robot, q + e, dq, ddq, chi) - pin_torque(robot, q - e, dq, ddq, chi)) / (2 * h))[:, :, None]

        _close(col, F.full_rate_columns_batched(fd, 1), 1e-6)


def test_the_kept_zero_tangent_holds_its_nonzero_columns_only(rx90_frame):
    """Only the columns the angle changes are kept (the drive terms' and the earlier links' are 0), so the
    cache of a joint's tangent is smaller than ``W``."""
    model, F = rx90_frame
    fams = {f.joint: f for f in make_families(F, ("joint_zero",), model=model)}
    j = max(fams)
    theta = dict.fromkeys(model.BASE_NAMES, 1.0)
    fams[j].build(F, FitContext(model, theta))
    full = decimated_zero_matrix(F, model, j)
    nonzero = int(np.any(full != 0.0, axis=0).sum())
    assert 0 < nonzero < full.shape[1]
    kept = [e for e in candidates._ZERO_CACHE if e[1] == j and e[3].shape[0] == F.n_rows]
    assert kept and kept[-1][3].shape == (F.n_rows, nonzero)
    assert dgeo.rigid_model(_law_model(model)) is model


def test_geometry_terms_are_the_derivatives_entries():
    """``geometry_terms`` of a generated package: scattered at their (standard, geometry) pairs they are
    ``geometry_derivative``, every other entry of which is 0; a model without the emitted derivative has none."""
    import symoro_gen
    from symoro_gen.runtime.model import geometry_terms_of

    model = symoro_gen.load_model("rx90")
    terms = geometry_terms_of(model)
    assert terms is not None and geometry_terms_of(symoro_gen.load_model("rx90").regressor) is None
    rng = np.random.default_rng(12)
    q, dq, ddq = rng.uniform(-2, 2, (5, 6)), rng.normal(size=(5, 6)), rng.normal(size=(5, 6))
    values, pairs = terms(q, dq, ddq)
    dense = model.geometry_derivative(q, dq, ddq)
    assert values.shape == (5, 6, pairs.shape[0])
    np.testing.assert_array_equal(dense[:, :, pairs[:, 0], pairs[:, 1]], values)
    rest = dense.copy()
    rest[:, :, pairs[:, 0], pairs[:, 1]] = 0.0
    assert not rest.any() and np.abs(values).max() > 0
    one, _ = terms(q[0], dq[0], ddq[0])
    np.testing.assert_array_equal(one, values[0])


def test_each_full_rate_sample_is_evaluated_once(rx90_frame):
    """The decimation's stretches overlap by the filter window; the geometry builders' callback is reused there:
    every sample evaluated once (short stretches: many overlaps) and the columns the same numbers as without."""
    _, F = rx90_frame
    ex = F.experiments[0]
    assert ex.settings.ftype == "fir" and ex.settings.n_d > 1
    seen = np.zeros(ex.n_samples, int)

    def cols(e, a, b):
        seen[a:b] += 1
        x = np.stack([np.sin(e.q[a:b] * (i + 1)) * e.dq[a:b] ** i for i in range(3)], axis=2)
        return x * (1.0 + np.arange(F.n_joints))[None, :, None]

    plain = F.full_rate_columns_batched(cols, 3, batch_bytes=1, call_samples=7)
    assert seen.max() > 1   # the overlaps evaluated again without the reuse
    seen[:] = 0
    once = F.full_rate_columns_batched(dgeo._SampleReuse(cols), 3, batch_bytes=1, call_samples=7)
    assert seen.min() == seen.max() == 1
    np.testing.assert_array_equal(once, plain)
