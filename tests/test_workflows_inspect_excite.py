"""The ``inspect`` and ``excite`` workflows against their commands and the golden outputs an earlier main wrote
(tests/golden): ``to_dict()`` is exactly the command's JSON, ``summary()`` its text; options named and checked."""
from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.errors import OptionError
from symoro_gen.excite import ExcitationError
from symoro_gen.loader import model_for
from symoro_gen.preprocessing import LogFormat, load_trajectory
from symoro_gen.workflows import SCHEMA_VERSION

from .golden.inputs import write_inputs
from .test_workflows import GOLDEN, _normalise_text, _same

#: the golden excite command (tests/golden/README.md), with the effort that was the default then
EXCITE_ARGS = ("--duration", "4", "--seed", "1", "--effort", "thorough", "--starts", "2", "--refine", "0",
               "--max-iter", "30")
#: keys the excite JSON gained since the golden file: the effort and the settings it resolved to
EXCITE_NEW = {"effort", "settings", "wall_time"}
#: keys the inspect JSON gained since the golden file: the time steps of each file as logged
INSPECT_NEW = {"steps"}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    return write_inputs(tmp_path_factory.mktemp("golden-inputs"))


# ---- inspect ----------------------------------------------------------------------------------------------
def test_inspect_command_matches_the_golden_output_and_the_api(cli, inputs, tmp_path):
    a, _ = inputs
    out = tmp_path / "inspect.json"
    r = cli("inspect", "scara", a, "--json", out)
    written = json.loads(out.read_text())
    _same({k: v for k, v in written.items() if k not in INSPECT_NEW}, json.loads((GOLDEN / "inspect.json").read_text()))
    assert [x["file"] for x in written["steps"]] == [x["file"] for x in written["data"]]
    assert list(written)[:3] == ["generator", "schema_version", "robot"] and list(written)[-1] == "provenance"
    assert written["generator"] == "symoro-gen inspect" and written["schema_version"] == SCHEMA_VERSION
    prov = written["provenance"]
    assert [Path(x["path"]).name for x in prov["inputs"]] == ["scara_a.csv"] and len(prov["inputs"][0]["sha256"]) == 64
    assert _normalise_text(r.out, a.parent) == _normalise_text((GOLDEN / "inspect.txt").read_text(), "/tmp/golden/in")
    res = symoro_gen.inspect("scara", a)
    assert isinstance(res, symoro_gen.InspectResults) and res.usable
    assert res.to_dict() == written                  # exactly the command's JSON
    assert res.summary() + "\n" == r.out             # exactly its text


def test_inspect_options_and_data_forms(inputs):
    a, _ = inputs
    with pytest.raises(OptionError, match="unknown option 'cutof'; did you mean 'cutoff'"):
        symoro_gen.inspect("scara", a, cutof=5.0)
    with pytest.raises(OptionError, match=r"--decimate 0"):
        symoro_gen.InspectOptions(decimate=0)
    with pytest.raises(OptionError, match="not both"):
        symoro_gen.inspect("scara", a, options=symoro_gen.InspectOptions(), cutoff=5.0)
    with pytest.raises(OptionError, match="no data"):
        symoro_gen.inspect("scara", [])
    ref = symoro_gen.inspect("scara", a, cutoff=8.0)
    tr = load_trajectory(a, n_joints=4)
    res = symoro_gen.inspect(model_for("scara")[0], (tr.t, tr.q, tr.tau), options=symoro_gen.InspectOptions(cutoff=8.0))
    assert res.inspection.cond == pytest.approx(ref.inspection.cond, rel=1e-12)
    assert res.inspection.rel_std_pct == pytest.approx(ref.inspection.rel_std_pct, rel=1e-10)
    assert [e.cutoff_hz for e in res.inspection.experiments] == [8.0]
    # a data format is an option like the others: the same file read as degrees is another recording
    deg = symoro_gen.inspect("scara", a, data_format=LogFormat(deg=True))
    assert deg.inspection.experiments[0].joints[0].q_range == pytest.approx(
        np.deg2rad(ref.inspection.experiments[0].joints[0].q_range), rel=1e-9)


def test_inspect_not_usable_exits_2_with_the_reason(cli, inputs, tmp_path):
    """A recording whose joint 1 stands still cannot identify that joint's parameters: the command exits 2 and
    prints why even under --quiet; the workflow returns ``usable == False`` with the same reason."""
    a, _ = inputs
    short = tmp_path / "still.csv"
    header, *rows = a.read_text().splitlines()
    col = header.split(",").index("q1")
    short.write_text("\n".join([header] + [",".join("0.3" if i == col else x for i, x in enumerate(r.split(",")))
                                           for r in rows]) + "\n")
    r = cli("--quiet", "inspect", "scara", short, rc=2)
    res = symoro_gen.inspect("scara", short)
    assert not res.usable and res.inspection.errors
    assert res.inspection.errors[0] in r.out


