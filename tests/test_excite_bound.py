"""The relaxation of the excitation design (cond over distributions of states, no continuity in time):
``research.excite_relaxation.relaxation_bracket`` on the SCARA, checked against trajectories it never saw, the
weak-duality argument of ``relaxation_dual_bound`` on explicit distributions, and the rigorous
``cond_lower_bound``."""
import numpy as np
import pytest
from scipy.linalg import eigh

from research.excite_relaxation import relaxation_bracket, relaxation_dual_bound, relaxation_rows
from symoro_gen.excite import (
    FourierBasis,
    basis_eval,
    check_limits,
    cond_lower_bound,
    limits_of,
    output_times,
    random_trajectory,
    stacked_cond,
)
from symoro_gen.loader import model_for

#: the excitation relaxation is research (``research/``, not installed): its bound tests run with the slow set
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def scara():
    robot, model = model_for("scara")
    lim = limits_of(robot)
    b = relaxation_bracket(model, lim, atoms=100, rounds=3, fresh=2000, starts=6, add=20, seed=3)
    return model, lim, b


def _trajectories(model, lim, k, seed):
    basis, t = FourierBasis(5, 0.1), output_times(10.0, 50.0)
    rng = np.random.default_rng(seed)
    return [basis_eval(basis, random_trajectory(basis, lim, rng, t), t) for _ in range(k)]


def test_rows_sign_convention():
    """FS_j follows the given sign (the closed state set); with sign(dq) it is the model's regressor."""
    _, model = model_for("scara")
    n, names = model.N_JOINTS, list(model.BASE_NAMES)
    rng = np.random.default_rng(0)
    X = np.hstack([rng.uniform(-1, 1, (5, n)), np.zeros((5, n)), rng.uniform(-1, 1, (5, n))])
    X[:, n] = 0.3  # joint 1 moving, the others at rest
    ref = np.asarray(model.regressor(X[:, :n], X[:, n:2 * n], X[:, 2 * n:])).reshape(5, n, -1)
    assert np.array_equal(relaxation_rows(model, X), ref)
    assert np.array_equal(relaxation_rows(model, X, np.sign(X[:, n:2 * n])), ref)
    S = np.ones((5, n))
    W = relaxation_rows(model, X, S)
    for j in range(n):
        if f"FS{j + 1}" in names:
            assert np.all(W[:, j, names.index(f"FS{j + 1}")] == 1.0)
            assert np.all(ref[:, j, names.index(f"FS{j + 1}")] == (1.0 if j == 0 else 0.0))


def test_bracket_is_ordered_and_upper_is_an_explicit_distribution(scara):
    model, lim, b = scara
    assert 0 < b.lower <= b.upper * (1 + 1e-6)
    assert b.upper / b.lower - 1 < 0.25  # converged to a useful bracket on this small arm
    W = relaxation_rows(model, b.states, b.signs)
    M = np.einsum("k,kia,kib->ab", b.weights, W, W)
    ev = np.linalg.eigvalsh(M)
    assert np.sqrt(ev[-1] / ev[0]) == pytest.approx(b.upper, rel=1e-6)
    # every state of the support lies in the box, with a sign consistent with its velocity
    n = model.N_JOINTS
    q, dq, ddq = b.states[:, :n], b.states[:, n:2 * n], b.states[:, 2 * n:]
    assert np.all((q >= lim.q_min - 1e-9) & (q <= lim.q_max + 1e-9))
    assert np.all(np.abs(dq) <= lim.dq_max + 1e-9) and np.all(np.abs(ddq) <= lim.ddq_max + 1e-9)
    assert np.all((np.sign(dq) == b.signs) | (dq == 0))


def test_lower_end_holds_on_unseen_trajectories(scara):
    """The dual estimate is below the cond of random trajectories within the limits, and the dual
    ratio on their samples does not exceed the r found by the search (what the bound rests on)."""
    model, lim, b = scara
    for q, dq, ddq in _trajectories(model, lim, 10, seed=11):
        assert stacked_cond(model, q, dq, ddq) >= b.lower
        W = relaxation_rows(model, np.hstack([q, dq, ddq]))
        num = np.einsum("kia,ab,kib->k", W, b.A, W)
        den = np.einsum("kia,ab,kib->k", W, b.B, W)
        assert np.all(num <= b.r * den * (1 + 1e-9))


def test_relaxation_is_above_the_rigorous_bound(scara):
    model, lim, b = scara
    bound = cond_lower_bound(model, lim)
    assert bound is not None and b.upper >= bound.bound


def test_primal_no_worse_than_a_trajectory_it_was_given():
    """The uniform distribution over a trajectory's samples is feasible: the first round's primal is at
    most that trajectory's cond."""
    robot, model = model_for("scara")
    lim = limits_of(robot)
    q, dq, ddq = _trajectories(model, lim, 1, seed=5)[0]
    b = relaxation_bracket(model, lim, atoms=20, rounds=0, fresh=500, starts=2, add=5,
                           extra_states=np.hstack([q, dq, ddq])[::5])
    c_sub = stacked_cond(model, q[::5], dq[::5], ddq[::5])
    assert b.rounds[0].primal <= c_sub * (1 + 1e-4)


def test_weak_duality_on_explicit_distributions():
    """sqrt(tr A / (r tr B)) <= cond of every distribution over states where the ratio is <= r, for
    arbitrary PSD A, B (and symmetric, indefinite inputs are projected on the PSD cone)."""
    _, model = model_for("scara")
    n, nb = model.N_JOINTS, len(model.BASE_NAMES)
    rng = np.random.default_rng(2)
    X = rng.uniform(-1, 1, (300, 3 * n))
    W = relaxation_rows(model, X)
    for _ in range(20):
        L1, L2 = rng.normal(size=(nb, nb)), rng.normal(size=(nb, nb))
        A, B = L1 @ L1.T, L2 @ L2.T + np.diag(rng.uniform(-5, 0, nb))  # B indefinite: projected
        w, V = np.linalg.eigh((B + B.T) / 2)
        Bp = (V * np.clip(w, 0, None)) @ V.T
        r = float((np.einsum("kia,ab,kib->k", W, A, W) / np.einsum("kia,ab,kib->k", W, Bp, W)).max())
        lb = relaxation_dual_bound(A, B, r)
        for _ in range(5):
            mu = rng.dirichlet(np.full(len(X), 0.3))
            ev = np.linalg.eigvalsh(np.einsum("k,kia,kib->ab", mu, W, W))
            assert lb <= np.sqrt(ev[-1] / ev[0]) * (1 + 1e-9)


# --- the stationarity moments: distributions that a trajectory can have -------------------------------

def test_stationarity_moments_vanish_on_trajectories_not_on_random_states():
    """The mean of every moment over one period of a periodic trajectory is 0 (to quadrature accuracy),
    over random states it is not; the CasADi form (used for gradients) is the NumPy form."""
    import casadi as ca

    from research.excite_relaxation import _random_states, stationarity_moments, stationarity_scales

    robot, model = model_for("scara")
    lim = limits_of(robot)
    n = model.N_JOINTS
    scale = stationarity_scales(lim)
    for q, dq, ddq in _trajectories(model, lim, 5, seed=21):
        m = stationarity_moments(q[:-1], dq[:-1], ddq[:-1]) / scale  # one period: drop the repeated end sample
        assert m.shape[1] == len(scale) == 6 * n + 3 * n * n + n * (n - 1) // 2
        assert np.abs(m.mean(0)).max() < 1e-6
    X, _ = _random_states(np.random.default_rng(0), lim, 2000)
    m = stationarity_moments(X[:, :n], X[:, n:2 * n], X[:, 2 * n:]) / scale
    assert np.abs(m.mean(0)).max() > 0.05
    z = ca.SX.sym("z", 3 * n)
    f = ca.Function("m", [z], [stationarity_moments(z[:n], z[n:2 * n], z[2 * n:], lib=ca)])
    for x in X[:5]:
        np.testing.assert_allclose(np.array(f(x)).ravel(), stationarity_moments(x[:n], x[n:2 * n], x[2 * n:])[0],
                                   rtol=1e-12, atol=1e-12)


