"""Run every benchmark in bench/ (``make bench``)."""
import runpy
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: command-line arguments of the benches run here with a quick setting (their default is long)
QUICK = {"bench_loop_truth.py": ["--cases", "1,7,11", "--seconds", "15", "--rate", "250"]}
for f in sorted(HERE.glob("bench_*.py")):
    print(f"===== {f.name}")
    argv = sys.argv
    sys.argv = [str(f), *QUICK.get(f.name, [])]
    try:
        runpy.run_path(str(f), run_name="__main__")
    except SystemExit as e:
        if e.code not in (0, None):
            sys.exit(e.code)
    finally:
        sys.argv = argv
