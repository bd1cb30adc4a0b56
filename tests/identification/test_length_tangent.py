"""The torque field ``d tau / d L`` of a link length that ``identify --geometry length``'s Gauss-Newton column
assembles (:func:`symoro_gen.identification.geometry.length_torque_field`): the generated package's emitted
derivative at the file's geometry equals the central difference of the numeric Newton-Euler model it replaces;
loaded recordings keep the central difference with the payload (the emitted derivative has no payload columns)."""
from __future__ import annotations

import dataclasses
import functools

import numpy as np

import symoro_gen
import symoro_gen.identification.geometry as geometry
from symoro_gen.description import load_robot
from symoro_gen.observations.assembly import AssemblyOptions
from symoro_gen.preprocessing.trajectory import Trajectory
from symoro_gen.simulate import fourier_trajectory


@functools.cache
def _case(name: str):
    robot, model = load_robot(name), symoro_gen.load_model(name)
    rng = np.random.default_rng(4)
    t, q, dq, ddq = fourier_trajectory(model.N_JOINTS, 4.0, 1.0 / 200.0, rng, base_frequency_hz=0.5)
    tr = Trajectory(t=t, q=q, tau=rng.standard_normal(q.shape), source="scara length field")
    chi = rng.standard_normal(len(robot.standard_names))
    lengths = tuple((v.frame, v.field) for v in geometry.length_identifiability(robot, model=model) if v.visible)
    return robot, model, tr, chi, lengths


def test_emitted_field_is_the_central_difference(monkeypatch):
    """At the file's geometry, per visible length: the emitted field equals the central difference of the numeric
    Newton-Euler torque to 1e-6 of its largest value, is 0 on the edge samples, and is not 0 elsewhere."""
    robot, model, tr, chi, lengths = _case("scara")
    assert lengths
    opts = AssemblyOptions()
    emitted = [geometry.length_torque_field(model, robot, [tr], opts, lengths, np.zeros(len(lengths)), i, chi)[0]
               for i in range(len(lengths))]
    monkeypatch.setattr(geometry, "emitted_length_column", lambda *args, **kwargs: None)
    for i, (f, fld) in enumerate(lengths):
        fd = geometry.length_torque_field(model, robot, [tr], opts, lengths, np.zeros(len(lengths)), i, chi)[0]
        scale = float(np.abs(fd).max())
        assert scale > 0, (f, fld)
        assert float(np.abs(emitted[i] - fd).max()) <= 1e-6 * scale, (f, fld)
        assert np.any(emitted[i] != fd)   # two computations: the analytic derivative and the difference
        assert not np.any(emitted[i][0]) and not np.any(emitted[i][-1])


def test_loaded_recordings_keep_the_payload():
    """A loaded recording of the RX-90 (whose robot file has a payload frame): with a zero payload the field is the
    unloaded (emitted) one; with a payload it differs (the payload's torque depends on the lengths too, which the
    emitted derivative would leave out)."""
    robot, model, tr, chi, lengths = _case("rx90")
    assert robot.payload_names
    opts = AssemblyOptions()
    zero = np.zeros(len(lengths))
    free = geometry.length_torque_field(model, robot, [tr], opts, lengths, zero, 0, chi)[0]
    loaded = dataclasses.replace(tr, loaded=True)
    pay0 = np.zeros(len(robot.payload_names))
    same = geometry.length_torque_field(model, robot, [loaded], opts, lengths, zero, 0, chi, pay0)[0]
    assert float(np.abs(same - free).max()) <= 1e-6 * float(np.abs(free).max())
    pay = np.random.default_rng(9).uniform(0.1, 1.0, len(robot.payload_names))
    heavy = geometry.length_torque_field(model, robot, [loaded], opts, lengths, zero, 0, chi, pay)[0]
    assert float(np.abs(heavy - free).max()) > 1e-3 * float(np.abs(free).max())
