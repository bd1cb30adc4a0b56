"""The library's promises across every public entry point of ``symoro_gen`` (its ``__init__`` exports):
a misspelt option raises :class:`~symoro_gen.errors.OptionError` naming the nearest valid one; ``plot()`` and
``report()`` without matplotlib name the extra to install; the scripts' contract on the real LWR4 recording
(``identify("lwr4", [f1, f3], validate=[f2], method="wls").to_dict()["validation"]["rel_err"]`` is the list
of the command's JSON)."""
from __future__ import annotations

import hashlib
import inspect
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import symoro_gen
from symoro_gen import workflows
from symoro_gen.errors import OptionError, OutputError

from .golden.inputs import write_inputs
from .test_import_layout import ISSUE_NUMBER

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    return write_inputs(tmp_path_factory.mktemp("contract"))[0]


#: one misspelt option per public entry point: (call, the keyword given, the name it should suggest)
MISSPELT = [
    ("identify", lambda rec, **kw: symoro_gen.identify("scara", rec, **kw), "metod", "method"),
    ("diagnose", lambda rec, **kw: symoro_gen.diagnose("scara", rec, **kw), "max_efects", "max_effects"),
    # the workflows' own keywords (data given beside the options) are named too
    ("identify", lambda rec, **kw: symoro_gen.identify("scara", rec, **kw), "valdate", "validate"),
    ("diagnose", lambda rec, **kw: symoro_gen.diagnose("scara", rec, **kw), "valdate", "validate"),
    ("diagnose", lambda rec, **kw: symoro_gen.diagnose("scara", rec, **kw), "loadded", "loaded"),
    ("excite", lambda rec, **kw: symoro_gen.excite("scara", **kw), "ouptut", "output"),
    ("inspect", lambda rec, **kw: symoro_gen.inspect("scara", rec, **kw), "cutof", "cutoff"),
    ("excite", lambda rec, **kw: symoro_gen.excite("scara", **kw), "duraton", "duration"),
    ("fleet", lambda rec, **kw: symoro_gen.fleet("scara", [rec], by="{robot}/{day}.csv", **kw), "alpah", "alpha"),
    ("read_recording", lambda rec, **kw: symoro_gen.read_recording(rec, **kw), "n_joint", "n_joints"),
    ("read_recording", lambda rec, **kw: symoro_gen.read_recording(rec, n_joints=4, **kw), "topik", "topic"),
    ("export_urdf", lambda rec, **kw: symoro_gen.export_urdf("scara", **kw), "from_results", "from_result"),
    ("export_mjcf", lambda rec, **kw: symoro_gen.export_mjcf("scara", **kw), "time_step", "timestep"),
    ("export_par", lambda rec, **kw: symoro_gen.export_par("scara", **kw), "robots", "robot"),
]


@pytest.mark.parametrize(("what", "call", "given", "nearest"), MISSPELT, ids=[f"{m[0]}-{m[2]}" for m in MISSPELT])
def test_a_misspelt_option_names_the_nearest(recording, what, call, given, nearest):
    """Every entry point checks its keyword names before any work and names the nearest valid one (an
    :class:`OptionError`, a ``ValueError``: the same as a bad option value)."""
    with pytest.raises(OptionError, match=f"^{what}: unknown option '{given}'; did you mean '{nearest}'"):
        call(recording, **{given: 1})


def test_named_options_keeps_the_signature():
    """The exports' keyword check leaves their signature as written (no ``**kwargs``: help() and IDEs show
    the options) and passes the valid keywords through unchanged."""
    params = inspect.signature(symoro_gen.export_mjcf).parameters
    assert list(params) == ["robot", "from_result", "timestep"]
    assert all(p.kind is not p.VAR_KEYWORD for p in params.values())
    with pytest.raises(OptionError, match="timestep -1"):
        symoro_gen.export_mjcf("scara", timestep=-1)


