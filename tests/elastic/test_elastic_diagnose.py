"""The loop's elasticity candidate is not offered for joints the robot file declares elastic."""
import pytest

from symoro_gen.diagnostics import DiagnoseSettings, diagnose
from tests.diagnostics.simdata import recording


@pytest.mark.slow
def test_no_elasticity_candidate_on_declared_elastic_joints():
    model, tr = recording("scara", 3, "elasticity", 1, K=300.0)
    kw = dict(candidates=("elasticity", "time_delay"), friction_laws=False, composed=False, structure=False,
              unexplained=False, stability=False, max_effects=1)
    free = diagnose(model, tr, DiagnoseSettings(**kw))
    declared = diagnose(model, tr, DiagnoseSettings(**kw, declared_elastic=(0, 1)))
    el = lambda rep: {c.joint for c in rep.tried if c.kind == "elasticity"}  # noqa: E731
    assert {0, 1} <= el(free)            # offered on every joint without a declaration
    assert not el(declared) & {0, 1}     # not on the declared ones
    assert el(declared) == el(free) - {0, 1}
    assert any(c.kind == "time_delay" and c.joint in (0, 1) for c in declared.tried)  # the others stay
