"""Reports with gains and a payload (LWR4 torque-sensor calibration, simulated, truth known) and of a
residual diagnosis (RX-90 with a Stribeck friction its model lacks)."""
import json
import re

import numpy as np
import pytest

from symoro_gen.simulate import write_recording_csv

from .pngcheck import IMG_RE, decode_png, embedded_images, ink_stats
from .test_markdown import LINK_RE, _md_table

pytest.importorskip("matplotlib", reason="report plots need matplotlib (the 'plots' extra)")

LWR4_DURATION_S = 5.0


def test_sensor_gain_report_shows_gains_and_payload_mass(tmp_path, cli):
    """identify --gains sensor with a known payload mass and loaded validation data: the gains table,
    the known mass and the mass re-identified on the validation data (Table IV), four plots."""
    from symoro_gen.demo import PAYLOAD_MASS, TRUE_GAINS, demo_payload
    from symoro_gen.loader import model_for
    from symoro_gen.simulate.recording import simulate_recording
    from symoro_gen.simulate.trajectories import fourier_trajectory

    rng = np.random.default_rng(1)
    robot, model = model_for("lwr4")
    chi = model.nominal_parameters()
    files = []
    for k, loaded in enumerate((False, True, True)):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, LWR4_DURATION_S, 0.005, rng, vmax=1.5, amax=6.0)
        tr = simulate_recording(model, t, q, dq, ddq, chi, chi_payload=demo_payload() if loaded else None,
                                gains=TRUE_GAINS, noise_q=2e-5, noise_tau=0.02, rng=rng, loaded=loaded)
        files.append(tmp_path / f"rec{k}.csv")
        write_recording_csv(files[-1], tr)
    out = tmp_path / "gains.md"
    cli("--quiet", "identify", "lwr4", files[0], "--loaded", files[1], "--payload", f"M8={PAYLOAD_MASS}",
        "--gains", "sensor", "--validate", files[2], "--validate-loaded", "--json", tmp_path / "gains.json",
        "--report", out, rc=0)
    res = json.loads((tmp_path / "gains.json").read_text())
    md = out.read_text(encoding="utf-8")
    gains = _md_table(md, "Gain")
    assert [r[0] for r in gains] == [f"g{j}" for j in range(1, 8)]
    assert [float(r[2]) for r in gains] == pytest.approx(TRUE_GAINS, rel=5e-3)
    assert [float(r[4]) for r in gains] == pytest.approx(res["gains"]["rel_std_pct"], abs=0.006)
    assert f"Payload mass in the identification: M8 = {PAYLOAD_MASS:g} kg (known, weighed)" in md
    m = re.search(r"Payload mass re-identified on the validation data, robot known \(Table IV\): M8 = ([0-9.]+) kg", md)
    assert m and float(m.group(1)) == pytest.approx(PAYLOAD_MASS, rel=0.01)
    payload_rows = _md_table(md, "Parameter")  # the first parameter table is the payload's
    assert [r[0] for r in payload_rows] == list(model.PAYLOAD_NAMES)
    assert payload_rows[-1][1:] == ["4.6136", "-", "-", "known"]
    errs = {r[0]: [float(x) for x in r[1:]] for r in _md_table(md, "Data")}
    assert set(errs) == {"identification (as fitted)", "identification data (unloaded)",
                         "identification data (loaded)", "validation data (loaded)"}
    assert errs["validation data (loaded)"] == pytest.approx(res["validation"]["rel_err"], abs=6e-5)
    links = LINK_RE.findall(md)
    assert [s.split("/")[-1] for s in links] == [
        "torque-identification-data-unloaded.png", "torque-identification-data-loaded.png",
        "torque-validation-data-loaded.png", "singular-values.png"]
    for s in links:
        rgb = decode_png((tmp_path / s).read_bytes())
        assert rgb.shape[1] == 1100 and ink_stats(rgb)[0] > 0.03