@pytest.mark.slow
def test_plot_and_report_without_matplotlib_name_the_extra(recording, tmp_path):
    """On an install without the 'plots' extra (matplotlib hidden in a fresh interpreter), ``plot()`` and
    ``report()`` of inspect, excite and diagnose raise :class:`MissingDependencyError` naming the extra, and
    write nothing (identify: tests/test_workflows.py)."""
    code = (
        "import sys; sys.modules['matplotlib'] = None\n"
        "import symoro_gen\n"
        "a, out = sys.argv[1], sys.argv[2]\n"
        "res = {'inspect': symoro_gen.inspect('scara', a),\n"
        "       'excite': symoro_gen.excite('scara', duration=2, harmonics=3, rate=50, starts=1, pool=1, max_iter=5,\n"
        "                                   refine=0),\n"
        "       'diagnose': symoro_gen.diagnose('scara', a, candidates=('offset',), max_effects=1)}\n"
        "for k, r in res.items():\n"
        "    for name, call in (('plot', r.plot), ('report', lambda: r.report(f'{out}/{k}.html'))):\n"
        "        try:\n"
        "            call()\n"
        "            print(k, name, 'no error')\n"
        "        except Exception as exc:\n"
        "            print(k, name, type(exc).__name__, exc, exc.hint if getattr(exc, 'hint', None) else '')\n")
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", code, str(recording), str(tmp_path)], capture_output=True, text=True,
                       env=env, check=False, timeout=600)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.splitlines()
    assert [line.split()[:2] for line in lines] == [[k, m] for k in ("inspect", "excite", "diagnose")
                                                   for m in ("plot", "report")], lines
    assert all(line.split()[2] == "MissingDependencyError" and "[plots]" in line for line in lines), lines
    assert not list(tmp_path.iterdir())


@pytest.mark.slow
@pytest.mark.realdata
def test_the_scripts_contract_on_the_real_lwr4(shared_data, cli, tmp_path):
    """``symoro_gen.identify("lwr4", [f1, f3], validate=[f2], method="wls")`` on the FloBaRoID recordings (files 1
    and 2 repeat one trajectory, 3 is another: shared/data/README.md): ``to_dict()["validation"]["rel_err"]`` is
    the per-joint list the command's JSON holds, one relative error per joint of the LWR4, each below 1 (the
    model explains most of each joint's torque on the repeated trajectory)."""
    hw = shared_data / "kuka_lwr4_flobaroid" / "data" / "KUKA" / "HW"
    f1, f2, f3 = (hw / f"measurements_{k}.npz" for k in (1, 2, 3))
    if not all(f.is_file() for f in (f1, f2, f3)):
        pytest.skip(f"the LWR4 recordings are not in {hw}")
    out = tmp_path / "lwr4.json"
    cli("--quiet", "identify", "lwr4", f1, f3, "--validate", f2, "--method", "wls", "--json", out)
    res = symoro_gen.identify("lwr4", [f1, f3], validate=[f2], method="wls")
    rel = res.to_dict()["validation"]["rel_err"]
    assert rel == json.loads(out.read_text())["validation"]["rel_err"]
    assert len(rel) == 7 and all(0 < x < 1 for x in rel), rel


def _python_blocks(text: str) -> list[list[str]]:
    """The lines of each fenced ```python block of a Markdown text."""
    blocks, current = [], None
    for line in text.splitlines():
        if current is None and line.strip() == "```python":
            current = []
        elif current is not None and line.strip() == "```":
            blocks.append(current)
            current = None
        elif current is not None:
            current.append(line)
    return blocks


def test_readme_stays_a_front_page():
    """README.md: at most 300 lines, what the package is and a tour, the Python API in about a dozen lines,
    links into docs/ and no results tables (those live in docs/results.md) nor issue numbers; docs/ free of
    issue numbers too (features are named)."""
    readme = (ROOT / "README.md").read_text()
    lines = readme.splitlines()
    assert len(lines) <= 300, len(lines)
    assert not [x for x in lines if x.lstrip().startswith("|") and x.rstrip().endswith("|")], "a table in README.md"
    blocks = _python_blocks(readme)
    assert blocks and all(len([x for x in b if x.strip()]) <= 12 for b in blocks), blocks
    assert "symoro-gen identify" in readme and "symoro-gen diagnose" in readme and "(docs/" in readme
    found = [f"{p.relative_to(ROOT)}:{k}" for p in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")),
                                                    *sorted((ROOT / "docs").rglob("*.json"))]
             for k, line in enumerate(p.read_text().splitlines(), start=1) if ISSUE_NUMBER.search(line)]
    assert not found, found