@pytest.fixture(scope="module")
def scara_stationary():
    robot, model = model_for("scara")
    lim = limits_of(robot)
    b = relaxation_bracket(model, lim, atoms=100, rounds=5, fresh=3000, starts=8, add=20, seed=3,
                           stationary=True, trajectories=5)
    return model, lim, b


def test_stationary_upper_end_is_a_distribution_with_trajectory_moments(scara_stationary):
    from research.excite_relaxation import stationarity_moments, stationarity_scales

    model, lim, b = scara_stationary
    n = model.N_JOINTS
    W = relaxation_rows(model, b.states, b.signs)
    ev = np.linalg.eigvalsh(np.einsum("k,kia,kib->ab", b.weights, W, W))
    assert np.sqrt(ev[-1] / ev[0]) == pytest.approx(b.upper, rel=1e-5)
    p = b.weights / b.weights.sum()
    m = p @ (stationarity_moments(b.states[:, :n], b.states[:, n:2 * n], b.states[:, 2 * n:])
             / stationarity_scales(lim))
    assert np.abs(m).max() <= b.moment_tol * 1.01
    assert b.lower <= b.upper


def test_stationary_lower_end_holds_on_unseen_trajectories_and_excludes_the_plain_optimum(scara, scara_stationary):
    """Weak duality with the moment multipliers: the ratio N/D on unseen trajectories' samples stays
    below r, their cond above the lower end - and that lower end is above the plain relaxation's
    optimum (a distribution no trajectory can have)."""
    from research.excite_relaxation import _DualPricer

    model, lim, b = scara_stationary
    assert b.stationary and b.lam is not None and b.c0 >= b.moment_tol * np.abs(b.lam).sum() * (1 - 1e-9)
    pricer = _DualPricer(model, lim, b.A, b.B, b.lam, b.c0)
    for q, dq, ddq in _trajectories(model, lim, 10, seed=12):
        assert stacked_cond(model, q, dq, ddq) >= b.lower
        X = np.hstack([q, dq, ddq])
        num, den = pricer.num_den(X, np.sign(dq))
        assert np.all(num <= b.r * den * (1 + 1e-9))
    assert b.lower > scara[2].upper


def test_verification_reprices_the_same_duals():
    """relaxation_verify searches more: r never falls, the bound never rises, and with the search of the
    bracket itself (same seed and size) nothing changes."""
    from research.excite_relaxation import relaxation_verify

    robot, model = model_for("scara")
    lim = limits_of(robot)
    b = relaxation_bracket(model, lim, atoms=60, rounds=1, fresh=300, starts=1, add=10, seed=4,
                           stationary=True, trajectories=3)
    r, bound = relaxation_verify(model, lim, b, states=5000, starts=10, seed=9)
    assert r >= b.r and bound <= b.lower * (1 + 1e-12)
    assert bound == pytest.approx(relaxation_dual_bound(b.A, b.B, r))


def test_perturbed_atoms_are_states_of_the_box_priced_as_such_and_reach_the_random_search(scara_stationary):
    """relaxation_verify(perturb=K): the perturbed atoms stay in the box, their velocity signs follow their speeds
    (a joint at rest keeps its atom's sign), their ratios are the pricer's; alone with its local searches the
    search reaches the largest ratio that a deep random search finds (within 1 %), which the bracket's own
    pricing missed by more than that."""
    from research.excite_relaxation import PERTURB_SCALES, _DualPricer, _perturbed_states, relaxation_verify

    model, lim, b = scara_stationary
    n = model.N_JOINTS
    pricer = _DualPricer(model, lim, b.A, b.B, b.lam, b.c0, degree=b.degree, closed=b.closed)
    on = b.weights > 1e-6 * b.weights.max()
    X, S, r = _perturbed_states(pricer, b.states[on], b.signs[on], np.random.default_rng(0), 30)
    atoms = int(on.sum())
    assert X.shape == (atoms * len(PERTURB_SCALES), 3 * n)
    assert np.all((pricer.lo <= X) & (pricer.hi >= X))
    dq = X[:, n:2 * n]
    assert np.all(S[dq != 0] == np.sign(dq[dq != 0])) and np.isin(S, (-1.0, 0.0, 1.0)).all()
    np.testing.assert_allclose(r, pricer.ratio(X, S), rtol=1e-12)
    r_random, _ = relaxation_verify(model, lim, b, states=20_000, starts=20, seed=5)
    r_perturb, bound = relaxation_verify(model, lim, b, states=0, starts=20, seed=5, perturb=20)
    assert r_random > b.r * 1.01  # the bracket's pricing is not global here: a search has something to find
    assert r_perturb == pytest.approx(r_random, rel=0.01)
    assert bound == pytest.approx(relaxation_dual_bound(b.A, b.B, r_perturb))


def test_bracket_priced_around_its_atoms_leaves_the_deeper_searches_nothing_to_find(scara_stationary):
    """relaxation_bracket(perturb=K) also prices perturbations of its atoms every round: on the SCARA the same
    five rounds that, without it, left a ratio > 1 % above their own to the deeper searches (test above) now
    leave them nothing (within 0.2 %), so the lower end survives verification, and the upper end is no higher."""
    from research.excite_relaxation import relaxation_verify

    model, lim, plain = scara_stationary  # the same five rounds without perturbations
    b = relaxation_bracket(model, lim, atoms=100, rounds=5, fresh=3000, starts=8, add=20, seed=3, stationary=True,
                           trajectories=5, perturb=20)
    assert all(h.r >= 1.0 for h in b.rounds) and b.upper <= plain.upper * (1 + 1e-9)
    r_random, _ = relaxation_verify(model, lim, b, states=20_000, starts=20, seed=5)
    r_perturb, _ = relaxation_verify(model, lim, b, states=0, starts=20, seed=5, perturb=20)
    assert max(r_random, r_perturb) <= b.r * 1.002


# --- degree-3 test functions and the bandwidth of a design basis -------------------------------------

def test_degree3_moments_vanish_on_trajectories_and_extend_degree2():
    """degree=3 keeps the degree-2 moments first (same values, names) and adds conditions that one period
    of a periodic trajectory also meets, random states do not; CasADi form = NumPy form."""
    import casadi as ca

    from research.excite_relaxation import (
        _random_states,
        stationarity_moment_names,
        stationarity_moments,
        stationarity_scales,
    )

    robot, model = model_for("scara")
    lim = limits_of(robot)
    n = model.N_JOINTS
    s2, s3 = stationarity_scales(lim), stationarity_scales(lim, 3)
    k2 = len(s2)
    assert len(s3) > k2 and stationarity_moment_names(n, 3)[:k2] == stationarity_moment_names(n)
    assert len(set(stationarity_moment_names(n, 3))) == len(s3)
    for q, dq, ddq in _trajectories(model, lim, 5, seed=23):
        m3 = stationarity_moments(q[:-1], dq[:-1], ddq[:-1], degree=3)
        np.testing.assert_array_equal(m3[:, :k2], stationarity_moments(q[:-1], dq[:-1], ddq[:-1]))
        assert np.abs((m3 / s3).mean(0)).max() < 1e-6
    X, _ = _random_states(np.random.default_rng(1), lim, 2000)
    Xp = np.abs(X)  # every joint speeding up in the positive direction: no trajectory returns from that
    m = stationarity_moments(Xp[:, :n], Xp[:, n:2 * n], Xp[:, 2 * n:], degree=3) / s3
    assert np.abs(m[:, k2:].mean(0)).max() > 0.05
    z = ca.SX.sym("z", 3 * n)
    f = ca.Function("m", [z], [stationarity_moments(z[:n], z[n:2 * n], z[2 * n:], lib=ca, degree=3)])
    for x in X[:5]:
        np.testing.assert_allclose(np.array(f(x)).ravel(),
                                   stationarity_moments(x[:n], x[n:2 * n], x[2 * n:], degree=3)[0], rtol=1e-12, atol=1e-12)
    # a finite difference of one degree-3 test function along a trajectory: d/dt(cos q1 sin q2 dq2)
    q, dq, ddq = _trajectories(model, lim, 1, seed=3)[0]
    k = stationarity_moment_names(n, 3).index("d/dt(cos q1 sin q2 dq2)")
    g = np.cos(q[:, 0]) * np.sin(q[:, 1]) * dq[:, 1]
    fd = np.gradient(g, output_times(10.0, 50.0))
    m = stationarity_moments(q, dq, ddq, degree=3)[:, k]
    assert np.abs(fd - m)[5:-5].max() < 1e-2 * np.abs(m).max()


