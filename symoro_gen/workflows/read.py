"""``read_recording``: one DATA file (or split-file spec) -> its experiments and what reading it did, as a results
object.

The library's front door to the readers (``symoro_gen.read_recording``)::

    trajectories, load = symoro_gen.read_recording("run1.csv", n_joints=4)     # the reader's pair, unpacked
    rec = symoro_gen.read_recording("run1.csv", n_joints=4)
    rec.summary(); rec.to_dict()["data"]; rec.report("run1.html"); rec.plot()

It reads with :func:`symoro_gen.preprocessing.readers.read_recording` (the same arguments, every format, ROS bags
with ``topic=``...) and returns :class:`RecordingResults`: still the reader's tuple ``(trajectories, load_report)``
(immutable), with the results methods of every workflow: ``summary()`` the ``Data:`` block the commands print for
the file, ``to_dict()`` its ``data`` entry of their JSON with the experiments, ``schema_version`` and
``provenance``, ``plot()`` and ``report(path)`` the signals per joint (as ``inspect``'s report shows them).
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..errors import DataFileError
from ..preprocessing.cli import data_block, data_text
from ..preprocessing.inspect import signal_figures
from ..preprocessing.readers import LoadReport, LogFormat, parse_data_spec
from ..preprocessing.readers import read_recording as read_one
from ..preprocessing.trajectory import Trajectory
from ..report.document import Figure, Heading, Paragraph, Report, Table, write_report_files
from ..report.plots import figure_png, require_matplotlib
from .base import SCHEMA_VERSION, Results, robot_description
from .provenance import provenance_block

__all__ = ["RecordingResults", "read_recording"]


class RecordingResults(tuple, Results):
    """What :func:`read_recording` read: the reader's pair ``(trajectories, load_report)`` (a tuple: unpack it as
    before) with the results methods. Immutable: no attribute can be set."""

    __slots__ = ()
    command = "read_recording"

    def __new__(cls, trajectories: tuple[Trajectory, ...], load: LoadReport):
        return super().__new__(cls, (tuple(trajectories), load))

    def __repr__(self) -> str:
        return f"RecordingResults({self.load.file!r}, {len(self.trajectories)} experiment(s))"

    @property
    def trajectories(self) -> tuple[Trajectory, ...]:
        """One trajectory per experiment (a file splits at its gaps with ``resample``)."""
        return self[0]

    @property
    def load(self) -> LoadReport:
        """What reading did: rows read and dropped, resampling, gaps, options, notes."""
        return self[1]

    def to_dict(self) -> dict:
        """``generator``, ``schema_version``, ``data`` (the file's entry of the commands' JSON ``data`` list),
        ``experiments`` (per experiment its ``source``, ``samples``, ``t_start``, ``t_end`` [s], ``joints``,
        ``loaded``) and ``provenance``."""
        exps = [{"source": tr.source, "samples": int(tr.n_samples), "t_start": float(tr.t[0]),
                 "t_end": float(tr.t[-1]), "joints": int(tr.n_joints), "loaded": bool(tr.loaded)}
                for tr in self.trajectories]
        return {"generator": f"symoro-gen {self.command}", "schema_version": SCHEMA_VERSION,
                "data": data_block([self.load]), "experiments": exps, "provenance": self.provenance()}

    def summary(self) -> str:
        """The ``Data:`` block ``identify`` and ``diagnose`` print for this file (rows read, dropped, resampling,
        experiments, notes)."""
        return data_text([self.load])

    def figures(self) -> list:
        """One matplotlib figure per experiment and joint: q and tau against t."""
        return [fig for _, fig, _ in signal_figures(self.trajectories)]

    def report(self, path: str | os.PathLike[str], *, force: bool = False) -> Path:
        """How the file was read (table) and the signals per joint, ``.html`` self-contained or ``.md`` with its
        images beside it (the 'plots' extra)."""
        require_matplotlib()
        self.check_output(path, force=force, label="report", report=True)
        ld = self.load
        blocks: list = [Paragraph(self.summary().splitlines()[1].strip()),
                        Table(("experiment", "samples", "t start [s]", "t end [s]", "joints", "payload"),
                              tuple((tr.source, str(tr.n_samples), f"{tr.t[0]:.6g}", f"{tr.t[-1]:.6g}",
                                     str(tr.n_joints), "yes" if tr.loaded else "no") for tr in self.trajectories),
                              caption=f"{ld.file}: the experiments read")]
        blocks.append(Heading("Signals per joint", 2))
        for name, fig, caption in signal_figures(self.trajectories):
            blocks.append(Figure(name, figure_png(fig, int(fig.dpi)), caption=caption, figure=fig))
        write_report_files(Report(f"Recording {ld.file}", tuple(blocks)), path, force=force)
        return Path(path)

    def provenance(self) -> dict:
        """The provenance block: package version and commit, the reading's options (the format's, as the load
        report gives them), the joints, the payload flag, and each file the DATA argument names with its sha256."""
        trs = self.trajectories
        options = {"format": list(self.load.options), "n_joints": int(trs[0].n_joints) if trs else None,
                   "loaded": bool(trs and trs[0].loaded)}
        return provenance_block(options, _spec_files(self.load.file))

    def input_files(self) -> tuple[tuple[str, str | os.PathLike[str]], ...]:
        """The files read (never an output of :meth:`report`)."""
        return tuple(("input", f) for f in _spec_files(self.load.file))


def _spec_files(spec: str) -> list[str]:
    """The files a DATA argument names (a split spec's each; a segment ``path[start:stop]`` its file)."""
    text = spec.split("[", 1)[0] if spec.endswith("]") else spec
    try:
        return [os.fspath(f) for f in parse_data_spec(text).files.values()]
    except DataFileError:  # not a spec: the name as given
        return [text]


def read_recording(path, fmt: LogFormat | None = None, *, robot=None, n_joints: int | None = None,
                   drive_chain=None, loaded: bool = False, start: int = 0, stop: int = -1, base_dir=None,
                   **bag: Any) -> RecordingResults:
    """Read one DATA file (or split-file spec): :func:`symoro_gen.preprocessing.readers.read_recording`, the same
    arguments (``fmt`` a :class:`LogFormat`; ``robot`` — a name, a robot file, a :class:`RobotDescription` or a
    loaded model, as ``identify`` takes it — or ``n_joints``; ``drive_chain`` (default: the robot file's
    ``[drive_chain]``, so that a motor-side recording is read at the joint side as the commands read it),
    ``loaded``, ``start``, ``stop``, ``base_dir``; a ROS bag's ``topic``, ``stamp``, ``prefix``, ``joint_names``, ``reference_topic``; any
    other name raises :class:`~symoro_gen.errors.OptionError` naming the nearest), the same errors.

    Returns
    -------
    RecordingResults
        The reader's pair ``(trajectories, load_report)``, with ``summary()``, ``to_dict()``, ``plot()``,
        ``report(path)``.
    """
    robot = None if robot is None else robot_description(robot)
    if drive_chain is None and robot is not None:
        drive_chain = robot.drive_chain
    trajectories, load = read_one(path, fmt, robot=robot, n_joints=n_joints, drive_chain=drive_chain,
                                  loaded=loaded, start=start, stop=stop, base_dir=base_dir, **bag)
    return RecordingResults(trajectories, load)
