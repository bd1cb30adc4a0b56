"""Editing a robot file's text in place: fields of its ``[[frames]]`` entries changed line by line, every
other line (comments, blank lines, the order of the keys, the other tables) unchanged.

Used by ``identify -o/--robot-out`` to write the quantities it identified into a copy of the input robot
file (docs/robot-file.md): the joint zeros added to ``theta = "..."`` (``r`` of a prismatic joint), the
link-length errors added to ``d``/``r``, the
``K`` and ``D`` of an ``elastic = {K = ..., D = ...}`` table, the scale of a
``friction_law = {kind = ..., vs|v|delta = ...}`` table. Inline tables are edited by key (a missing key
is appended inside the braces); a frame without the table gets a line of its own at the end of its entry.
A field that is not on a line of its own in a ``[[frames]]`` table (an array of inline tables, a
multi-line value) is refused, naming the file, the frame and the field.
"""
from __future__ import annotations

import re
from collections.abc import Callable, Mapping
from pathlib import Path

from ..errors import Problem, RobotFileError

__all__ = ["RobotText", "format_number"]

_FRAMES = re.compile(r"^\s*\[\[\s*frames\s*\]\]\s*(#.*)?$")
_TABLE = re.compile(r"^\s*\[")
_J = re.compile(r"^\s*j\s*=\s*(\d+)")
_BLANK_OR_COMMENT = re.compile(r"^\s*(#.*)?$")


def format_number(v: float, digits: int = 12) -> str:
    """``v`` as a TOML float to ``digits`` significant digits (``2500.0``, ``0.0512``, ``1e-05``)."""
    return repr(float(f"{float(v):.{digits}g}"))


