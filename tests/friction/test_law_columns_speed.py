"""The friction-law stage's shortcuts give the numbers of the definitions, exactly.

* The law columns the searches build from full-rate pieces kept per velocity array (``sign(v)``, ``|v|``,
  ``tanh(v / s)``, ``exp(-(v / vs)^2)``) equal, bit for bit, the columns of the one definition of the laws
  (:func:`symoro_gen.description.friction_law.coulomb_columns`, ``viscous_columns``; the pre-sliding laws of
  :mod:`symoro_gen.diagnostics.friction`), whatever was evaluated before, on which velocity array, with
  nothing kept.
* The friction-law splice (:class:`symoro_gen.identification.friction_law.LawSplicedModel`), which copies the
  kept columns by runs and writes a generated model's regressor into a buffer it keeps, equals the wrapped
  model's regressor with the replaced columns deleted and the law's columns appended on its joint's rows;
  what one call returned is not changed by the next ones.
"""
from __future__ import annotations

import threading

import numpy as np
import pytest

import symoro_gen
from symoro_gen.description.friction_law import coulomb_columns, viscous_columns
from symoro_gen.diagnostics import friction
from symoro_gen.diagnostics.friction import FrictionChoice, LawFit, LawModel, dahl_column, lugre_columns
from symoro_gen.identification.friction_law import LawSplicedModel

LAWS = [
    ("sign", None, "linear", None, None),
    ("sign", None, "linear", None, 0.02),
    ("sign", None, "power", 0.5, 0.02),
    ("tanh", 0.02, "linear", None, None),
    ("tanh", 0.05, "power", 1.5, None),
    ("stribeck", 0.1, "linear", None, None),
    ("stribeck", 0.1, "linear", None, 0.02),     # smoothed sign: tanh(v / 0.02), shared with tanh(v=0.02)
    ("stribeck", 0.3, "power", 0.65, 0.02),
    ("dahl", 5.0, "linear", None, None),
    ("lugre", (0.1, 5.0, 0.3), "power", 0.8, None),
]


def _definition(args: tuple, v: np.ndarray) -> np.ndarray:
    """The columns from the definitions, written out here (not through the friction module's shortcuts)."""
    claw, cpar, vlaw, vpar, smooth = args
    if claw == "dahl":
        c = dahl_column(v, float(cpar))[:, None]
    elif claw == "lugre":
        c = lugre_columns(v, *cpar)
    else:
        c = coulomb_columns(claw, v, cpar, smooth)
    return np.hstack([c, viscous_columns(vlaw, v, vpar)])


def _velocity(seed: int, n: int = 3000) -> np.ndarray:
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 6.0, n)
    v = 0.4 * np.sin(2.1 * t) + 0.05 * rng.standard_normal(n)
    v[1000:1300] = 0.0                                     # a rest segment: the sliding velocity is 0 there
    v.setflags(write=False)                                # as the friction stage's hook passes it: pieces kept
    return v


@pytest.mark.parametrize("keep", [True, False])
def test_law_columns_from_kept_pieces_equal_the_definitions_bit_for_bit(monkeypatch, keep):
    if not keep:
        monkeypatch.setattr(friction, "FULL_RATE_PIECES_BYTES", 0)
    friction.clear_law_columns()
    va, vb = _velocity(0), _velocity(1)
    for _ in range(2):                                     # the second pass reads every piece kept
        for v in (va, vb, va):
            for args in LAWS:
                want = _definition(args, v)
                got = friction._law_values(args, v, want.shape[1])
                assert got.shape == want.shape
                assert np.array_equal(got, want), args
    if keep:
        assert friction._PIECES._bytes > 0
    # another velocity array of the same length: its own pieces, its own numbers
    vc = va.copy()
    vc[:10] += 1.0
    vc.setflags(write=False)
    for args in LAWS:
        assert np.array_equal(friction._law_values(args, vc, _definition(args, vc).shape[1]), _definition(args, vc))
    # a writeable array changed in place between two calls: nothing of its first values is used again
    vw = _velocity(3).copy()
    for scale in (1.0, 0.5):
        vw *= scale
        for args in LAWS:
            assert np.array_equal(friction._law_values(args, vw, _definition(args, vw).shape[1]),
                                  _definition(args, vw))
    friction.clear_law_columns()


