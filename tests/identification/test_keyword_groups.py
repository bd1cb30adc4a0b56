"""The typed keyword groups of the closed-loop methods and of the payload fit: every keyword of the group is
accepted with its default, a misspelt one is the TypeError Python gives for an unexpected keyword."""
from __future__ import annotations

import typing

import pytest

from symoro_gen.identification.estimators import Options, Tolerances, tolerance_keywords
from symoro_gen.identification.iv import MAX_ITER, TOL, LoopOptions, LoopSettings
from symoro_gen.simulate.closed_loop import FRICTION_EPS
from symoro_gen.simulate.recording import RecordingOptions, RecordingSettings


def test_loop_settings_defaults_and_keywords():
    lp = LoopSettings.of("identify_didim", {})
    assert (lp.max_iter, lp.tol, lp.friction_eps, lp.start, lp.gains) == (MAX_ITER, TOL, FRICTION_EPS, None, None)
    assert LoopSettings.of("iterate", {"max_iter": 3, "bandwidth_hz": 5.0}).max_iter == 3
    with pytest.raises(TypeError, match="identify_didim\\(\\) got an unexpected keyword argument 'max_iters'"):
        LoopSettings.of("identify_didim", {"max_iters": 3})


def test_tolerance_keywords():
    assert tolerance_keywords("fit_with_known_payload", {"rank_tol": 1e-9}) == {"rank_tol": 1e-9}
    with pytest.raises(TypeError, match="unexpected keyword argument 'rank_tl'"):
        tolerance_keywords("fit_with_known_payload", {"rank_tl": 1e-9})


@pytest.mark.parametrize("group, settings", [(LoopOptions, LoopSettings), (RecordingOptions, RecordingSettings)])
def test_each_typed_keyword_group_names_the_fields_of_its_settings(group, settings):
    """The TypedDict that types the keywords and the dataclass that holds their defaults name the same fields."""
    assert set(typing.get_type_hints(group)) == set(settings.__dataclass_fields__)


def test_tolerances_are_fields_of_the_estimators_options():
    assert set(typing.get_type_hints(Tolerances)) <= set(Options.__dataclass_fields__)