def test_inspect_report_and_figures(inputs, tmp_path):
    pytest.importorskip("matplotlib")
    a, _ = inputs
    res = symoro_gen.inspect("scara", a)
    figs = res.plot()
    assert len(figs) == 4 and all(hasattr(f, "savefig") for f in figs)  # one per joint of the one experiment
    page = res.report(tmp_path / "i.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and "Signals per joint" in page


# ---- excite -----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def excited(cli, tmp_path_factory):
    """The golden excite command (with the effort that was the default then) and the same design through the
    library: (stdout, written JSON, CSV path, ExciteResults)."""
    out = tmp_path_factory.mktemp("excite")
    r = cli("excite", "scara", "-o", out / "excite.csv", *EXCITE_ARGS, "--json", out / "excite.json")
    res = symoro_gen.excite("scara", duration=4, seed=1, effort="thorough", starts=2, refine=0, max_iter=30,
                            output=out / "api.csv")
    return r.out, json.loads((out / "excite.json").read_text()), out, res


def test_excite_command_matches_the_golden_output(excited):
    _, written, _, _ = excited
    golden = json.loads((GOLDEN / "excite.json").read_text())
    _same({k: v for k, v in written.items() if k not in EXCITE_NEW},
          {k: v for k, v in golden.items() if k not in EXCITE_NEW}, rtol=1e-6)
    assert written["generator"] == "symoro-gen excite" and written["schema_version"] == SCHEMA_VERSION
    assert written["effort"] == "thorough" and written["settings"]["starts"] == 2
    assert written["provenance"]["seeds"] == {"seed": 1}
    assert Path(written["provenance"]["inputs"][0]["path"]).name == "scara.toml"


def test_excite_api_is_the_command(excited):
    text, written, out, res = excited
    assert isinstance(res, symoro_gen.ExciteResults)
    d = res.to_dict()
    # the same design, the same JSON (the run's wall time and the provenance's options aside: the API wrote to
    # another CSV name, which the options do not hold, so the provenance matches as well)
    assert {k: v for k, v in d.items() if k != "wall_time"} == {k: v for k, v in written.items() if k != "wall_time"}
    assert (out / "api.csv").read_text() == (out / "excite.csv").read_text()
    lines, api_lines = text.splitlines(), res.summary().splitlines()
    assert lines[0].replace("excite.csv", "api.csv") == api_lines[0]
    assert lines[2:] == api_lines[2:] and lines[1].split("; ")[:2] == api_lines[1].split("; ")[:2]
    data = np.loadtxt(out / "excite.csv", delimiter=",", skiprows=1)
    assert np.allclose(data[:, 0], res.t) and np.allclose(data[:, 1:5], res.q)


def test_excite_options_are_named_and_checked():
    with pytest.raises(OptionError, match="unknown option 'harmonic'; did you mean 'harmonics'"):
        symoro_gen.excite("scara", harmonic=3)
    with pytest.raises(ExcitationError, match="--kind 'sine'"):
        symoro_gen.ExciteOptions(kind="sine")
    with pytest.raises(ExcitationError, match="--effort 'fast'"):
        symoro_gen.excite("scara", effort="fast")
    with pytest.raises(ExcitationError, match="whole number of periods"):
        symoro_gen.excite("scara", duration=4, base_frequency=0.3)
    with pytest.raises(OptionError, match="not both"):
        symoro_gen.excite("scara", options=symoro_gen.ExciteOptions(), seed=2)


def test_excite_in_memory_then_written(tmp_path):
    """Without ``output`` nothing is written; ``write_csv`` then writes the CSV the command would, and refuses to
    replace a file symoro-gen did not write."""
    res = symoro_gen.excite("scara", duration=2, harmonics=3, rate=50, starts=1, pool=1, max_iter=5, refine=0)
    assert "(not written" in res.summary().splitlines()[0] and not list(tmp_path.iterdir())
    p = res.write_csv(tmp_path / "t.csv")
    data = np.loadtxt(p, delimiter=",", skiprows=1)
    assert data.shape == (res.t.size, 1 + 3 * 4) and np.allclose(data[:, 9:13], res.ddq)
    foreign = tmp_path / "mine.csv"
    foreign.write_text("t,q1\n0,0\n")
    from symoro_gen.errors import OutputError
    with pytest.raises(OutputError, match=r"mine\.csv"):
        res.write_csv(foreign)
    assert foreign.read_text() == "t,q1\n0,0\n"
    if importlib.util.find_spec("matplotlib"):
        figs = res.plot()
        assert len(figs) == 1 and hasattr(figs[0], "savefig")
        assert "Predicted precision" in res.report(tmp_path / "e.html").read_text()


def test_a_design_too_large_for_memory_is_refused_before_any_work(cli, tmp_path):
    """``--duration 1e7`` or ``--rate 1e9`` would allocate terabytes: a one-line error naming both options, the
    memory needed and available and the longest duration that fits, before the optimisation, nothing written."""
    from symoro_gen.workflows.excite import check_size

    for args, words in ((("--duration", "1e7"), "--duration 1e+07 at --rate 100 Hz"),
                        (("--rate", "1e9"), "--duration 10 at --rate 1e+09 Hz")):
        r = cli("excite", "scara", "-o", tmp_path / "t.csv", *args, rc=2)
        assert words in r.err and "of memory" in r.err and "use --duration" in r.err, r.err
        assert not list(tmp_path.iterdir())
    opts = symoro_gen.ExciteOptions(duration=10, rate=100)
    check_size(opts, 4, 20, available=10**12)                 # 1,001 samples: a few MB
    # 1,001 samples x 4 joints x (20 regressor columns x 8 B + 264 B of q, dq, ddq and the 10x check) = 1.62 MiB;
    # 1000 KiB hold 602 samples: 6.028 s at 100 Hz
    with pytest.raises(ExcitationError, match=r"1001 output samples would need about 1\.62 MiB of memory, 1e\+03 KiB "
                                              r"is available; use --duration 6\.028 or less at this rate"):
        check_size(opts, 4, 20, available=1000 * 1024)