def test_basis_bandwidth_is_the_largest_ratio_of_any_design():
    """Every design of the basis has E[ddq ddq^T] <= rho E[dq dq^T] on the samples, and rho is attained
    (a largest ratio, not a loose bound); for K harmonics of w it lies between ((K-1) w)^2 and (K w)^2."""
    from research.excite_relaxation import basis_bandwidth
    from symoro_gen.excite import SplineBasis

    robot, _ = model_for("scara")
    lim = limits_of(robot)
    t = output_times(10.0, 100.0)
    rng = np.random.default_rng(4)
    for basis in (FourierBasis(5, 0.1), SplineBasis(20, 10.0)):
        rho = basis_bandwidth(basis, t)
        if isinstance(basis, FourierBasis):
            w = 2 * np.pi * 0.1
            assert (4 * w) ** 2 < rho <= (5 * w) ** 2 * (1 + 1e-9)
        for _ in range(10):
            _, dq, ddq = basis_eval(basis, random_trajectory(basis, lim, rng, t), t)
            gap = np.linalg.eigvalsh(rho * dq.T @ dq - ddq.T @ ddq)
            assert gap[0] >= -1e-9 * gap[-1]
        _, D, A = basis.matrices(t)
        ratio = []
        for _ in range(200):  # random directions of the design space stay below rho
            y = rng.standard_normal(basis.m)
            ratio.append(np.sum((A @ y) ** 2) / max(np.sum((D @ y) ** 2), 1e-300))
        assert max(ratio) <= rho * (1 + 1e-9)
        Gd, Ga = D.T @ D, A.T @ A  # the maximiser reaches it
        ev = np.linalg.eigvalsh(Gd)
        if ev[0] > 1e-12 * ev[-1]:
            y = eigh(Ga, Gd)[1][:, -1]
            assert np.sum((A @ y) ** 2) / np.sum((D @ y) ** 2) == pytest.approx(rho, rel=1e-6)


def test_bandwidth_relaxation_meets_its_lmi_and_bounds_the_designs_of_its_basis(scara):
    """relaxation_bracket(bandwidth=rho): the upper-end distribution satisfies the LMI, its lower end lies
    above the plain relaxation's optimum (a distribution no 5-harmonic design can have), and weak duality
    with the LMI multiplier C holds on unseen designs of that basis: the pricer's numerator exceeds
    tr(A G) by E[tr(C (rho dq dq^T - ddq ddq^T))] >= 0, their cond is above the lower end."""
    from research.excite_relaxation import _DualPricer, basis_bandwidth

    model, lim, plain = scara
    n = model.N_JOINTS
    rho = basis_bandwidth(FourierBasis(5, 0.1), output_times(10.0, 50.0))
    b = relaxation_bracket(model, lim, atoms=100, rounds=4, fresh=2000, starts=6, add=20, seed=5, trajectories=5,
                           bandwidth=rho)
    assert b.bandwidth == rho and b.C is not None and b.lower <= b.upper
    assert b.lower > plain.upper * 1.05
    p = b.weights / b.weights.sum()
    dq, ddq = b.states[:, n:2 * n], b.states[:, 2 * n:]
    lmi = rho * (dq.T * p) @ dq - (ddq.T * p) @ ddq
    assert np.linalg.eigvalsh(lmi)[0] >= -1e-5 * np.abs(lmi).max()
    pricer = _DualPricer(model, lim, b.A, b.B, rho=rho, C=b.C)
    for q, dq_, ddq_ in _trajectories(model, lim, 10, seed=13):
        assert stacked_cond(model, q, dq_, ddq_) >= b.lower
        X = np.hstack([q, dq_, ddq_])
        num, den = pricer.num_den(X, np.sign(dq_))
        W = relaxation_rows(model, X)
        gain = num.mean() - np.einsum("kia,ab,kib->k", W, b.A, W).mean()
        K = rho * dq_.T @ dq_ / len(q) - ddq_.T @ ddq_ / len(q)
        assert np.sum(pricer.C * K) > 0 and gain == pytest.approx(np.sum(pricer.C * K), rel=1e-9)
        assert num.mean() <= b.r * den.mean() * (1 + 1e-9)


# --- the rest-to-rest moments: the momentum regressor and the frame kinematics ------------------------

def _rest_designs(lim, k, seed, t):
    """Random rest-to-rest spline designs (they end elsewhere than they start)."""
    from symoro_gen.excite import SplineBasis

    basis = SplineBasis(30, 10.0)
    rng = np.random.default_rng(seed)
    return [basis_eval(basis, random_trajectory(basis, lim, rng, t), t) for _ in range(k)]


def _weak_duality_on_rest_designs(model, lim, b, pricer, k, seed):
    """On ``k`` unseen rest-to-rest spline designs (100 Hz, 10 s): cond >= the bracket's lower end, and the
    dual ratio at every sample <= the bracket's ``r`` (what weak duality rests on)."""
    for q, dq, ddq in _rest_designs(lim, k, seed, output_times(10.0, 100.0)):
        assert stacked_cond(model, q, dq, ddq) >= b.lower
        num, den = pricer.num_den(np.hstack([q, dq, ddq]), np.sign(dq))
        assert np.all(num <= b.r * den * (1 + 1e-9))


