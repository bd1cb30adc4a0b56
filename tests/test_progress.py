"""Progress feedback: off in library use, off with --quiet or when stderr is not a terminal, on when
forced (SYMORO_PROGRESS=1 or a terminal), and never changing results."""
import io
import sys

import numpy as np
import pytest

from symoro_gen import progress as P
from symoro_gen.commands.generate import generation_steps
from symoro_gen.simulate import write_recording_csv


class _Tty(io.StringIO):
    """A captured stream that says it is a terminal."""

    def isatty(self):
        return True


@pytest.fixture(autouse=True)
def _no_env(monkeypatch):
    monkeypatch.delenv(P.ENV_VAR, raising=False)


def test_enabled_rules(monkeypatch):
    tty, pipe = _Tty(), io.StringIO()
    assert not P.progress_enabled(stream=tty)  # library default: off, even on a terminal
    with P.progress_mode("auto"):
        assert P.progress_enabled(stream=tty) and not P.progress_enabled(stream=pipe)
        monkeypatch.setenv(P.ENV_VAR, "1")
        assert P.progress_enabled(stream=pipe)
        monkeypatch.setenv(P.ENV_VAR, "0")
        assert not P.progress_enabled(stream=tty)
        assert P.progress_enabled(True, stream=pipe) and not P.progress_enabled(False, stream=tty)
    with P.progress_mode("off"):
        monkeypatch.setenv(P.ENV_VAR, "1")
        assert not P.progress_enabled(stream=tty)  # --quiet wins over the environment
    with P.progress_mode("on"):
        assert P.progress_enabled(stream=pipe)
    assert P.current_mode() == "off"
    with pytest.raises(ValueError), P.progress_mode("loud"):
        pass


def test_null_bar_writes_nothing(capsys):
    with P.progress_bar(3, "x") as bar:
        bar.update(3)
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("with_tqdm", [True, False])
def test_forced_bar_draws(monkeypatch, with_tqdm):
    if with_tqdm:
        pytest.importorskip("tqdm")
    else:
        monkeypatch.setitem(sys.modules, "tqdm", None)  # import fails: text fallback
    s = io.StringIO()
    with P.progress_bar(4, "loading data", enabled=True, unit="file", stream=s) as bar:
        for _ in range(4):
            bar.update(1)
    out = s.getvalue()
    assert "loading data" in out and "/4" in out
    if not with_tqdm:
        assert "4/4 file" in out  # the text bar draws its last state


def test_progress_updates_forms():
    got = []
    with P.progress_updates(got.append, total=3) as step:
        step(2)
        step(1)
    assert got == [2, 1]
    with P.progress_updates(False, total=3) as step:
        step(3)  # no bar, no error
    s = _Tty()
    with P.progress_mode("auto"):
        sys_stderr = sys.stderr
        try:
            sys.stderr = s
            with P.progress_updates(None, total=2, desc="assembling W") as step:
                step(2)
        finally:
            sys.stderr = sys_stderr
    assert "assembling W" in s.getvalue()


def test_close_all_closes_open_bars():
    s = io.StringIO()
    bar = P.progress_bar(10, "left open", enabled=True, stream=s)
    bar.update(1)
    P.close_all()
    assert bar not in set(P._OPEN)
    assert getattr(bar, "disable", False) or getattr(bar, "stream", 0) is None  # tqdm / text bar closed


def test_generation_stage_count_matches_newton_euler():
    from symoro_gen.description import load_robot
    from symoro_gen.dynamics.newton_euler import build_regressor

    for name in ("scara", "lwr4"):  # lwr4 has a payload frame
        robot = load_robot(name)
        calls = []
        build_regressor(robot, progress=lambda stage, j: calls.append((stage, j)))  # noqa: B023 - called in this iteration
        assert {s for s, _ in calls} == {"forward", "backward"}
        assert len(calls) + 2 == generation_steps(robot)


def test_generate_quiet_without_terminal(tmp_path, cli):
    # the captured stderr is not a terminal: no bar even without --quiet
    cap = cli("generate", "scara", "--out", tmp_path, rc=0)
    assert cap.err == "" and "22 base parameters" in cap.out


class _SpyBar:
    def __init__(self, total, desc, **kw):
        self.total, self.descs, self.n = total, [desc], 0
        SPIES.append(self)

    def update(self, n=1):
        self.n += n

    def set_description(self, desc, refresh=True):
        self.descs.append(desc)

    def close(self):
        pass

    def __enter__(self):
        return self

    def __exit__(self, *a):
        pass


SPIES: list = []


