"""The library's workflows (``symoro_gen.identify`` ...) against the commands and against the golden outputs main
wrote before the workflows existed (tests/golden): ``to_dict()`` is exactly the command's JSON, ``summary()`` its
text; options are named (an unknown one names the nearest); data as paths, Trajectory objects or arrays."""
from __future__ import annotations

import importlib.util
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.errors import OptionError
from symoro_gen.loader import model_for
from symoro_gen.preprocessing import load_trajectory
from symoro_gen.workflows import SCHEMA_VERSION, IdentifyOptions

from .golden.inputs import write_inputs

GOLDEN = Path(__file__).resolve().parent / "golden"
NEW_KEYS = {"generator", "schema_version", "provenance", "robot_id", "plausibility", "bounded_bodies", "verdict",
            "positions", "elasticity", "robot_file", "declared_friction_laws", "robot_out",
            "verdict_reason", "alternatives", "degenerate", "cond_degenerate", "score_se", "chosen_over", "prior"}


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    return write_inputs(tmp_path_factory.mktemp("golden-inputs"))


_STATISTICS = {"z", "z_validation", "score", "p_value"}


def _same(a, b, where="$", rtol=1e-7, atol=1e-12):
    """Recursive comparison: floats within tolerance, paths (strings naming an input) by file name."""
    if isinstance(a, dict) and isinstance(b, dict):
        ka, kb = set(a) - NEW_KEYS, set(b) - NEW_KEYS
        assert ka == kb, f"{where}: keys differ: {sorted(ka ^ kb)}"
        for k in ka:
            # a test statistic is O(1): one near 0 is a difference of two sums, exact only to ~1e-9 absolute
            _same(a[k], b[k], f"{where}.{k}", rtol, max(atol, 1e-7) if k in _STATISTICS else atol)
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), f"{where}: lengths {len(a)} != {len(b)}"
        for i, (x, y) in enumerate(zip(a, b)):
            _same(x, y, f"{where}[{i}]", rtol, atol)
    elif isinstance(a, bool) or isinstance(b, bool) or a is None or b is None:
        assert a == b, f"{where}: {a!r} != {b!r}"
    elif isinstance(a, (int, float)) and isinstance(b, (int, float)):
        assert math.isclose(a, b, rel_tol=rtol, abs_tol=atol), f"{where}: {a!r} != {b!r}"
    elif isinstance(a, str) and isinstance(b, str) and ("/" in a or "/" in b):
        assert Path(a).name == Path(b).name, f"{where}: {a!r} != {b!r}"
    elif isinstance(a, str) and isinstance(b, str):
        _same_text(a, b, where, rtol)
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def _same_text(a: str, b: str, where: str, rtol: float) -> None:
    """Texts equal but for the numbers in them, which agree within ``rtol`` or are both at the rounding level
    (|x| < 1e-12: an identifiability of 6e-15 is 0 computed in another summation order)."""
    if a == b:
        return
    assert _NUMBER.split(a) == _NUMBER.split(b), f"{where}: {a!r} != {b!r}"
    for x, y in zip(_NUMBER.findall(a), _NUMBER.findall(b)):
        assert math.isclose(float(x), float(y), rel_tol=max(rtol, 1e-3), abs_tol=1e-12), f"{where}: {a!r} != {b!r}"


def _normalise_text(text: str, *folders) -> str:
    for f in folders:
        text = text.replace(str(f) + "/", "")
    return text


def test_identify_command_matches_the_golden_output_and_the_api(cli, inputs, tmp_path):
    a, b = inputs
    out = tmp_path / "identify.json"
    r = cli("identify", "scara", a, "--validate", b, "--method", "wls", "--json", out)
    written = json.loads(out.read_text())
    golden = json.loads((GOLDEN / "identify.json").read_text())
    _same(written, golden)
    assert written["generator"] == "symoro-gen identify" and written["schema_version"] == SCHEMA_VERSION
    prov = written["provenance"]
    assert [Path(x["path"]).name for x in prov["inputs"]] == ["scara_a.csv", "scara_b.csv"]
    assert all(len(x["sha256"]) == 64 for x in prov["inputs"]) and prov["options"]["method"] == "wls"
    assert prov["package"]["version"] == symoro_gen.__version__
    # the text: the golden one (paths aside), and exactly summary()
    assert _normalise_text(r.out, a.parent) == _normalise_text((GOLDEN / "identify.txt").read_text(), "/tmp/golden/in")
    res = symoro_gen.identify("scara", [a], validate=[b], method="wls")
    assert res.to_dict() == written                      # exactly the command's JSON
    assert res.summary() + "\n" == r.out
    assert res.summary() in res._repr_html_().replace("&#x27;", "'").replace("&quot;", '"') or "<pre" in res._repr_html_()