@pytest.mark.parametrize("name", ["scara", "palletizer"])
def test_rest_moments_vanish_on_rest_to_rest_designs_that_end_elsewhere(name):
    """Every RestMoments condition has mean 0 over a spline design at rest at both ends that ends elsewhere
    (where the closed-trajectory stationarity moments do not vanish), not over random states; the CasADi
    form is the NumPy form; and two rates against finite differences of their test functions along a
    design: the momentum regressor (Y_p = W(q, 0, dq) - W(q, 0, 0), from the NumPy regressor) and the
    height of the last frame origin (from the Workspace's forward kinematics). The palletizer's design is
    in its actuated joints (the closure carries the kinematics)."""
    import casadi as ca

    from research.excite_relaxation import RestMoments, _random_states, stationarity_moments, stationarity_scales
    from symoro_gen.excite import Workspace

    robot, model = model_for(name)
    lim = limits_of(robot, model=model)
    n = lim.n
    R = RestMoments(model, lim, robot)
    assert len(R.names) == len(set(R.names)) == len(R.scale) and np.all(R.scale > 0)
    assert any(s.startswith("d/dt(Yp[") for s in R.names) and any(s.startswith("d/dt(d/dt p") for s in R.names)
    t = np.linspace(0.0, 10.0, 4001)
    w = np.full(len(t), 1.0)
    w[[0, -1]] = 0.5  # the trapezoidal mean: exact up to the quadrature error
    w /= w.sum()
    for q, dq, ddq in _rest_designs(lim, 3, 31, t):
        assert np.abs(q[-1] - q[0]).max() > 0.1
        assert np.abs(w @ R.numpy(q, dq, ddq) / R.scale).max() < 1e-5
        if name == "scara":
            assert np.abs(w @ stationarity_moments(q, dq, ddq) / stationarity_scales(lim)).max() > 0.01
    X, _ = _random_states(np.random.default_rng(0), lim, 2000)
    assert np.abs(R.numpy(X[:, :n], X[:, n:2 * n], X[:, 2 * n:]).mean(0) / R.scale).max() > 0.02
    z = ca.SX.sym("z", 3 * n)
    f = ca.Function("m", [z], [R.casadi(z[:n], z[n:2 * n], z[2 * n:])])
    for x in X[:5]:
        np.testing.assert_allclose(np.array(f(x)).ravel(), R.numpy(x[:n], x[n:2 * n], x[2 * n:])[0],
                                   rtol=1e-12, atol=1e-12)
    q, dq, ddq = _rest_designs(lim, 1, 32, t)[0]
    m = R.numpy(q, dq, ddq)
    nb = len(model.BASE_NAMES)
    zero = np.zeros_like(q)
    Yp = (np.asarray(model.regressor(q, zero, dq)) - np.asarray(model.regressor(q, zero, zero))).reshape(len(t), n, nb)
    b, j = next((b, j) for b in range(nb) for j in range(n)
                if f"d/dt(Yp[{j + 1}, {model.BASE_NAMES[b]}])" in R.names and np.ptp(Yp[:, j, b]) > 1e-3)
    k = R.names.index(f"d/dt(Yp[{j + 1}, {model.BASE_NAMES[b]}])")
    fd = np.gradient(Yp[:, j, b], t)
    assert np.abs(fd - m[:, k])[5:-5].max() < 1e-2 * np.abs(m[:, k]).max()  # a spline: jerk jumps at its knots
    lc = model.linear_closure() if hasattr(model, "linear_closure") else None
    ws = Workspace(robot, -1e9, n, None if lc is None else lc.numeric())
    last = ws.frames[-1]
    k = R.names.index(f"d/dt(d/dt p{last}.z)")
    fd = np.gradient(np.gradient(ws.heights(q)[:, -1], t), t)
    assert np.abs(fd - m[:, k])[10:-10].max() < 1e-2 * np.abs(m[:, k]).max()


def test_rest_relaxation_bounds_designs_that_end_elsewhere_and_excludes_the_plain_optimum(scara):
    """relaxation_bracket(rest=True): the upper-end distribution meets the rest moments; weak duality with
    their multipliers holds on unseen rest-to-rest spline designs (not closed: the stationary bound does not
    apply to them), whose cond stays above the lower end; that lower end is above the plain relaxation's
    optimum (on the SCARA, it accelerates joint 3 one way on average, which no trajectory at rest at both
    ends does)."""
    from research.excite_relaxation import _DualPricer

    robot, model = model_for("scara")
    lim, plain = scara[1], scara[2]
    n = model.N_JOINTS
    b = relaxation_bracket(model, lim, atoms=100, rounds=4, fresh=2000, starts=6, add=20, seed=3, trajectories=5,
                           rest=True, robot=robot)
    assert b.rest is not None and not b.closed and not b.stationary and b.lam is not None
    assert len(b.lam) == len(b.rest.names)
    p = b.weights / b.weights.sum()
    m = p @ (b.rest.numpy(b.states[:, :n], b.states[:, n:2 * n], b.states[:, 2 * n:]) / b.rest.scale)
    assert np.abs(m).max() <= b.moment_tol * 1.01
    assert plain.upper * 1.1 < b.lower <= b.upper
    pricer = _DualPricer(model, lim, b.A, b.B, b.lam, b.c0, closed=False, rest=b.rest)
    _weak_duality_on_rest_designs(model, lim, b, pricer, 8, 33)


@pytest.mark.parametrize("name", ["scara", "palletizer"])
def test_kinetic_rest_moments_are_the_power_balance_and_vanish_at_rest_to_rest(name):
    """RestMoments(kinetic=...): test functions quadratic in dq. The rates of the kinetic-energy
    regressor's entries (``T_b = dq^T Y_p[:, b] / 2``) equal the power of the inertial and Coriolis part of
    each rigid-body column, ``sum_j dq_j (W_jb(q, dq, ddq) - W_jb(q, 0, 0))`` (the energy theorem, from the
    NumPy regressor: independent of the CasADi derivative); the rates of ``dq_j Y_p[j, b]`` match finite
    differences; both vanish on average over rest-to-rest designs that end elsewhere, not over random states."""
    from research.excite_relaxation import RestMoments, _random_states

    robot, model = model_for(name)
    lim = limits_of(robot, model=model)
    n, nb = lim.n, len(model.BASE_NAMES)
    E = RestMoments(model, lim, robot, kinetic="energy")
    J = RestMoments(model, lim, robot, kinetic="joint")
    base = len(RestMoments(model, lim, robot).names)
    assert len(E.names) > base and len(J.names) > len(E.names)
    t = np.linspace(0.0, 10.0, 4001)
    w = np.full(len(t), 1.0)
    w[[0, -1]] = 0.5
    w /= w.sum()
    designs = _rest_designs(lim, 3, 41, t)
    for R in (E, J):
        for q, dq, ddq in designs:
            assert np.abs(w @ R.numpy(q, dq, ddq) / R.scale).max() < 1e-5
        X, _ = _random_states(np.random.default_rng(0), lim, 2000)
        assert np.abs(R.numpy(X[:, :n], X[:, n:2 * n], X[:, 2 * n:]).mean(0) / R.scale)[base:].max() > 0.02
    q, dq, ddq = designs[0]
    zero = np.zeros_like(q)
    W = np.asarray(model.regressor(q, dq, ddq)).reshape(len(t), n, nb)
    W0 = np.asarray(model.regressor(q, zero, zero)).reshape(len(t), n, nb)
    power = np.einsum("kj,kjb->kb", dq, W - W0)
    m = E.numpy(q, dq, ddq)
    checked = 0
    for b, c in enumerate(model.BASE_NAMES):
        if c.startswith(("FV", "FS", "OFF")) or f"d/dt(T[{c}])" not in E.names:
            continue
        k = E.names.index(f"d/dt(T[{c}])")
        np.testing.assert_allclose(m[:, k], power[:, b], rtol=1e-6, atol=1e-7 * E.scale[k])
        checked += 1
    assert checked >= 3
    Yp = np.asarray(model.regressor(q, zero, dq)).reshape(len(t), n, nb) - W0
    m = J.numpy(q, dq, ddq)
    b, j = next((b, j) for b in range(nb) for j in range(n)
                if f"d/dt(dq{j + 1} Yp[{j + 1}, {model.BASE_NAMES[b]}])" in J.names and np.ptp(Yp[:, j, b]) > 1e-3)
    k = J.names.index(f"d/dt(dq{j + 1} Yp[{j + 1}, {model.BASE_NAMES[b]}])")
    fd = np.gradient(dq[:, j] * Yp[:, j, b], t)
    assert np.abs(fd - m[:, k])[5:-5].max() < 1e-2 * np.abs(m[:, k]).max()
    with pytest.raises(ValueError, match="kinetic"):
        RestMoments(model, lim, robot, kinetic="potential")


# --- braking: the states a trajectory within its range and acceleration limits can be in --------------

