"""``symoro-gen build ROBOT``: compile the C kernels of a generated package (otherwise done on first use).

A leaf, light: it loads the generated package (plain NumPy) and compiles, without SymPy or SciPy.
"""
from __future__ import annotations

from ..errors import ModelError
from ..loader import load_model

__all__ = ["add_parser", "run"]


def run(args) -> int:
    """Compile the C kernels of a generated package; 0 on success."""
    m = load_model(args.robot)
    m = getattr(m, "tree", m)  # a closed-loop or coupled robot: the kernels are its tree's package's
    model = getattr(m, "_MODEL", None)
    if model is None:
        raise ModelError(f"{args.robot}: not a generated package with C kernels")
    res = model.build(force=args.force, timeout=args.timeout)
    if not args.quiet:
        print(f"{m.ROBOT}: C kernels {'compiled' if res.compiled else 'already built'} -> {res.path}")
    return 0


def add_parser(sub) -> None:
    """Register ``build``."""
    b = sub.add_parser("build", help="compile the C kernels of a generated package (otherwise done on first use)")
    b.add_argument("robot", help="robot name, generated package folder, or robot .toml file")
    b.add_argument("--force", action="store_true", help="compile even when a library of this source exists")
    b.add_argument("--timeout", type=float, default=None, help="seconds before the compiler is killed (default 900)")
    b.set_defaults(func=run)
