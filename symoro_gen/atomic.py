"""Writing outputs, the one place: atomically, and never over an input or a user's file.

**Atomic**: a temporary sibling renamed over the target, so a failure never leaves a half-written
output. Files get ordinary permissions (``0666 & ~umask``), not mkstemp's private ones. Used for robot
files, JSON results, reports (single files and a report's image folder) and figures. The generated
packages are written by ``emit.package.write_package_atomic`` (the same folder swap, kept beside the
emitter).

**No output clobbers an input** (:func:`check_outputs`, run by every command before any work, and
:func:`check_replaceable`, run by every writer of the Python API):

* an output is never one of the command's inputs (same path, symbolic or hard link included), nor a
  folder replaced whole that holds one, nor inside an input folder -- refused even with ``--force``;
* two outputs of one command are never the same file;
* an existing file is replaced only when symoro-gen wrote it (:func:`written_by_symoro`: the mark each
  format carries), otherwise only with ``--force`` (``force=True``). Robot files and CSV recordings are
  never replaced without it, even when symoro-gen wrote them: they are meant to be edited or kept (a
  CSV recording has no mark: a measured one looks the same).

The marks: JSON results start with ``"generator": "symoro-gen <command>"``; URDF, MJCF and Markdown
carry an ``<!-- ... by symoro-gen ... -->`` comment (Markdown on its last line), ``.par`` files a
``(* ... written by symoro_gen *)`` first line, HTML reports ``<meta name="generator"
content="symoro-gen">``, PNG figures a ``Software: symoro-gen`` text chunk, Parquet logs (the fleet
simulator's) the key-value metadata ``generator: symoro-gen`` (:data:`PARQUET_MARK`), and ``excite``'s
trajectory CSV its header ``t,q1..qn,dq1..dqn,ddq1..ddqn``. A folder replaced whole (a Markdown report's
``<stem>_files/``) is symoro-gen's when every file in it is.
"""
from __future__ import annotations

import errno
import json
import os
import re
import shutil
import struct
import tempfile
import zlib
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, Literal

from .errors import OutputError

__all__ = ["FORCE_HELP", "GENERATOR", "MARKDOWN_MARK", "PARQUET_MARK", "Target", "check_outputs",
           "check_replaceable", "folder_written_by_symoro", "inside", "json_output", "mark_png", "ordinary_mode",
           "replace_folder_atomic", "same_file", "write_bytes_atomic", "write_output_bytes", "write_output_text",
           "write_text_atomic", "written_by_symoro"]

#: the name every output carries (see the module docstring)
GENERATOR = "symoro-gen"

#: help of the ``--force`` option of every command that writes files
FORCE_HELP = ("replace existing output files that symoro-gen did not write (an output never replaces one of "
              "the command's inputs, even with --force)")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def ordinary_mode(is_dir: bool = False) -> int:
    """``0777`` (folders) or ``0666`` (files) minus the process umask."""
    return (0o777 if is_dir else 0o666) & ~_umask()


