"""``fleet`` errors that used to mislead: a ``--scheduler`` that is none of the forms (tried as an address for
20 s), a Dask worker that dies at start-up (``Stream is closed`` with a hint about files)."""
from __future__ import annotations

import subprocess
import sys

import pytest

from symoro_gen.errors import SymoroError
from symoro_gen.fleet import FleetOptions, simulate_fleet


@pytest.mark.parametrize("bad, words", [
    ("threads:-3", "--scheduler threads:-3: threads:N needs N >= 1 (the number of workers), got -3"),
    ("local:0", "--scheduler local:0: local:N needs N >= 1 (the number of workers), got 0"),
    ("thread:2", "--scheduler thread:2: not a scheduler: give local:N or processes:N"),
    ("tcp://host", "--scheduler tcp://host: not a scheduler: give local:N or processes:N"),
])
def test_a_scheduler_that_is_none_of_the_forms_is_refused_at_once(bad, words, cli, tmp_path):
    r = cli("fleet", "scara", tmp_path, "--by", "{robot}/{day}.parquet", "--scheduler", bad, rc=2)
    assert r.err_lines[0] == f"symoro-gen: error: {words}" or r.err_lines[0].startswith(f"symoro-gen: error: {words}")
    with pytest.raises(SymoroError, match="--scheduler"):
        FleetOptions(scheduler=bad)
    for good in ("threads:1", "local:2", "processes:3", "local", "tcp://10.0.0.2:8786", "scheduler.lan:8786"):
        assert FleetOptions(scheduler=good).scheduler == good


@pytest.mark.slow
def test_a_worker_killed_at_start_up_is_named_with_what_to_do(cli, tmp_path):
    """The worker process ends right after it started (Dask's worker preload: a stand-in for the kernel's OOM
    killer): the error says a worker died at start-up, and the hint proposes threads and fewer workers, not files."""
    simulate_fleet(tmp_path / "logs", "scara", n_robots=2, n_days=1, duration=1.0, drifts=(), seed=1)
    killer = tmp_path / "kill_worker.py"
    killer.write_text("import os\n\n\ndef dask_setup(worker):\n    os._exit(1)\n")
    env = {**cli.env, "DASK_DISTRIBUTED__WORKER__PRELOAD": f'["{killer}"]'}
    r = subprocess.run([sys.executable, "-m", "symoro_gen", "fleet", "scara", str(tmp_path / "logs"), "--by",
                        "{robot}/{day}.parquet", "--scheduler", "local:1"], capture_output=True, text=True, env=env,
                       timeout=240, check=False)
    assert r.returncode == 2, r.stderr
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith(("symoro-gen:", "hint:"))]
    assert lines[0].startswith("symoro-gen: error: --scheduler local:1: a Dask worker died at start-up ("), r.stderr
    assert lines[1].startswith("hint: a worker process that dies at once is most often out of memory"), r.stderr
    assert "--scheduler threads:2" in lines[1] and "path" not in lines[1] and "file" not in lines[1]


def test_a_closed_stream_at_the_workers_setup_is_a_dead_worker_not_a_file(tmp_path, monkeypatch):
    """A worker that dies while the run registers its setup gives Dask's ``CommClosedError: Stream is closed`` (an
    ``OSError``, which the command line took for a file): it is the error of a worker that died at start-up."""
    from distributed.comm.core import CommClosedError

    from symoro_gen.fleet import FleetError, identify_fleet, open_client

    simulate_fleet(tmp_path, "scara", n_robots=2, n_days=1, duration=1.0, drifts=(), seed=1)
    with open_client("threads:1") as client:
        def closed(*a, **k):
            raise CommClosedError("in <TCP (closed) ConnectionPool.register_worker_plugin>: Stream is closed")

        monkeypatch.setattr(client, "register_plugin", closed)
        with pytest.raises(FleetError) as err:
            identify_fleet("scara", [str(tmp_path)], "{robot}/{day}.parquet", FleetOptions(scheduler="local:2"),
                           client=client)
    assert str(err.value).startswith("--scheduler local:2: a Dask worker died at start-up (CommClosedError: ")
    assert not isinstance(err.value, OSError) and "--scheduler threads:2" in err.value.hint


def test_no_usable_log_names_each_problem_not_only_their_count(cli, tmp_path):
    """A log the reader refuses with a list of problems (``1 problem in data:`` and the problem on the next line):
    the fleet's error and its ``skipped`` give the problem itself (file, field), not the bare count."""
    (tmp_path / "r1").mkdir()
    log = tmp_path / "r1" / "d1.csv"
    log.write_text("t,q1,q2,q3,q4\n" + "".join(f"{k * 0.001},0,0,0,0\n" for k in range(50)))
    r = cli("fleet", "scara", tmp_path, "--by", "{robot}/{day}.csv", "--scheduler", "threads:1", rc=2)
    line = r.err_lines[0]
    assert line.startswith(f"symoro-gen: error: fleet: no log could be used; {log}") and "problem in data" not in line
    assert "tau" in line, line
    assert r.err_lines[1].startswith("hint: each log needs the columns t, q1..qn, tau1..taun")