@pytest.fixture(scope="module")
def diagnosis():
    """diagnose() on RX-90 recordings with a Stribeck friction on joint 2 (0-based 1) the model lacks."""
    dg = pytest.importorskip("symoro_gen.diagnostics", reason="diagnostics package not available")
    from symoro_gen.loader import model_for
    from symoro_gen.preprocessing.trajectory import Trajectory
    from symoro_gen.simulate.parameters import random_physical_parameters
    from symoro_gen.simulate.recording import true_torques
    from symoro_gen.simulate.trajectories import fourier_trajectory

    rng = np.random.default_rng(5)
    robot, model = model_for("rx90")
    p = random_physical_parameters(robot, rng)
    chi = getattr(p, "chi_std", p)
    trs = []
    # 16 s to identify (the loop accepts a change on the trailing 30 % of it: at least MIN_ACCEPTANCE_ROWS
    # decimated rows per joint), 8 s to validate
    for k, seconds in enumerate((16.0, 8.0)):
        t, q, dq, ddq = fourier_trajectory(robot.n_joints, seconds, 0.002, rng)
        tau = true_torques(model, q, dq, ddq, chi)
        qm, tm = dg.inject_effect("stribeck", t, q, dq, ddq, tau, joint=1, Fst=3.0, vs=0.1)
        trs.append(Trajectory(t, qm + rng.normal(0, 1e-5, q.shape), tm + rng.normal(0, 0.05, tau.shape),
                              source=f"simulated {k}"))
    return dg.diagnose(model, trs[:1], dg.DiagnoseSettings(method="wls", candidates=("stribeck", "offset", "drift")),
                       validation=trs[1:])


def test_diagnosis_report_plots_the_residual_before_and_after_each_effect(diagnosis, tmp_path):
    from symoro_gen.diagnostics.render import diagnosis_plot_series
    from symoro_gen.workflows.reporting import write_report

    rep = diagnosis
    assert [(e.kind, e.joint) for e in rep.effects][:1] == [("stribeck", 1)]
    html = write_report(tmp_path / "diag.html", diagnosis=rep).read_text(encoding="utf-8")
    # the residual series the plots are drawn from are the ones the diagnosis reports its errors of
    ser = diagnosis_plot_series(rep)
    assert ser is not None and len(ser["rounds"]) == len(rep.effects) + 1
    for rounds, y, joint, key in ((ser["rounds"], ser["Y"], ser["joint"], ""), (ser["rounds"], ser["Yv"],
                                                                                 ser["jointv"], "validation_")):
        i = 0 if key == "" else 1
        for r, errs in ((rounds[0][i], getattr(rep, f"before_{key}rel_err")), (rounds[-1][i], getattr(rep, f"after_{key}rel_err"))):
            e = np.sqrt(np.bincount(joint, r ** 2) / np.bincount(joint, y ** 2))
            assert e == pytest.approx(errs, rel=1e-6)
    # one residual figure per effect, identification and validation panels, non-blank
    ids = re.findall(r'<figure id="fig-([a-z0-9-]+)">', html)
    assert ids[0] == "diagnosis-errors"
    assert [f"diagnosis-effect-{i}-{e.kind}" for i, e in enumerate(rep.effects, 1)] == \
           [s for s in ids if s.startswith("diagnosis-effect-")]
    assert ids[-2:] == ["diagnosis-torque-identification", "diagnosis-torque-validation"]
    imgs = dict(zip(ids, embedded_images(html)))
    png, w, h = imgs["diagnosis-effect-1-stribeck"]
    rgb = decode_png(png)
    assert rgb.shape == (h, w, 3) == (390, 1100, 3)
    assert ink_stats(rgb)[0] > 0.03
    # tables: errors before/after and the effect with its parameters
    text = IMG_RE.sub("", html)
    assert "Effects added, in order" in text and "<td>stribeck</td><td>joint 2</td>" in text
    for lab, errs in (("validation, before", rep.before_validation_rel_err), ("validation, after", rep.after_validation_rel_err)):
        row = re.search(rf"<td>{lab}</td>((?:<td class=\"num\">[^<]*</td>)+)", text).group(1)
        assert [float(x) for x in re.findall(r">([^<]*)<", row) if x] == pytest.approx(errs, abs=6e-5)
    md = write_report(tmp_path / "diag.md", diagnosis=rep).read_text(encoding="utf-8")
    assert "diag_files/diagnosis-effect-1-stribeck.png" in md