class RobotText:
    """The lines of a robot file, edited per frame (``j``) and field.

    Parameters
    ----------
    path : path
        The robot file (read as UTF-8; its line endings are kept).
    """

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        if not self.path.is_file():
            raise RobotFileError([Problem(str(path), "", "", "the robot file is needed to write the corrected "
                                          "one: load the robot from a file")])
        self.lines = self.path.read_text(encoding="utf-8").splitlines(keepends=True)
        self._newline = "\r\n" if self.lines and self.lines[0].endswith("\r\n") else "\n"

    # ---- the frames' entries ----------------------------------------------------------------------------
    def _blocks(self) -> dict[int, tuple[int, int]]:
        """Frame ``j`` -> (index of its ``[[frames]]`` line, index after its last line)."""
        out: dict[int, tuple[int, int]] = {}
        i, lines = 0, self.lines
        while i < len(lines):
            if _FRAMES.match(lines[i]):
                b = i + 1
                while b < len(lines) and not _TABLE.match(lines[b]):
                    b += 1
                for t in range(i + 1, b):
                    m = _J.match(lines[t])
                    if m:
                        out[int(m.group(1))] = (i, b)
                        break
                i = b
            else:
                i += 1
        return out

    def _refuse(self, frame: int, fld: str, what: str) -> RobotFileError:
        return RobotFileError([Problem(str(self.path), f"frame j = {frame}", fld,
                                       f"no {what} line of its own to write the identified value on "
                                       "(write the frame as a [[frames]] table, one field per line)")])

    def _field_line(self, frame: int, key: str) -> tuple[int | None, tuple[int, int]]:
        blocks = self._blocks()
        if frame not in blocks:
            raise self._refuse(frame, key, "[[frames]] entry with a j = ... line and a")
        a, b = blocks[frame]
        pat = re.compile(rf"^\s*{re.escape(key)}\s*=")
        for t in range(a + 1, b):
            if pat.match(self.lines[t]):
                return t, (a, b)
        return None, (a, b)

    def _set(self, t: int, body: str) -> None:
        eol = self._newline if self.lines[t].endswith(("\n", "\r")) else ""
        self.lines[t] = body + eol

    # ---- edits ----------------------------------------------------------------------------------------------
    def edit_string(self, frame: int, key: str, edit: Callable[[str], str]) -> None:
        """Replace the string value of ``key = "..."`` in frame ``frame``'s entry by ``edit(old)``."""
        t, _ = self._field_line(frame, key)
        m = re.match(rf'^(\s*{re.escape(key)}\s*=\s*)"([^"]*)"(.*)$', self.lines[t].rstrip("\r\n")) if t is not None \
            else None
        if t is None or m is None:
            raise self._refuse(frame, key, f'{key} = "..."')
        self._set(t, f'{m.group(1)}"{edit(m.group(2))}"{m.group(3)}')

    def edit_value(self, frame: int, key: str, edit: Callable[[str], str]) -> None:
        """Replace the value of ``key = ...`` (a number or a quoted string, as written) in frame ``frame``'s entry
        by ``edit(old)`` (TOML text); a frame without the line gets ``key = edit("0")`` at the end of its entry
        (an absent length is 0)."""
        t, (a, b) = self._field_line(frame, key)
        if t is None:
            end = b
            while end > a + 1 and _BLANK_OR_COMMENT.match(self.lines[end - 1]):
                end -= 1
            if end > 0 and not self.lines[end - 1].endswith(("\n", "\r")):
                self.lines[end - 1] += self._newline
            self.lines.insert(end, f"{key} = {edit('0')}{self._newline}")
            return
        m = re.match(rf'^(\s*{re.escape(key)}\s*=\s*)("[^"]*"|[-+0-9.eE_]+)(\s*(#.*)?)$', self.lines[t].rstrip("\r\n"))
        if m is None:
            raise self._refuse(frame, key, f"{key} = <number> or {key} = \"...\"")
        self._set(t, f"{m.group(1)}{edit(m.group(2))}{m.group(3)}")

    def set_inline(self, frame: int, key: str, values: Mapping[str, str], *, create: bool = False) -> None:
        """Set the fields ``values`` (name -> TOML text) of the inline table ``key = {...}`` of frame ``frame``:
        each field edited by its name, a missing one appended inside the braces. Without the table, ``create``
        adds the line ``key = {...}`` at the end of the frame's entry (else it is refused)."""
        t, (a, b) = self._field_line(frame, key)
        if t is None:
            if not create:
                raise self._refuse(frame, key, f"{key} = {{...}}")
            end = b
            while end > a + 1 and _BLANK_OR_COMMENT.match(self.lines[end - 1]):
                end -= 1
            if end > 0 and not self.lines[end - 1].endswith(("\n", "\r")):
                self.lines[end - 1] += self._newline
            body = ", ".join(f"{k} = {v}" for k, v in values.items())
            self.lines.insert(end, f"{key} = {{{body}}}{self._newline}")
            return
        line = self.lines[t].rstrip("\r\n")
        m = re.match(rf"^(\s*{re.escape(key)}\s*=\s*\{{)([^{{}}]*)(\}}.*)$", line)
        if m is None:
            raise self._refuse(frame, key, f"{key} = {{...}} (an inline table on one line)")
        inner = m.group(2)
        for k, v in values.items():
            pat = re.compile(rf"(^|,)(\s*){re.escape(k)}(\s*=\s*)([^,]*?)(\s*)(?=,|$)")
            if pat.search(inner):
                inner = pat.sub(lambda mm, k=k, v=v: f"{mm.group(1)}{mm.group(2)}{k}{mm.group(3)}{v}{mm.group(5)}",
                                inner, count=1)
            else:
                stripped = inner.rstrip()
                sep = ", " if stripped.strip() else ""
                inner = f"{stripped}{sep}{k} = {v}" + (" " if inner != stripped or not stripped.strip() else "")
        self._set(t, f"{m.group(1)}{inner}{m.group(3)}")

    def text(self, header: list[str]) -> str:
        """The edited file with the comment lines ``header`` (without ``#``) before it."""
        return "".join(f"# {h}{self._newline}" for h in header) + "".join(self.lines)
