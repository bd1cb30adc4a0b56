"""``identify`` on the three real recordings with two versions of the code: every parameter's change in its
own standard deviation (the assembly engine's acceptance check: within 0.1 sigma).

The recordings of ``../shared/data`` (see its README) and the commands of the tests and the docs:

* KUKA LWR4+ (FloBaRoID, 200 Hz): files 1 and 3, validation on file 2 (``docs/results.md``,
  ``tests/identification/test_realdata_identification.py``);
* Staubli TX40 (figaroh, 5 kHz, motor side, coupled wrist), with the published table
  (``tests/identification/test_realdata_tx40.py``);
* KUKA LBR Med 7 (lbr-stack, 100 Hz, from its URDF), 30 % held back (``tests/test_logs_cli.py``).

Each command runs as ``python -m symoro_gen.cli ... --json`` with ``PYTHONPATH`` set to the code tree under
test, in a fresh process. ``--before`` defaults to the ``main`` branch exported (``git archive``) into a
temporary folder, ``--after`` to this checkout. Prints, per recording and method, the largest
``|after - before| / sigma_before`` over the parameters (and which), the settings used, the times.

Run: ``python bench/bench_engine_realdata.py [--before DIR|REF] [--after DIR] [--method wls ols]``.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("SYMORO_SHARED_DATA", ROOT.parent / "shared" / "data"))
if not DATA.is_dir():
    DATA = Path("/work/shared/data")
LWR4 = DATA / "kuka_lwr4_flobaroid" / "data" / "KUKA" / "HW"
TX40 = DATA / "staubli_tx40_figaroh"
MED7 = DATA / "kuka_lbr_med7_lbrstack"


def _cases(tmp: Path) -> dict[str, list[str]]:
    tx = f"q={TX40}/data/pos_read_data.csv,tau={TX40}/data/curr_data.csv,dt=0.0002"
    return {
        "LWR4 (files 1+3, validate 2)": ["lwr4", str(LWR4 / "measurements_1.npz"), str(LWR4 / "measurements_3.npz"),
                                         "--validate", str(LWR4 / "measurements_2.npz")],
        "TX40 (motor side, 5 kHz)": ["tx40", tx, "--reference", str(TX40 / "reference_results" / "TX40_bp_5.csv")],
        "LBR Med 7 (URDF, 30 % held back)": [str(tmp / "med7.toml"), str(MED7 / "data" / "measurements.csv"),
                                             "--columns", "q=q_0:q_6,tau=tau_0:tau_6", "--dt", "0.01",
                                             "--validate-fraction", "0.3"],
    }


def _run(tree: Path, args: list[str], out: Path) -> tuple[dict, float]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "symoro_gen.cli", "--quiet", "identify", *args, "--json", str(out)], env=env,
                       cwd=tree, capture_output=True, text=True, check=False)
    dt = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"identify failed in {tree}: {' '.join(args)}\n{r.stderr[-3000:]}")
    return json.loads(out.read_text()), dt


def _export(ref: str, dest: Path) -> Path:
    """The tree of git ref ``ref`` of this repository, extracted into ``dest`` (no worktree, no checkout)."""
    tar = dest / "src.tar"
    subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", "-o", str(tar), ref], check=True)
    with tarfile.open(tar) as t:
        t.extractall(dest / "tree", filter="data")
    return dest / "tree"


def _compare(before: dict, after: dict) -> tuple[float, str, float]:
    """Largest |after - before| / sigma_before over the parameters, its name, and the largest relative change
    of the relative errors."""
    pb, pa = before["parameters"], after["parameters"]
    if pb["names"] != pa["names"]:
        raise SystemExit(f"different parameters: {pb['names']} vs {pa['names']}")
    worst, name = 0.0, ""
    for n, vb, sb, va in zip(pb["names"], pb["values"], pb["std"], pa["values"]):
        z = abs(va - vb) / sb if sb and sb > 0 else (0.0 if va == vb else float("inf"))
        if z > worst:
            worst, name = z, n
    eb, ea = before.get("rel_err") or [], after.get("rel_err") or []
    rel = max((abs(a - b) / abs(b) for a, b in zip(ea, eb) if b), default=0.0)
    return worst, name, rel


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", default="main", help="a code folder or a git ref of this repository (default: main)")
    ap.add_argument("--after", default=str(ROOT), help="a code folder (default: this checkout)")
    ap.add_argument("--method", nargs="+", default=["wls", "ols"])
    a = ap.parse_args()
    if not (LWR4.is_dir() and TX40.is_dir() and MED7.is_dir()):
        print(f"[engine real data] skipped: the recordings are not in {DATA}")
        return
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        before = Path(a.before) if Path(a.before).is_dir() else _export(a.before, tmp)
        after = Path(a.after)
        r = subprocess.run([sys.executable, "-m", "symoro_gen.cli", "--quiet", "import-urdf",
                            str(MED7 / "urdf" / "med7dock.urdf"), "-o", str(tmp / "med7.toml")],
                           env={**os.environ, "PYTHONPATH": str(after)}, cwd=after, capture_output=True, text=True,
                           check=False)
        if r.returncode != 0:
            raise SystemExit(r.stderr)
        print(f"before: {before if Path(a.before).is_dir() else a.before + ' (git archive)'}; after: {after}")
        overall = 0.0
        for label, args in _cases(tmp).items():
            for method in a.method:
                jb, tb = _run(before, [*args, "--method", method], tmp / "b.json")
                ja, ta = _run(after, [*args, "--method", method], tmp / "a.json")
                z, name, rel = _compare(jb, ja)
                overall = max(overall, z)
                basis = ja.get("rel_err_basis") or {}
                print(f"  {label}, {method}: {len(ja['parameters']['names'])} parameters, cut-off "
                      f"{basis.get('cutoff_hz')} Hz, n_d {basis.get('n_d')}, {basis.get('rows')} rows; "
                      f"max |delta|/sigma = {z:.2e} ({name or '-'}); rel_err max relative change {rel:.1e}; "
                      f"{tb:.1f} s before, {ta:.1f} s after (whole command)")
        print(f"[engine real data] every parameter within 0.1 sigma: {'yes' if overall <= 0.1 else 'NO'} "
              f"(largest {overall:.2e} sigma)")


if __name__ == "__main__":
    main()
