"""The one door to a model: :func:`load_model`.

``load_model("lwr4")``, ``load_model("path/to/generated/lwr4")``, ``load_model("path/to/robot.toml")``
or ``load_model(robot_description)`` all return an :class:`~symoro_gen.model.IdentificationModel`
(a generated package). A robot file or description is generated when needed:

* the repository's ``generated/<name>/`` is used when it was generated from the same file (same
  sha256), and is never written by this function;
* a robot file outside the repository is generated next to it, into ``<dir>/generated/<name>/``
  when that folder is writable (and is not something else than a generated package);
* otherwise into the user cache, ``$XDG_CACHE_HOME/symoro_gen/models/<file sha256[:16]>/<name>/``.

:func:`model_for` returns the robot description too.

A closed-loop robot (``[[loops]]`` in its robot file) is generated as its tree (the package's
``manifest.json`` says ``closed_loops``) and returned wrapped in
:class:`symoro_gen.closedloop.ClosedLoopModel` (the tree model projected on the actuated joints); a floating-base
robot (``base = "floating"``) gets its generated package (``symoro-gen generate`` writes it; a
:class:`symoro_gen.runtime.floating_package.GeneratedFloatingModel`) when one from the same file exists, else a
:class:`symoro_gen.runtime.floating.FloatingModel` built in memory (the same contract; never written by this function).
"""
from __future__ import annotations

import hashlib
import importlib.util
import json
import os
import sys
from pathlib import Path
from types import ModuleType
from typing import TYPE_CHECKING, cast

from .errors import ModelError
from .model import IdentificationModel, check_model
from .paths import REPO_ROOT as REPO_ROOT
from .paths import generated_dir as generated_dir
from .paths import robots_dir as robots_dir

if TYPE_CHECKING:
    from .description.model import RobotDescription

