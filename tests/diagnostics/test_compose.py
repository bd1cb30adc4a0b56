"""Composed candidates (effect x modulating signal) with multiple-testing control
(symoro_gen.diagnostics.compose), on simulated SCARA torques with one modulated effect of known kind,
joint and signal; the rows are the samples (no filtering)."""
from __future__ import annotations

import itertools

import numpy as np
import pytest

from symoro_gen.diagnostics.compose import (
    Composed,
    RowSignals,
    library,
    score_composed,
)
from symoro_gen.diagnostics.stability import (
    BlockedLS,
    selection_frequency,
    stable,
    time_blocks,
)
from symoro_gen.diagnostics.stats import benjamini_hochberg, holm

from .test_friction import scara_rows

NOISE = 0.05


def setup(seed, duration=30.0, dt=0.01):
    d = scara_rows(seed, duration, dt)
    W, J, S = d["W"], d["J"], d["S"]
    tau = (W @ d["theta"]).reshape(4, -1).T          # true torque per sample: the "tau_hat" of a good fit
    sig = RowSignals(J, d["t"][S], d["q"][S], d["dq"][S], d["ddq"][S], tau[S])
    y = W @ d["theta"] + NOISE * d["rng"].standard_normal(W.shape[0])
    return d, sig, y, tau


def _scaled(d, j, x, size=0.5):
    """``x`` (torque on joint ``j``) scaled so that its part the declared model cannot fit has a standard
    deviation of ``size`` N m (10 times the torque noise)."""
    Wj = d["W"][d["J"] == j]
    left = x - Wj @ np.linalg.lstsq(Wj, x, rcond=None)[0]
    return size * x / np.std(left)


def _effects(d, tau):
    t, q, dq, ddq = d["t"], d["q"], d["dq"], d["ddq"]
    return {
        # (joint, effect, signal, extra torque on that joint)
        "viscous x |tau|": (1, "viscous", "abs_tau", _scaled(d, 1, dq[:, 1] * np.abs(tau[:, 1]))),
        "ripple x |dq|": (0, "ripple", "abs_dq", _scaled(d, 0, np.sin(3 * q[:, 0] + 0.3) * np.abs(dq[:, 0]))),
        "constant x step": (3, "constant", "step", _scaled(d, 3, 1.0 * (t >= 12.0))),
        "coulomb x time": (0, "coulomb", "time", _scaled(d, 0, t * np.sign(dq[:, 0]))),
        "inertia x q_other": (3, "inertia", "q_other", _scaled(d, 3, ddq[:, 3] * q[:, 0])),
    }


@pytest.mark.slow
@pytest.mark.parametrize("name", ["viscous x |tau|", "ripple x |dq|", "constant x step", "coulomb x time",
                                  "inertia x q_other"])
def test_each_modulated_family_is_found_on_its_joint_with_its_signal(name):
    d, sig, y, tau = setup(11)
    j, eff, signal, extra = _effects(d, tau)[name]
    y = y.copy()
    y[sig.joint == j] += extra
    A = d["W"]
    if eff == "ripple":
        # the plain ripple (the mean amplitude) is a plain candidate of the loop, accepted before
        A = np.hstack([A, Composed("ripple", j, "step", order=3, step_time=-1.0).columns(sig)])
    res = score_composed(A, y, sig)
    top = res[0]
    c = top.candidate
    assert (c.effect, c.joint, c.signal) == (eff, j, signal), [r.description for r in res[:3]]
    assert top.significant and top.p_adjusted < 1e-6
    if eff == "ripple":
        # the injected order 3, unless the joint moves over less than half its period (k range(q) >= pi,
        # compose.library): then the nearest order the library keeps for this joint
        import math

        from symoro_gen.diagnostics.compose import RIPPLE_ORDERS

        span = float(np.ptp(sig.q[sig.joint == j, j]))
        kept = [k for k in RIPPLE_ORDERS if k * span >= math.pi]
        assert c.order == (3 if 3 in kept else min(kept, key=lambda k: abs(k - 3)))
    if signal == "step":
        assert abs(c.step_time - 12.0) <= 1.0
        assert "appearing at t = 1" in top.description
    if signal == "q_other":
        assert c.source == 0
    if name == "viscous x |tau|":
        assert top.description == "viscous friction of joint 2 growing with |\u03c4\u03022|"
    # time-blocked out-of-fold error of that joint with the composed column: cut by >= 30 %
    blocks = time_blocks(np.zeros(y.size, int), d["S"], 5)
    cv = BlockedLS(A, y, blocks)
    rows = sig.joint == j
    before, after = cv.rel_err(None, rows), cv.rel_err(c.columns(sig), rows)
    assert after < 0.7 * before, (before, after)


@pytest.mark.parametrize("seed", [21, 22, 23, 24])
def test_clean_data_name_nothing(seed):
    d, sig, y, _ = setup(seed, duration=20.0, dt=0.02)
    res = score_composed(d["W"], y, sig)
    assert len(res) > 100                       # the whole library was tested ...
    assert not [r.description for r in res if r.significant]   # ... and nothing passes Holm at 1 %


