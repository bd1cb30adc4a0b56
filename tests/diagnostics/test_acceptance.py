"""One acceptance for every change to the model: the loop accepts candidates on the trailing share of the
identification experiments (never on the validation data), and its block-bootstrap noise bands
(:mod:`symoro_gen.diagnostics.bootstrap`) cover the error they bound."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

from symoro_gen.diagnostics import DiagnoseSettings, diagnose
from symoro_gen.diagnostics.bootstrap import optimal_block_length, rel_err_band
from symoro_gen.diagnostics.frame import split_holdout
from symoro_gen.preprocessing.trajectory import Trajectory

from .simdata import recording


def _ar1(rng, phi: float, n: int, burn: int = 300) -> np.ndarray:
    return lfilter([1.0], [1.0, -phi], rng.standard_normal(n + burn))[burn:]


@pytest.mark.slow
@pytest.mark.parametrize("phi", [0.0, 0.6])
def test_block_bootstrap_band_covers_about_95_percent(phi):
    """Monte-Carlo: the 95 % band of the RMS of white noise and of an AR(1) (coefficient 0.6) holds the true
    RMS ``1/sqrt(1 - phi^2)`` in about 95 % of 300 series of 800 samples (block bootstrap undercovers a
    little in short series: Politis & White 2004, Table 1); the block length grows with the correlation."""
    rng = np.random.default_rng(11)
    true = 1.0 / np.sqrt(1.0 - phi ** 2)
    reps, hits, blocks = 300, 0, []
    for _ in range(reps):
        x = _ar1(rng, phi, 800)
        lo, hi = rel_err_band(x, None, n_boot=399, rng=rng)
        hits += lo <= true <= hi
        blocks.append(optimal_block_length(x))
    cover = hits / reps
    assert 0.88 <= cover <= 0.99, cover
    assert np.median(blocks) <= 3 if phi == 0 else np.median(blocks) >= 5, np.median(blocks)


def test_band_is_scale_free_and_brackets_the_error():
    rng = np.random.default_rng(3)
    e, y = _ar1(rng, 0.5, 2000), 10 * rng.standard_normal(2000)
    lo, hi = rel_err_band(e, y)
    r = np.linalg.norm(e) / np.linalg.norm(y)
    assert lo < r < hi
    lo2, hi2 = rel_err_band(3 * e, 3 * y)
    assert np.isclose(lo, lo2) and np.isclose(hi, hi2)


def _corrupted(tr: Trajectory) -> Trajectory:
    """The validation recording with a huge torque only it has (a sentinel the acceptance must never see):
    a slow sine of 20 times the torque noise on joints 1 and 2 and a 40 % gain error of joint 4."""
    tau = tr.tau.copy()
    tau[:, 0] += 1.0 * np.sin(2 * np.pi * 0.07 * tr.t)
    tau[:, 1] += 1.0 * np.sin(2 * np.pi * 0.11 * tr.t + 1.0)
    tau[:, 3] *= 1.4
    return Trajectory(t=tr.t, q=tr.q, tau=tau, source=tr.source + " corrupted")


@pytest.mark.slow
def test_acceptance_never_reads_the_validation_data():
    """The same identification data (a position ripple on joint 1) validated on a clean recording and on
    the same recording corrupted by large effects: the effects named, every candidate's score and z and
    the final parameters are identical; only the validation errors reported change."""
    model, tr = recording("scara", 21, "position_ripple", 0, amplitude=0.4, k=6, duration=36.0)
    (ident,), (valid,) = split_holdout([tr], 1.0 / 3.0)   # the same robot: its last 12 s validate
    cfg = DiagnoseSettings(unexplained=False, structure=False, max_effects=2)
    clean = diagnose(model, ident, cfg, validation=valid)
    dirty = diagnose(model, ident, cfg, validation=_corrupted(valid))
    key = [(e.kind, e.joint, e.variant) for e in clean.effects]
    assert ("position_ripple", 0, "") in [(k, j, "") for k, j, _ in key], clean.summary()
    assert key == [(e.kind, e.joint, e.variant) for e in dirty.effects]
    assert [(c.label, c.variant, c.score, c.z_validation, c.eligible) for c in clean.tried] == \
        [(c.label, c.variant, c.score, c.z_validation, c.eligible) for c in dirty.tried]
    np.testing.assert_array_equal(clean.result_after.values, dirty.result_after.values)
    assert clean.acceptance == dirty.acceptance
    # the reported validation errors are the only thing that sees the corruption
    assert dirty.after_validation_rel_err[0] > 2 * clean.after_validation_rel_err[0]
    assert dirty.after_validation_rel_err[3] > 2 * clean.after_validation_rel_err[3]
