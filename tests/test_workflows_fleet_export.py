"""The ``fleet`` and export workflows against their commands: ``symoro_gen.fleet(...)`` returns the results object the
command writes and prints (``to_dict()`` is exactly its JSON, ``summary()`` its text), named options (an unknown one
names the nearest), and ``export_urdf/mjcf/par("scara")`` give the text of ``symoro-gen export-* scara -o F``."""
from __future__ import annotations

import json

import pytest

import symoro_gen
from symoro_gen.commands import fleet as fleet_command
from symoro_gen.errors import OptionError, OutputError
from symoro_gen.workflows import SCHEMA_VERSION, FleetOptions, FleetResults

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