def test_braking_speed_holds_on_designs_and_is_met_by_a_stop_at_the_range_end():
    """braking_speed is a property of trajectories, not a guess: every sample of random rest-to-rest spline
    designs and random Fourier trajectories within the limits is below it, and a joint that runs at its
    velocity limit and brakes at its acceleration limit to stop exactly at the end of its range (the fastest
    approach there is) meets it with equality all along the braking; the sampler and the pricer's local
    search keep to it, and the latter's gradient through the change of variables matches finite differences."""
    import scipy.optimize as so

    from research.excite_relaxation import _DualPricer, _random_states, braking_speed

    robot, model = model_for("rx90")
    lim = limits_of(robot)
    n = lim.n
    t = output_times(10.0, 200.0)
    for q, dq, _ddq in _rest_designs(lim, 3, 51, t) + _trajectories(model, lim, 3, 52):
        assert np.all(np.abs(dq) <= braking_speed(lim, q, np.sign(dq)))
    j, v, a = 3, lim.dq_max[3], lim.ddq_max[3]  # joint 4 (wrist): a braking distance of ~100 deg
    tb = np.linspace(0.0, v / a, 200)
    qb = lim.q_max[j] - v ** 2 / (2 * a) + v * tb - a * tb ** 2 / 2
    dqb = v - a * tb
    Q = np.tile((lim.q_min + lim.q_max) / 2, (len(tb), 1))
    Q[:, j] = qb
    sb = np.ones((len(tb), n))
    ratio = dqb[:-1] / braking_speed(lim, Q, sb, slack=0.0)[:-1, j]
    np.testing.assert_allclose(ratio, 1.0, rtol=1e-9)
    assert np.all(braking_speed(lim, Q, sb)[:, j] >= braking_speed(lim, Q, sb, slack=0.0)[:, j])
    assert v ** 2 / (2 * a) > np.radians(30)  # the constraint matters on this arm
    rng = np.random.default_rng(5)
    X, S = _random_states(rng, lim, 4000, braking=True)
    assert np.all(np.abs(X[:, n:2 * n]) <= braking_speed(lim, X[:, :n], np.sign(X[:, n:2 * n])) + 1e-12)
    X0, _ = _random_states(np.random.default_rng(5), lim, 4000)
    assert np.any(np.abs(X0[:, n:2 * n]) > braking_speed(lim, X0[:, :n], np.sign(X0[:, n:2 * n])) * 1.5)
    nb = len(model.BASE_NAMES)
    M = rng.normal(size=(nb, nb))
    A, B = M @ M.T, np.eye(nb)
    pricer = _DualPricer(model, lim, A, B, braking=True)
    errs, orig = [], so.minimize

    def checked(fun, x0, jac=None, bounds=None, **kw):
        u = np.array([rng.uniform(lo, hi) for lo, hi in bounds])
        g = fun(u)[1]
        fd = np.array([(fun(u + e)[0] - fun(u - e)[0]) / 2e-6 if lo < hi else 0.0
                       for e, (lo, hi) in zip(np.eye(len(u)) * 1e-6, bounds)])
        errs.append(np.abs(g - fd).max() / np.abs(fd).max())
        return orig(fun, x0, jac=jac, bounds=bounds, **kw)

    so.minimize = checked
    try:
        for x, s in zip(X[:4], S[:4]):
            xm, r = pricer.local_max(x, s)
            assert r >= pricer.ratio(x[None], s[None])[0] * (1 - 1e-9)
            assert np.all(np.abs(xm[n:2 * n]) <= braking_speed(lim, xm[:n], s) * (1 + 1e-9))
            assert np.all(xm[n:2 * n] * s >= 0)
    finally:
        so.minimize = orig
    assert len(errs) == 4 and max(errs) < 1e-4


def test_braking_relaxation_bounds_unseen_designs(scara):
    """relaxation_bracket(braking=True): its distribution's states keep to braking_speed, and weak duality
    with its duals holds on the samples of unseen designs (which keep to it too)."""
    from research.excite_relaxation import _DualPricer, braking_speed

    robot, model = model_for("scara")
    lim = scara[1]
    n = lim.n
    b = relaxation_bracket(model, lim, atoms=100, rounds=3, fresh=2000, starts=6, add=20, seed=3, trajectories=5,
                           rest=True, robot=robot, braking=True)
    assert b.braking and b.lower <= b.upper
    dq = b.states[:, n:2 * n]
    assert np.all(np.abs(dq) <= braking_speed(lim, b.states[:, :n], np.sign(dq)) * (1 + 1e-9))
    pricer = _DualPricer(model, lim, b.A, b.B, b.lam, b.c0, closed=False, rest=b.rest, braking=True)
    _weak_duality_on_rest_designs(model, lim, b, pricer, 6, 53)


def test_mixture_cond_is_the_best_time_sharing_of_designs():
    """mixture_cond: the cond of the returned time fractions' mixture is what it reports, no better than any
    random mixture of the same designs and no worse than the best single one; two designs that excite
    complementary halves of the parameters mix into a well-conditioned experiment that neither is."""
    robot, model = model_for("scara")
    lim = limits_of(robot)
    from research.excite_relaxation import mixture_cond

    Ms = []
    for q, dq, ddq in _trajectories(model, lim, 6, 61):
        W = np.asarray(model.regressor(q, dq, ddq)).reshape(-1, len(model.BASE_NAMES))
        Ms.append(W.T @ W / len(q))
    Ms = np.array(Ms)
    c, p = mixture_cond(Ms)
    assert p.shape == (6,) and np.all(p >= 0) and p.sum() == pytest.approx(1.0)
    ev = np.linalg.eigvalsh(np.einsum("k,kab->ab", p, Ms))
    assert np.sqrt(ev[-1] / ev[0]) == pytest.approx(c, rel=1e-9)
    singles = [np.sqrt(e[-1] / e[0]) for e in map(np.linalg.eigvalsh, Ms)]
    assert c <= min(singles) * (1 + 1e-6)
    rng = np.random.default_rng(0)
    for _ in range(50):
        e = np.linalg.eigvalsh(np.einsum("k,kab->ab", rng.dirichlet(np.ones(6)), Ms))
        assert np.sqrt(e[-1] / e[0]) >= c * (1 - 1e-4)
    D1, D2 = np.diag([1.0, 1.0, 1e-4, 1e-4]), np.diag([1e-4, 1e-4, 4.0, 4.0])
    c2, p2 = mixture_cond(np.array([D1, D2]))
    assert c2 == pytest.approx(1.0, rel=1e-4) and p2[0] == pytest.approx(0.8, rel=1e-3)
    with pytest.raises(ValueError, match="mixture_cond"):
        mixture_cond(np.zeros((2, 3)))


# --- random test functions: a cutting plane over the occupation-measure conditions ---------------------

def test_feature_moments_are_rates_that_vanish_at_rest_to_rest_and_are_bounded_by_their_scale():
    """FeatureMoments: each rate is d/dt of dq_j cos(omega . q + nu . dq + phi) along a design (finite
    differences of the test function itself), the CasADi form is the NumPy form, the means vanish over
    rest-to-rest designs that end elsewhere (not over random states), no state of the box exceeds the
    analytic ``scale``, subset/concatenation keep each feature's identity, and the chunked weighted sum is the
    plain one."""
    import casadi as ca

    from research.excite_relaxation import FeatureMoments, _random_states

    robot, model = model_for("scara")
    lim = limits_of(robot)
    n = lim.n
    F = FeatureMoments(lim, 300, seed=4)
    t = np.linspace(0.0, 10.0, 4001)
    q, dq, ddq = _rest_designs(lim, 1, 61, t)[0]
    m = F.numpy(q, dq, ddq)
    for k in (0, 17, 123):
        f = dq[:, F.joint[k]] * np.cos(q @ F.omega[k] + dq @ F.nu[k] + F.phase[k])
        fd = np.gradient(f, t)
        assert np.abs(fd - m[:, k])[5:-5].max() < 1e-2 * np.abs(m[:, k]).max()
    w = np.full(len(t), 1.0)
    w[[0, -1]] = 0.5
    w /= w.sum()
    for q, dq, ddq in _rest_designs(lim, 3, 62, t):
        assert np.abs(w @ F.numpy(q, dq, ddq) / F.scale).max() < 1e-5
    X, _ = _random_states(np.random.default_rng(5), lim, 5000)
    V = F.numpy(X[:, :n], X[:, n:2 * n], X[:, 2 * n:])
    assert np.all(np.abs(V) <= F.scale * (1 + 1e-12))
    assert np.abs(V.mean(0) / F.scale).max() > 0.02
    z = ca.SX.sym("z", 3 * n)
    f = ca.Function("m", [z], [F.casadi(z[:n], z[n:2 * n], z[2 * n:])])
    np.testing.assert_allclose(np.array(f(X[0])).ravel(), V[0], rtol=1e-12, atol=1e-12)
    G = F.subset([5, 2]) + F.subset([250])
    assert list(G.ids) == [5, 2, 250] and G.names == [F.names[5], F.names[2], F.names[250]]
    np.testing.assert_array_equal(G.numpy(X[:3, :n], X[:3, n:2 * n], X[:3, 2 * n:]), V[:3][:, [5, 2, 250]])
    p = np.random.default_rng(6).random(len(X))
    np.testing.assert_allclose(F.weighted_sum(X, p, chunk=7), p @ V, rtol=1e-12, atol=1e-9)


