"""export-mjcf of a joint with a declared friction law: MuJoCo's frictionloss (Coulomb level) and damping
(viscous, or the least-squares linear fit of a power law), the approximation stated in the file."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from symoro_gen.description.friction_law import FrictionLaw
from symoro_gen.description.mjcf_export import export_mjcf
from symoro_gen.loader import model_for
from symoro_gen.simulate import random_physical_parameters

mujoco = pytest.importorskip("mujoco", reason="the 'mjcf' extra (mujoco wheel) is not installed")


def _exported(kind: str, scale: float):
    robot, _ = model_for("scara")
    robot = dataclasses.replace(robot, friction_laws={2: FrictionLaw(2, kind, scale)})
    chi = np.asarray(random_physical_parameters(robot, np.random.default_rng(3)))
    vals = dict(zip(robot.standard_names, chi))
    text = export_mjcf(robot, chi)
    return robot, vals, text, mujoco.MjModel.from_xml_string(text)


@pytest.mark.parametrize("kind, scale", [("stribeck", 0.05), ("tanh", 0.02)])
def test_coulomb_level_and_viscous_with_the_approximation_stated(kind, scale):
    _, vals, text, m = _exported(kind, scale)
    assert m.dof_frictionloss[1] == pytest.approx(vals["FS2"], rel=1e-9)
    assert m.dof_damping[1] == pytest.approx(vals["FV2"], rel=1e-9)
    assert f"MuJoCo has no {kind} law" in text
    assert m.dof_frictionloss[0] == pytest.approx(vals["FS1"], rel=1e-9)     # joints without a law unchanged


def test_power_law_damping_is_the_least_squares_linear_fit():
    """The damping equals the slope through the origin that best fits FV |dq|^delta on a fine grid of
    [0, dq_max] (1 rad/s: the SCARA file has no dq_max), computed here numerically."""
    delta = 0.5
    _, vals, text, m = _exported("power", delta)
    v = np.linspace(0.0, 1.0, 200001)
    f = vals["FV2"] * v ** delta
    slope = float(v @ f / (v @ v))
    assert m.dof_damping[1] == pytest.approx(slope, rel=1e-4)
    assert m.dof_frictionloss[1] == pytest.approx(vals["FS2"], rel=1e-9)
    assert "no power law of the speed" in text


def test_export_takes_the_identified_scale_from_a_result():
    """``with_identified_laws``: the scales an identify result fitted replace the declared ones (a law the
    result did not fit keeps its declared scale), and the MJCF comment names the identified one."""
    from symoro_gen.description.friction_law import with_identified_laws

    robot, _ = model_for("scara")
    robot = dataclasses.replace(robot, friction_laws={2: FrictionLaw(2, "stribeck", 0.08),
                                                      4: FrictionLaw(4, "tanh", 0.01)})
    doc = {"friction_laws": [{"frame": 2, "kind": "stribeck", "scale": 0.0499, "fitted": True},
                             {"frame": 4, "kind": "tanh", "scale": None, "fitted": False}]}
    new = with_identified_laws(robot, doc)
    assert new.friction_laws[2].scale == 0.0499 and new.friction_laws[4].scale == 0.01
    assert with_identified_laws(robot, {}) is robot
    chi = np.asarray(random_physical_parameters(robot, np.random.default_rng(3)))
    assert "stribeck(vs=0.0499)" in export_mjcf(new, chi)