@pytest.mark.slow
def test_a_log_that_kills_its_worker_every_time_stops_the_run_naming_it(tmp_path):
    """A worker process that dies on every attempt at one log (a stand-in for a log it always runs out of memory
    on): Dask re-queues the task after each death and, once the nanny stops restarting the worker, waits for a
    worker forever. The run stops after --retries re-runs (here 1: two deaths) with the log named."""
    import functools
    import time

    from symoro_gen.fleet import FleetError, identify_fleet

    from .killer import kill_on

    simulate_fleet(tmp_path, "scara", n_robots=1, n_days=1, duration=1.0, drifts=(), seed=1)
    log = tmp_path / "r00" / "d00.parquet"
    assert log.is_file()
    t0 = time.monotonic()
    with pytest.raises(FleetError) as err:
        identify_fleet("scara", [str(tmp_path)], "{robot}/{day}.parquet", FleetOptions(scheduler="local:1", retries=1),
                       kernel=functools.partial(kill_on, name="r00/d00.parquet"))
    assert str(err.value) == (f"fleet: {log}: the Dask worker reading it died twice (--retries 1): the run is "
                              "stopped instead of re-running it without end")
    assert "--segment-samples" in err.value.hint and "--scheduler threads:2" in err.value.hint
    assert time.monotonic() - t0 < 200


def test_the_watch_of_a_run_stops_it_on_a_log_whose_workers_died(tmp_path, monkeypatch):
    """The watch itself, on an in-process cluster whose scheduler is made to report the deaths Dask counts per
    task (``suspicious``): more than --retries deaths on one log's task stop the run naming that log; a cluster
    left without workers after they died stops it after WORKERLESS_S."""
    import functools

    import symoro_gen.fleet.engine as engine
    from symoro_gen.fleet import FleetError, identify_fleet, open_client

    from .killer import slow

    simulate_fleet(tmp_path, "scara", n_robots=2, n_days=1, duration=1.0, drifts=(), seed=1)
    monkeypatch.setattr(engine, "WATCH_S", 0.05)
    kernel = functools.partial(slow, seconds=0.6)
    with open_client("threads:2") as client:
        on_scheduler, info = client.run_on_scheduler, client.scheduler_info

        fake = {"-file-r01-": 3}

        def deaths(fn):
            tasks = on_scheduler(lambda dask_scheduler: list(dask_scheduler.tasks))
            return {k: n for k in tasks for part, n in fake.items() if part in k}

        monkeypatch.setattr(client, "run_on_scheduler", deaths)
        with pytest.raises(FleetError) as err:
            identify_fleet("scara", [str(tmp_path)], "{robot}/{day}.parquet", FleetOptions(retries=2),
                           client=client, kernel=kernel)
        assert str(err.value).startswith(f"fleet: {tmp_path / 'r01' / 'd00.parquet'}: the Dask worker reading it "
                                         "died 3 times (--retries 2): the run is stopped")
        # two logs whose tasks were running on the same dying worker each time: both named, as candidates
        fake = {"-file-r01-": 1, "-file-r00-": 1}
        with pytest.raises(FleetError) as err:
            identify_fleet("scara", [str(tmp_path)], "{robot}/{day}.parquet", FleetOptions(retries=0),
                           client=client, kernel=kernel)
        assert str(err.value).startswith(f"fleet: one of {tmp_path / 'r00' / 'd00.parquet'}, "
                                         f"{tmp_path / 'r01' / 'd00.parquet'}: the Dask worker reading it died once "
                                         "(--retries 0)")
        # the same deaths within --retries: the run goes on
        monkeypatch.setattr(client, "run_on_scheduler", lambda fn: {})
        res = identify_fleet("scara", [str(tmp_path)], "{robot}/{day}.parquet", FleetOptions(retries=3),
                             client=client, kernel=kernel)
        assert sorted(res.days) == ["r00", "r01"]
        # workers seen, then none left (a nanny that stopped restarting them): stopped after WORKERLESS_S
        monkeypatch.setattr(engine, "WORKERLESS_S", 0.2)
        looks = []

        def workers_gone(**kw):
            looks.append(1)
            return info(**kw) if len(looks) == 1 else {"workers": {}}

        monkeypatch.setattr(client, "scheduler_info", workers_gone)
        with pytest.raises(FleetError) as err:
            identify_fleet("scara", [str(tmp_path)], "{robot}/{day}.parquet", client=client, kernel=kernel)
        assert str(err.value) == ("--scheduler client: a Dask worker died during the run (RuntimeError: no worker "
                                  "left for 0.2 s)")
