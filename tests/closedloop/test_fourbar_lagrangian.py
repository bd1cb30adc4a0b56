"""Closed four-bar: the projected tree model against an independent Lagrangian of the closed chain.

The reference is sympy's Euler-Lagrange equation of the one-degree-of-freedom four-bar, written with
its own closed-form position analysis (intersection of two circles), so it shares nothing with
symoro_gen's Newton-Euler model, loop-closure solver or projection:

    L(q1, qd1) = sum_links T_j - U_j = 1/2 M(q1) qd1^2 - U(q1),
    tau1 = d/dt dL/dqd1 - dL/dq1 = M qdd1 + 1/2 M' qd1^2 + U'   (+ drive terms of joint 1)

with ``T_j = 1/2 m v_o^2 + v_o . (w x R MS) + 1/2 ZZ w^2`` and ``U_j = -g . (m p_o + R MS)`` for a
link turning in the plane about z (Khalil & Dombre 2002, ch. 9, energy of a link from its standard
parameters at the frame origin).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

from symoro_gen.closedloop import ClosedLoopModel, ClosureError
from symoro_gen.description import parse_robot_text
from symoro_gen.emit.package import build_in_memory

A, BC, C, D = 0.20, 0.45, 0.40, 0.50  # crank, coupler, rocker, ground: crank-rocker (Grashof)
G = (0.0, -9.81, 0.0)                  # gravity in the plane of the mechanism


def closed_form(q1: float) -> tuple[float, float]:
    """Absolute angles of the coupler and the rocker (upper assembly) by intersecting two circles."""
    bx, by = A * math.cos(q1), A * math.sin(q1)
    ex, ey = D - bx, -by
    e = math.hypot(ex, ey)
    a = (BC**2 - C**2 + e**2) / (2 * e)
    h = math.sqrt(BC**2 - a**2)
    cx, cy = bx + (a * ex - h * ey) / e, by + (a * ey + h * ex) / e
    return math.atan2(cy - by, cx - bx), math.atan2(cy, cx - D)


def fourbar_text(reference: bool = True) -> str:
    ph2, ph3 = closed_form(0.0)
    ref = f"\n[loop_reference]\nq2 = {ph2!r}\nq3 = {ph3!r}\nq4 = {ph3 - ph2!r}\n" if reference else ""
    return f"""
