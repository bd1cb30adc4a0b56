"""Progress feedback for long steps (symbolic generation, data loading, regressor assembly, diagnosis).

Library code never prints on its own: a bar shows only inside :func:`progress_mode` ``"auto"`` or
``"on"`` (the ``symoro-gen`` command enters ``"auto"`` unless ``--quiet``), or when a caller asks
for one explicitly (``enabled=True``). In ``"auto"`` mode a bar is drawn on standard error when it
is a terminal; the environment variable ``SYMORO_PROGRESS`` overrides that test (``1`` forces the
bars, ``0`` hides them). Bars use tqdm when it is installed (the ``plots`` extra), otherwise a
one-line text counter.

How to use it in a long loop (e.g. over diagnosis candidates)::

    from symoro_gen.progress import progress_bar

    with progress_bar(len(candidates), "diagnose: candidates", unit="candidate") as bar:
        for cand in candidates:
            ...
            bar.update(1)

and for a function that takes a ``progress=`` argument (``None``: the ambient bar, ``False``: none,
a callable: called with the number of items just done)::

    with progress_updates(progress, total=n_samples, desc="assembling W", unit="sample") as step:
        for block in blocks:
            ...
            step(block_size)

The symbolic Newton-Euler calls ``progress(stage, j)`` per link; :func:`stage_callback` turns a bar
into such a callback.
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import sys
import time
import weakref
from collections.abc import Callable, Iterator
from typing import TypeAlias

__all__ = [
    "ENV_VAR",
    "MODES",
    "progress_mode",
    "current_mode",
    "progress_enabled",
    "progress_bar",
    "progress_updates",
    "ProgressArg",
    "ProgressCounter",
    "close_all",
    "stage_callback",
]

ENV_VAR = "SYMORO_PROGRESS"
MODES = ("off", "auto", "on")
_MODE: contextvars.ContextVar[str] = contextvars.ContextVar("symoro_progress_mode", default="off")
_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}

#: the ``progress=`` argument of library functions (see :func:`progress_updates`)
ProgressArg: TypeAlias = "bool | Callable[[int], object] | None"


@contextlib.contextmanager
def progress_mode(mode: str) -> Iterator[None]:
    """Set the ambient progress mode within a ``with`` block.

    Parameters
    ----------
    mode : {"off", "auto", "on"}
        ``"off"``: no bars (the library default); ``"auto"``: bars when standard error is a terminal
        (``SYMORO_PROGRESS=1``/``0`` overrides); ``"on"``: always.
    """
    if mode not in MODES:
        raise ValueError(f"progress mode must be one of {MODES}, got {mode!r}")
    token = _MODE.set(mode)
    try:
        yield
    finally:
        _MODE.reset(token)


def current_mode() -> str:
    """The ambient progress mode (``"off"`` unless inside :func:`progress_mode`)."""
    return _MODE.get()


def _isatty(stream) -> bool:
    isatty = getattr(stream, "isatty", None)
    if isatty is None:
        return False
    try:
        return bool(isatty())
    except (ValueError, OSError):  # closed or detached stream
        return False


def progress_enabled(enabled: bool | None = None, stream=None) -> bool:
    """Whether a bar should be drawn.

    Parameters
    ----------
    enabled : bool, optional
        An explicit choice wins; None follows the ambient mode (see :func:`progress_mode`).
    stream : file-like, optional
        Where the bar would go (default: ``sys.stderr`` at call time).
    """
    if enabled is not None:
        return bool(enabled)
    mode = _MODE.get()
    if mode == "off":
        return False
    if mode == "on":
        return True
    env = os.environ.get(ENV_VAR, "").strip().lower()
    if env in _TRUE:
        return True
    if env in _FALSE:
        return False
    return _isatty(sys.stderr if stream is None else stream)


class _NullBar:
    """A bar that draws nothing (same methods as the others)."""

    n = 0
    total = None

    def update(self, n: int = 1) -> None:
        self.n += n

    def set_description(self, desc: str, refresh: bool = True) -> None:
        pass

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class _TextBar(_NullBar):
    """Fallback without tqdm: ``desc: n/total unit`` rewritten in place on ``stream``."""

    def __init__(self, total, desc, unit, stream, min_interval: float = 0.1):
        self.total, self.desc, self.unit, self.stream = total, desc, unit, stream
        self.min_interval = min_interval
        self.n = 0
        self._last = 0.0
        self._width = 0
        self._draw(force=True)

    def _draw(self, force: bool = False) -> None:
        now = time.monotonic()
        if not force and now - self._last < self.min_interval:
            return
        self._last = now
        tot = f"/{self.total}" if self.total is not None else ""
        pct = f" {100.0 * self.n / self.total:3.0f}%" if self.total else ""
        line = f"{self.desc}:{pct} {self.n}{tot} {self.unit}"
        pad = " " * max(0, self._width - len(line))
        self._width = len(line)
        self.stream.write("\r" + line + pad)
        self.stream.flush()

    def update(self, n: int = 1) -> None:
        self.n += n
        self._draw(force=self.total is not None and self.n >= self.total)

    def set_description(self, desc: str, refresh: bool = True) -> None:
        self.desc = desc
        if refresh:
            self._draw()

    def close(self) -> None:
        if self.stream is not None:
            self._draw(force=True)
            self.stream.write("\n")
            self.stream.flush()
            self.stream = None


_OPEN: weakref.WeakSet = weakref.WeakSet()


def close_all() -> None:
    """Close every bar still open (the command line calls it before printing an error)."""
    for bar in list(_OPEN):
        _OPEN.discard(bar)
        try:
            bar.close()
        except (ValueError, OSError):  # stream already closed
            pass


def progress_bar(total: int | float | None = None, desc: str = "", *, enabled: bool | None = None,
                 unit: str = "it", unit_scale: bool = False, leave: bool = False, stream=None):
    """A progress bar, or a silent stand-in when bars are off.

    Parameters
    ----------
    total : int or float, optional
        Number of items (None: unknown, the bar counts).
    desc : str
        Label shown before the bar.
    enabled : bool, optional
        Force on/off; None follows :func:`progress_enabled`.
    unit : str
        Name of one item (``"link"``, ``"file"``, ``"sample"``...).
    unit_scale : bool
        Show large counts as 1.2M (tqdm only).
    leave : bool
        Keep the finished bar on screen (tqdm only).
    stream : file-like, optional
        Default ``sys.stderr`` at call time.

    Returns
    -------
    object
        With ``update(n=1)``, ``set_description(desc)``, ``close()``; usable as a context manager.
    """
    stream = sys.stderr if stream is None else stream
    if not progress_enabled(enabled, stream):
        return _NullBar()
    try:
        from tqdm import tqdm
    except ImportError:
        bar = _TextBar(total, desc, unit, stream)
    else:
        bar = tqdm(total=total, desc=desc, unit=unit, unit_scale=unit_scale, leave=leave, file=stream,
                   dynamic_ncols=True, disable=False, mininterval=0.1)
    _OPEN.add(bar)
    return bar


def _no_step(n: int = 1) -> None:
    return None


class ProgressCounter:
    """``step(n)`` / ``close()`` over the ``progress=`` argument of a library function, for loops that
    cannot sit in a ``with`` block (generators); see :func:`progress_updates` for the meaning of
    ``progress``. Bars left open by an exception are closed by :func:`close_all`."""

    def __init__(self, progress: ProgressArg, *, total: int | None = None, desc: str = "", unit: str = "it", unit_scale: bool = False):
        self._bar = None
        self.step: Callable[[int], object]
        if callable(progress) and not isinstance(progress, bool):
            self.step = progress
        elif progress is False:
            self.step = _no_step
        else:
            self._bar = progress_bar(total, desc, enabled=True if progress is True else None, unit=unit,
                                     unit_scale=unit_scale)
            self.step = self._bar.update

    def describe(self, desc: str) -> None:
        """Relabel the bar (what the step in progress is, the best value so far); nothing for a callable."""
        if self._bar is not None:
            self._bar.set_description(desc)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None


@contextlib.contextmanager
def progress_updates(progress: ProgressArg, *, total: int | None = None, desc: str = "", unit: str = "it",
                     unit_scale: bool = False) -> Iterator[Callable[[int], object]]:
    """Resolve the ``progress=`` argument of a library function into an ``update(n)`` function.

    Parameters
    ----------
    progress : None, bool or callable
        None: a bar if the ambient mode allows one (see :func:`progress_bar`); False: nothing;
        True: a bar even outside the command line; a callable: called with each increment.
    total, desc, unit, unit_scale
        Passed to :func:`progress_bar`.

    Yields
    ------
    callable
        ``step(n)``: report ``n`` more items done.
    """
    counter = ProgressCounter(progress, total=total, desc=desc, unit=unit, unit_scale=unit_scale)
    try:
        yield counter.step
    finally:
        counter.close()


def stage_callback(bar, prefix: str = "") -> Callable[[str, int], None]:
    """A ``progress(stage, j)`` callback (as :func:`~symoro_gen.dynamics.newton_euler.build_regressor`
    calls it) that names the stage on ``bar`` and advances it by one."""

    def cb(stage: str, j: int) -> None:
        bar.set_description(f"{prefix}{stage}" + (f" (link {j})" if j else ""), refresh=False)
        bar.update(1)

    return cb
