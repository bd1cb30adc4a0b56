"""The data options every command that reads DATA shares (identify, diagnose, inspect).

:func:`add_data_options` registers them on an argparse parser, :func:`load_data` turns the parsed
arguments into trajectories and :class:`~symoro_gen.preprocessing.readers.LoadReport` s,
:func:`data_block` / :func:`data_text` echo the reports (JSON ``data`` block, text output).
"""
from __future__ import annotations

import argparse
from collections.abc import Sequence

from ..errors import OptionError
from .readers import ABSURD_VALUE, LoadReport, LogFormat, make_format, read_recordings
from .readers.options import BAG_KEYS, RESHAPE_ORDERS
from .trajectory import Trajectory, hold_back

__all__ = ["add_data_options", "format_from_args", "load_data", "data_block", "data_text", "data_notes",
           "split_held_back"]


def add_data_options(p: argparse.ArgumentParser, *, validate_fraction: bool = False) -> None:
    """Add ``--format --columns --dt --dt-overrides-time --tau-scale --deg --mm --resample --max-gap --drop-bad-rows
    --skip-rows --reshape``, the ROS bag options ``--topic --stamp --prefix --joint-names --reference-topic`` (and,
    with ``validate_fraction``, ``--validate-fraction``) to a command's parser."""
    g = p.add_argument_group("reading the DATA files (docs/data-files.md)")
    g.add_argument("--format", metavar="FILE.toml", help="a log format file with the keys below (options given "
                   "on the command line override it)")
    g.add_argument("--columns", metavar="SPEC", help="which columns are what: t=0,q=1:7,tau=13:19 (0-based, "
                   "Python slices) or q=q_0:q_6,tau=tau_0:tau_6 (header names, inclusive); optional dq=, ddq=, "
                   "q_link= (link-side position); in .npz/.mat array names, nested structs dotted (q=rec.pos)")
    g.add_argument("--dt", type=float, metavar="SECONDS", help="sampling period when the file has no time column "
                   "(a single file, or a split recording without t=); a time column or t= file and --dt is an error "
                   "unless --dt-overrides-time")
    g.add_argument("--dt-overrides-time", action="store_true", default=None,
                   help="with --dt: ignore the files' time column and use --dt as the time base")
    g.add_argument("--tau-scale", metavar="V[,V...]", help="factor(s) turning the logged torque signal into N m "
                   "(one per joint or one for all), e.g. current x torque constant x ratio")
    g.add_argument("--deg", action="store_true", default=None, help="positions of the revolute joints are logged "
                   "in degrees (converted to rad; prismatic joints stay in m, the robot file gives the joint types)")
    g.add_argument("--mm", action="store_true", default=None, help="positions of the prismatic joints are logged "
                   "in millimetres (converted to m; revolute joints and the prismatic joints' forces untouched; with "
                   "a drive chain only a link-side q_link column)")
    g.add_argument("--resample", action="store_true", default=None,
                   help="resample irregular time stamps on a uniform grid at the median step (cubic for q, linear "
                        "for the rest); steps longer than --max-gap split the file into experiments")
    g.add_argument("--max-gap", type=float, metavar="SECONDS", help="longest step bridged by --resample "
                   "(default 5 median steps)")
    g.add_argument("--drop-bad-rows", action="store_true", default=None,
                   help=f"drop rows with a wrong field count, unparsable/non-finite numbers or |value| > "
                        f"{ABSURD_VALUE:g}, and a few isolated rows whose time is out of order (counted in the "
                        "output) instead of stopping")
    g.add_argument("--skip-rows", type=int, metavar="N", help="skip the first N data rows of every file (below the "
                   "header): garbage a logger writes before the recording starts")
    g.add_argument("--reshape", choices=RESHAPE_ORDERS, help="files of a split recording with one value per "
                   "line hold the n joint values of each sample in this order: sample-major (the n joints of "
                   "sample 1, then sample 2 ...) or joint-major (every sample of joint 1, then joint 2 ...: "
                   "MATLAB's M(:)); default: the one order in which the signals are smooth")
    b = p.add_argument_group("reading ROS bags (.mcap, .db3, .bag, rosbag2 folders; docs/data-files.md)")
    b.add_argument("--topic", metavar="TOPIC[,TOPIC...]", help="the sensor_msgs/JointState topic(s) (default: every "
                   "JointState topic carrying the robot's joints)")
    b.add_argument("--stamp", choices=("header", "log"), default=None, help="time of a message: its header stamp "
                   "(default; the bag's log times when every header stamp is zero) or the bag's log time")
    b.add_argument("--prefix", metavar="TEXT", help="the robot's joints are named TEXT + name in the bag "
                   "(several robots in one bag: left_, right_)")
    b.add_argument("--joint-names", metavar="A,B,C", help="the bag's names of the robot's joints, in the robot's "
                   "order (default: the URDF joint names kept in the robot file, else the order of the messages)")
    b.add_argument("--reference-topic", metavar="TOPIC", help="commanded positions (JointState, trajectory_msgs/"
                   "JointTrajectory, or a controller state with joint_names and reference/desired): the recorded "
                   "reference of --method iv/didim")
    if validate_fraction:
        g.add_argument("--validate-fraction", type=float, metavar="F",
                       help="hold back the last F (0 < F < 1) of each DATA file for validation (of the whole file "
                            "when --resample splits it into experiments)")