def test_diagnosis_html_tables_without_plots(diagnosis):
    from symoro_gen.diagnostics.render import diagnosis_html

    from .test_repr_html import parse

    html = diagnosis_html(diagnosis)
    assert "<img" not in html
    p = parse(html)
    errs = next(t for t in p.tables if t[0][1][0] == "Data")
    assert [r[1][0] for r in errs[1:]] == ["identification, before", "identification, after", "validation, before",
                                          "validation, after"]
    assert [float(x) for x in errs[4][1][1:]] == pytest.approx(diagnosis.after_validation_rel_err, abs=6e-5)
    effects = next(t for t in p.tables if t[0][1][:3] == ["#", "Effect", "Where"])
    assert [(c[1], c[2]) for _, c in effects[1:]] == [(e.kind, f"joint {e.joint + 1}") for e in diagnosis.effects]


@pytest.mark.slow
def test_each_effect_plot_shows_its_own_residual_change_on_the_real_lwr4(shared_data):
    """On the real LWR4 the stability stage drops effects the loop named (only WLS names them): the effects kept
    were named in rounds 1, 3, 5..., while the residuals behind the plots are after the first 1, 2, 3... effects
    kept. Every loop effect still gets its figure, drawn from the residual just before and just after it: the
    figure's pair is the one whose change on the effect's own joint is the largest of all pairs (adding the
    effect's columns is what changes that joint), and its 'after' residual of the last effect is the final one."""
    import symoro_gen
    from symoro_gen.diagnostics.render import diagnosis_blocks, diagnosis_plot_series, residual_position
    from symoro_gen.report import Figure

    d = shared_data / "kuka_lwr4_flobaroid/data/KUKA/HW"
    res = symoro_gen.diagnose("lwr4", [d / "measurements_1.npz", d / "measurements_3.npz"],
                              validate=[d / "measurements_2.npz"])
    rep = res.residual
    ser = diagnosis_plot_series(rep)
    loop = [e for e in rep.effects if e.kind != "friction_law" and e.round >= 1]
    assert loop and len(ser["rounds"]) == len(loop) + 1
    positions = [residual_position(e, ser) for e in loop]
    assert positions == list(range(1, len(loop) + 1))
    for e, k in zip(loop, positions):
        rows = ser["joint"] == e.joint
        drop = [np.linalg.norm(ser["rounds"][m - 1][0][rows]) - np.linalg.norm(ser["rounds"][m][0][rows])
                for m in range(1, len(ser["rounds"]))]
        assert int(np.argmax(drop)) + 1 == k, (e.label, drop)
    names = [b.name for b in diagnosis_blocks(rep, [], plots=True) if isinstance(b, Figure)]
    assert [n for n in names if n.startswith("diagnosis-effect-")] == [
        f"diagnosis-effect-{i}-{e.kind.replace('_', '-')}" for i, e in enumerate(rep.effects, 1) if e in loop]


def test_effects_table_shows_no_nan_where_the_json_has_no_number(diagnosis):
    """An effect without a validation z (a friction law, chosen by cross-validation: ``z_validation`` NaN, null in
    the JSON) shows '-' in the report's effects table, as every other value the JSON leaves out; a z the JSON
    has is shown as a number."""
    import dataclasses
    import math

    from symoro_gen.diagnostics.render import diagnosis_html

    from .test_repr_html import parse

    e0 = diagnosis.effects[0]
    rep = dataclasses.replace(diagnosis, effects=(dataclasses.replace(e0, z_validation=math.nan),
                                                  *diagnosis.effects))
    table = next(t for t in parse(diagnosis_html(rep)).tables if t[0][1][:2] == ["#", "Effect"])
    col = table[0][1].index("z_val")
    zs = [row[1][col] for row in table[1:]]
    json_z = [e["z_validation"] for e in rep.to_dict()["effects"]]
    assert json_z[0] is None and zs[0] == "-"
    assert all(float(z) == pytest.approx(j, rel=1e-3) for z, j in zip(zs[1:], json_z[1:]))
