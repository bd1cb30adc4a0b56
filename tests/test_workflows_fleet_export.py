"""The ``fleet`` and export workflows against their commands: ``symoro_gen.fleet(...)`` returns the results object the
command writes and prints (``to_dict()`` is exactly its JSON, ``summary()`` its text), named options (an unknown one
names the nearest), and ``export_urdf/mjcf/par("scara")`` give the text of ``symoro-gen export-* scara -o F``."""
from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen.commands import fleet as fleet_command
from symoro_gen.errors import OptionError, OutputError
from symoro_gen.report import MissingDependencyError
from symoro_gen.workflows import SCHEMA_VERSION, FleetOptions, FleetResults
from symoro_gen.workflows.export_report import body_values

from .golden.inputs import write_inputs

BY = "{robot}/{day}.parquet"


@pytest.fixture(scope="module")
def tiny_fleet(tmp_path_factory):
    pytest.importorskip("distributed", reason="the fleet extra (dask[distributed]) is not installed")
    pytest.importorskip("pyarrow", reason="the fleet extra (pyarrow) is not installed")
    root = tmp_path_factory.mktemp("tiny-fleet")
    symoro_gen.fleet.simulate_fleet(root, "scara", n_robots=2, n_days=2, duration=3.0, seed=3)
    return root


def test_fleet_is_the_command(tiny_fleet, cli, tmp_path, monkeypatch):
    """The command's JSON file is ``to_dict()`` of the result it computed, its standard output ``summary()``; a
    second run from Python gives the same document but for the timing."""
    seen, workflow = [], fleet_command.fleet

    def spy(*args, **kwargs):
        seen.append(workflow(*args, **kwargs))
        return seen[-1]

    monkeypatch.setattr(fleet_command, "fleet", spy)
    out = tmp_path / "fleet.json"
    r = cli("fleet", "scara", tiny_fleet, "--by", BY, "--scheduler", "threads:2", "--json", out)
    (res,) = seen
    assert isinstance(res, FleetResults) and res.command == "fleet"
    written = json.loads(out.read_text())
    assert res.to_dict() == written
    assert r.out == res.summary() + "\n"
    assert written["generator"] == "symoro-gen fleet" and written["schema_version"] == SCHEMA_VERSION
    prov = written["provenance"]
    assert prov["options"]["scheduler"] == "threads:2" and len(prov["inputs"]) == 4
    assert all(len(x["sha256"]) == 64 for x in prov["inputs"])
    # the library call: the same options, the same document (the timing aside)
    lib = symoro_gen.fleet("scara", tiny_fleet, by=BY, scheduler="threads:2")
    doc = lib.to_dict()
    assert {k: v for k, v in doc.items() if k != "timing"} == {k: v for k, v in written.items() if k != "timing"}
    assert lib.summary() == res.summary() and str(lib) == lib.summary()
    assert lib.options == FleetOptions(scheduler="threads:2")


def test_fleet_options_are_named_and_checked(tiny_fleet):
    with pytest.raises(OptionError, match="unknown option 'schedular'; did you mean 'scheduler'"):
        symoro_gen.fleet("scara", tiny_fleet, by=BY, schedular="threads:2")
    with pytest.raises(OptionError, match="not both"):
        symoro_gen.fleet("scara", tiny_fleet, by=BY, options=FleetOptions(), alpha=0.05)
    with pytest.raises(OptionError, match="correction 'fdr'"):
        FleetOptions(correction="fdr")
    with pytest.raises(ValueError, match="alpha must be in"):
        FleetOptions(alpha=2.0)
    assert FleetOptions(cutoff=12.0).as_dict()["cutoff"] == 12.0


@pytest.mark.parametrize(("command", "suffix", "call"), [
    ("export-urdf", ".urdf", lambda: symoro_gen.export_urdf("scara")),
    ("export-mjcf", ".xml", lambda: symoro_gen.export_mjcf("scara")),
    ("export-par", ".par", lambda: symoro_gen.export_par("scara")),
])
def test_exports_are_the_commands(cli, tmp_path, command, suffix, call):
    f = tmp_path / f"scara{suffix}"
    cli(command, "scara", "-o", f)
    res = call()
    assert res.text == f.read_text() and res.command == command and res.sidecar is None
    assert res.summary() == res.text and res.to_dict()["generator"] == f"symoro-gen {command}"
    # written by the library: the same bytes, and replaced only when symoro-gen wrote the file
    g = tmp_path / f"lib{suffix}"
    assert res.write(g) == [g] and g.read_text() == f.read_text()
    res.write(g)
    other = tmp_path / f"other{suffix}"
    other.write_text("mine")
    with pytest.raises(OutputError, match="was not written by symoro-gen"):
        res.write(other)