def test_feature_cuts_hold_on_the_final_distribution_and_weak_duality_on_designs():
    """relaxation_bracket(rest=True, features=K, cut_at=...): cuts are added after the rounds asked (the rest-only
    optimum violates random test functions), the upper-end distribution meets the rest moments and every cut of its round, and weak duality
    with the lower end's multipliers (cuts included) holds on unseen rest-to-rest designs, whose cond stays
    above the lower end."""
    from research.excite_relaxation import _DualPricer

    robot, model = model_for("scara")
    lim = limits_of(robot)
    n = model.N_JOINTS
    b = relaxation_bracket(model, lim, atoms=100, rounds=4, fresh=2000, starts=6, add=20, seed=3, trajectories=5,
                           rest=True, robot=robot, features=10, dictionary=2000, tol=0.0, cut_at=(0, 2))
    assert [h.cuts for h in b.rounds] == [0, 10, 10, 20, 20] and b.lam is not None
    assert b.features is not None and len(b.lam) == len(b.rest.names) + len(b.features)
    p = b.weights / b.weights.sum()
    X = b.states
    assert np.abs(p @ (b.rest.numpy(X[:, :n], X[:, n:2 * n], X[:, 2 * n:]) / b.rest.scale)).max() <= b.moment_tol * 1.01
    cut = b.upper_features
    assert cut is not None and len(cut) == b.rounds[-1].cuts
    assert np.abs(p @ (cut.numpy(X[:, :n], X[:, n:2 * n], X[:, 2 * n:]) / cut.scale)).max() <= b.moment_tol * 1.01
    pricer = _DualPricer(model, lim, b.A, b.B, b.lam, b.c0, closed=False, rest=b.rest, features=b.features)
    _weak_duality_on_rest_designs(model, lim, b, pricer, 8, 63)


def test_a_saved_cut_run_continues_where_it_stopped():
    """relaxation_bracket(cuts=, extra_designs=): the cuts of a run's upper end (``upper_features.ids``) held from
    round 0 and its distribution given back (its plain states, and its whole-trajectory atoms as the blocks
    ``design_sizes`` says) start the next run at that run's upper end or below (the saved distribution is
    feasible for it), with the same cuts and no new ones unless asked; cuts need ``rest=True`` and ids in the
    dictionary."""
    from research.excite_relaxation import split_saved_atoms

    robot, model = model_for("scara")
    lim = limits_of(robot)
    kw = dict(atoms=100, fresh=2000, starts=6, add=20, seed=3, rest=True, robot=robot, dictionary=2000, tol=0.0)
    b = relaxation_bracket(model, lim, rounds=2, trajectories=5, features=10, cut_at=(0,), **kw)
    assert b.upper_features is not None and len(b.upper_features) == 10
    ids = [int(k) for k in b.upper_features.ids]
    cut = len(b.states) - sum(b.design_sizes)
    for k in b.design_sizes:  # each block: one trajectory's samples in equal shares
        assert np.ptp(b.weights[cut:cut + k]) <= 1e-12 * b.weights[cut:cut + k].max()
        cut += k
    states, signs, designs = split_saved_atoms(b.states, b.signs, b.design_sizes)
    assert len(designs) == len(b.design_sizes) and len(states) + sum(b.design_sizes) == len(b.states)
    c = relaxation_bracket(model, lim, rounds=1, trajectories=0, cuts=ids, extra_states=states,
                           extra_signs=signs, extra_designs=designs, **kw)
    assert [h.cuts for h in c.rounds] == [10, 10]
    assert sorted(int(k) for k in c.upper_features.ids) == sorted(ids)
    assert c.rounds[0].primal <= b.upper * (1 + 1e-3)
    with pytest.raises(ValueError, match="rest=True"):
        relaxation_bracket(model, lim, rounds=0, cuts=ids)
    with pytest.raises(ValueError, match="ids in the dictionary"):
        relaxation_bracket(model, lim, rounds=0, cuts=[5000], **kw)


@pytest.mark.parametrize("name", ["rx90", "lwr4"])
def test_random_cuts_hold_on_designs_sampled_at_100_hz_within_the_bench_tolerance(name):
    """What the cut relaxation bounds: the cond is taken over a design's 100-Hz samples, whose uniform mean
    meets E[d/dt f] = 0 only to quadrature accuracy. A Fourier design's samples (one period) meet every test
    function of a dictionary like the bench's (5,000 here, seed 1) to rounding; rest-to-rest splines of up to 231 control
    points over 10 s meet them within the bench's --moment-tol 0.001 of their scale (the error grows with the
    knot density: jerk jumps at every knot)."""
    from research.excite_relaxation import FeatureMoments
    from symoro_gen.excite import SplineBasis

    robot, _ = model_for(name)
    lim = limits_of(robot)
    F = FeatureMoments(lim, 5000, seed=1)
    t = output_times(10.0, 100.0)
    rng = np.random.default_rng(8)
    for basis, tol in ((FourierBasis(5, 0.1), 1e-12), (SplineBasis(60, 10.0), 1e-3), (SplineBasis(231, 10.0), 1e-3)):
        q, dq, ddq = basis_eval(basis, random_trajectory(basis, lim, rng, t), t)
        assert np.abs(F.numpy(q, dq, ddq).mean(0) / F.scale).max() < tol