def write_bytes_atomic(path: str | os.PathLike[str], data: bytes, *, overwrite: bool = True) -> None:
    """Write ``data`` to ``path`` through a temporary sibling and a rename.

    Parameters
    ----------
    path : str or PathLike
        Destination; its folder is created when missing.
    data : bytes
    overwrite : bool
        When false an existing ``path`` is never replaced, even one that appears while writing
        (the temporary file is hard-linked to ``path``): ``FileExistsError``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        try:
            with os.fdopen(fd, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        except OSError as exc:  # a full disk (ENOSPC), a quota...: name the file being written, not a temporary one
            raise _naming(exc, path) from exc
        os.chmod(tmp, ordinary_mode())
        if overwrite:
            os.replace(tmp, path)
        else:
            try:
                os.link(tmp, path)  # fails if path exists: never clobbers
            except FileExistsError:
                raise
            except OSError:  # file system without hard links
                if path.exists():
                    raise FileExistsError(str(path)) from None
                os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


def _naming(exc: OSError, path: Path) -> OSError:
    """``exc`` with ``path`` as its file name (the write errors of a file object, ENOSPC among them, carry none;
    those on the temporary sibling name a file the user never sees)."""
    return type(exc)(exc.errno, exc.strerror or str(exc), str(path)) if exc.errno else OSError(
        errno.EIO, str(exc), str(path))


def write_text_atomic(path: str | os.PathLike[str], text: str, *, overwrite: bool = True) -> None:
    """UTF-8 text, ``\\n`` line ends, written atomically (see :func:`write_bytes_atomic`)."""
    write_bytes_atomic(path, text.encode("utf-8"), overwrite=overwrite)


def replace_folder_atomic(folder: str | os.PathLike[str], files: Mapping[str, bytes | str]) -> None:
    """Make ``folder`` hold exactly ``files`` (name -> content), swapped in with one rename.

    The files are written into a temporary sibling folder, the old folder (if any) is moved
    aside, the new one renamed into place, and the old one removed; on failure the old folder
    is restored. Text is written as UTF-8.

    Raises
    ------
    NotADirectoryError
        ``folder`` exists and is not a folder.
    """
    folder = Path(folder)
    folder.parent.mkdir(parents=True, exist_ok=True)
    if folder.exists() and not folder.is_dir():
        raise NotADirectoryError(str(folder))
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".tmp", dir=folder.parent))
    old = None
    try:
        os.chmod(tmp, ordinary_mode(is_dir=True))  # mkdtemp makes it private
        for name, data in files.items():
            try:
                (tmp / name).write_bytes(data.encode("utf-8") if isinstance(data, str) else data)
            except OSError as exc:  # name the file of the folder being written, not the temporary one
                raise _naming(exc, folder / name) from exc
        if folder.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", suffix=".old", dir=folder.parent))
            old.rmdir()
            os.replace(folder, old)
        os.replace(tmp, folder)
    except BaseException:
        if tmp.exists():
            shutil.rmtree(tmp)
        if old is not None and old.exists() and not folder.exists():
            os.replace(old, folder)
        raise
    if old is not None and old.exists():
        shutil.rmtree(old)


# ---------------------------------------------------------------------------------------------
# what symoro-gen wrote
# ---------------------------------------------------------------------------------------------
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_KEY = b"Software"
_TEXT_MARKS = (
    re.compile(r'\A\s*\{\s*"generator"\s*:\s*"symoro[-_]gen\b'),                         # JSON results
    re.compile(r"^\s*<!--\s*(?:written|exported|generated) by symoro[-_]gen\b", re.M),  # XML, Markdown
    re.compile(r"^\(\*[^\n]*\bwritten by symoro[-_]gen\b[^\n]*\*\)", re.M),                   # SYMORO .par
    re.compile(r'^\s*<meta name="generator" content="symoro[-_]gen\b', re.M),                # HTML reports
)
#: the last line of a Markdown report (its mark)
MARKDOWN_MARK = f"\n<!-- written by {GENERATOR} -->\n"
_TRAJECTORY_HEADER = re.compile(r"t((?:,q\d+)+)((?:,dq\d+)+)((?:,ddq\d+)+)")
_PARQUET_MAGIC = b"PAR1"
#: the key-value metadata of a Parquet file symoro-gen wrote (its schema metadata: its mark)
PARQUET_MARK = {b"generator": GENERATOR.encode("ascii")}
#: that pair as it stands in the file's footer (Thrift compact protocol: a KeyValue struct, two binary fields)
_PARQUET_MARK_BYTES = b"".join(b"\x18" + bytes([len(x)]) + x for kv in PARQUET_MARK.items() for x in kv) + b"\x00"


def mark_png(png: bytes) -> bytes:
    """``png`` with a ``Software: symoro-gen`` text chunk after its header (unchanged when it has it,
    or is not a PNG)."""
    if png[:8] != _PNG_SIGNATURE or png[12:16] != b"IHDR" or _png_marked(png):
        return png
    data = _PNG_KEY + b"\x00" + GENERATOR.encode("ascii")
    chunk = struct.pack(">I", len(data)) + b"tEXt" + data + struct.pack(">I", zlib.crc32(b"tEXt" + data) & 0xFFFFFFFF)
    end = 8 + 8 + struct.unpack(">I", png[8:12])[0] + 4  # after IHDR (length, type, data, crc)
    return png[:end] + chunk + png[end:]


def _png_marked(png: bytes) -> bool:
    """The PNG has a ``Software: symoro-gen`` text chunk before its image data."""
    i = 8
    while i + 8 <= len(png):
        n, kind = struct.unpack(">I", png[i:i + 4])[0], png[i + 4:i + 8]
        if kind in (b"IDAT", b"IEND"):
            return False
        if kind == b"tEXt" and png[i + 8:i + 8 + n] == _PNG_KEY + b"\x00" + GENERATOR.encode("ascii"):
            return True
        i += 12 + n
    return False


def _parquet_marked(fh: BinaryIO, size: int) -> bool:
    """The Parquet file open in ``fh`` (``size`` bytes) carries :data:`PARQUET_MARK` in its footer's key-value
    metadata (the footer: its length in the 4 bytes before the closing ``PAR1``)."""
    if size < 12:
        return False
    fh.seek(size - 8)
    tail = fh.read(8)
    n = struct.unpack("<I", tail[:4])[0]
    if tail[4:] != _PARQUET_MAGIC or n > size - 12:
        return False
    fh.seek(size - 8 - n)
    return _PARQUET_MARK_BYTES in fh.read(n)


def _trajectory_header(line: str) -> bool:
    """``t,q1..qn,dq1..dqn,ddq1..ddqn`` (the header of ``excite``'s CSV), n >= 1."""
    m = _TRAJECTORY_HEADER.fullmatch(line.strip())
    if m is None:
        return False
    groups = [[int(x) for x in re.findall(r"\d+", g)] for g in m.groups()]
    n = len(groups[0])
    return all(g == list(range(1, n + 1)) for g in groups)


def written_by_symoro(path: str | os.PathLike[str]) -> bool:
    """True when ``path`` is a regular file carrying symoro-gen's mark (see the module docstring):
    a previous run's output, which a new one may replace."""
    p = Path(path)
    try:
        if not p.is_file():
            return False
        with open(p, "rb") as fh:
            head = fh.read(8192)
            if head[:8] == _PNG_SIGNATURE:
                return _png_marked(head + fh.read(1 << 20))
            size = fh.seek(0, os.SEEK_END)
            if head[:4] == _PARQUET_MAGIC:
                return _parquet_marked(fh, size)
            fh.seek(max(0, size - 256))
            tail = fh.read()
    except OSError:
        return False
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff")
    lines = text.splitlines()
    first = "\n".join(lines[:8])
    if _TEXT_MARKS[0].search(text) or any(rx.search(first) for rx in _TEXT_MARKS[1:]):
        return True
    if lines and _trajectory_header(lines[0]):
        return True
    last = tail.decode("utf-8", errors="replace").rstrip().splitlines()[-1:]
    return bool(last) and last[0].strip() == MARKDOWN_MARK.strip()


def folder_written_by_symoro(folder: str | os.PathLike[str]) -> bool:
    """True when ``folder`` is a folder whose every entry is a file symoro-gen wrote (an empty one too)."""
    p = Path(folder)
    try:
        return p.is_dir() and not p.is_symlink() and all(written_by_symoro(e) for e in p.iterdir())
    except OSError:
        return False


# ---------------------------------------------------------------------------------------------
# outputs against inputs
# ---------------------------------------------------------------------------------------------
def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """``a`` and ``b`` name the same file or folder: :func:`os.path.samefile` (device and inode: symbolic
    and hard links) when both exist, else the same path once resolved."""
    try:
        if os.path.exists(a) and os.path.exists(b):
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.normcase(os.path.realpath(a)) == os.path.normcase(os.path.realpath(b))


def inside(path: str | os.PathLike[str], folder: str | os.PathLike[str]) -> bool:
    """``path`` lies below ``folder`` (symbolic links resolved; a folder is not below itself)."""
    return any(same_file(parent, folder) for parent in Path(os.path.realpath(path)).parents)


Owner = Literal["marked", "never", "caller"]


@dataclass(frozen=True)
class Target:
    """An output of a command, for :func:`check_outputs`.

    Attributes
    ----------
    path : Path
    folder : bool
        A folder the output replaces whole (a Markdown report's images): an input inside it is refused.
    owner : {"marked", "never", "caller"}
        When an existing target may be replaced without ``force``: ``"marked"`` when symoro-gen wrote it
        (:func:`written_by_symoro`, :func:`folder_written_by_symoro`), ``"never"`` (robot files,
        recordings), ``"caller"``: the writer decides (generated packages, ``emit.package``).
    into : bool
        A folder the command writes files into, not replaced whole (``diagnose --plots DIR``).
    """

    path: Path
    folder: bool = False
    owner: Owner = "marked"
    into: bool = False


def _cli(label: str) -> bool:
    """``label`` is a command-line option (``--json``, ``-o/--output (its .json)``...), not an API argument."""
    return label.startswith("-")


def _force_hint(label: str) -> str:
    return (f"choose another path for {label.split(' (')[0]}, or pass --force to replace it" if _cli(label)
            else "choose another path, or pass force=True to replace it")


def _force(label: str) -> str:
    return "--force" if _cli(label) else "force=True"


def _refuse_folder(label: str, t: Target) -> None:
    """A file output never replaces a folder, ``--force`` or not (the write would fail once the work is done)."""
    if not t.folder and t.owner != "caller" and t.path.is_dir() and not t.path.is_symlink():
        raise OutputError(f"{label} {t.path}: a folder exists there; a file output never replaces a folder, even "
                          f"with {_force(label)}", f"choose another path for {label.split(' (')[0]}")


def _refuse_file(label: str, t: Target) -> None:
    """A folder output (replaced whole, or written into) never replaces a file, ``--force`` or not; the writers
    that decide themselves (``owner="caller"``: ``generate``'s package) are left to do so."""
    if ((t.folder and t.owner != "caller") or t.into) and t.path.exists() and not t.path.is_dir():
        raise OutputError(f"{label} {t.path}: a file exists there; {label.split(' (')[0]} writes a folder, which "
                          f"never replaces a file, even with {_force(label)}",
                          f"choose another path for {label.split(' (')[0]}")


def _refuse_existing(label: str, t: Target) -> None:
    p = t.path
    if not (p.exists() or p.is_symlink()):
        return
    if t.owner == "caller":
        return
    if t.owner == "never":
        raise OutputError(f"{label} {p}: the file exists; not overwritten ({_force(label)} replaces it)", _force_hint(label))
    if p.is_dir() and not p.is_symlink():
        if t.folder and folder_written_by_symoro(p):
            return
        if t.folder:
            foreign = next((e.name for e in sorted(p.iterdir()) if not written_by_symoro(e)), "")
            raise OutputError(f"{label} {p}: the folder exists and holds {foreign!r}, which symoro-gen did not write; "
                              f"not overwritten ({_force(label)} replaces the folder)", _force_hint(label))
        raise OutputError(f"{label} {p}: a folder exists there; not overwritten", f"choose another path for {label}")
    if not written_by_symoro(p):
        raise OutputError(f"{label} {p}: the file exists and was not written by symoro-gen; not overwritten "
                          f"({_force(label)} replaces it)", _force_hint(label))


def check_replaceable(path: str | os.PathLike[str], force: bool = False, *, folder: bool = False,
                      owner: Owner = "marked", label: str = "output") -> None:
    """The rule of the writers of the Python API: an existing ``path`` is replaced only when symoro-gen
    wrote it (``owner="marked"``; never for ``owner="never"``), unless ``force``.

    Raises
    ------
    OutputError
        Naming ``label`` and the path.
    """
    t = Target(Path(path), folder=folder, owner=owner)
    _refuse_folder(label, t)
    _refuse_file(label, t)
    if not force:
        _refuse_existing(label, t)


def _target(t: str | os.PathLike[str] | Target) -> Target:
    return t if isinstance(t, Target) else Target(Path(t))


def check_outputs(outputs: Mapping[str, str | os.PathLike[str] | Target | None],
                  inputs: Iterable[tuple[str, str | os.PathLike[str] | None]] = (), force: bool = False) -> None:
    """The one rule for the outputs of a command, checked before any work.

    Parameters
    ----------
    outputs : mapping
        Option (``"--json"``, ``"-o/--output"``...) -> path or :class:`Target`; None entries are skipped.
    inputs : iterable of (label, path)
        What the command reads: ``("ROBOT", "my.toml")``, ``("DATA", "a.csv")``... (files or folders).
    force : bool
        ``--force``: existing files symoro-gen did not write may be replaced (inputs never).

    Raises
    ------
    OutputError
        An output is an input (or a folder replaced whole holds one, or it lies in an input folder), two
        outputs are the same file, or an existing target is not replaceable (see :class:`Target`).
    """
    outs = [(label, _target(t)) for label, t in outputs.items() if t is not None and str(t) != ""]
    ins = [(label, Path(p)) for label, p in inputs if p is not None and str(p) != ""]
    keep = "an output never replaces an input, even with --force"
    for label, t in outs:
        hint = f"write {label.split(' (')[0]} to another path"
        for il, ip in ins:
            if same_file(t.path, ip):
                what = "folder" if ip.is_dir() else "file"
                raise OutputError(f"{label} {t.path}: that {what} is an input of the command ({il} {ip}); {keep}", hint)
            if t.folder and inside(ip, t.path):
                raise OutputError(f"{label} {t.path}: this folder is replaced whole and holds an input of the command "
                                  f"({il} {ip}); {keep}", hint)
            if ip.is_dir() and inside(t.path, ip):
                raise OutputError(f"{label} {t.path}: inside a folder the command reads ({il} {ip}); {keep}", hint)
    for i, (la, a) in enumerate(outs):
        for lb, b in outs[i + 1:]:
            if same_file(a.path, b.path):
                raise OutputError(f"{la} {a.path} and {lb} {b.path} are the same file: each output needs its own path",
                                  "give each output its own path")
            for (lx, x), (ly, y) in (((la, a), (lb, b)), ((lb, b), (la, a))):
                if x.folder and inside(y.path, x.path):
                    raise OutputError(f"{ly} {y.path} is inside the folder {x.path} that {lx} replaces whole",
                                      "give each output its own path")
    for label, t in outs:
        _refuse_folder(label, t)
        _refuse_file(label, t)
        if not force:
            _refuse_existing(label, t)


# ---------------------------------------------------------------------------------------------
# writers
# ---------------------------------------------------------------------------------------------
def json_output(obj: Mapping[str, Any], command: str, **dumps: Any) -> str:
    """JSON text of a command's result, marked ``"generator": "symoro-gen <command>"`` (first key);
    ``dumps``: :func:`json.dumps` options (default ``indent=2``)."""
    marked = {"generator": f"{GENERATOR} {command}".strip(), **{k: v for k, v in obj.items() if k != "generator"}}
    return json.dumps(marked, **{"indent": 2, **dumps}) + "\n"


def write_output_text(path: str | os.PathLike[str], text: str, *, force: bool = False,
                      label: str = "output") -> None:
    """:func:`write_text_atomic` after :func:`check_replaceable` (``text`` carries its mark)."""
    check_replaceable(path, force, label=label)
    write_text_atomic(path, text)


def write_output_bytes(path: str | os.PathLike[str], data: bytes, *, force: bool = False,
                       label: str = "output") -> None:
    """:func:`write_bytes_atomic` after :func:`check_replaceable`; a PNG is marked (:func:`mark_png`)."""
    check_replaceable(path, force, label=label)
    write_bytes_atomic(path, mark_png(data))