def test_library_counts_and_words():
    _, sig, _, _ = setup(31, duration=10.0, dt=0.05)
    fams = library(sig)
    # per joint: 5 effects x 7 signals (no temperature), q_other for 3 other joints; the plain candidates of
    # the loop skipped: constant x q (own and 3 others: spring), constant x time (drift), ripple x own q
    # (ripple only on joints that move over half a period of at least one order: k range(q_j) >= pi)
    import math

    from symoro_gen.diagnostics.compose import RIPPLE_ORDERS

    per_joint = 5 * (6 + 3) - (1 + 3) - 1 - 1
    orders = [[k for k in RIPPLE_ORDERS if k * float(np.ptp(sig.q[sig.joint == j, j])) >= math.pi] for j in range(4)]
    assert len(fams) == 4 * per_joint - (6 + 3 - 1) * sum(not o for o in orders)
    assert not [f for f in fams if (f[0].effect, f[0].signal) in (("constant", "time"), ("ripple", "q_own"))]
    ripple_step = [f for f in fams if f[0].effect == "ripple" and f[0].signal == "step"]
    assert ripple_step and all(len(f) == len(orders[f[0].joint]) * len({c.step_time for c in f}) for f in ripple_step)
    sig_t = RowSignals(sig.joint, sig.t, sig.q, sig.dq, sig.ddq, None, np.linspace(20, 40, sig.n_rows))
    fams_t = library(sig_t)
    assert any(f[0].signal == "temperature" for f in fams_t)
    assert not any(f[0].signal in ("abs_tau", "tau") for f in fams_t)
    assert Composed("ripple", 5, "abs_dq", order=4).describe() == \
        "position ripple of order 4 on joint 6 whose amplitude changes with |dq6|"
    assert Composed("viscous", 2, "q_other", source=0).describe([-0.3]) == "viscous friction of joint 3 decreasing with q1"
    assert Composed("constant", 1, "step", step_time=12.04).describe().startswith(
        "constant (gravity-like) torque on joint 2 appearing at t = 12 s")
    with pytest.raises(ValueError, match="unknown effects/signals"):
        library(sig, signals=("pressure",))


def test_holm_matches_the_step_down_definition():
    rng = np.random.default_rng(0)
    for _ in range(50):
        p = rng.uniform(0, 0.05, 7) ** rng.uniform(0.5, 2)
        adj = holm(p)
        for alpha in (0.01, 0.05):
            # step-down: reject sorted hypotheses while p_(i) <= alpha/(m - i + 1) (i from 1)
            order = np.argsort(p)
            rejected = set()
            for i, k in enumerate(order):
                if p[k] <= alpha / (len(p) - i):
                    rejected.add(int(k))
                else:
                    break
            assert {int(k) for k in np.flatnonzero(adj <= alpha)} == rejected
    assert list(holm([0.01, 0.04, 0.03])) == pytest.approx([0.03, 0.06, 0.06])
    assert not list(itertools.chain(holm([])))
    # a test that could not be run (NaN) stays NaN and does not count in m
    np.testing.assert_allclose(holm([0.01, np.nan, 0.03]), [0.02, np.nan, 0.03])


def test_benjamini_hochberg_matches_the_step_up_definition():
    rng = np.random.default_rng(1)
    for _ in range(50):
        p = rng.uniform(0, 0.05, 9) ** rng.uniform(0.5, 2)
        adj = benjamini_hochberg(p)
        srt = np.sort(p)
        for alpha in (0.01, 0.05):
            k = max([i + 1 for i in range(p.size) if srt[i] <= alpha * (i + 1) / p.size], default=0)
            assert int((adj <= alpha).sum()) == k
    np.testing.assert_allclose(benjamini_hochberg([0.01, np.nan, 0.04]), [0.02, np.nan, 0.04])


@pytest.mark.slow
def test_selection_frequency_over_time_blocked_folds():
    """A real modulated effect is named in every fold; on clean data nothing is named in any fold."""
    d, sig, y, tau = setup(12, duration=20.0, dt=0.02)
    j, _, _, extra = _effects(d, tau)["viscous x |tau|"]
    y_eff = y.copy()
    y_eff[sig.joint == j] += extra
    blocks = time_blocks(np.zeros(y.size, int), d["S"], 5)

    def names(yy):
        def select(train):
            res = score_composed(d["W"][train], yy[train], sig.subset(train))
            return [r.candidate.family for r in res[:1] if r.significant]
        return select
    f = selection_frequency(names(y_eff), blocks)
    assert f == {("viscous", 1, "abs_tau", None): 1.0}
    assert stable(f) == [("viscous", 1, "abs_tau", None)]
    assert selection_frequency(names(y), blocks) == {}