@pytest.mark.slow
def test_bench_saves_continues_and_reverifies_a_cut_run(tmp_path):
    """The commands docs/excitation.md gives for the cut runs: ``--save`` writes the cuts and the trajectory atoms,
    ``--start`` continues with the cuts held from round 0, ``--reverify`` re-prices the saved lower-end duals on a
    search of its own, which can only find larger dual ratios (its lower end at most the run's estimate)."""
    import os
    import re
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(root), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    small = ["--robot", "scara", "--rest", "--atoms", "100", "--fresh", "2000", "--starts", "6", "--add", "20",
             "--dictionary", "500", "--trajectories", "3", "--tol", "0"]

    def bench(*args):
        out = subprocess.run([sys.executable, str(root / "bench" / "bench_excite_relaxation.py"), *small, *args],
                             capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
        assert out.returncode == 0, out.stderr[-2000:]
        return out.stdout

    first, second = tmp_path / "cut.npz", tmp_path / "cut2.npz"
    bench("--features", "5", "--cut-at", "0", "--rounds", "1", "--save", str(first))
    saved = np.load(first)
    assert len(saved["cut_ids"]) == 5 and sum(saved["design_sizes"]) <= len(saved["states"])
    out = bench("--start", str(first), "--rounds", "0", "--save", str(second))
    assert re.search(r"warm start from .*: \d+ states, \d+ trajectory atoms, 5 random test functions held", out)
    assert sorted(np.load(second)["cut_ids"]) == sorted(saved["cut_ids"])
    out = bench("--reverify", str(second), "--verify", "3000", "--verify-starts", "4", "--seed", "5")
    m = re.search(r"dual estimate ([\d.]+)\); 3000 fresh states \+ 4 local searches \(seed 5\): r [\d.]+, lower end ([\d.]+)",
                  out)
    assert m and float(m.group(2)) <= float(m.group(1)) + 1e-3
    out = bench("--reverify", str(second), "--perturb", "3", "--verify-starts", "2", "--seed", "5")
    m = re.search(r"dual estimate ([\d.]+)\); 3 perturbations of each atom x 4 scales \+ 2 local searches \(seed 5\): "
                  r"r [\d.]+, lower end ([\d.]+)", out)
    assert m and float(m.group(2)) <= float(m.group(1)) + 1e-3


def test_bench_prices_rest_to_rest_pieces_and_their_equal_time_sets(tmp_path):
    """``bench_excite_mixture.py --pieces``: every priced piece is a spline at rest at both ends within the limits,
    the best mixture never rises as pieces join the pool, and K distinct pieces for equal times (``--equal``)
    never beat the mixture of all (the SDP's optimum over every time sharing); ``best_equal_set`` ends where
    no exchange of one piece lowers cond."""
    import itertools
    import os
    import re
    import subprocess
    import sys
    from pathlib import Path

    from symoro_gen.excite import SplineBasis

    root = Path(__file__).resolve().parents[1]
    env = dict(os.environ, PYTHONPATH=str(root), OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1")
    out = subprocess.run([sys.executable, str(root / "bench" / "bench_excite_mixture.py"), "--robots", "scara",
                          "--random", "--pieces", "1", "--points", "9", "--init", "8", "--per-round", "2",
                          "--price", "2", "--max-iter", "20", "--equal", "2", "4", "--save", str(tmp_path / "p.npz")],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert out.returncode == 0, out.stderr[-2000:]
    mixes = [float(x) for x in re.findall(r"round \d+: \d+ pieces, best mixture ([\d.]+)", out.stdout)]
    assert len(mixes) == 3 and all(b <= a * (1 + 1e-3) for a, b in itertools.pairwise(mixes))
    equal = [float(x) for x in re.findall(r"for equal times \(\d+ s of motion\): cond ([\d.]+)", out.stdout)]
    assert len(equal) == 2 and min(equal) >= mixes[-1] * (1 - 1e-3)
    saved = np.load(tmp_path / "p.npz")
    robot, model = model_for("scara")
    lim = limits_of(robot)
    basis, t = SplineBasis(9, 1.0), np.linspace(0.0, 1.0, 1001)
    assert len(saved["designs"]) == 8 + 2 * 2
    for X in saved["designs"]:
        q, dq, ddq = basis_eval(basis, X, t)
        assert check_limits(lim, q, dq, ddq)["ok"]
        assert np.abs(dq[[0, -1]]).max() < 1e-9 and np.abs(ddq[[0, -1]]).max() < 1e-6

    sys.path.insert(0, str(root / "bench"))
    try:
        from bench_excite_mixture import best_equal_set, cond_of
    finally:
        sys.path.remove(str(root / "bench"))
    Ms = saved["Ms"]
    c, sel = best_equal_set(Ms, 3, [0, 1, 2])
    assert c <= cond_of(Ms[[0, 1, 2]].mean(0)) and len(set(sel)) == 3
    for slot in range(3):
        for j in set(range(len(Ms))) - set(sel):
            trial = list(sel)
            trial[slot] = j
            assert cond_of(Ms[trial].mean(0)) >= c - 1e-9


def test_transit_inequalities_hold_on_designs_and_are_nearly_met_by_a_full_range_sweep():
    """TransitInequalities: E[g] <= 0 on the samples of random rest-to-rest spline designs, structured designs
    (bursts at the velocity limit) and random Fourier designs at 100 Hz and 1 kHz (and kappa falls with the
    sampling interval, so the 100-Hz rows hold for every finer sampling); the distribution that jumps between
    creeping and the velocity limit violates them (a sweep of a joint's range at its limits, nearly meeting the
    widest bands' bound: test_transit_inequalities_hold_on_bursts_whose_speed_dips_between_samples)."""
    from research.excite_relaxation import TransitInequalities
    from symoro_gen.excite import SplineBasis, dense_times, friction_trajectory

    robot, model = model_for("rx90")
    lim = limits_of(robot)
    n = lim.n
    T = TransitInequalities(lim, 8)
    assert len(T) > 0 and np.all(T.kappa > 0) and set(T.joint) == set(range(n))
    T_fine = TransitInequalities(lim, 8, dt=0.001)
    assert len(T_fine) >= len(T)
    rng = np.random.default_rng(61)
    inner = lim.shrunk(0.01)
    for rate in (100.0, 1000.0):
        t = output_times(10.0, rate)
        designs = _rest_designs(lim, 3, 62, t) + _trajectories(model, lim, 3, 63)
        sb = SplineBasis(60, 10.0)
        for _ in range(3):
            designs.append(basis_eval(sb, friction_trajectory(sb, inner, rng, dense_times(t, 10.0, sb), 10.0), t))
        for q, dq, ddq in designs:
            assert check_limits(lim, q, dq, ddq)["ok"]
            assert T.worst(np.hstack([q, dq, ddq])) <= 0.0
    # kappa of the same rows is smaller at a finer sampling (or both at the floor 1 of the samples' kappa)
    key = {(j, s, round(u1, 12), round(u2, 12)): k for j, s, u1, u2, k in zip(T_fine.joint, T_fine.sign, T_fine.u1,
                                                                         T_fine.u2, T_fine.kappa)}
    fine = np.array([key[(j, s, round(u1, 12), round(u2, 12))] for j, s, u1, u2 in zip(T.joint, T.sign, T.u1, T.u2)])
    assert np.all((T.kappa > fine) | ((T.kappa == 1.0) & (fine == 1.0))) and np.any(T.kappa > 1.0)
    # the relaxations' favourite: 30 % at the velocity limit, the rest creeping - nothing in between
    Xj = np.zeros((2, 3 * n))
    Xj[0, n:2 * n], Xj[1, n:2 * n] = lim.dq_max, 0.01 * lim.dq_max
    assert T.worst(Xj, np.array([0.3, 0.7])) > 0.02


def test_transit_friction_ceiling_is_below_the_friction_ceiling():
    """transit_friction_ceiling: without rows (every band narrower than the sampling allows) it is
    friction_ceiling's one-dimensional optimum; with the rows of 8 levels it is a few per cent below it."""
    from research.excite_relaxation import TransitInequalities, transit_friction_ceiling
    from symoro_gen.excite import friction_ceiling

    robot, _ = model_for("rx90")
    lim = limits_of(robot)
    c0 = np.array([friction_ceiling(v) for v in lim.dq_max])
    none = TransitInequalities(lim, 8, dt=10.0)
    assert len(none) == 0
    np.testing.assert_allclose(transit_friction_ceiling(lim, none, grid=200), c0, rtol=2e-3)
    c = transit_friction_ceiling(lim, TransitInequalities(lim, 8), grid=200)
    assert np.all(c < c0 * 0.995) and np.all(c > c0 * 0.9)


def test_transit_relaxation_meets_its_inequalities_rises_and_bounds_unseen_designs():
    """relaxation_bracket(transit=8) on the SCARA: its distribution meets the transit inequalities (the rest
    relaxation's does not: it jumps between creeping and the velocity limits), its upper end is above the rest
    relaxation's, and weak duality with the inequalities' multipliers holds on unseen rest-to-rest designs."""
    from research.excite_relaxation import TransitInequalities, _DualPricer

    robot, model = model_for("scara")
    lim = limits_of(robot)
    kw = dict(atoms=100, rounds=4, fresh=2000, starts=6, add=20, seed=3, trajectories=5, rest=True, robot=robot)
    plain = relaxation_bracket(model, lim, **kw)
    b = relaxation_bracket(model, lim, transit=8, **kw)
    T = TransitInequalities(lim, 8)
    assert b.transit is not None and len(b.eta) == len(T) and np.all(b.eta >= 0)
    assert T.worst(plain.states, plain.weights) > 0.01
    assert T.worst(b.states, b.weights) <= 1e-6
    assert b.upper > plain.upper * 1.01 and b.lower <= b.upper
    pricer = _DualPricer(model, lim, b.A, b.B, b.lam, b.c0, closed=False, rest=b.rest, transit=b.transit, eta=b.eta)
    _weak_duality_on_rest_designs(model, lim, b, pricer, 6, 64)
    # the pricer's local search crosses the transit term's steps: its result is no worse than the smooth search
    # alone and no single joint's speed moved anywhere on a fine grid (either sign at rest) raises the ratio
    n = lim.n
    X0, S0 = b.states[:5], b.signs[:5]
    for x0, s0 in zip(X0, S0):
        x, s, r = pricer.local_max_with_signs(x0, s0)
        assert r >= pricer._local_max_signed(x0, s0)[1] * (1 - 1e-9)
        assert r == pytest.approx(pricer.ratio(x[None], s[None])[0], rel=1e-12)
        assert np.all((np.sign(x[n:2 * n]) == s) | (x[n:2 * n] == 0))
        for j in range(n):
            v = np.linspace(-lim.dq_max[j], lim.dq_max[j], 1001)
            Xc, Sc = np.tile(x, (len(v), 1)), np.tile(s, (len(v), 1))
            Xc[:, n + j], Sc[:, j] = v, np.sign(v)
            assert pricer.ratio(Xc, Sc).max() <= r * (1 + 1e-2)


@pytest.mark.parametrize("name", ["scara", "lwr4"])
def test_speed_scan_rows_from_four_probes_equal_the_direct_evaluation(name):
    """The speed scan's regressor rows and rest moments come from the cubic through four probe speeds
    (``_DualPricer._scan_rows``: the rows are quadratic in one joint's speed, the rest moments at most cubic):
    equal to evaluating every state of the scan, on random states, every joint and both signs; a model whose rows
    are not polynomial in the speed is detected and evaluated state by state."""
    from types import SimpleNamespace

    from research.excite_relaxation import RestMoments, _DualPricer, _random_states

    robot, model = model_for(name)
    lim = limits_of(robot)
    n, nb = lim.n, len(model.BASE_NAMES)
    rest = RestMoments(model, lim, robot)
    rng = np.random.default_rng(5)
    M = rng.standard_normal((nb, nb))
    A, B = M @ M.T, np.eye(nb)
    lam = rng.standard_normal(len(rest.names))
    pricer = _DualPricer(model, lim, A, B, lam, 1.0, closed=False, rest=rest)
    X, S = _random_states(rng, lim, 4)
    for x, s in zip(X, S):
        for j in range(n):
            v = np.concatenate([np.linspace(-1, 1, 41) * lim.dq_max[j], [0.0, 0.0]])
            Sc = np.tile(s, (len(v), 1))
            Sc[:, j] = np.concatenate([np.sign(v[:-2]), [1.0, -1.0]])
            Xc = np.tile(x, (len(v), 1))
            Xc[:, n + j] = v
            W, R = pricer._scan_rows(x, s, j, v, Sc)
            Wd = relaxation_rows(model, Xc, Sc)
            Rd = rest.numpy(Xc[:, :n], Xc[:, n:2 * n], Xc[:, 2 * n:])
            assert np.abs(W - Wd).max() <= 1e-9 * np.abs(Wd).max()
            assert np.abs(R - Rd).max() <= 1e-9 * np.abs(Rd).max()
            num, den = pricer.num_den(Xc, Sc, W, R)
            numd, dend = pricer.num_den(Xc, Sc)
            assert num == pytest.approx(numd, rel=1e-9, abs=1e-9 * np.abs(numd).max())
            assert den == pytest.approx(dend, rel=1e-9)
    # rows with a smooth-friction column (tanh of the speed): not a polynomial, detected
    smooth = SimpleNamespace(N_JOINTS=model.N_JOINTS, BASE_NAMES=model.BASE_NAMES, regressor=lambda q, dq, ddq: (
        np.asarray(model.regressor(q, dq, ddq)).reshape(len(q), n, nb) * (1 + np.tanh(dq / 0.1))[:, :, None]))
    p2 = _DualPricer(smooth, lim, A, B, lam, 1.0, closed=False, rest=rest, coulomb=pricer.coul, jac=False)
    x, s = X[0], S[0]
    v = np.linspace(-1, 1, 11) * lim.dq_max[0]
    assert p2._scan_rows(x, s, 0, v, np.tile(s, (len(v), 1))) == (None, None)


@pytest.mark.parametrize("name", ["rx90", "lwr4"])
def test_transit_inequalities_hold_on_bursts_whose_speed_dips_between_samples(name):
    """The sampled transit inequalities hold whatever the speed does within a burst: for every row, a burst at
    the acceleration limit that cruises at u2 (the sharpest case: its widest rows within 10 % of equality) and
    one whose cruise has a ripple at half the sampling rate (its samples alternate between u2 and just below:
    as many runs at >= u2 as the range allows, each separated by one band sample), sampled at 100 Hz with
    random phases, at rest at both ends and within the range. The widest band's burst - a sweep of the joint's
    whole range at its acceleration and velocity limits, the fastest burst there is - comes within 20 % of the
    bound on every joint whose widest row is not at the floor kappa = 1."""
    from research.excite_relaxation import TRANSIT_DT, TransitInequalities

    robot, _ = model_for(name)
    lim = limits_of(robot)
    n, dt = lim.n, TRANSIT_DT
    T = TransitInequalities(lim, 8)
    rng = np.random.default_rng(7)
    sharp = []
    for r in np.flatnonzero(T.sign > 0):
        j, u1, u2 = int(T.joint[r]), float(T.u1[r]), float(T.u2[r])
        a, R = float(lim.ddq_max[j]), float(lim.q_max[j] - lim.q_min[j])
        for d in (0.0, a * dt / np.pi):  # ripple amplitude: |d/dt (d cos(pi t / dt))| <= a
            base = u2 - d
            ta = base / a  # reach the cruise at a, leave it at a
            room = R - base ** 2 / a - 1e-3
            if room <= 0:
                continue
            tc = room / base
            t = np.arange(0.0, 2 * ta + tc, dt / 20)
            k0 = int(rng.integers(20))  # the first sample; the ripple is at u2 on every other sample
            v = np.minimum.reduce([a * t, base + d * np.cos(np.pi * (t - t[k0]) / dt), a * (2 * ta + tc - t)])
            v = v.clip(0.0)
            q = lim.q_min[j] + np.concatenate([[0.0], np.cumsum((v[1:] + v[:-1]) / 2 * np.diff(t))])
            assert q.max() <= lim.q_max[j] and v.max() <= lim.dq_max[j] * (1 + 1e-12)
            X = np.zeros((len(t[k0::20]), 3 * n))
            X[:, n + j] = v[k0::20]  # the 100-Hz samples
            hi = X[:, n + j] >= u2
            band = (X[:, n + j] >= u1) & ~hi
            assert hi.sum() > 3 and (d == 0 or np.any(hi[1:] != hi[:-1]))
            assert float(T.numpy(X)[:, r].mean()) <= 0.0
            if d == 0 and u1 == T.u1[T.joint == j].min() and u2 == T.u2[T.joint == j].max():
                sharp.append((hi.mean() / (T.kappa[r] * band.mean()), T.kappa[r]))
    assert len(sharp) == n and max(f for f, _ in sharp) > 0.9
    assert all(f > 0.8 for f, k in sharp if k > 1.0) and sum(k > 1.0 for _, k in sharp) >= 2
