"""The regressor of a model whose friction columns are replaced by a law's (``LawSplicedModel``: the declared laws
of ``identify``, the diagnosis loop's chosen laws and offsets, nested) column by column against the wrapped
model's regressor and the laws' own columns, on the SCARA."""
from __future__ import annotations

import numpy as np

import symoro_gen
from symoro_gen.description.friction_law import FrictionLaw
from symoro_gen.identification.friction_law import JointColumns, LawDeclaredModel, LawSplicedModel


def _offset(v: np.ndarray) -> np.ndarray:
    return np.ones((v.size, 1))


def test_spliced_columns_are_the_kept_columns_then_each_laws_on_its_joint_only():
    base = symoro_gen.load_model("scara")
    rng = np.random.default_rng(5)
    N, n = 300, base.N_JOINTS
    q, dq, ddq = rng.uniform(-1, 1, (N, n)), rng.uniform(-0.5, 0.5, (N, n)), rng.uniform(-2, 2, (N, n))
    laws = [(1, FrictionLaw(2, "stribeck", 0.1)), (0, FrictionLaw(1, "tanh", 0.02))]
    declared = LawDeclaredModel(base, laws)
    nested = LawSplicedModel(declared, [JointColumns(3, ("OFF4x",), _offset), JointColumns(2, (), _offset)])
    inner = np.asarray(base.regressor(q, dq, ddq))
    for model in (declared, nested):
        R = model.regressor(q, dq, ddq)
        assert R.shape == (N, n, len(model.BASE_NAMES)) and R.flags.c_contiguous
        names = list(model.BASE_NAMES)
        for nm in names:
            if nm in base.BASE_NAMES and nm not in ("FS1", "FV1", "FS2", "FV2"):
                np.testing.assert_array_equal(R[:, :, names.index(nm)], inner[:, :, list(base.BASE_NAMES).index(nm)])
        for j, lw in laws:
            cols = np.asarray(lw.columns(dq[:, j], scale=lw.scale))
            for i, nm in enumerate(lw.names()):
                k = names.index(nm)
                np.testing.assert_array_equal(R[:, j, k], cols[:, i])
                assert not np.any(np.delete(R[:, :, k], j, axis=1))          # the other joints' rows: 0
        # one sample: the same row as in a batch
        np.testing.assert_array_equal(model.regressor(q[7], dq[7], ddq[7]), R[7])
    R = nested.regressor(q, dq, ddq)
    k = list(nested.BASE_NAMES).index("OFF4x")
    assert np.all(R[:, 3, k] == 1.0) and not np.any(np.delete(R[:, :, k], 3, axis=1))
    assert "FS2" in declared.BASE_NAMES and "FSS2" in declared.BASE_NAMES    # a Stribeck law names its FS2 anew