def test_signals_the_data_cannot_tell_apart_are_reported_as_aliases():
    d, sig, y, tau = setup(11)
    j, _, _, extra = _effects(d, tau)["inertia x q_other"]
    y = y.copy()
    y[sig.joint == j] += extra
    q = sig.q.copy()
    q[:, 2] = 3.0 * q[:, 0] + 1.0          # joint 3 driven by the waveform of joint 1 (as on the LWR4 recordings)
    sig2 = RowSignals(sig.joint, sig.t, q, sig.dq, sig.ddq, sig.tau_hat)
    res = score_composed(d["W"], y, sig2, joints=[j])
    top = res[0]
    assert (top.candidate.effect, top.candidate.signal) == ("inertia", "q_other")
    assert {top.candidate.source} | {a.source for a in top.aliases} == {0, 2}
    assert "indistinguishable here from: q" in top.description
    listed = [r.candidate.source for r in res if (r.candidate.effect, r.candidate.signal) == ("inertia", "q_other")]
    assert sorted(listed) == [top.candidate.source, 1]      # q1 and q3 listed once; q2 on its own


def _speed_change_rows(seed, law):
    """One joint moving slowly for 10 s, then three times faster for 10 s (point-to-point-like regimes);
    its torque is a viscous ``law(dq)`` plus Coulomb friction plus noise. The declared model: ``dq``,
    ``sign(dq)``, offset."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 20.0, 0.01)
    ph = rng.uniform(0, 2 * np.pi, 3)
    dq = sum(np.sin(2 * np.pi * f * t + p) for f, p in zip((0.3, 0.7, 1.1), ph)) / 2.0
    dq = dq * np.where(t < 10.0, 1.0, 3.0)
    q = np.cumsum(dq) * 0.01
    ddq = np.gradient(dq, t)
    y = law(dq) + 0.5 * np.sign(dq) + 0.05 * rng.standard_normal(t.size)
    sig = RowSignals(np.zeros(t.size, int), t, q[:, None], dq[:, None], ddq[:, None])
    A = np.column_stack([dq, np.sign(dq), np.ones(t.size)])
    return A, y, sig


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_nonlinear_viscous_law_is_not_named_a_change_in_time(seed):
    """Quadratic drag (``0.3 dq |dq|``) where the speeds differ between the two halves: a viscous
    coefficient "changing at t = 10 s" fits it, but the speed modulation of the same effect is partialled
    out of the time-like tests (``Composed.confounder_columns``), so no change in time is named; a true
    step of the viscous coefficient at equal speeds still is."""
    A, y, sig = _speed_change_rows(seed, lambda v: 0.3 * v * np.abs(v))
    lib = library(sig, effects=("viscous",), signals=("step", "time"))
    res = score_composed(A, y, sig, families=lib)
    assert not any(r.significant for r in res), [(r.description, r.p_adjusted) for r in res]
    # without the partialling (the plain effect only) the step is taken for a change of the law
    naive = score_composed(A, y, sig, families=[[replace_signal(c) for c in f] for f in lib])
    assert any(r.significant and r.candidate.signal == "step" for r in naive)
    # a real change: the viscous coefficient drops by 0.4 at t = 12 s, speeds equal on both sides
    A2, y2, sig2 = _speed_change_rows(seed, lambda v: 0.0 * v)
    t = sig2.t
    dq = sig2.dq[:, 0] / np.where(t < 10.0, 1.0, 3.0)            # undo the speed change
    sig2 = RowSignals(sig2.joint, t, np.cumsum(dq)[:, None] * 0.01, dq[:, None], np.gradient(dq, t)[:, None])
    A2 = np.column_stack([dq, np.sign(dq), np.ones(t.size)])
    y2 = 1.0 * dq - 0.4 * dq * (t >= 12.0) + 0.5 * np.sign(dq) + 0.05 * np.random.default_rng(seed).standard_normal(t.size)
    res2 = score_composed(A2, y2, sig2, families=library(sig2, effects=("viscous",), signals=("step",)))
    assert res2 and res2[0].significant and abs(res2[0].candidate.step_time - 12.0) < 1.5, res2[:1]


def replace_signal(c):
    """``c`` tested as if its signal were not time-like: its confounder columns are then empty (the test
    before ``confounder_columns`` existed)."""
    class _Naive(Composed):
        def confounder_columns(self, sig):
            return np.zeros((sig.n_rows, 0))
    return _Naive(**{f: getattr(c, f) for f in c.__dataclass_fields__})


def test_rank_puts_the_named_kind_first_when_a_composed_candidate_is_the_same_fit():
    """A composed candidate whose columns span a plain kind's ('constant torque changing with tau_hat' is a
    gain) scores the same up to the last bits, which differ between BLAS builds: the plain kind goes first
    whichever rounding wins; a real difference in score still decides."""
    from types import SimpleNamespace

    from symoro_gen.diagnostics.core import TIE_RTOL, _rank

    plain = SimpleNamespace(info=())
    composed = SimpleNamespace(info=(("composed", object()), ("plain", False)))
    other = SimpleNamespace(info=())
    s = 6.380050004216558
    for sc_comp in (s * (1 + 2e-15), s * (1 - 2e-15), s):
        got = _rank([(sc_comp, composed, "c"), (s, plain, "p"), (3.0, other, "o")])
        assert [t[2] for t in got] == ["p", "c", "o"]
    got = _rank([(s * (1 + 100 * TIE_RTOL), composed, "c"), (s, plain, "p")])
    assert [t[2] for t in got] == ["c", "p"]
