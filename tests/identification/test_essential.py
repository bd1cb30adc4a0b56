"""Essential parameters: the iterative cancellation of the LWR4 paper (Sec. IV-B)."""
import numpy as np
import pytest

from symoro_gen.errors import IdentificationError
from symoro_gen.identification import ObservationSystem, essential_parameters, fit_ols, identify

from .simdata import joint_noise


def sparse_system(seed, c=10, zero=(2, 5, 7, 8)):
    rng = np.random.default_rng(seed)
    x = rng.uniform(1.0, 3.0, c) * rng.choice([-1, 1], c)
    x[list(zero)] = 0.0
    W = rng.normal(size=(600, c))
    joint = np.repeat(np.arange(3), 200)
    return ObservationSystem(W, W @ x + 0.05 * rng.normal(size=600), tuple(f"p{i + 1}" for i in range(c)), joint), x


def check_procedure(ess, system, method, r_sigma, keep=()):
    """Replays the procedure with independent fits: at each step the cancelled parameter is the one
    with the largest %sigma, the ratio was >= r_sigma; at the end the ratio is < r_sigma."""
    active = list(system.names)
    for step in ess.history:
        cols = [system.names.index(n) for n in active]
        res = identify(ObservationSystem(system.W[:, cols], system.Y, tuple(active), system.joint), method=method)
        cand = [i for i, n in enumerate(active) if n not in keep]
        pct = res.rel_std_pct[cand]
        assert active[cand[int(np.argmax(pct))]] == step.removed
        assert step.ratio >= r_sigma and step.n_params == len(active)
        np.testing.assert_allclose(step.ratio, pct.max() / pct.min(), rtol=1e-9)
        active.remove(step.removed)
    assert tuple(active) == ess.result.names
    cand = [i for i, n in enumerate(active) if n not in keep]
    p = ess.result.rel_std_pct[cand]
    assert p.max() / p.min() < r_sigma


@pytest.mark.parametrize("seed", range(5))
def test_zero_parameters_are_cancelled_and_the_others_kept(seed):
    system, x = sparse_system(seed)
    ess = essential_parameters(system, r_sigma=30)
    assert set(ess.removed) == {"p3", "p6", "p8", "p9"}
    check_procedure(ess, system, "ols", 30)
    # the reduced estimate is the OLS of the reduced model
    cols = [system.names.index(n) for n in ess.result.names]
    ref = np.linalg.lstsq(system.W[:, cols], system.Y, rcond=None)[0]
    np.testing.assert_allclose(ess.result.values, ref, rtol=1e-10)
    assert ess.result.eliminated == ess.removed
    assert ess.initial.n_params == 10 and ess.result.n_params == 6
    assert ess.result.value("p3") == 0.0


def test_keep_protects_parameters_and_excludes_them_from_the_ratio():
    system, x = sparse_system(0)
    ess = essential_parameters(system, r_sigma=30, keep=("p3",))
    assert "p3" not in ess.removed and "p3" in ess.result.names
    check_procedure(ess, system, "ols", 30, keep=("p3",))


def test_nothing_cancelled_when_all_parameters_are_well_identified():
    system, x = sparse_system(1, zero=())
    ess = essential_parameters(system, r_sigma=30)
    assert ess.history == () and ess.result.names == system.names
    np.testing.assert_allclose(ess.result.values, fit_ols(system).values, rtol=1e-12)


def test_robot_essential_parameters(rx90_sim):
    """RX-90 base parameters, WLS, 2 % per-joint noise: the parameters with (nearly) no effect go
    first. With r_sigma = 30 and min %sigma ~ 0.14 % the procedure goes on to cancel real but
    less well identified parameters too (the papers tune r_sigma to the perturbation level), so
    the reconstruction error grows, but stays of the order of the noise."""
    sim = rx90_sim
    rng = np.random.default_rng(31)
    system = sim.unloaded(sim.tau_a + joint_noise(rng, sim.tau_a, sim.joint_a, 0.02))
    ess = essential_parameters(system, r_sigma=30, method="wls")
    check_procedure(ess, system, "wls", 30)
    true = dict(zip(sim.names, sim.chi_base))
    assert len(ess.removed) > 5
    assert all(abs(true[n]) < 0.01 for n in ess.removed[:5]), [(n, true[n]) for n in ess.removed]
    assert np.all(ess.result.rel_err < 3 * ess.initial.rel_err)
    # a looser ratio keeps more parameters, and only drops small ones
    loose = essential_parameters(system, r_sigma=300, method="wls")
    assert set(loose.removed) < set(ess.removed)
    assert all(abs(true[n]) < 0.01 for n in loose.removed)
    d = ess.to_dict()
    assert d["essential"]["removed"] == list(ess.removed) and d["eliminated"] == list(ess.removed)
    assert "cancelled" in ess.summary() and ess.removed[0] in ess.summary()


def test_identify_essential_returns_reduced_result():
    system, _ = sparse_system(2)
    res = identify(system, method="ols", essential=True)
    assert res.n_params == 6 and set(res.eliminated) == {"p3", "p6", "p8", "p9"}


def test_bad_arguments():
    system, _ = sparse_system(3)
    with pytest.raises(IdentificationError, match="r_sigma must be > 1"):
        essential_parameters(system, r_sigma=1.0)
    with pytest.raises(IdentificationError, match=r"keep names \['nope'\]"):
        essential_parameters(system, keep=("nope",))


def test_warns_when_the_essential_model_fits_a_joint_much_worse():
    system, _ = sparse_system(4)
    ess = essential_parameters(system, r_sigma=1.5)           # far too strict: real parameters go
    assert any("much worse than the base model" in w and "consider a larger r_sigma" in w
               for w in ess.result.warnings), ess.result.warnings
    ok = essential_parameters(system, r_sigma=30)
    assert not any("much worse" in w for w in ok.result.warnings)