def test_callable_packages_show_the_workflows_signature():
    """``symoro_gen.excite`` and ``symoro_gen.fleet`` are packages callable as their workflows: what
    :func:`inspect.signature` (help, IDEs, Jupyter's ``?``) shows is the workflow's signature, not ``*args``."""
    assert inspect.signature(symoro_gen.excite) == inspect.signature(workflows.excite)
    assert inspect.signature(symoro_gen.fleet) == inspect.signature(workflows.fleet)
    assert "by" in inspect.signature(symoro_gen.fleet).parameters


def test_read_recording_is_the_readers_pair_and_a_results_object(recording, cli, tmp_path):
    """``symoro_gen.read_recording`` returns the reader's pair (unpacks, compares and indexes as the tuple
    ``(trajectories, load_report)`` of :func:`symoro_gen.preprocessing.readers.read_recording`) as a frozen results
    object: ``summary()`` is the ``Data:`` block ``symoro-gen identify`` prints for the file, ``to_dict()["data"]``
    the file's entry of that command's JSON, with ``schema_version`` and the file's sha256 in ``provenance``."""
    from symoro_gen.preprocessing.readers import read_recording as reader
    from symoro_gen.workflows import SCHEMA_VERSION

    res = symoro_gen.read_recording(recording, n_joints=4)
    trajectories, load = reader(recording, n_joints=4)
    got_t, got_load = res
    assert isinstance(res, tuple) and len(res) == 2 and got_load == load and res[1] == load
    assert len(got_t) == len(trajectories) and all(
        np.array_equal(a.q, b.q) and np.array_equal(a.tau, b.tau) for a, b in zip(got_t, trajectories))
    with pytest.raises(AttributeError):
        res.note = "mine"  # no attribute can be set (a tuple without __dict__)
    out = tmp_path / "id.json"
    r = cli("identify", "scara", recording, "--method", "wls", "--json", out)
    assert r.out.rstrip("\n").endswith(res.summary()) and res.summary().startswith("Data:")
    d = res.to_dict()
    assert d["data"] == json.loads(out.read_text())["data"]
    assert d["schema_version"] == SCHEMA_VERSION and d["generator"] == "symoro-gen read_recording"
    digest = hashlib.sha256(Path(recording).read_bytes()).hexdigest()
    assert d["provenance"]["inputs"] == [{"path": str(recording), "sha256": digest}]
    assert d["experiments"] == [{"source": str(recording), "samples": int(t.n_samples), "t_start": float(t.t[0]),
                                 "t_end": float(t.t[-1]), "joints": 4, "loaded": False} for t in trajectories]
    assert res._repr_html_().startswith('<pre class="symoro-gen-read_recording">')