def test_the_scripts_contract(cli, inputs, tmp_path):
    """``identify(robot, [f1, f3], validate=[f2], method="wls").to_dict()["validation"]["rel_err"]`` is the list of
    the command's JSON."""
    a, b = inputs
    c = tmp_path / "scara_c.csv"
    c.write_bytes(a.read_bytes())
    out = tmp_path / "x.json"
    cli("identify", "scara", a, c, "--validate", b, "--method", "wls", "--json", out)
    res = symoro_gen.identify("scara", [a, c], validate=[b], method="wls")
    rel = res.to_dict()["validation"]["rel_err"]
    assert rel == json.loads(out.read_text())["validation"]["rel_err"] and len(rel) == 4


def test_options_are_named_and_checked(inputs):
    a, _ = inputs
    with pytest.raises(OptionError, match="unknown option 'cutof'; did you mean 'cutoff'"):
        symoro_gen.identify("scara", a, cutof=10.0)
    with pytest.raises(OptionError, match="method 'olss'"):
        symoro_gen.identify("scara", a, method="olss")
    with pytest.raises(OptionError, match="not both"):
        symoro_gen.identify("scara", a, options=IdentifyOptions(), cutoff=10.0)
    with pytest.raises(OptionError, match=r"validate-fraction 1\.5"):
        IdentifyOptions(validate_fraction=1.5)
    o = IdentifyOptions(method="ols", cutoff=12.0)
    assert o.as_dict()["cutoff"] == 12.0 and symoro_gen.identify("scara", a, options=o).options is o


def test_data_as_paths_trajectories_or_arrays_and_robot_in_any_form(inputs):
    a, _ = inputs
    ref = symoro_gen.identify("scara", a, method="ols")
    tr = load_trajectory(a, n_joints=4)
    desc, model = model_for("scara")
    for robot, data in ((desc, tr), (model, (tr.t, tr.q, tr.tau)), ("scara", {"t": tr.t, "q": tr.q, "tau": tr.tau})):
        res = symoro_gen.identify(robot, data, method="ols")
        assert np.allclose(res.result.values, ref.result.values, rtol=1e-10, atol=1e-12)
    with pytest.raises(OptionError, match=r"q and tau \(N, 4\)"):
        symoro_gen.identify("scara", (tr.t, tr.q[:, :3], tr.tau), method="ols")
    with pytest.raises(OptionError, match="expected a robot name"):
        symoro_gen.identify(3.5, a)


def test_report_and_plot(inputs, tmp_path):
    pytest.importorskip("matplotlib")
    a, b = inputs
    res = symoro_gen.identify("scara", a, validate=b, method="wls")
    figs = res.plot()
    assert figs and all(hasattr(f, "savefig") for f in figs)
    page = res.report(tmp_path / "r.html")
    assert page.read_text().startswith("<!DOCTYPE html>") and "Identified parameters" in page.read_text()
    j = res.write_json(tmp_path / "r.json")
    assert json.loads(j.read_text()) == res.to_dict()
    # without matplotlib (as on an install without the 'plots' extra): plot() and report() name the extra
    code = ("import sys; sys.modules['matplotlib'] = None\n"
            "import symoro_gen\n"
            f"res = symoro_gen.identify('scara', {str(a)!r}, method='ols')\n"
            "for call in (res.plot, lambda: res.report(sys.argv[1])):\n"
            "    try:\n"
            "        call()\n"
            "    except Exception as exc:\n"
            "        print(type(exc).__name__, exc.hint if getattr(exc, 'hint', None) else exc)\n")
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1]))
    out = subprocess.run([sys.executable, "-c", code, str(tmp_path / "no.html")], capture_output=True, text=True,
                         env=env, check=True).stdout.splitlines()
    assert len(out) == 2 and all(line.startswith("MissingDependencyError") and "[plots]" in line for line in out), out
    assert not (tmp_path / "no.html").exists()


# ---- diagnose ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def diagnosed(cli, inputs, tmp_path_factory):
    """``symoro-gen diagnose scara A --validate B --json OUT --plots DIR`` (the golden command, with plots) and
    the same through the library: (stdout, written JSON, plots written, DiagnoseResults)."""
    a, b = inputs
    out = tmp_path_factory.mktemp("diagnose")
    # --plots prints a note instead of writing without matplotlib (the 'plots' extra): only with it
    plots = ("--plots", out / "plots") if importlib.util.find_spec("matplotlib") else ()
    r = cli("diagnose", "scara", a, "--validate", b, "--json", out / "d.json", *plots)
    res = symoro_gen.diagnose("scara", [a], validate=[b])
    return r.out, json.loads((out / "d.json").read_text()), sorted((out / "plots").glob("*.png")), res