def format_from_args(args) -> LogFormat:
    """The :class:`LogFormat` of parsed arguments (over ``--format FILE``)."""
    return make_format(columns=getattr(args, "columns", None), dt=getattr(args, "dt", None),
                       tau_scale=getattr(args, "tau_scale", None), deg=getattr(args, "deg", None),
                       mm=getattr(args, "mm", None),
                       resample=getattr(args, "resample", None), max_gap=getattr(args, "max_gap", None),
                       drop_bad_rows=getattr(args, "drop_bad_rows", None), format_file=getattr(args, "format", None),
                       dt_overrides_time=getattr(args, "dt_overrides_time", None),
                       skip_rows=getattr(args, "skip_rows", None), reshape=getattr(args, "reshape", None),
                       bag={k: getattr(args, k, None) for k in BAG_KEYS})


def load_data(args, paths: Sequence, robot, *, loaded: bool = False
              ) -> tuple[tuple[Trajectory, ...], tuple[LoadReport, ...]]:
    """Read ``paths`` with the data options of ``args`` for ``robot`` (its drive chain applied)."""
    fmt = format_from_args(args)
    return read_recordings(paths, fmt, n_joints=len(robot.model_joints), robot=robot, drive_chain=robot.drive_chain,
                           loaded=loaded)


def split_held_back(args, trajectories):
    """``--validate-fraction F``: (identification part, held-back part); without it (all, ())."""
    f = getattr(args, "validate_fraction", None)
    if f is None:
        return tuple(trajectories), ()
    if not 0 < f < 1:
        raise OptionError(f"--validate-fraction {f:g}: must lie between 0 and 1 (a share of each recording)")
    return hold_back(trajectories, f)


def data_block(reports: Sequence[LoadReport]) -> list[dict]:
    """The JSON ``data`` block: one entry per file."""
    return [r.to_dict() for r in reports]


def data_text(reports: Sequence[LoadReport]) -> str:
    """The text echo: one line per file, plus the dropped rows and notes."""
    lines = ["Data:"]
    for r in reports:
        lines.append("  " + r.summary())
        lines += [f"    dropped {d}" for d in r.dropped] + [f"    note: {x}" for x in r.notes]
    return "\n".join(lines)


def data_notes(reports: Sequence[LoadReport]) -> list[str]:
    """Report notes (one per file)."""
    return ["data " + r.summary() for r in reports]
