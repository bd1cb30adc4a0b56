"""Identification on the real KUKA LWR4+ recordings (FloBaRoID, ../shared/data): files 1 and 3 for
identification, file 2 for validation, as the issue asks. Skipped when the data are absent.

The recordings are of another LWR4+ unit than the paper's, without payload, so only what should
carry over is checked: the two best identified gravity parameters against Table II of the LWR4
paper (MY2R = 3.51, MY4R = -1.38, %sigma 0.23 and 0.21), the torque reconstruction on the joints the
paper reconstructs best (Table III: joint 2 0.018, joint 4 0.024), and the streamed system giving the
same estimate as the whole one.
"""
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.realdata

LWR4_DIR = Path("kuka_lwr4_flobaroid") / "data" / "KUKA" / "HW"


@pytest.fixture(scope="module")
def lwr4_real(shared_data):
    import symoro_gen
    from symoro_gen.identification.assemble import build_observation
    from symoro_gen.preprocessing.readers import load_trajectory

    paths = [shared_data / LWR4_DIR / f"measurements_{i}.npz" for i in (1, 2, 3)]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        pytest.skip(f"LWR4 recordings not found: {missing}")
    model = symoro_gen.load_model("lwr4")
    trajs = [load_trajectory(p, n_joints=7) for p in paths]
    ident = build_observation(model, [trajs[0], trajs[2]])
    valid = build_observation(model, [trajs[1]])
    return model, trajs, ident, valid


def test_wls_gravity_parameters_agree_with_table_ii(lwr4_real):
    from symoro_gen.identification import fit_wls

    _, _, ident, valid = lwr4_real
    res = fit_wls(ident)
    for name, paper in (("MY2R", 3.51), ("MY4R", -1.38)):
        i = res.index(name)
        assert abs(res.values[i] - paper) < 0.1 * abs(paper), (name, res.values[i], paper)
        assert res.rel_std_pct[i] < 1.0
    # cross-validation on file 2 (Table III): the well-modelled joints 2 and 4
    e = res.rel_err_on(valid)
    assert e.shape == (7,) and e[1] < 0.05 and e[3] < 0.05, e
    text = res.summary()
    assert "MY2R" in text and "joint 7:" in text


def test_streamed_identification_equals_whole_system(lwr4_real):
    from symoro_gen.identification import accumulate, fit_ols, fit_wls
    from symoro_gen.identification.assemble import iter_observation_chunks

    model, trajs, ident, _ = lwr4_real
    acc = accumulate(iter_observation_chunks(model, [trajs[0], trajs[2]], chunk_samples=1000))
    assert acc.n_rows == ident.Y.size
    for fit in (fit_ols, fit_wls):
        a, b = fit(acc), fit(ident)
        np.testing.assert_allclose(a.values, b.values, rtol=1e-8, atol=1e-8 * np.abs(b.values).max())
        np.testing.assert_allclose(a.std, b.std, rtol=1e-8)
        np.testing.assert_allclose(a.rel_err, b.rel_err, rtol=1e-8)


def test_plain_tls_on_real_data_warns(lwr4_real):
    """The real W is far from the i.i.d.-errors model of eq. 14: plain TLS says it is unreliable."""
    from symoro_gen.identification import fit_tls

    _, _, ident, _ = lwr4_real
    assert any("TLS residual is" in w for w in fit_tls(ident).warnings)