def test_diagnose_command_matches_the_golden_output(inputs, diagnosed):
    a, _ = inputs
    text, written, _, _ = diagnosed
    _same(written, json.loads((GOLDEN / "diagnose.json").read_text()))
    assert list(written)[:2] == ["generator", "schema_version"] and list(written)[-1] == "provenance"
    assert written["generator"] == "symoro-gen diagnose" and written["schema_version"] == SCHEMA_VERSION
    prov = written["provenance"]
    assert [Path(x["path"]).name for x in prov["inputs"]] == ["scara_a.csv", "scara_b.csv"]
    assert all(len(x["sha256"]) == 64 for x in prov["inputs"]) and prov["seeds"] == {"seed": 0}
    assert prov["options"]["method"] == "ols" and prov["options"]["max_effects"] == 5
    assert _normalise_text(text, a.parent) == _normalise_text((GOLDEN / "diagnose.txt").read_text(), "/tmp/golden/in")


def test_diagnose_report_says_what_the_text_says_when_nothing_is_added(diagnosed, tmp_path):
    """The HTML report of a diagnosis that adds nothing gives the text's reason, on the held-out acceptance data
    (the loop never reads the validation data)."""
    pytest.importorskip("matplotlib")
    text, _, _, res = diagnosed
    sentence = next(ln for ln in text.splitlines() if ln.startswith("No effect added"))
    assert "acceptance" in sentence
    assert sentence in res.report(tmp_path / "d.html").read_text()


def test_diagnose_api_is_the_command(diagnosed):
    text, written, plots, res = diagnosed
    assert isinstance(res, symoro_gen.DiagnoseResults) and res.options == symoro_gen.DiagnoseOptions()
    assert res.to_dict() == written                      # exactly the command's JSON
    assert res.summary() + "\n" == text                  # exactly its text
    assert "<table" in res._repr_html_()
    if importlib.util.find_spec("matplotlib"):  # --plots wrote the figures of the diagnosis
        assert plots and all(p.name.startswith("diagnosis-") for p in plots)


def test_diagnose_options_are_named_and_checked(inputs):
    a, b = inputs
    with pytest.raises(OptionError, match="unknown option 'max_efects'; did you mean 'max_effects'"):
        symoro_gen.diagnose("scara", a, max_efects=1)
    with pytest.raises(OptionError, match="unknown option 'candidate'; did you mean 'candidates'"):
        symoro_gen.diagnose("scara", a, candidate=("spring",))
    with pytest.raises(OptionError, match="method 'ridge'"):
        symoro_gen.diagnose("scara", a, method="ridge")
    with pytest.raises(OptionError, match=r"--significance 1\.5"):
        symoro_gen.DiagnoseOptions(significance=1.5)
    with pytest.raises(OptionError, match="unknown kind 'sprung'"):
        symoro_gen.DiagnoseOptions(candidates=("sprung",))
    with pytest.raises(OptionError, match="not both"):
        symoro_gen.diagnose("scara", a, options=symoro_gen.DiagnoseOptions(), max_effects=1)


def test_diagnose_data_as_trajectories(inputs, diagnosed):
    """Trajectory objects and (t, q, tau) arrays give the diagnosis the files give (their names aside)."""
    a, b = inputs
    *_, ref = diagnosed
    ta, tb = (load_trajectory(p, n_joints=4) for p in (a, b))
    opts = symoro_gen.DiagnoseOptions(candidates=("spring", "offset"), max_effects=1)
    by_file = symoro_gen.diagnose("scara", a, validate=b, options=opts)
    res = symoro_gen.diagnose(model_for("scara")[1], ta, validate=(tb.t, tb.q, tb.tau), options=opts)
    d, f = res.to_dict(), by_file.to_dict()
    assert d["before"] == f["before"] and d["after"] == f["after"] and d["effects"] == f["effects"]
    assert d["validate"] == ["<array 1>"] and d["provenance"]["inputs"][0] == {"path": str(a), "sha256": None}
    assert [c["kind"] for c in d["tried"]] == [c["kind"] for c in f["tried"]]
    assert np.array_equal(res.residual.before_rel_err, by_file.residual.before_rel_err)
    assert res.residual.settings["candidates"] == ["spring", "offset"] != ref.residual.settings["candidates"]


def test_diagnose_report_and_figures(diagnosed, tmp_path):
    pytest.importorskip("matplotlib")
    *_, res = diagnosed
    figs = res.plot()
    assert figs and all(hasattr(f, "savefig") for f in figs)
    page = res.report(tmp_path / "d.html")
    assert page.read_text().startswith("<!DOCTYPE html>") and "Residual diagnosis" in page.read_text()
    assert json.loads(res.write_json(tmp_path / "d.json").read_text()) == res.to_dict()