def test_read_recording_plot_and_report(recording, tmp_path):
    """``plot()``: one figure per experiment and joint (q and tau against t); ``report(path)`` writes them, never
    over the recording read."""
    pytest.importorskip("matplotlib")
    res = symoro_gen.read_recording(recording, n_joints=4)
    figs = res.plot()
    assert len(figs) == 4 and all(len(f.axes) == 2 for f in figs)
    line = figs[0].axes[0].lines[0]
    assert np.array_equal(line.get_ydata(), res.trajectories[0].q[:, 0][::max(1, res.trajectories[0].n_samples
                                                                                // 4000)])
    page = res.report(tmp_path / "r.html").read_text()
    assert page.count("<img") == 4 and "Signals per joint" in page
    link = tmp_path / "rec.html"
    link.symlink_to(recording)
    with pytest.raises(OutputError):
        res.report(link, force=True)


@pytest.mark.parametrize("as_given", ["name", "description", "model"])
def test_read_recording_takes_the_robot_as_identify_does_and_applies_its_drive_chain(as_given, tmp_path):
    """``symoro_gen.read_recording(path, robot=...)`` reads a file as the commands read their DATA: the robot as a
    name, a :class:`RobotDescription` or a loaded model (as ``identify`` takes it), and the robot file's
    ``[drive_chain]`` maps a motor-side recording to the joint side. Checked on the TX40 (gear ratios, the coupled
    wrist, zero offsets): motor-side signals made from known joint-side ones by the inverse mapping are read back
    as those joint-side signals, and as ``identify`` reads the same file."""
    from symoro_gen.description import load_robot
    from symoro_gen.preprocessing.drive_chain import joint_to_motor
    from symoro_gen.workflows.base import as_trajectories

    robot = load_robot("tx40")
    rng = np.random.default_rng(5)
    t = np.arange(200) * 0.002
    q = 0.3 * np.sin(2 * np.pi * np.outer(t, rng.uniform(0.2, 1.0, 6)) + rng.uniform(0, 6, 6))
    tau = rng.normal(size=(200, 6))
    q_m, tau_m = joint_to_motor(robot.drive_chain, q=q, tau=tau)[:2]
    np.savetxt(tmp_path / "pos.csv", q_m, delimiter=",")
    np.savetxt(tmp_path / "cur.csv", tau_m, delimiter=",")
    spec = f"q={tmp_path / 'pos.csv'},tau={tmp_path / 'cur.csv'},dt=0.002"
    given = {"name": "tx40", "description": robot, "model": symoro_gen.load_model("tx40")}[as_given]
    (tr,), _ = symoro_gen.read_recording(spec, robot=given)
    assert np.allclose(tr.q, q, atol=1e-9) and np.allclose(tr.tau, tau, atol=1e-9)
    (ref,), _ = as_trajectories(spec, None, robot)
    assert np.array_equal(tr.q, ref.q) and np.array_equal(tr.tau, ref.tau)


def test_data_options_by_name_as_the_commands_flags(recording, cli, tmp_path):
    """The data options are named as the command's flags (``--columns``, ``--dt``, ``--tau-scale``...: docs/
    data-files.md) from Python too: ``identify(..., columns=..., dt=..., tau_scale=...)`` reads a headerless log
    without a time column as ``symoro-gen identify ... --columns ... --dt ... --tau-scale ...`` does (the same
    parameters as the command's JSON), and as ``data_format=LogFormat(...)`` does; both at once is an error."""
    from symoro_gen.preprocessing.readers import make_format

    a = np.loadtxt(recording, delimiter=",", skiprows=1)
    log = tmp_path / "log.txt"  # no header, no time column: tau scaled by 1/2, then two status columns
    np.savetxt(log, np.column_stack([a[:, 1:5], 0.5 * a[:, 5:9], np.zeros((len(a), 2))]))
    dt = float(np.median(np.diff(a[:, 0])))
    flags = dict(columns="q=0:4,tau=4:8", dt=dt, tau_scale=2.0)
    res = symoro_gen.identify("scara", log, method="wls", **flags)
    out = tmp_path / "id.json"
    cli("identify", "scara", log, "--method", "wls", "--columns", "q=0:4,tau=4:8", "--dt", repr(dt),
        "--tau-scale", "2", "--json", out)
    want = json.loads(out.read_text())["parameters"]["values"]
    assert np.allclose(res.to_dict()["parameters"]["values"], want, rtol=1e-9, atol=1e-12)
    same = symoro_gen.identify("scara", log, method="wls", data_format=make_format(**flags))
    assert np.array_equal(same.result.values, res.result.values)
    direct = symoro_gen.identify("scara", recording, method="wls")
    assert np.allclose(res.result.values, direct.result.values, rtol=1e-6, atol=1e-9)
    ins = symoro_gen.inspect("scara", log, **flags)
    assert ins.usable
    with pytest.raises(OptionError, match="data_format"):
        symoro_gen.identify("scara", log, dt=dt, data_format=make_format(dt=dt))


@pytest.mark.parametrize("workflow", ["identify", "diagnose"])
def test_payload_as_the_commands_items_or_a_mapping(workflow):
    """``payload=`` takes what ``--payload NAME=VALUE ...`` takes (a list of items, or one string of them) as well as
    a mapping, with the same values as the command's parser; a malformed item raises the command's error naming
    it (not a bare ``ValueError`` of ``dict()``)."""
    from symoro_gen.commands.common import parse_payload
    from symoro_gen.errors import IdentificationError

    cls = {"identify": workflows.IdentifyOptions, "diagnose": workflows.DiagnoseOptions}[workflow]
    items = ["M7=2.5", "MX7=0.125", "XX7=1e-3"]
    want = parse_payload(items)
    assert cls.create(workflow, payload=items).payload == want
    assert cls.create(workflow, payload=" ".join(items)).payload == want
    assert cls.create(workflow, payload=want).payload == want
    for bad, named in (("M7", "M7"), (["M7=heavy"], "heavy"), ([("M7", 2.5)], "M7")):
        with pytest.raises(IdentificationError, match=named):
            cls.create(workflow, payload=bad)


def test_the_poorly_identified_warning_names_an_option_that_exists():
    """The warning on parameters with a large %sigma points to the essential parameters by the option that computes
    them (a flag of ``identify``, an option of ``symoro_gen.identify``), and that option, given, leaves only
    parameters within the limit."""
    import re

    from symoro_gen.description import load_robot
    from symoro_gen.simulate import fourier_trajectory, random_physical_parameters, simulate_recording

    rng = np.random.default_rng(2)
    robot, model = load_robot("rx90"), symoro_gen.load_model("rx90")
    chi = np.asarray(random_physical_parameters(robot, rng))
    t, q, dq, ddq = fourier_trajectory(robot.n_joints, 3.0, 0.005, rng)  # short: some parameters poorly seen
    rec = simulate_recording(model, t, q, dq, ddq, chi, noise_q=1e-5, noise_tau=0.5, rng=rng)
    res = symoro_gen.identify("rx90", (rec.t, rec.q, rec.tau), method="wls")
    hint = [w for w in res.to_dict()["warnings"] if "poorly identified" in w]
    assert hint, res.to_dict()["warnings"]
    flag = re.search(r"consider the essential parameters \((--[a-z-]+)\)", hint[0])
    assert flag, hint[0]
    name = flag.group(1)[2:].replace("-", "_")
    assert name in workflows.IdentifyOptions.option_names()
    ess = symoro_gen.identify("rx90", (rec.t, rec.q, rec.tau), method="wls", **{name: True})
    assert not [w for w in ess.to_dict()["warnings"] if "poorly identified" in w]


@pytest.mark.parametrize("command", ["identify", "diagnose", "inspect", "excite", "fleet"])
def test_every_flag_of_the_command_has_its_python_name(command):
    """docs/tutorial-python.md: the options are named as the command's flags without their dashes. Every flag of
    the command is an option of the workflow (its options class, its own keywords, or a data option made into
    ``data_format``), but those that name an output, which are results methods (``write_json``, ``report``,
    ``write_plots``, ``write_plot``, ``write_robot``), and the command line's own ``--quiet``/``--debug``."""
    import argparse

    from symoro_gen.cli import build_parser
    from symoro_gen.workflows.base import DATA_FORMAT_OPTIONS

    fn = getattr(symoro_gen, command)
    opts = {"identify": workflows.IdentifyOptions, "diagnose": workflows.DiagnoseOptions,
            "inspect": workflows.InspectOptions, "excite": workflows.ExciteOptions,
            "fleet": workflows.FleetOptions}[command]
    parser = build_parser(command)
    sub = next((a for a in parser._actions if isinstance(a, argparse._SubParsersAction)), None)
    leaf = sub.choices[command] if sub is not None else parser
    flags = {a.dest for a in leaf._actions if a.dest != "help"}
    names = set(opts.option_names()) | set(inspect.signature(fn).parameters)
    if "data_format" in names:
        names |= set(DATA_FORMAT_OPTIONS)
    outputs = {"json", "report", "plots", "plot", "robot_out", "force", "quiet", "debug"}
    assert flags - names - outputs == set()


def test_one_recordings_arrays_given_as_a_list_get_the_tuple_hint():
    """``identify(robot, [t, q, tau])``: a list is several recordings, so its first item is a bare array; the
    error says to give one recording's arrays as a tuple, and the tuple is then read."""
    t = np.arange(400) * 0.01
    q = 0.5 * np.sin(np.outer(t, [1.0, 1.3, 0.7, 1.9]))
    q[:, 2] *= 0.1
    tau = np.cos(np.outer(t, [1.1, 0.9, 1.7, 1.2]))
    with pytest.raises(OptionError, match=r"got ndarray: a list is read as several recordings; give one .*tuple"):
        symoro_gen.inspect("scara", [t, q, tau])
    assert symoro_gen.inspect("scara", (t, q, tau)).trajectories[0].n_samples == t.size