def test_export_urdf_params_from_a_result_mapping(cli, tmp_path):
    """``params`` as an identify JSON file or its content give the command's ``--params`` text."""
    doc = {"parameters": {"names": ["FV1"], "values": [0.25]}}
    src = tmp_path / "r.json"
    src.write_text(json.dumps(doc))
    f = tmp_path / "p.urdf"
    cli("export-urdf", "scara", "--params", src, "-o", f)
    assert symoro_gen.export_urdf("scara", params=doc).text == f.read_text()
    assert symoro_gen.export_urdf("scara", params=src).text == f.read_text()
    assert symoro_gen.export_urdf("scara", params={"FV1": 0.25}).text == f.read_text()


# ---- the exports' results: JSON with provenance, figure, report --------------------------------------------------
#: the sidecar's keys before schema_version and provenance were added (the file's contract: keys only added)
SIDECAR_KEYS = ("generator", "robot", "from", "exact", "base_error", "notes", "bodies", "active_constraints", "drive",
                "drive_note", "changed_links")


def _sha256(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def test_export_to_dict_is_the_sidecar_the_command_writes(cli, tmp_path):
    """``export_urdf(from_result=RESULT.json).to_dict()`` is exactly the ``OUT.json`` of ``symoro-gen export-urdf
    --from RESULT.json -o OUT``: the sidecar's keys as before, plus ``schema_version`` and a provenance block
    whose hashes are those of the robot file and the result read; a result given in memory is named so."""
    pytest.importorskip("cvxpy", reason="the physical extra (cvxpy) is not installed")
    a, _ = write_inputs(tmp_path)
    result = tmp_path / "id.json"
    cli("--quiet", "identify", "scara", a, "--method", "wls", "--json", result)
    out = tmp_path / "scara.urdf"
    cli("--quiet", "export-urdf", "scara", "--from", result, "-o", out)
    written = json.loads(Path(str(out) + ".json").read_text())
    res = symoro_gen.export_urdf("scara", from_result=result)
    assert res.to_dict() == written and res.text == out.read_text()
    assert next(iter(written)) == "generator" and set(SIDECAR_KEYS) <= set(written)
    assert written["schema_version"] == SCHEMA_VERSION and list(written)[-1] == "provenance"
    prov = written["provenance"]
    assert prov["options"] == {"params": None, "from_result": str(result)}
    assert prov["inputs"] == [{"path": res.robot.file, "sha256": _sha256(res.robot.file)},
                              {"path": str(result), "sha256": _sha256(result)}]
    mj = symoro_gen.export_mjcf("scara", from_result=json.loads(result.read_text()), timestep=0.002).to_dict()
    assert mj["provenance"]["options"] == {"from_result": "<in memory>", "timestep": 0.002}
    assert mj["provenance"]["inputs"][1] == {"path": "<in memory>", "sha256": None}
    # without an identification: no sidecar file, a minimal document with the same stamp
    par = symoro_gen.export_par("scara").to_dict()
    assert par["schema_version"] == SCHEMA_VERSION and par["robot"] == "scara"
    assert par["provenance"]["inputs"] == [{"path": res.robot.file, "sha256": _sha256(res.robot.file)}]


def test_export_bodies_are_what_pinocchio_reads_from_the_file():
    """The bodies the export's figure and report show are those of the file written: Pinocchio's parse of the
    URDF text gives the same mass, centre of mass and inertia at the centre of mass for every moving link, also
    for a link whose given parameters the exporter had to make physically consistent (LWR4, ``XX2`` breaking
    the triangle inequality); the nominal values are those of the export without parameters. (Pinocchio merges a
    fixed frame, the payload's, into its parent link: that link is left out.)"""
    pin = pytest.importorskip("pinocchio")
    res = symoro_gen.export_urdf("lwr4", params={"M2": 3.0, "MX2": 0.1, "XX2": 0.5})
    assert any("link 2" in n for n in res.notes)
    bodies = {b.frame: b for b in body_values(res.robot, res.values, res.command)}
    for text, which in ((res.text, "exported"), (symoro_gen.export_urdf("lwr4").text, "nominal")):
        model = pin.buildModelFromXML(text)
        merged = {r.ant for r in res.robot.rows if r.sigma == 2}
        for row in (r for r in res.robot.joints if r.j not in merged):
            inert = model.inertias[model.getJointId(f"joint{row.j}")]
            b = bodies[row.j]
            m, c, ic = (b.mass, b.com, b.inertia) if which == "exported" else (
                b.nominal_mass, b.nominal_com, b.nominal_inertia)
            assert np.isclose(inert.mass, m, rtol=1e-9), (which, row.j)
            assert np.allclose(inert.lever, c, atol=1e-9) and np.allclose(inert.inertia, ic, atol=1e-9), (which, row.j)
    assert bodies[2].mass == 3.0 and bodies[2].nominal_mass != 3.0 and bodies[3].com_shift == 0.0


def test_export_report_and_plot(tmp_path):
    """``plot()``: one figure whose panels hold every body's nominal and exported mass; ``report(path)``: HTML with
    the bodies' table and figure, the notes and the text, or Markdown with its image beside it; a file symoro-gen did
    not write is replaced only with ``force``, the robot file (through a symlink) never."""
    pytest.importorskip("matplotlib")
    res = symoro_gen.export_urdf("lwr4", params={"M2": 3.0})
    bodies = body_values(res.robot, res.values, res.command)
    (fig,) = res.plot()
    ax = fig.axes[0]
    heights = [p.get_height() for p in ax.patches]
    assert np.allclose(heights, [b.nominal_mass for b in bodies] + [b.mass for b in bodies])
    page = res.report(tmp_path / "e.html").read_text()
    assert page.startswith("<!DOCTYPE html>") and "Bodies" in page and "<img" in page
    assert all(b.label in page for b in bodies) and "joint1" in page
    md = res.report(tmp_path / "e.md")
    assert "Bodies" in md.read_text() and len(list((tmp_path / "e_files").glob("*.png"))) == 1
    mine = tmp_path / "mine.html"
    mine.write_text("mine")
    with pytest.raises(OutputError, match="was not written by symoro-gen"):
        res.report(mine)
    link = tmp_path / "robot.html"
    link.symlink_to(res.robot.file)
    with pytest.raises(OutputError):
        res.report(link, force=True)
    assert mine.read_text() == "mine" and Path(res.robot.file).read_text().startswith(("#", "["))


def _hide_matplotlib(monkeypatch) -> None:
    """This interpreter as without the 'plots' extra: every matplotlib module unimportable."""
    for name in [m for m in sys.modules if m == "matplotlib" or m.startswith("matplotlib.")] + ["matplotlib"]:
        monkeypatch.setitem(sys.modules, name, None)


def test_reports_without_matplotlib_name_the_extra(tiny_fleet, monkeypatch, tmp_path):
    """Without matplotlib, ``plot()`` and ``report()`` of an export and of ``read_recording``, and ``report()`` of a
    fleet run in which no robot is flagged (its report would have no figure) raise :class:`MissingDependencyError` naming the 'plots'
    extra, and write nothing."""
    fleet = symoro_gen.fleet("scara", tiny_fleet, by=BY, scheduler="threads:1")
    assert not fleet.flagged
    exported = symoro_gen.export_par("scara")
    recording = symoro_gen.read_recording(sorted(tiny_fleet.rglob("*.parquet"))[0], n_joints=4)
    _hide_matplotlib(monkeypatch)
    for call in (exported.plot, lambda: exported.report(tmp_path / "e.html"),
                 lambda: fleet.report(tmp_path / "f.html"), lambda: fleet.report(tmp_path / "f.md"),
                 recording.plot, lambda: recording.report(tmp_path / "r.html")):
        with pytest.raises(MissingDependencyError) as err:
            call()
        assert "[plots]" in (err.value.hint or "")
    assert not list(tmp_path.iterdir())
