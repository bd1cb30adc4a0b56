"""symoro_gen: MDH robot table -> symbolic identification model -> identified parameters.

``load_model`` is imported with the package; the workflows (``identify``...) and their option and result
types load on first use, so that ``import symoro_gen`` stays light (no SymPy, no SciPy)::

    import symoro_gen
    res = symoro_gen.identify("lwr4", ["a.csv", "c.csv"], validate=["b.csv"], method="wls")
    print(res.summary())
"""
__version__ = "0.1.0"

from .loader import load_model

#: names served by symoro_gen.workflows on first use
_WORKFLOWS = ("identify", "IdentifyOptions", "IdentifyResults", "diagnose", "DiagnoseOptions", "DiagnoseResults")

__all__ = ["load_model", "__version__", *_WORKFLOWS]


def __getattr__(name: str):
    if name in _WORKFLOWS:
        from . import workflows

        return getattr(workflows, name)
    raise AttributeError(f"module 'symoro_gen' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(list(globals()) + list(_WORKFLOWS))
