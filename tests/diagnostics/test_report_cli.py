"""ResidualReport contract (JSON keys, summary, Markdown, plots) and the ``symoro-gen diagnose`` command."""
from __future__ import annotations

import json

import pytest

from symoro_gen.diagnostics import DiagnoseSettings, ResidualReport, diagnose
from symoro_gen.simulate import write_recording_csv

from .simdata import recording


@pytest.fixture(scope="module")
def stribeck_report():
    model, tr = recording("scara", 11, "stribeck", 1, Fst=1.0, vs=0.1)
    # the plain candidate path: with the friction-law stage the Stribeck law is chosen there (round 0)
    return diagnose(model, tr, DiagnoseSettings(friction_laws=False))


def test_json_contract(stribeck_report):
    rep = stribeck_report
    assert isinstance(rep, ResidualReport)
    d = json.loads(json.dumps(rep.to_dict()))          # plain JSON types
    n = rep.n_joints
    for k in ("before", "after"):
        assert set(d[k]) >= {"rel_err", "validation_rel_err"}
        assert len(d[k]["rel_err"]) == n and len(d[k]["validation_rel_err"]) == n
    assert d["effects"] and set(d["effects"][0]) >= {"kind", "joint", "params", "score"}
    assert d["effects"][0]["joint"] == 2                  # 1-based
    assert all(set(c) >= {"kind", "joint", "score"} for c in d["tried"])
    kinds_round1 = {c["kind"] for c in d["tried"] if c["round"] == 1}
    assert "stribeck" in kinds_round1 and "elasticity" in kinds_round1
    # errors: before from the declared model, after with the effect (validation of joint 2 dropped)
    assert d["after"]["validation_rel_err"][1] < d["before"]["validation_rel_err"][1]
    assert isinstance(d["unexplained"], list) and len(d["unexplained_all"]) == n
    assert {"modulation", "selection_frequency", "ci"} <= set(d["effects"][0])


def test_summary_and_markdown(stribeck_report):
    s = stribeck_report.summary()
    assert "stribeck on joint 2" in s and "%sigma" in s and "valid after" in s
    md = stribeck_report.to_markdown(plots=["plots/x.png"])
    assert "| validation, after |" in md and "**stribeck** on joint 2" in md and "![x](plots/x.png)" in md


def test_write_plots(stribeck_report, tmp_path):
    pytest.importorskip("matplotlib")
    files = stribeck_report.write_plots(tmp_path / "plots")
    names = {f.name for f in files}
    assert any(n.startswith("diagnosis-effect-1-stribeck") for n in names), names
    assert all(f.stat().st_size > 1000 for f in files)


def test_cli_diagnose(tmp_path, cli):
    _, tr = recording("scara", 12, "offset", 3, offset=0.3)
    # the declared scara has OFF4: an offset is not missing, so inject a drift instead
    _, tr = recording("scara", 12, "drift", 3, rate=0.01)
    csv = tmp_path / "rec.csv"
    write_recording_csv(csv, tr)
    out = tmp_path / "out.json"
    cli("diagnose", "scara", csv, "--json", out, "--max-effects", "2", "--quiet", rc=0)
    d = json.loads(out.read_text())
    first = next(e for e in d["effects"] if e["kind"] != "friction_law")
    # the composed library leaves "a constant torque changing with time" to the drift candidate
    assert (first["kind"], first["modulation"], first["joint"]) == ("drift", None, 4)
    assert [e["file"] for e in d["data"]] == [str(csv)] and "validation_rel_err" in d["after"]


def test_cli_validate_and_candidates(tmp_path, cli):
    _, tr = recording("scara", 13, "spring", 0, stiffness=-5.0)
    _, tv = recording("scara", 13, "spring", 0, stiffness=-5.0, duration=20.0)
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    write_recording_csv(a, tr)
    write_recording_csv(b, tv)
    out = tmp_path / "o.json"
    cli("diagnose", "scara", a, "--validate", b, "--candidates", "spring", "offset", "--json", out, "--quiet", rc=0)
    d = json.loads(out.read_text())
    assert {c["kind"] for c in d["tried"]} == {"spring", "offset"}
    first = next(e for e in d["effects"] if e["kind"] != "friction_law")
    assert first["kind"] == "spring" and first["joint"] == 1
    assert d["settings"]["validation_sources"] == [str(b)]


def test_cli_rejects_bad_report_suffix(tmp_path, cli):
    _, tr = recording("scara", 14, duration=10.0)
    csv = tmp_path / "r.csv"
    write_recording_csv(csv, tr)
    assert "suffix" in cli("diagnose", "scara", csv, "--report", tmp_path / "r.pdf", rc=2).err


@pytest.mark.parametrize("opt", [["--significance", "1.5"], ["--holdout", "0"], ["--max-effects", "-1"]])
def test_cli_rejects_bad_options_before_loading(opt, cli):
    err = cli("diagnose", "scara", "no-such-file.csv", *opt, rc=2).err
    assert opt[0] in err and "no-such-file" not in err


def test_repr_html_tables(stribeck_report):
    html = stribeck_report._repr_html_()
    assert "<table" in html and "stribeck" in html


@pytest.mark.slow
def test_progress_bar_over_candidates(monkeypatch, capsys):
    """With bars forced on, diagnose reports its candidate rounds on stderr; off by default."""
    from symoro_gen.progress import progress_mode

    model, tr = recording("scara", 12)
    monkeypatch.setenv("SYMORO_PROGRESS", "1")
    with progress_mode("auto"):  # what the CLI sets unless --quiet
        diagnose(model, tr, DiagnoseSettings(max_effects=1))
    assert "diagnose: round 1" in capsys.readouterr().err
    diagnose(model, tr, DiagnoseSettings(max_effects=1))  # library default: no bars
    assert "diagnose: round" not in capsys.readouterr().err
