"""``plot()``, ``report(path)`` and ``--report``/``--plots`` of a floating-base robot's ``identify`` and ``diagnose``
results (docs/floating-base.md, "Identify from logs").

The logs are Pinocchio-simulated (:func:`tests.floating.test_cli_floating.simulate_log`: free-flyer RNEA, two
contact wrenches, IMU and joint noise). The figures are read back from their matplotlib artists and compared with
the result's numbers: the relative error each row's two curves give is the one the workflow computed on its own
(``rel_err`` of the JSON), the bars are the JSON's errors, the error bars twice the standard deviations.
"""
from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

from symoro_gen.description import load_robot
from symoro_gen.errors import OutputError
from symoro_gen.report import MissingDependencyError
from symoro_gen.report.tables import fmt_value
from symoro_gen.workflows import diagnose, identify
from symoro_gen.workflows.floating_report import P_FLOOR

from .test_cli_floating import HOPPER, simulate_log

CONTACTS = {"frame1": 1, "foot": 3}


@pytest.fixture(scope="module")
def hopper(tmp_path_factory):
    """The hopper with its knee declared with a rotor inertia only, an 8 s log with joint torques and a 5 s
    validation log of the same robot (the seed draws the same parameters and motion; the noise differs)."""
    d = tmp_path_factory.mktemp("hopper_report")
    anchor = "[[frames]]\nj = 2\n"
    (d / "hopper.toml").write_text(HOPPER.replace(anchor, anchor + 'drive = ["IA"]\n'))
    robot = load_robot(d / "hopper.toml")
    chi = simulate_log(robot, d / "a.csv", seed=3, duration=8.0, fs=200.0, contacts=CONTACTS)
    chi_b = simulate_log(robot, d / "b.csv", seed=3, duration=5.0, fs=200.0, contacts=CONTACTS)
    assert np.array_equal(chi, chi_b)
    return robot, d


@pytest.fixture(scope="module")
def fitted(hopper):
    robot, d = hopper
    return identify(robot.file, [str(d / "a.csv")], validate=[str(d / "b.csv")])


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(a))


def test_identify_plot_draws_the_results_numbers(fitted):
    """Each row's measured and modelled curves on the validation log give the validation error the workflow
    computed (every decimated sample drawn); the bars are the four per-row errors of the JSON; the error bars are
    the identified values ± 2 sigma."""
    d = fitted.to_dict()
    rows = d["floating"]["rows"]
    assert rows == ["FX0", "FY0", "FZ0", "MX0", "MY0", "MZ0", "tau1", "tau2"]  # both kinds: the log has torques
    curves, errors, params = fitted.plot()
    axes = [ax for ax in curves.axes if ax.get_visible()]
    assert len(axes) == len(rows)
    n_val = sum(r.Y.shape[0] for r in fitted.validation["rows"])
    for ax, name, err in zip(axes, rows, d["validation"]["rel_err"]):
        measured, model = ax.lines[0], ax.lines[1]
        assert np.array_equal(measured.get_xdata(), np.arange(n_val))   # no sample left out
        assert ax.get_title(loc="left").startswith(name)
        assert _rel(np.asarray(measured.get_ydata()), np.asarray(model.get_ydata())) == pytest.approx(err, rel=1e-9)
    (ax,) = errors.axes
    bars = {c.get_label(): [p.get_height() for p in c.patches] for c in ax.containers}
    expected = {"identification, filtered": d["rel_err"], "identification, raw": d["rel_err_raw"],
                "validation, filtered": d["validation"]["rel_err"], "validation, raw": d["validation"]["rel_err_raw"]}
    assert bars.keys() == expected.keys()
    for k, v in expected.items():
        assert np.allclose(bars[k], v, rtol=1e-12, atol=0), k
    assert [t.get_text() for t in ax.get_xticklabels()] == rows
    (ax,) = params.axes
    line, _, (bar_lines,) = ax.containers[0]
    values, std = np.array(d["parameters"]["values"]), np.array(d["parameters"]["std"])
    assert np.array_equal(line.get_ydata(), values)
    seg = np.array(bar_lines.get_segments())  # (p, 2, 2): (x, value - 2 sigma), (x, value + 2 sigma)
    assert np.allclose(seg[:, 0, 1], values - 2 * std) and np.allclose(seg[:, 1, 1], values + 2 * std)
    assert [t.get_text() for t in ax.get_xticklabels()] == d["parameters"]["names"]


