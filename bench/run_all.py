"""Run every benchmark in bench/ (``make bench``)."""
import runpy
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
for f in sorted(HERE.glob("bench_*.py")):
    print(f"===== {f.name}")
    try:
        runpy.run_path(str(f), run_name="__main__")
    except SystemExit as e:
        if e.code not in (0, None):
            sys.exit(e.code)
