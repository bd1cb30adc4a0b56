"""``inspect`` prints each note of a load report once: under ``Data:``, not again as a ``warning:`` line; the JSON
keeps them in ``data[].notes`` and its ``warnings`` (the key kept) holds the findings, not the notes again."""
from __future__ import annotations

import json

import numpy as np

import symoro_gen


def _logs(folder):
    """Two 1 kHz SCARA logs whose reading leaves notes: three garbage rows before the recording (``--skip-rows
    3``: rows skipped), and a log whose time stamps have two 8.8 ms steps (``--resample``: split in three)."""
    t = np.arange(3000) * 0.001
    q = np.column_stack([0.5 * np.sin(2 * np.pi * 0.3 * (j + 1) * t + j) for j in range(4)])
    tau = np.column_stack([2.0 * np.cos(2 * np.pi * 0.2 * (j + 1) * t) + 0.3 * j for j in range(4)])
    hdr = "t," + ",".join(f"q{j}" for j in range(1, 5)) + "," + ",".join(f"tau{j}" for j in range(1, 5))
    rows = np.column_stack([t, q, tau])
    garbage = np.zeros((3, 9))
    garbage[:, 0] = [-0.12, 0.79, 0.0]
    a, b = folder / "garbage.csv", folder / "gaps.csv"
    np.savetxt(a, np.vstack([garbage, rows]), delimiter=",", header=hdr, comments="", fmt="%.10g")
    gaps = rows.copy()
    for k in (1000, 2000):
        gaps[k:, 0] += 0.0078
    np.savetxt(b, gaps, delimiter=",", header=hdr, comments="", fmt="%.10g")
    return a, b


def test_inspect_prints_each_note_once(cli, tmp_path):
    a, b = _logs(tmp_path)
    out = tmp_path / "i.json"
    r = cli("inspect", "scara", a, b, "--skip-rows", "3", "--resample", "--json", out)
    d = json.loads(out.read_text())
    notes = [n for blk in d["data"] for n in blk["notes"]]
    # the notes the readers wrote: rows skipped in both files, the split of the second one
    assert any("skipped (--skip-rows 3)" in n for n in notes)
    assert any("split the file" in n for n in notes) and any("3 experiment(s)" in n for n in notes)
    for n in notes:
        assert r.out.count(n) == notes.count(n), (n, r.out)   # printed once per file, under Data:
        assert r.out.count(f"    note: {n}\n") == notes.count(n)
        assert not any(n in w for w in d["warnings"])      # not repeated as a warning
    assert not any(line.startswith("warning:") and "skipped" in line for line in r.out.splitlines())
    res = symoro_gen.inspect("scara", [a, b], data_format=symoro_gen.preprocessing.make_format(skip_rows=3,
                                                                                              resample=True))
    assert res.summary() + "\n" == r.out                  # the library call prints the same
    assert list(res.inspection.warnings) == d["warnings"]


def test_inspect_still_warns_what_may_spoil_the_identification(cli, tmp_path):
    """Dropping the notes from the warnings leaves the findings there: a joint that never moves is a warning (and
    the recording not usable, exit 2)."""
    a, _ = _logs(tmp_path)
    header, *rows = a.read_text().splitlines()
    still = tmp_path / "still.csv"
    still.write_text("\n".join([header] + [",".join("0.3" if i == 4 else x for i, x in enumerate(r.split(",")))
                                           for r in rows]) + "\n")
    out = tmp_path / "s.json"
    r = cli("inspect", "scara", still, "--skip-rows", "3", "--json", out, rc=2)
    d = json.loads(out.read_text())
    assert any("joint 4 never moves" in w for w in d["warnings"])
    assert "warning: " + next(w for w in d["warnings"] if "never moves" in w) in r.out
    assert r.out.count("skipped (--skip-rows 3)") == 1