name = "fourbar"
gravity = [{G[0]}, {G[1]}, {G[2]}]
drive = ["IA", "FV", "FS", "OFF"]
[values]
A = {A}
BC = {BC}
C = {C}
D = {D}
[[frames]]
j = 1
ant = 0
sigma = 0
alpha = 0
d = 0
theta = "q"
r = 0
[[frames]]
j = 2
ant = 1
sigma = 0
mu = 0
alpha = 0
d = "A"
theta = "q"
r = 0
[[frames]]
j = 3
ant = 0
sigma = 0
mu = 0
alpha = 0
d = "D"
theta = "q"
r = 0
[[loops]]
cut = {{ ant = 2, sigma = 0, alpha = 0, d = "BC", theta = "q", r = 0 }}
close = {{ ant = 3, alpha = 0, d = "C", theta = 0, r = 0 }}
{ref}"""


def lagrangian_torque():
    """``tau1(q1, qd1, qdd1, params)`` of the closed four-bar, by sympy (lambdified).

    One degree of freedom: ``L = 1/2 M(q) qd^2 - U(q)``, so Lagrange's equation is
    ``tau = M qdd + 1/2 M'(q) qd^2 + U'(q)``; ``M`` and ``U`` come from the link energies above with the
    positions and angles of the closed-form position analysis (sympy differentiates them twice; ``M'``
    and ``U'`` are then written out by the product rule, with ``d(R MS)/dq = w k x R MS``).
    """
    x = sp.Symbol("x")
    names = [f"{k}{j}" for j in (1, 2, 3) for k in ("ZZ", "MX", "MY", "M")] + ["IA1", "FV1", "FS1", "OFF1"]
    bx, by = A * sp.cos(x), A * sp.sin(x)
    ex, ey = D - bx, -by
    e = sp.sqrt(ex**2 + ey**2)
    a = (BC**2 - C**2 + e**2) / (2 * e)
    h = sp.sqrt(BC**2 - a**2)
    cx, cy = bx + (a * ex - h * ey) / e, by + (a * ey + h * ex) / e
    phis = [x, sp.atan2(cy - by, cx - bx), sp.atan2(cy, cx - D)]
    origins = [(sp.S(0), sp.S(0)), (bx, by), (sp.S(D), sp.S(0))]
    # per link: origin velocity (vx, vy) and angular velocity w per unit qd, and their q-derivatives
    kin = []
    for phi, (ox, oy) in zip(phis, origins):
        d1 = [sp.diff(v, x) for v in (ox, oy, phi)]
        kin.append(sp.lambdify(x, [phi, *d1, *(sp.diff(v, x) for v in d1)], "numpy"))

    def tau(q, qd, qdd, *p):
        par = dict(zip(names, p))
        M = dM = dU = 0.0
        for j, f in enumerate(kin, start=1):
            phi, vx, vy, w, dvx, dvy, dw = (float(v) for v in f(q))
            m, mx, my, zz = (par[f"{k}{j}"] for k in ("M", "MX", "MY", "ZZ"))
            sx, sy = math.cos(phi) * mx - math.sin(phi) * my, math.sin(phi) * mx + math.cos(phi) * my  # R MS
            dsx, dsy = -w * sy, w * sx
            M += m * (vx**2 + vy**2) + 2 * w * (vy * sx - vx * sy) + zz * w**2  # 2 T / qd^2
            dM += (2 * m * (vx * dvx + vy * dvy) + 2 * dw * (vy * sx - vx * sy)
                   + 2 * w * (dvy * sx + vy * dsx - dvx * sy - vx * dsy) + 2 * zz * w * dw)
            dU += -(G[0] * (m * vx + dsx) + G[1] * (m * vy + dsy))  # U = -g . (m p_o + R MS)
        return (M * qdd + 0.5 * dM * qd**2 + dU
                + par["IA1"] * qdd + par["FV1"] * qd + par["FS1"] * np.sign(qd) + par["OFF1"])
    return tau, names


@pytest.fixture(scope="module")
def fourbar():
    robot = parse_robot_text(fourbar_text(), file="fourbar.toml")
    return robot, ClosedLoopModel(robot, build_in_memory(robot))


def test_actuated_torque_equals_the_lagrangian_of_the_closed_chain(fourbar):
    robot, model = fourbar
    f, names = lagrangian_torque()
    rng = np.random.default_rng(4)
    chi = rng.uniform(-1.0, 1.0, len(model.STANDARD_NAMES))  # every standard parameter (planar ones matter)
    idx = [model.STANDARD_NAMES.index(n) for n in names]
    N = 40
    q = rng.uniform(-math.pi, math.pi, (N, 1))  # a crank-rocker: the crank turns all the way round
    dq, ddq = rng.normal(0, 2, (N, 1)), rng.normal(0, 5, (N, 1))
    tau = model.torque(q, dq, ddq, chi)
    ref = np.array([f(q[i, 0], dq[i, 0], ddq[i, 0], *chi[idx]) for i in range(N)])
    np.testing.assert_allclose(tau[:, 0], ref, rtol=0, atol=1e-9 * max(1.0, np.abs(ref).max()))
    # and the standard regressor projected gives the same torques
    np.testing.assert_allclose(model.standard_regressor(q, dq, ddq) @ chi, tau, rtol=0, atol=1e-9)


def test_closure_residual_and_passive_joints_against_the_closed_form(fourbar):
    robot, model = fourbar
    q1 = np.linspace(-math.pi, math.pi, 25)[:, None]
    st = model.kinematics.solve(q1, np.ones_like(q1), np.zeros_like(q1))
    assert st.residual.max() < 1e-12
    for i, v in enumerate(q1[:, 0]):
        ph2, ph3 = closed_form(v)
        assert math.remainder(st.q[i, 1] - (ph2 - v), 2 * math.pi) == pytest.approx(0, abs=1e-10)
        assert math.remainder(st.q[i, 2] - ph3, 2 * math.pi) == pytest.approx(0, abs=1e-10)


def test_a_general_loop_has_no_casadi_form_and_excite_says_why(fourbar):
    """The four-bar's passive angles are not linear in the crank's: no closed form, so no CasADi regressor;
    ``excite`` turns that into its own error naming the reason, not a traceback."""
    from symoro_gen.errors import ModelError
    from symoro_gen.excite import ExcitationError, casadi_regressor

    _, model = fourbar
    assert model.linear_closure() is None
    with pytest.raises(ModelError, match="not linear in the actuated joints"):
        model.casadi_regressor()
    with pytest.raises(ExcitationError, match=r"not linear.*excite cannot optimise a trajectory for it"):
        casadi_regressor(model)


def test_base_parameters_of_the_four_bar(fourbar):
    """A one-dof closed chain: the projected regressor's numeric rank equals the base count, and the
    base parameters reproduce the standard model's torques."""
    robot, model = fourbar
    rng = np.random.default_rng(7)
    q = rng.uniform(-math.pi, math.pi, (200, 1))
    dq, ddq = rng.normal(0, 2, (200, 1)), rng.normal(0, 5, (200, 1))
    Ws = model.standard_regressor(q, dq, ddq)[:, 0, :]
    norms = np.linalg.norm(Ws, axis=0)
    live = norms > 1e-10 * norms.max()  # columns that are zero up to rounding are not scaled up
    s = np.linalg.svd(Ws[:, live] / norms[live], compute_uv=False)
    assert int(np.sum(s > 1e-8 * s[0])) == len(model.BASE_NAMES)
    chi = rng.normal(size=len(model.STANDARD_NAMES))
    np.testing.assert_allclose(model.regressor(q, dq, ddq) @ model.base_parameters(chi), Ws[:, None, :] @ chi,
                               atol=1e-9)


def test_unusable_reference_is_one_error_naming_the_table():
    robot = parse_robot_text(fourbar_text(reference=False).replace("D = 0.5", "D = 2.0"), file="fourbar.toml")
    with pytest.raises(ClosureError, match=r"fourbar.toml, \[loop_reference\]"):
        ClosedLoopModel(robot, build_in_memory(robot))


def test_payload_on_a_passive_link_is_projected_like_the_link():
    """A payload frame fixed on the rocker (a passive link) at the rocker's own frame: its parameters
    act exactly as the same values added to the rocker's."""
    text = fourbar_text().replace("[[loops]]", "[[frames]]\nj = 4\nant = 3\nsigma = 2\nalpha = 0\nd = 0\ntheta = 0\n"
                                                "r = 0\n[[loops]]").replace('drive = ["IA"', 'payload = 4\ndrive = ["IA"')
    text = text.replace("q4 = ", "q5 = ")  # the cut joint is now frame 5 (after the 4 frames)
    robot = parse_robot_text(text, file="fourbar_payload.toml")
    model = ClosedLoopModel(robot, build_in_memory(robot))
    rng = np.random.default_rng(5)
    q = rng.uniform(-math.pi, math.pi, (20, 1))
    dq, ddq = rng.normal(0, 2, (20, 1)), rng.normal(0, 5, (20, 1))
    chi = rng.uniform(-1, 1, len(model.STANDARD_NAMES))
    pay = rng.uniform(-1, 1, 10)
    merged = chi.copy()
    for k, name in enumerate(model.PAYLOAD_NAMES):
        merged[model.STANDARD_NAMES.index(name.replace("4", "3"))] += pay[k]
    np.testing.assert_allclose(model.torque(q, dq, ddq, chi, pay), model.torque(q, dq, ddq, merged), atol=1e-9)
