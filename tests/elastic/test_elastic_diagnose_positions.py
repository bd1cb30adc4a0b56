"""``diagnose --positions motor``: the same meaning as identify's (link positions ``q = positions - tau/K`` on the
declared elastic joints, LWR4 paper eq. 17), through the one function
:func:`symoro_gen.identification.elastic.link_side`, on every recording the loop sees."""
from __future__ import annotations

import importlib

import numpy as np
import pytest

from symoro_gen.errors import OptionError
from symoro_gen.preprocessing.trajectory import Trajectory
from tests.elastic.pinsim import JOINT, K_TRUE, elastic_log, lwr4_elastic_file

wd = importlib.import_module("symoro_gen.workflows.diagnose")  # the module (the package exports the function)


class _Seen(Exception):
    """Raised by the stand-in loop with what it was given."""


def _capture(monkeypatch) -> dict:
    seen: dict = {}

    def fake_loop(model, ident, settings, validation=None, loaded=None, **kw):
        seen.update(ident=ident, validation=validation, settings=settings)
        raise _Seen

    monkeypatch.setattr(wd, "run_loop", fake_loop)
    return seen


def _trajs(seconds=4.0):
    logs = [elastic_log(s, seconds=seconds) for s in (1, 2)]
    return logs, [Trajectory(t=lg.t, q=lg.theta, tau=lg.tau, source=f"motor{i}.csv") for i, lg in enumerate(logs)]


def test_diagnose_motor_positions_are_the_link_side(monkeypatch, tmp_path):
    """Every recording the loop gets (identification and validation) has q = positions - tau/K on the declared
    joint only; its positions are then the simulated link positions up to the deflection's damping part."""
    f = lwr4_elastic_file(tmp_path / "lwr4e.toml", K_TRUE)
    logs, trs = _trajs()
    seen = _capture(monkeypatch)
    with pytest.raises(_Seen):
        wd.diagnose(str(f), [trs[0]], validate=[trs[1]], positions="motor")
    for got, tr, lg in zip((seen["ident"][0], seen["validation"][0]), trs, logs):
        expect = tr.q.copy()
        expect[:, JOINT] -= tr.tau[:, JOINT] / K_TRUE
        np.testing.assert_allclose(got.q, expect, rtol=0, atol=1e-12)
        assert got.dq is None and got.ddq is None
        # against the simulated truth: the static correction leaves the damped part D/K ddelta/dt (< 0.1 mrad)
        # and the torque noise / K, far below the deflection itself (several mrad)
        err = np.abs(got.q[:, JOINT] - lg.q_link[:, JOINT]).max()
        assert err < 0.05 * np.abs(lg.delta[:, JOINT]).max(), err
    assert JOINT in seen["settings"].declared_elastic
    # without the option the positions are used as read
    with pytest.raises(_Seen):
        wd.diagnose(str(f), [trs[0]], validate=[trs[1]])
    np.testing.assert_array_equal(seen["ident"][0].q, trs[0].q)


def test_diagnose_motor_positions_errors(tmp_path):
    with pytest.raises(OptionError, match="--positions 'rotor'"):
        wd.DiagnoseOptions(positions="rotor")
    _, trs = _trajs(seconds=2.0)
    with pytest.raises(OptionError, match=r"--positions motor.*lwr4.*no elastic joint"):
        wd.diagnose("lwr4", [trs[0]], positions="motor")


def test_diagnose_command_line_positions():
    from symoro_gen.cli import build_parser
    from symoro_gen.commands.diagnose import options_from_args

    args = build_parser().parse_args(["diagnose", "lwr4", "x.csv", "--positions", "motor"])
    assert options_from_args(args).positions == "motor"
    args = build_parser().parse_args(["diagnose", "lwr4", "x.csv"])
    assert options_from_args(args).positions == "link"
