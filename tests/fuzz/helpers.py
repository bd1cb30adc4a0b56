"""What every fuzz case checks: the exit status, a message naming the file (and the field
when the mutation targeted one), and that nothing outside the command's output was touched.

``run_case(cli, workdir, argv, output=..., file=...)`` snapshots ``workdir`` (every file's bytes,
every folder), runs ``symoro-gen argv`` in-process, and checks:

* exit 0 (the input was valid after all) or 2 (a user error); never 1 (internal error);
* on exit 2: the first error line is ``symoro-gen: error: ...`` and names ``file``, a ``hint:`` line
  follows, no traceback; ``output`` does not exist (nothing written);
* on exit 0: ``output`` exists;
* every other path of ``workdir`` is exactly as before (bytes, and no new or removed path).
"""
from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

from hypothesis import HealthCheck, settings

#: bounded example counts keep the whole folder under a minute; ``SYMORO_FUZZ_EXAMPLES=500`` runs a
#: deeper, random (not derandomized) search locally
_DEEP = int(os.environ.get("SYMORO_FUZZ_EXAMPLES", "0"))
FUZZ = settings(max_examples=_DEEP or 25, deadline=None, derandomize=not _DEEP, database=None,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture,
                                       HealthCheck.data_too_large])


def snapshot(root: Path) -> dict[str, str]:
    """Every path below ``root`` -> sha256 of its bytes (``"dir"`` for folders, ``"->target"`` for links)."""
    out: dict[str, str] = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for d in dirnames:
            p = Path(dirpath) / d
            out[str(p.relative_to(root))] = f"->{os.readlink(p)}" if p.is_symlink() else "dir"
        for f in filenames:
            p = Path(dirpath) / f
            rel = str(p.relative_to(root))
            out[rel] = f"->{os.readlink(p)}" if p.is_symlink() else hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def changed_paths(before: dict[str, str], after: dict[str, str]) -> set[str]:
    return {k for k in before.keys() | after.keys() if before.get(k) != after.get(k)}


@dataclass
class Case:
    rc: int
    out: str
    err: str

    @property
    def first_error(self) -> str:
        return next((ln for ln in self.err.splitlines() if ln.startswith("symoro-gen: error:")), "")


def run_case(cli, workdir: Path, argv, *, output: Path | None = None, file: str | None = None,
             fields: tuple[str, ...] = (), allow_ok: bool = True) -> Case:
    """Run ``symoro-gen argv`` and check the properties above (see the module docstring).

    ``fields``: when non-empty and the run fails, one of them must be named in the error.
    """
    before = snapshot(workdir)
    res = cli(*argv, rc=None)
    after = snapshot(workdir)
    case = Case(res.rc, res.out, res.err)
    cmd = "symoro-gen " + " ".join(map(str, argv))
    assert "Traceback" not in res.err and "Traceback" not in res.out, f"{cmd}: traceback\n{res.err}"
    assert res.rc in ((0, 2) if allow_ok else (2,)), f"{cmd}: exit {res.rc}\n{res.err}"
    changed = changed_paths(before, after)
    if output is not None:
        out_rel = str(output.relative_to(workdir))
        changed = {c for c in changed if c != out_rel and not c.startswith(out_rel + os.sep)}
    assert not changed, f"{cmd}: touched paths outside its output: {sorted(changed)}"
    if res.rc == 2:
        first = case.first_error
        assert first, f"{cmd}: no 'symoro-gen: error:' line\n{res.err}"
        assert any(ln.startswith("hint: ") for ln in res.err.splitlines()), f"{cmd}: no hint\n{res.err}"
        if file is not None:
            assert file in res.err, f"{cmd}: the error does not name {file}\n{res.err}"
        if fields:
            assert any(f"'{f}'" in res.err or f" {f} " in res.err or f"{f}=" in res.err for f in fields), \
                f"{cmd}: the error names none of {fields}\n{res.err}"
        if output is not None:
            assert not output.exists(), f"{cmd}: failed but wrote {output}"
    elif output is not None:
        assert output.exists(), f"{cmd}: exit 0 without writing {output}"
    return case
