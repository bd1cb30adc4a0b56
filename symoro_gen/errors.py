"""Error types of symoro_gen.

One base class, :class:`SymoroError`; every concrete error also derives from the
builtin exception a caller would naturally catch (``ValueError`` or ``TypeError``).
Messages name the file, the frame/line/joint and the field at fault.
"""
from __future__ import annotations

import difflib
import functools
import inspect
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from typing import ParamSpec, TypeVar

_P = ParamSpec("_P")
_R = TypeVar("_R")


class SymoroError(Exception):
    """Base class of all errors raised on purpose by symoro_gen."""

    hint: str | None = None


@dataclass(frozen=True)
class Problem:
    """One problem found in an input file.

    Attributes
    ----------
    file : str
        Path of the file (or ``"<string>"``).
    where : str
        Location inside the file: ``"frame 3"``, ``"line 12"``, ``"column tau2, rows 10-20"``...
    field : str
        The field at fault (``"sigma"``, ``"ant"``...), or ``""``.
    message : str
        What is wrong.
    """

    file: str
    where: str
    field: str
    message: str

    def __str__(self) -> str:
        loc = ", ".join(p for p in (self.file, self.where, f"field '{self.field}'" if self.field else "") if p)
        return f"{loc}: {self.message}"


class RobotFileError(SymoroError, ValueError):
    """A robot description file is invalid; lists every problem found."""

    def __init__(self, problems: list[Problem] | tuple[Problem, ...], hint: str | None = None):
        self.problems = tuple(problems)
        self.hint = hint
        n = len(self.problems)
        head = f"{n} problem{'s' if n != 1 else ''} in robot description"
        super().__init__(head + ":\n" + "\n".join(f"  - {p}" for p in self.problems))


class DataFileError(SymoroError, ValueError):
    """A measured-data file is invalid (names file, column and row range)."""

    def __init__(self, problems: list[Problem] | tuple[Problem, ...], hint: str | None = None):
        self.problems = tuple(problems)
        self.hint = hint
        n = len(self.problems)
        head = f"{n} problem{'s' if n != 1 else ''} in data"
        super().__init__(head + ":\n" + "\n".join(f"  - {p}" for p in self.problems))


class ModelError(SymoroError, ValueError):
    """A model cannot be built, loaded or used as asked (wrong shapes, unknown robot...)."""


class IdentificationError(SymoroError, ValueError):
    """An identification problem cannot be solved as posed."""


class OptionError(SymoroError, ValueError):
    """A command-line option has a value the command cannot use (the message starts with the option)."""


class OutputError(SymoroError, FileExistsError):
    """An output cannot be written where asked: it is one of the command's inputs, two outputs are the
    same file, or an existing file there was not written by symoro-gen (``--force`` / ``force=True``
    replaces that one; see :func:`symoro_gen.atomic.check_outputs`). The message names the option and
    the path."""

    def __init__(self, message: str, hint: str | None = None):
        super().__init__(message)
        self.hint = hint


class ShapeError(SymoroError, TypeError):
    """An array argument has the wrong shape or type."""


class RobotFileWarning(UserWarning):
    """A robot file is valid but something in it is probably not what was meant (names file and field)."""


def check_option_names(names: Iterable[str], valid: Sequence[str], what: str) -> None:
    """Raise :class:`OptionError` for the first name not in ``valid``, naming the nearest valid one
    (:func:`difflib.get_close_matches`), else listing them all."""
    for name in names:
        if name in valid:
            continue
        near = difflib.get_close_matches(name, valid, n=1, cutoff=0.5)
        hint = f"; did you mean {near[0]!r}?" if near else f"; valid options: {', '.join(valid)}"
        raise OptionError(f"{what}: unknown option {name!r}{hint}")


def named_options(fn: Callable[_P, _R]) -> Callable[_P, _R]:
    """``fn`` whose keyword arguments are checked by :func:`check_option_names` against its own parameter
    names before the call: a misspelt option raises :class:`OptionError` naming the nearest one instead of
    Python's bare ``TypeError`` (the signature, and what :func:`inspect.signature` shows, stay ``fn``'s)."""
    valid = tuple(p.name for p in inspect.signature(fn).parameters.values()
                  if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY))

    @functools.wraps(fn)
    def checked(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        check_option_names(kwargs, valid, fn.__name__)
        return fn(*args, **kwargs)

    return checked
