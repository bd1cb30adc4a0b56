"""The paired held-out test of a change of the model (the acceptance of the friction-law stage's notes): two
models whose acceptance residuals agree to rounding are the same model (z 0, p 0.5, gain 0), not the ratio of
two rounding errors, which came out anywhere in [-3, 1] with the BLAS and library versions; a real change keeps
its statistic."""
from __future__ import annotations

import numpy as np
import scipy.stats as sst

from symoro_gen.diagnostics.core import _paired_held_out


def test_a_change_at_rounding_level_is_no_change():
    rng = np.random.default_rng(0)
    e_old = rng.normal(size=400)
    groups = np.zeros(400, dtype=int)
    for scale in (1e-14, 1e-12, 1e-10):
        e_new = e_old + scale * rng.normal(size=400)
        assert _paired_held_out(e_old, e_new, groups) == (0.0, 0.5, 0.0)


def test_a_real_change_keeps_its_statistic():
    rng = np.random.default_rng(1)
    e_old = rng.normal(size=400) + 0.5 * np.sign(np.sin(np.linspace(0, 20, 400)))
    groups = np.zeros(400, dtype=int)
    e_new = e_old - 0.5 * np.sign(np.sin(np.linspace(0, 20, 400)))    # the change removes a structured error
    z, p, gain = _paired_held_out(e_old, e_new, groups)
    assert z > 3 and p == sst.norm.sf(z)
    assert np.isclose(gain, 1.0 - np.linalg.norm(e_new) / np.linalg.norm(e_old), rtol=1e-12) and gain > 0.05
    z2, _, gain2 = _paired_held_out(e_new, e_old, groups)             # the reverse change is worse
    assert z2 < -3 and gain2 < 0