def cache_dir() -> Path:
    """User cache of models generated from robot files (``$XDG_CACHE_HOME/symoro_gen/models``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "symoro_gen" / "models"


def _is_package(p: Path) -> bool:
    return (p / "__init__.py").is_file()


def _manifest_sha(p: Path) -> str | None:
    try:
        sha = json.loads((p / "manifest.json").read_text(encoding="utf-8")).get("robot_file_sha256")
        return None if sha is None else str(sha)
    except (OSError, ValueError, AttributeError):
        return None


def import_package(path: str | os.PathLike[str]) -> IdentificationModel:
    """Import the generated package in folder ``path`` (once per process, folder and package content).

    The module is named ``_symoro_generated_<name>_<sha256 of the path>_<sha256 of __init__.py>``:
    deterministic across processes, and a package regenerated in place is imported afresh.
    """
    p = Path(path).resolve()
    try:
        content = hashlib.sha256((p / "__init__.py").read_bytes()).hexdigest()[:8]
    except OSError as exc:
        raise ModelError(f"cannot read generated model at {p}: {exc.strerror or exc}") from None
    modname = f"_symoro_generated_{p.name}_{hashlib.sha256(str(p).encode()).hexdigest()[:12]}_{content}"
    if modname in sys.modules:
        return cast(IdentificationModel, sys.modules[modname])
    spec = importlib.util.spec_from_file_location(modname, p / "__init__.py", submodule_search_locations=[str(p)])
    if spec is None or spec.loader is None:
        raise ModelError(f"cannot import generated model at {p}")
    mod: ModuleType = importlib.util.module_from_spec(spec)
    sys.modules[modname] = mod
    try:
        spec.loader.exec_module(mod)
    except Exception as exc:
        del sys.modules[modname]
        raise ModelError(f"generated model at {p} failed to import: {exc}; regenerate it with "
                         f"`symoro-gen generate`") from exc
    return check_model(mod)


def _inside_repo(path: Path) -> bool:
    try:
        path.resolve().relative_to(REPO_ROOT)
    except ValueError:
        return False
    return True


def _generate(robot: RobotDescription, out_dir: Path, *, any_source: bool = False) -> Path:
    """Generate ``out_dir/<robot>``; ``any_source``: an existing package of this robot may come from
    another robot file (the cache, keyed by the file's content)."""
    # sympy and the Newton-Euler/emission stack (~0.5 s to import) only when generating
    from .emit.package import emit_robot, written_by_generate

    target = out_dir / robot.name
    if target.exists() and not written_by_generate(target, robot.name):
        raise ModelError(f"{target} exists and is not a generated package of {robot.name}")
    emit_robot(robot, out_dir, force=any_source)
    return target


def _from_other_file(target: Path, robot: RobotDescription) -> bool:
    """``target`` is a generated package of another robot file (of the same robot name)."""
    if not (target / "manifest.json").is_file():
        return False
    from .emit.package import other_source

    return other_source(target, robot.file) is not None


#: closed-loop models already built in this process: (package folder, robot-file sha256) -> model
_CLOSED: dict[tuple[str, str], IdentificationModel] = {}


def _closed(robot: RobotDescription, tree: IdentificationModel, folder: Path) -> IdentificationModel:
    """The closed-loop model of ``robot`` around its generated tree model (``symoro_gen.closedloop``)."""
    key = (str(folder.resolve()), robot.file_hash)
    if key not in _CLOSED:
        from .closedloop import ClosedLoopModel  # sympy: only for closed-loop robots

        _CLOSED[key] = check_model(ClosedLoopModel(robot, tree))
    return _CLOSED[key]


def _import_checked(folder: Path, robot: RobotDescription | None = None) -> IdentificationModel:
    """:func:`import_package`, wrapped in the closed-loop model when the package is the tree of a
    closed-loop robot (its ``manifest.json`` has ``closed_loops``, or ``couplings``: coupled joints); the robot file is then the one the
    package was generated from, looked for in ``robots/`` and beside the ``generated/`` folder."""
    model = import_package(folder)
    try:
        man = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return model
    if not (isinstance(man, dict) and (man.get("closed_loops") or man.get("couplings"))):
        return model
    if robot is None:
        from .description import load_robot, robots_dir  # sympy: only for closed-loop robots

        name, sha = str(man.get("robot_file", "")), man.get("robot_file_sha256")
        for cand in (robots_dir() / name, folder.resolve().parent.parent / name):
            if name and cand.is_file() and hashlib.sha256(cand.read_bytes()).hexdigest() == sha:
                robot = load_robot(cand)
                break
        else:
            raise ModelError(f"{folder} is the tree model of the closed-loop robot {man.get('robot')!r}; its robot "
                             f"file {name!r} (sha256 {str(sha)[:12]}...) was not found in {robots_dir()} or beside "
                             f"the generated/ folder: load the model from the robot file")
    return _closed(robot, model, folder)


def _floating_package(robot: RobotDescription) -> Path | None:
    """The generated package of a floating-base robot file, when ``generate`` wrote one from this file
    (same sha256): in the repository's ``generated/``, beside the file, or in the cache; else None."""
    f = Path(robot.file)
    places = [generated_dir(), cache_dir() / robot.file_hash[:16]]
    if robot.file and f.is_file():
        places.insert(1, f.resolve().parent / "generated")
    return next((p / robot.name for p in places
                 if _is_package(p / robot.name) and _manifest_sha(p / robot.name) == robot.file_hash), None)


def _model_of_robot(robot: RobotDescription) -> IdentificationModel:
    if robot.floating:  # its generated package (`symoro-gen generate`) when there is one, else built in memory
        found = _floating_package(robot)
        if found is not None:
            return _import_checked(found, robot)
        from .runtime.floating import FloatingModel  # sympy: only for floating-base robots

        return check_model(FloatingModel(robot))
    repo = generated_dir() / robot.name
    if _is_package(repo) and _manifest_sha(repo) == robot.file_hash:
        return _import_checked(repo, robot)
    f = Path(robot.file)
    if robot.file and f.is_file() and not _inside_repo(f):
        beside = f.resolve().parent / "generated"
        target = beside / robot.name
        if _is_package(target) and _manifest_sha(target) == robot.file_hash:
            return _import_checked(target, robot)
        try:
            writable = (beside.is_dir() or os.access(beside.parent, os.W_OK)) and (
                not beside.exists() or os.access(beside, os.W_OK))
        except OSError:
            writable = False
        if writable and (not target.exists() or ((target / "manifest.json").is_file()
                                                 and not _from_other_file(target, robot))):
            return _import_checked(_generate(robot, beside), robot)
    cached = cache_dir() / robot.file_hash[:16]
    if not (_is_package(cached / robot.name) and _manifest_sha(cached / robot.name) == robot.file_hash):
        _generate(robot, cached, any_source=True)
    return _import_checked(cached / robot.name, robot)


def load_model(source: str | os.PathLike[str] | RobotDescription) -> IdentificationModel:
    """The identification model of a robot, generating it when needed.

    Parameters
    ----------
    source : str, path or RobotDescription
        A robot name (``generated/<name>/``, else ``robots/<name>.toml``), a generated package
        folder, a robot ``.toml`` file, or a parsed :class:`~symoro_gen.description.model.RobotDescription`.

    Returns
    -------
    IdentificationModel
        The generated package (module) of the robot.

    Raises
    ------
    ModelError
        Unknown robot (the known ones are listed) or a package that does not import.
    """
    if not isinstance(source, (str, os.PathLike)):
        from .description.model import RobotDescription  # sympy: only for descriptions

        if not isinstance(source, RobotDescription):
            raise ModelError(f"load_model: expected a robot name, a path or a RobotDescription, got {type(source).__name__}")
        return _model_of_robot(source)
    p = Path(source)
    if _is_package(p):
        return _import_checked(p)
    if p.suffix == ".toml" or p.is_file():
        from .description import load_robot  # sympy: only for robot files

        return _model_of_robot(load_robot(p))
    cand = generated_dir() / str(source)
    shipped = robots_dir() / f"{source}.toml"
    named = p.name == str(source) and shipped.is_file()
    # a name means the robot file robots/<name>.toml when there is one (as model_for and every command read it):
    # generated/<name>/ stands for it only when generated from that file (same sha256); otherwise the file's
    # own package is found or generated (never another file's package under the same name)
    if _is_package(cand) and (not named or _manifest_sha(cand) == hashlib.sha256(shipped.read_bytes()).hexdigest()):
        return _import_checked(cand)
    if named:
        from .description import load_robot  # sympy: only for robot files

        return _model_of_robot(load_robot(str(source)))
    known = sorted(x.name for x in generated_dir().glob("*") if _is_package(x))
    raise ModelError(
        f"no generated model {str(source)!r} (looked in {p} and {cand}); "
        f"known: {', '.join(known) or 'none'}. Run `symoro-gen generate {p.name}` (or `make robot ROBOT={p.name}`)."
    )


def model_for(robot_or_name: str | os.PathLike[str] | RobotDescription) -> tuple[RobotDescription, IdentificationModel]:
    """``(robot description, model)`` for a robot name, robot file or description (see :func:`load_model`)."""
    from .description import load_robot
    from .description.model import RobotDescription

    robot = robot_or_name if isinstance(robot_or_name, RobotDescription) else load_robot(robot_or_name)
    return robot, load_model(robot)
