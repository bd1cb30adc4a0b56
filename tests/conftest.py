"""Fixtures shared by every test folder.

* ``shared_data``: the folder of real recordings (``../shared/data`` beside the repository, see its
  README), skipped with the reason when absent. ``SYMORO_SHARED_DATA`` overrides the location;
  otherwise the nearest ``shared/data`` beside the repository or one of its parent folders is used
  (so that a git worktree nested below the checkout finds it too).
* ``cli``: runs ``symoro-gen`` in this process (``main(argv)``, output captured) or, for what needs
  a real process (signals, pipes, the interpreter's own warning printing), as ``python -m symoro_gen``.
"""
from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from symoro_gen.cli import main  # after the path set-up above

DATA_ENV = "SYMORO_SHARED_DATA"


def find_shared_data() -> Path:
    """The real-data folder (may not exist: then the documented ``../shared/data``)."""
    if os.environ.get(DATA_ENV):
        return Path(os.environ[DATA_ENV]).expanduser().resolve()
    for parent in ROOT.parents:
        cand = parent / "shared" / "data"
        if cand.is_dir():
            return cand
    return ROOT.parent / "shared" / "data"


SHARED_DATA = find_shared_data()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real recordings folder; the test is skipped (with the path) when it is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real recordings not available: {SHARED_DATA} is absent (set {DATA_ENV})")
    return SHARED_DATA


@dataclass(frozen=True)
class CliResult:
    """Exit status and captured output of one ``symoro-gen`` run."""

    rc: int
    out: str
    err: str

    @property
    def err_lines(self) -> list[str]:
        return self.err.rstrip("\n").splitlines()


class CliRunner:
    """``symoro-gen`` for tests: ``cli("generate", "scara", rc=0)``.

    ``rc`` (default 0) is asserted unless None; the error output is shown when it differs.
    """

    env: ClassVar[dict[str, str]] = dict(
        os.environ, PYTHONPATH=os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")])))

    def __call__(self, *argv, rc: int | None = 0, capture: bool = True) -> CliResult:
        """Run ``symoro_gen.cli.main(argv)`` here. ``capture=False`` leaves ``sys.stdout``/``sys.stderr``
        alone (for tests that replace them, or read them with ``capsys``)."""
        args = [str(a) for a in argv]
        if capture:
            out, err = io.StringIO(), io.StringIO()
            with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
                status = main(args)
            res = CliResult(int(status or 0), out.getvalue(), err.getvalue())
        else:
            res = CliResult(int(main(args) or 0), "", "")
        if rc is not None:
            assert res.rc == rc, f"symoro-gen {' '.join(args)}: exit {res.rc}, expected {rc}\n{res.err}"
        return res

    def subprocess(self, *argv, rc: int | None = 0, timeout: float = 300, **kw) -> subprocess.CompletedProcess:
        """Run ``python -m symoro_gen argv`` (text output captured)."""
        r = subprocess.run([sys.executable, "-m", "symoro_gen", *map(str, argv)], capture_output=True, text=True,
                           env=self.env, timeout=timeout, check=False, **kw)
        if rc is not None:
            assert r.returncode == rc, f"symoro-gen {' '.join(map(str, argv))}: exit {r.returncode}\n{r.stderr}"
        return r

    def popen(self, *argv, **kw) -> subprocess.Popen:
        """Start ``python -m symoro_gen argv`` (pipes, signals)."""
        return subprocess.Popen([sys.executable, "-m", "symoro_gen", *map(str, argv)], env=self.env, **kw)


@pytest.fixture(scope="session")
def cli() -> CliRunner:
    """The one way tests run ``symoro-gen`` (see :class:`CliRunner`)."""
    return CliRunner()
