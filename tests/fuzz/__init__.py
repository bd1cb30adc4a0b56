"""Fuzz suite: malformed and unusual inputs through the command line, each case checking
the exit status, a one-line message naming the file (and field), and that nothing outside the
command's output was touched (:mod:`tests.fuzz.helpers`).

Classes and where they are:

* robot files, MDH expressions: ``test_robot_files.py``
* data files (CSV/NPZ/NPY/MAT, damaged or of the wrong kind), split-recording specs: ``test_data_files.py``
* data-format specs (``--columns``, ``--format FILE.toml``): ``test_format_specs.py``
* URDF and SYMORO ``.par`` imports: ``test_import_files.py``
* output paths (exports, ``generate --out``, ``identify --json/--report``) and interrupts (SIGINT during
  ``generate``, ``demo``, ``identify``): ``test_outputs_and_interrupts.py``

``SYMORO_FUZZ_EXAMPLES=500`` runs a deeper, random search locally.
"""