def test_identify_report_holds_the_parameter_table(fitted, hopper, tmp_path):
    """``report(path)``: HTML with every combination's value and sigma and the figures inline; Markdown with its
    images beside it; never an input (a report path that is a link to the log), an existing file symoro-gen did
    not write only with ``force``."""
    d = fitted.to_dict()
    html = fitted.report(tmp_path / "id.html").read_text()
    for name, v, s in zip(d["parameters"]["names"], d["parameters"]["values"], d["parameters"]["std"]):
        assert f"<td>{name}</td><td class=\"num\">{fmt_value(v)}</td><td class=\"num\">{fmt_value(s)}</td>" in html
    assert html.count("data:image/png;base64") == 3
    md = fitted.report(tmp_path / "id.md").read_text()
    name, v, s = d["parameters"]["names"][0], d["parameters"]["values"][0], d["parameters"]["std"][0]
    assert f"| {name} | {fmt_value(v)} | {fmt_value(s)} |" in md
    assert sorted(p.name for p in (tmp_path / "id_files").iterdir()) == [
        "floating-parameters.png", "floating-row-errors.png", "floating-rows.png"]
    fitted.report(tmp_path / "id.html")  # its own earlier report: replaced
    _, data = hopper
    link = tmp_path / "log.html"
    link.symlink_to(data / "a.csv")
    before = (data / "a.csv").read_bytes()
    with pytest.raises(OutputError):
        fitted.report(link, force=True)
    assert (data / "a.csv").read_bytes() == before
    foreign = tmp_path / "notes.html"
    foreign.write_text("mine")
    with pytest.raises(OutputError):
        fitted.report(foreign)
    assert foreign.read_text() == "mine"


def test_identify_report_through_the_cli(hopper, cli, tmp_path):
    """``symoro-gen identify ROBOT LOG --report OUT.html`` of a floating-base robot writes the report."""
    robot, d = hopper
    out = tmp_path / "cli.html"
    cli("--quiet", "identify", str(robot.file), str(d / "a.csv"), "--kind", "base", "--report", str(out))
    text = out.read_text()
    assert "Floating-base identification of" in text and "FX0" in text


