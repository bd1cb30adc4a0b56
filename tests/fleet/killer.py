"""A per-file kernel that kills its worker process the first time it runs (for the lost-worker test).

Module-level so that the worker processes import it by name."""
import os

from symoro_gen.fleet.kernel import process_file


def kill_once(model_ref, log, options=None, load_kw=None, *, marker: str):
    """``process_file``, except that the first call (no marker file yet) ends the worker process."""
    try:
        fd = os.open(marker, os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return process_file(model_ref, log, options, load_kw)
    os.close(fd)
    os._exit(1)


def kill_on(model_ref, log, options=None, load_kw=None, *, name: str):
    """``process_file``, except on the log whose path ends with ``name``: that one ends its worker process every
    time (a log a worker always runs out of memory on)."""
    if log.path.endswith(name):
        os._exit(1)
    return process_file(model_ref, log, options, load_kw)


def slow(model_ref, log, options=None, load_kw=None, *, seconds: float):
    """``process_file`` after ``seconds`` of sleep (a task still running while the run is watched)."""
    import time

    time.sleep(seconds)
    return process_file(model_ref, log, options, load_kw)