def test_generate_stages_on_the_bar(tmp_path, monkeypatch, cli):
    SPIES.clear()
    monkeypatch.setattr(P, "progress_bar", _SpyBar)
    cli("--quiet", "generate", "lwr4", "--out", tmp_path, rc=0)
    (bar,) = SPIES
    assert bar.n == bar.total == 8 + 8 + 2  # 8 frames forward, 7 links + payload backward, base, emission
    text = " | ".join(bar.descs)
    for stage in ("newton-euler forward (link 1)", "newton-euler backward (link 8)", "base parameters", "emission"):
        assert stage in text


def test_generate_bar_when_forced(tmp_path, monkeypatch, cli):
    monkeypatch.setenv(P.ENV_VAR, "1")
    err = cli("generate", "scara", "--out", tmp_path, rc=0).err
    assert "scara" in err and "/10 [" in err  # a bar over the 10 steps
    # --quiet wins over the environment
    assert cli("--quiet", "generate", "scara", "--out", tmp_path, rc=0).err == ""


def test_generate_bar_on_fake_terminal(tmp_path, monkeypatch, cli):
    tty = _Tty()
    monkeypatch.setattr(sys, "stderr", tty)
    cli("generate", "scara", "--out", tmp_path, "--quiet", rc=0, capture=False)  # stderr: the fake terminal
    assert tty.getvalue() == ""
    cli("generate", "scara", "--out", tmp_path, rc=0, capture=False)
    assert "/10 [" in tty.getvalue()


def test_generate_output_unchanged_by_progress(tmp_path, monkeypatch, cli):
    """The command's staged generation writes exactly what emit_robot writes."""
    from symoro_gen.description import load_robot
    from symoro_gen.emit.package import emit_robot

    monkeypatch.setenv(P.ENV_VAR, "1")
    cli("generate", "scara", "--out", tmp_path / "cli", rc=0)
    emit_robot(load_robot("scara"), tmp_path / "lib")
    a, b = tmp_path / "cli" / "scara", tmp_path / "lib" / "scara"
    names = sorted(p.name for p in a.iterdir() if p.is_file())
    assert names == sorted(p.name for p in b.iterdir() if p.is_file())
    for n in names:
        assert (a / n).read_bytes() == (b / n).read_bytes(), n


# ---------------------------------------------------------------------------------------------
# data loading and assembly
# ---------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    from symoro_gen.loader import model_for
    from symoro_gen.simulate.parameters import random_physical_parameters
    from symoro_gen.simulate.recording import simulate_recording
    from symoro_gen.simulate.trajectories import fourier_trajectory

    rng = np.random.default_rng(7)
    robot, model = model_for("scara")
    chi = random_physical_parameters(robot, rng)
    chi = getattr(chi, "chi_std", chi)
    d = tmp_path_factory.mktemp("rec")
    files, trajs = [], []
    n = robot.n_joints
    for k in range(2):
        t, q, dq, ddq = fourier_trajectory(n, 6.0, 0.002, rng)
        tr = simulate_recording(model, t, q, dq, ddq, chi, noise_q=1e-5, noise_tau=0.01, rng=rng)
        f = d / f"rec{k}.csv"
        write_recording_csv(f, tr)
        files.append(str(f))
        trajs.append(tr)
    return robot, model, files, trajs


def test_load_progress_per_file(recordings):
    from symoro_gen.preprocessing.readers import load_trajectories

    robot, _, files, _ = recordings
    got = []
    trs = load_trajectories(files, n_joints=robot.n_joints, progress=got.append)
    assert got == [1, 1] and len(trs) == 2


def test_assembly_progress_counts_samples_and_changes_nothing(recordings):
    from symoro_gen.identification.assemble import build_observation, iter_observation_chunks

    _, model, _, trajs = recordings
    total = sum(t.n_samples for t in trajs)
    got = []
    a = build_observation(model, trajs, progress=got.append)
    b = build_observation(model, trajs, progress=False)
    assert sum(got) == total and all(x >= 0 for x in got)
    assert np.array_equal(a.W, b.W) and np.array_equal(a.Y, b.Y)
    got = []
    chunks = list(iter_observation_chunks(model, trajs, progress=got.append, chunk_samples=1000))
    assert sum(got) == total and len(got) >= len(chunks)


def test_identify_bars_only_when_forced(recordings, tmp_path, monkeypatch, cli):
    _, _, files, _ = recordings
    args = ["identify", "scara", files[0], "--validate", files[1], "--method", "ols", "--json", str(tmp_path / "r.json")]
    assert "assembling W" not in cli(*args, rc=0).err
    monkeypatch.setenv(P.ENV_VAR, "1")
    err = cli(*args, rc=0).err
    assert "loading data" in err and "assembling W" in err
    assert cli("--quiet", *args, rc=0).err == ""
