"""The package version (its own module, so that modules the loader imports can name it without importing
the package's ``__init__`` and, through it, the loader)."""

__version__ = "0.1.0"
