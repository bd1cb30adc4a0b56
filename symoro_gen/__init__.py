"""symoro_gen: MDH robot table -> symbolic identification model -> identified parameters."""
__version__ = "0.1.0"

from .loader import load_model

__all__ = ["load_model", "__version__"]