def test_diagnose_plot_names_the_effect_on_its_row(hopper, tmp_path):
    """A 2 N m offset on the knee's torque: the figure's bars are the loop's validation errors per row before and
    after, and the offset's label is written above row tau2; the report's effects table holds its value and
    verdict; ``write_plots`` writes the figure as ``diagnosis-*.png``."""
    robot, _ = hopper
    clean = tmp_path / "clean.csv"   # 16 s: the loop accepts on the last share of the log
    simulate_log(robot, clean, seed=2, duration=16.0, fs=200.0, contacts=CONTACTS)
    names = clean.read_text().split("\n", 1)[0].split(",")
    table = np.loadtxt(clean, delimiter=",", skiprows=1)
    table[:, names.index("tau2")] += 2.0
    bad = tmp_path / "offset.csv"
    np.savetxt(bad, table, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
    res = diagnose(robot.file, [str(bad)])
    loop = res.to_dict()["floating"]["loop"]
    assert [(e["row"], e["kind"]) for e in loop["effects"]] == [("tau2", "offset")]
    (fig,) = res.plot()
    (ax,) = fig.axes
    bars = {c.get_label(): [p.get_height() for p in c.patches] for c in ax.containers}
    assert np.allclose(bars["validation, before"], loop["rel_err_before"], rtol=1e-12, atol=0)
    assert np.allclose(bars["validation, after"], loop["rel_err_after"], rtol=1e-12, atol=0)
    (text,) = [t for t in ax.texts if loop["effects"][0]["label"] in t.get_text()]
    assert text.get_position()[0] == loop["rows"].index("tau2")
    html = res.report(tmp_path / "diag.html").read_text()
    eff = loop["effects"][0]
    (pname, value), = eff["params"].items()
    assert f"{pname} {fmt_value(value)} ± {fmt_value(eff['std'][pname])}" in html
    assert f"<td>{eff['verdict']}</td>" in html and eff["verdict_reason"].split(",")[0] in html
    files = res.write_plots(tmp_path / "plots")
    assert [p.name for p in files] == ["diagnosis-floating-rows.png"]


def test_diagnose_checks_report_through_the_cli(hopper, cli, tmp_path):
    """Logs without joint torques (the loop does not run): ``--plots`` draws each candidate's ``-log10 p``
    against the Bonferroni level, ``--report`` holds the checks; the thigh's 5 N offset accepted."""
    robot, _ = hopper
    log = tmp_path / "notau.csv"
    simulate_log(robot, log, seed=3, duration=12.0, fs=200.0, contacts=CONTACTS, torques=False)
    names = log.read_text().split("\n", 1)[0].split(",")
    table = np.loadtxt(log, delimiter=",", skiprows=1)
    table[:, names.index("frame1_fz")] += 5.0
    np.savetxt(log, table, delimiter=",", header=",".join(names), comments="", fmt="%.10g")
    out, plots = tmp_path / "checks.md", tmp_path / "plots"
    cli("--quiet", "diagnose", str(robot.file), str(log), "--report", str(out), "--plots", str(plots))
    assert [p.name for p in plots.iterdir()] == ["diagnosis-floating-checks.png"]
    assert "accepted (1)" in out.read_text()
    res = diagnose(robot.file, [str(log)])
    (fig,) = res.plot()
    (ax,) = fig.axes
    shown = [c for c in res.checks if c["identifiable"]]
    heights = [p.get_height() for p in ax.patches]
    assert np.allclose(heights, [-math.log10(max(c["p_value"], P_FLOOR)) for c in shown], rtol=1e-12)
    level = res.to_dict()["floating"]["level"]
    (line,) = ax.lines
    assert line.get_ydata()[0] == pytest.approx(-math.log10(level))
    assert [c["frame"] for c in shown if c["accepted"]] == ["frame1"]
    assert all((h > line.get_ydata()[0]) == c["accepted"] for h, c in zip(heights, shown))


def test_without_matplotlib_the_extra_is_named(fitted, hopper, monkeypatch, tmp_path):
    """Without matplotlib, ``plot()`` and ``report()`` of both results raise :class:`MissingDependencyError`
    naming the 'plots' extra and write nothing; ``write_plots`` writes nothing."""
    robot, d = hopper
    diagnosed = diagnose(robot.file, [str(d / "a.csv")])
    for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")] + ["matplotlib"]:
        monkeypatch.setitem(sys.modules, name, None)
    for call in (fitted.plot, lambda: fitted.report(tmp_path / "i.html"), diagnosed.plot,
                 lambda: diagnosed.report(tmp_path / "d.md")):
        with pytest.raises(MissingDependencyError) as err:
            call()
        assert "[plots]" in (err.value.hint or "")
    assert diagnosed.write_plots(tmp_path / "plots") == []
    assert not os.listdir(tmp_path)


def test_report_path_rules(fitted, tmp_path):
    """A report path with another suffix is refused before anything is written."""
    from symoro_gen.report import ReportError

    with pytest.raises(ReportError):
        fitted.report(tmp_path / "r.txt")
    assert not list(Path(tmp_path).iterdir())


def test_quadruped_joint_rows_plot_and_report(tmp_path):
    """The quadruped-like tree (12 joints, contacts at two knees), its joint rows with a validation log: one
    subplot per joint row, each giving the validation error of the JSON; the Markdown report's table holds every
    combination's value and sigma."""
    robot = load_robot(Path(__file__).parent / "quadruped.toml")
    contacts = {"frame3": 3, "frame9": 9}
    simulate_log(robot, tmp_path / "a.csv", seed=11, duration=10.0, fs=200.0, contacts=contacts)
    simulate_log(robot, tmp_path / "b.csv", seed=11, duration=6.0, fs=200.0, contacts=contacts)
    res = identify(robot.file, [str(tmp_path / "a.csv")], validate=[str(tmp_path / "b.csv")], kind="joints")
    d = res.to_dict()
    assert d["floating"]["rows"] == [f"tau{j}" for j in range(1, 13)]
    curves = res.plot()[0]
    axes = [ax for ax in curves.axes if ax.get_visible()]
    assert len(axes) == 12
    for ax, err in zip(axes, d["validation"]["rel_err"]):
        m, y = (np.asarray(line.get_ydata()) for line in ax.lines[:2])
        assert _rel(m, y) == pytest.approx(err, rel=1e-9)
    md = res.report(tmp_path / "q.md").read_text()
    for name, v, s in zip(d["parameters"]["names"], d["parameters"]["values"], d["parameters"]["std"]):
        assert f"| {name} | {fmt_value(v)} | {fmt_value(s)} |" in md
