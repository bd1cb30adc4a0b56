"""The one-standard-error rule of the loop's rounds (Hastie, Tibshirani & Friedman 2009, sec. 7.10): among the
eligible candidates of the best's joints whose acceptance score is within one standard error of the paired
difference (over the acceptance time blocks) of the best's, the one with the fewest parameters goes first."""
from __future__ import annotations

import math

import numpy as np

from symoro_gen.diagnostics.candidates import Family
from symoro_gen.diagnostics.core import _Eval, _simplest_within_se
from symoro_gen.diagnostics.report import CandidateScore

K = 10


def _cand(label: str, joint: int, blocks: np.ndarray, n_cols: int):
    fam = Family("position_ripple", joint, tuple(f"{label}.c{i}" for i in range(n_cols)), lambda fr, ctx: [])
    score = float(blocks.sum())
    ev = _Eval(0, score, 1e-9, 10.0, 1.0, np.ones(2), np.ones(2), score_blocks=blocks)
    cs = CandidateScore(1, "position_ripple", label, joint, None, "", score, 1e-9, 10.0, 1e-3, 1.0, True, "")
    X = np.zeros((4, n_cols))
    return (score, fam, ev, X, X, cs)


def _se(d: np.ndarray) -> float:
    return math.sqrt(d.size) * float(np.std(d, ddof=1))


def test_the_smaller_candidate_within_one_se_of_the_difference_goes_first():
    rng = np.random.default_rng(3)
    big = 0.1 + 0.05 * rng.standard_normal(K)
    small = big - 0.002 + 0.03 * (-1.0) ** np.arange(K)     # lower by 0.02 in sum, the difference noisy
    assert big.sum() - small.sum() < _se(big - small)            # within one SE (independent check)
    elig = [_cand("big", 0, big, 5), _cand("small", 0, small, 2)]
    elig.sort(key=lambda t: -t[0])
    assert elig[0][5].label == "big"
    tried = [e[5] for e in elig]
    out, tried2 = _simplest_within_se(elig, tried, 2)
    assert out[0][5].label == "small" and out[1][5].label == "big"
    assert "chosen over big" in out[0][5].chosen_over and "2 vs 5 parameters" in out[0][5].chosen_over
    assert out[0][5] in tried2 and tried[1] not in tried2


def test_no_swap_beyond_one_se_or_across_joints():
    rng = np.random.default_rng(4)
    big = 0.1 + 0.05 * rng.standard_normal(K)
    small = big - 0.01 + 0.001 * rng.standard_normal(K)     # consistently lower in every block
    assert big.sum() - small.sum() > _se(big - small)
    elig = [_cand("big", 0, big, 5), _cand("small", 0, small, 2)]
    out, _ = _simplest_within_se(elig, [e[5] for e in elig], 2)
    assert out[0][5].label == "big" and not out[0][5].chosen_over
    # a smaller candidate of another joint is no rival, however close its score
    other = _cand("other", 1, big - 1e-6, 1)
    elig = [_cand("big", 0, big, 5), other]
    out, _ = _simplest_within_se(elig, [e[5] for e in elig], 2)
    assert out[0][5].label == "big"
