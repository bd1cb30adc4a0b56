"""symoro_gen: MDH robot table -> symbolic identification model -> identified parameters."""
from .loader import load_model
from .version import __version__

__all__ = ["load_model", "__version__"]