def test_kept_pieces_are_bounded():
    """The pieces kept never exceed their budget (least recently used dropped)."""
    friction.clear_law_columns()
    v = _velocity(2, 20000)
    for s in np.geomspace(1e-3, 1.0, 400):
        friction._law_values(("tanh", float(s), "linear", None, None), v, 2)
        assert friction._PIECES._bytes <= friction.FULL_RATE_PIECES_BYTES
    assert sum(x[2] for x in friction._PIECES._d.values()) == friction._PIECES._bytes
    friction.clear_law_columns()
    assert friction._PIECES._bytes == 0


def _reference_splice(model, choices, offsets, q, dq, ddq):
    """The spliced regressor by deleting and appending whole columns (no runs, no kept buffer)."""
    R = np.asarray(model.regressor(q, dq, ddq), float).copy()
    names = list(model.BASE_NAMES)
    drop = [names.index(nm) for ch in choices for nm in (f"FS{ch.joint + 1}", f"FV{ch.joint + 1}") if nm in names]
    parts = [np.delete(R, drop, axis=2)]
    for ch in choices:
        C = np.zeros(R.shape[:2] + (len(ch.names()),))
        C[:, ch.joint, :] = _definition((ch.coulomb.law, ch.coulomb.shape, ch.viscous.law, ch.viscous.param,
                                         ch.coulomb.smooth), dq[:, ch.joint])
        parts.append(C)
    for j in offsets:
        C = np.zeros(R.shape[:2] + (1,))
        C[:, j, 0] = 1.0
        parts.append(C)
    return np.concatenate(parts, axis=2)


class _NoOut:
    """A model whose regressor takes no ``out`` (the splice allocates its output)."""

    def __init__(self, model):
        self._m = model
        self.BASE_NAMES = model.BASE_NAMES
        self.N_JOINTS = model.N_JOINTS

    def regressor(self, q, dq, ddq):
        return self._m.regressor(q, dq, ddq)


@pytest.mark.parametrize("wrap", [False, True])
def test_law_splice_equals_deleting_and_appending_columns(wrap):
    base = symoro_gen.load_model("rx90")
    model = _NoOut(base) if wrap else base
    choices = [FrictionChoice(1, LawFit("stribeck", 0.05, 0.1, 0.01), LawFit("linear", None, 0.1), ()),
               FrictionChoice(3, LawFit("tanh", 0.02, 0.1), LawFit("power", 0.5, 0.1), ())]
    lm = LawModel(model, choices, [5])
    assert isinstance(lm, LawSplicedModel) and lm._into is (not wrap)
    rng = np.random.default_rng(4)
    kept = []
    for N in (700, 3, 1200, 700, 1):          # a larger batch after a smaller one, and back
        q, dq, ddq = (rng.standard_normal((N, 6)) for _ in range(3))
        got = lm.regressor(q, dq, ddq)
        want = _reference_splice(model, choices, [5], q, dq, ddq)
        assert got.shape == want.shape == (N, 6, len(lm.BASE_NAMES))
        assert np.array_equal(got, want)
        kept.append((got, got.copy()))
        assert np.array_equal(lm.regressor(q[0], dq[0], ddq[0]), want[0])
    for got, copy in kept:                    # later calls did not write into what earlier ones returned
        assert np.array_equal(got, copy)


def test_law_splice_buffers_are_per_thread():
    """Threads evaluating the same spliced model at once each get their own numbers."""
    model = symoro_gen.load_model("rx90")
    lm = LawModel(model, [FrictionChoice(2, LawFit("tanh", 0.03, 0.1), LawFit("linear", None, 0.1), ())])
    rng = np.random.default_rng(5)
    states = [tuple(rng.standard_normal((500, 6)) for _ in range(3)) for _ in range(4)]
    want = [_reference_splice(model, lm.choices, [], *s) for s in states]
    errors: list[str] = []

    def work(k: int) -> None:
        for _ in range(20):
            if not np.array_equal(lm.regressor(*states[k]), want[k]):
                errors.append(f"thread {k}")

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
