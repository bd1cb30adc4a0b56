"""Research code kept beside the package, not installed with it (``pyproject.toml`` installs ``symoro_gen*`` only):
studies the benches and tests use, which import :mod:`symoro_gen` and are never imported by it. See README.md."""
