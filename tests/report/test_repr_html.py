"""Result objects show as HTML tables in Jupyter (``_repr_html_``): every parameter with value, 2σ and
%σ, gains, relative error norms, warnings; well-formed and escaped. No matplotlib needed."""
import dataclasses
from html.parser import HTMLParser

import numpy as np
import pytest

from symoro_gen.identification import DriveGainsResult, Gains, ObservationSystem, fit_ols, fit_wls

VOID = {"br", "img", "meta", "hr", "input", "link"}


class _Tables(HTMLParser):
    """Checks the tags balance; collects tables as lists of (row class, cells)."""

    def __init__(self):
        super().__init__()
        self.stack, self.tables, self.items = [], [], []
        self._cell = None
        self._li = None

    def handle_starttag(self, tag, attrs):
        if tag not in VOID:
            self.stack.append(tag)
        if tag == "table":
            self.tables.append([])
        elif tag == "tr":
            self.tables[-1].append((dict(attrs).get("class", ""), []))
        elif tag in ("td", "th"):
            self._cell = ""
        elif tag == "li":
            self._li = ""

    def handle_endtag(self, tag):
        assert self.stack and self.stack[-1] == tag, f"</{tag}> closes <{self.stack[-1] if self.stack else None}>"
        self.stack.pop()
        if tag in ("td", "th"):
            self.tables[-1][-1][1].append(self._cell)
            self._cell = None
        elif tag == "li":
            self.items.append(self._li)
            self._li = None

    def handle_data(self, data):
        if self._cell is not None:
            self._cell += data
        if self._li is not None:
            self._li += data


def parse(html: str) -> _Tables:
    p = _Tables()
    p.feed(html)
    p.close()
    assert not p.stack, f"unclosed tags {p.stack}"
    return p


NAMES = ("ZZ1R", "FV1", "MX2", "a<b&c", "TINY3")


@pytest.fixture(scope="module")
def result():
    """WLS on a simulated system with known truth; the last column is almost zero (poorly identified)."""
    rng = np.random.default_rng(7)
    n_per, n_j = 120, 3
    W = rng.normal(size=(n_per * n_j, len(NAMES)))
    W[:, -1] *= 1e-4
    chi = np.array([2.0, 0.5, -1.2, 0.8, 0.3])
    joint = np.repeat(np.arange(n_j), n_per)
    Y = W @ chi + rng.normal(0, 0.05, W.shape[0])
    return fit_wls(ObservationSystem(W, Y, NAMES, joint))


def _param_rows(tables):
    t = next(t for t in tables if t[0][1][:4] == ["Parameter", "Value", "2σ", "%σ"])
    return t[1:]


def test_identification_result_html_lists_every_parameter_with_its_statistics(result):
    html = result._repr_html_()
    p = parse(html)
    rows = _param_rows(p.tables)
    assert [r[1][0] for r in rows] == list(NAMES)
    for (cls, (_name, v, s2, pct, note)), val, std in zip(rows, result.values, result.std):
        assert float(v) == pytest.approx(val, rel=6e-4)
        assert float(s2) == pytest.approx(2 * std, rel=6e-4)
        expect_pct = 100 * std / abs(val)
        assert float(pct) == pytest.approx(expect_pct, abs=0.006)
        assert (cls == "poor") == (expect_pct > 30) == (note == "poorly identified")
    assert rows[-1][0] == "poor" and rows[0][0] == ""
    # relative error norms per joint, as fitted
    err = next(t for t in p.tables if t[0][1][0] == "Data")
    assert err[0][1][1:] == ["joint 1", "joint 2", "joint 3"]
    assert [float(x) for x in err[1][1][1:]] == pytest.approx(result.rel_err, abs=6e-5)
    # names are escaped, never markup
    assert "a<b&c" not in html and "a&lt;b&amp;c" in html
    # warnings numbered, as in summary()
    assert result.warnings and p.items == list(result.warnings)


def test_known_and_cancelled_parameters_and_gains_are_shown(result):
    g = Gains((0, 1, 2), [1.02, 0.99, 1.05], [0.001, 0.002, 0.4], [0.098, 0.2, 38.1])
    r = dataclasses.replace(result, fixed=(("M8", 4.6136),), eliminated=("XY2",), gains=g)
    p = parse(r._repr_html_())
    gains = next(t for t in p.tables if t[0][1][0] == "Gain")
    assert [c[:3] for _, c in gains[1:]] == [["g1", "1", "1.02"], ["g2", "2", "0.99"], ["g3", "3", "1.05"]]
    assert [float(c[3]) for _, c in gains[1:]] == pytest.approx([0.002, 0.004, 0.8])
    assert [cls for cls, _ in gains[1:]] == ["", "", "poor"]
    rows = {c[0]: c for _, c in _param_rows(p.tables)}
    assert rows["M8"] == ["M8", "4.6136", "-", "-", "known"]
    assert rows["XY2"][1] == "0" and rows["XY2"][4].startswith("cancelled")


def test_gains_and_drive_gains_html(result):
    g = Gains((0, 3), [1.1, 0.95], [0.011, 0.0019], [1.0, 0.2])
    p = parse(g._repr_html_())
    assert [c for _, c in p.tables[0]] == [["Gain", "Joint", "Value", "2σ", "%σ"],
                                           ["g1", "1", "1.1", "0.022", "1.00"],
                                           ["g4", "4", "0.95", "0.0038", "0.20"]]
    r2 = fit_ols(ObservationSystem(np.eye(4)[:, :2] + 1.0, np.arange(4.0), ("A", "B"), np.zeros(4, int)))
    dg = DriveGainsResult(g, (result, r2), ("joint 4: drive gain poorly identified",))
    p = parse(dg._repr_html_())
    t = p.tables[0]
    assert t[0][1] == ["Gain", "Joint", "Value", "2σ", "%σ", "cond(W)"]
    assert float(t[1][1][5]) == pytest.approx(result.cond, rel=6e-4)
    assert float(t[2][1][5]) == pytest.approx(r2.cond, rel=6e-4)
    assert p.items == ["joint 4: drive gain poorly identified"]
