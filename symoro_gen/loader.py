"""Load an emitted model: ``load_model("lwr4")`` or ``load_model("path/to/generated/lwr4")``."""
from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path

from .errors import ModelError


def generated_dir() -> Path:
    """Default folder of generated models (``$SYMORO_GENERATED`` overrides)."""
    env = os.environ.get("SYMORO_GENERATED")
    return Path(env) if env else Path(__file__).resolve().parents[1] / "generated"


def load_model(name_or_path: str | os.PathLike):
    """Import a generated model package by robot name or folder path.

    Returns
    -------
    module
        With the generated-module contract (``regressor``, ``BASE_NAMES``...).
    """
    p = Path(name_or_path)
    if not (p / "__init__.py").exists():
        cand = generated_dir() / str(name_or_path)
        if not (cand / "__init__.py").exists():
            known = sorted(x.name for x in generated_dir().glob("*") if (x / "__init__.py").exists())
            raise ModelError(
                f"no generated model {str(name_or_path)!r} (looked in {p} and {cand}); "
                f"known: {', '.join(known) or 'none'}. Run `make robot ROBOT={p.name}` or `symoro-gen generate {p.name}`."
            )
        p = cand
    p = p.resolve()
    modname = f"_symoro_generated_{p.name}_{abs(hash(str(p))) % 10**8}"
    if modname in sys.modules:
        return sys.modules[modname]
    spec = importlib.util.spec_from_file_location(modname, p / "__init__.py", submodule_search_locations=[str(p)])
    if spec is None or spec.loader is None:
        raise ModelError(f"cannot import generated model at {p}")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[modname] = mod
    try:
        spec.loader.exec_module(mod)
    except Exception as exc:
        del sys.modules[modname]
        raise ModelError(f"generated model at {p} failed to import: {exc}") from exc
    return mod
