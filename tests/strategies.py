"""Hypothesis strategies of random MDH robots, as robot-file text (parse with ``parse_robot_text``).

``from tests.strategies import mdh_robots, mdh_trees``

The drawn robots of ``mdh_robots`` are serial chains of revolute and prismatic joints in Khalil-Kleinfinger
notation, exercising what the robot-file format allows: alpha in {0, +-pi/2} or arbitrary,
d and r zero / numeric / symbolic (with ``[values]``), theta (or r) offsets, ``-q`` joint
directions, gamma and b on some rows, per-joint drive-parameter subsets and sometimes a
payload frame (sigma = 2) fixed to one of the links.

Numeric values are either exactly zero or bounded away from it (|x| >= 0.05 m), and arbitrary
angles are bounded away from multiples of pi/2 (>= 0.1 rad), so that "zero" and "special
angle" mean the same thing symbolically and numerically (rank tests are not fooled by
1e-300 lengths).
"""
from __future__ import annotations

import math

from hypothesis import strategies as st

from symoro_gen.params import DRIVE_KINDS

_SPECIAL_ANGLES = ("0", "pi/2", "-pi/2")


def _fmt(x: float) -> str:
    return repr(float(x))


@st.composite
def _length(draw, *, zero_weight: int = 2) -> float:
    """0 (with weight ``zero_weight`` out of ``zero_weight + 3``) or +-[0.05, 0.8] m in mm steps."""
    if draw(st.integers(0, zero_weight + 2)) < zero_weight:
        return 0.0
    return draw(st.sampled_from((-1, 1))) * draw(st.integers(50, 800)) / 1000.0


@st.composite
def _arbitrary_angle(draw) -> float:
    """An angle in (-pi, pi] at least 0.1 rad away from every multiple of pi/2."""
    quadrant = draw(st.integers(-2, 1))
    return quadrant * math.pi / 2 + draw(st.integers(100, 1470)) / 1000.0


@st.composite
def _angle(draw, *, arbitrary_weight: int = 1) -> str:
    """``"0"``, ``"pi/2"``, ``"-pi/2"`` or an arbitrary angle (as a number string)."""
    k = draw(st.integers(0, 2 + arbitrary_weight))
    if k <= 2:
        return _SPECIAL_ANGLES[k]
    return _fmt(draw(_arbitrary_angle()))


def _expr_with(values: dict, name: str, x: float) -> str:
    """A length as a TOML value: numeric, or a symbol recorded in ``values``."""
    values[name] = x
    return f'"{name}"'


@st.composite
def _const_length(draw, values: dict, name: str, *, zero_weight: int = 2) -> str:
    x = draw(_length(zero_weight=zero_weight))
    if x != 0.0 and draw(st.booleans()):
        return _expr_with(values, name, x)
    return _fmt(x)


@st.composite
def _joint_expr(draw, values: dict, name: str, *, kind: str) -> str:
    """``q`` or ``-q`` plus an optional constant offset, as a quoted TOML string.

    ``kind`` is ``"angle"`` (offset 0, +-pi/2 or arbitrary) or ``"length"`` (offset 0,
    numeric or symbolic).
    """
    q = draw(st.sampled_from(("q", "q", "q", "-q")))
    if kind == "angle":
        off = draw(_angle(arbitrary_weight=1))
        if off == "0":
            return f'"{q}"'
        return f'"{q} + {off}"' if not off.startswith("-") else f'"{q} - {off[1:]}"'
    x = draw(_length(zero_weight=2))
    if x == 0.0:
        return f'"{q}"'
    if draw(st.booleans()):
        values[name] = x
        return f'"{q} + {name}"'
    return f'"{q} + {_fmt(x)}"' if x > 0 else f'"{q} - {_fmt(-x)}"'


@st.composite
def mdh_robots(draw, min_joints: int = 2, max_joints: int = 7, *, random_gravity: bool = False, payload: bool | None = None) -> str:
    """Robot-file text of a random serial MDH robot.

    Parameters
    ----------
    min_joints, max_joints : int
        Number of moving joints (inclusive bounds).
    random_gravity : bool
        When True the gravity vector is sometimes not along -z0 (default: always
        ``[0, 0, -9.81]``, which the closed-form base-parameter rules assume).
    payload : bool, optional
        Force (True) or forbid (False) a payload frame; by default drawn.

    Returns
    -------
    str
        TOML text in the robots/ format.
    """
    n = draw(st.integers(min_joints, max_joints))
    values: dict[str, float] = {}
    frames: list[str] = []
    for j in range(1, n + 1):
        sigma = draw(st.sampled_from((0, 0, 0, 1)))
        alpha = draw(_angle(arbitrary_weight=1))
        d = draw(_const_length(values, f"D{j}"))
        if sigma == 0:
            theta = draw(_joint_expr(values, f"TH{j}", kind="angle"))
            r = draw(_const_length(values, f"RL{j}"))
        else:
            theta = f'"{draw(_angle(arbitrary_weight=1))}"'
            r = draw(_joint_expr(values, f"RL{j}", kind="length"))
        lines = [f"j = {j}", f"ant = {j - 1}", f"sigma = {sigma}"]
        if draw(st.integers(0, 5)) == 0:  # gamma / b on about one row in six
            lines.append(f'gamma = "{draw(_angle(arbitrary_weight=2))}"')
            lines.append(f"b = {draw(_const_length(values, f'B{j}', zero_weight=1))}")
        lines += [f'alpha = "{alpha}"', f"d = {d}", f"theta = {theta}", f"r = {r}"]
        if draw(st.integers(0, 2)) == 0:  # a per-joint drive subset on about one row in three
            subset = [k for k in DRIVE_KINDS if draw(st.booleans())]
            lines.append("drive = [" + ", ".join(f'"{k}"' for k in subset) + "]")
        frames.append("\n".join(lines))

    has_payload = draw(st.booleans()) if payload is None else payload
    head = ['name = "random"', 'source = "hypothesis strategy tests.strategies.mdh_robots"']
    if has_payload:
        k = n + 1
        ant = draw(st.sampled_from([n] * 3 + list(range(1, n))))
        lines = [f"j = {k}", f"ant = {ant}", "sigma = 2"]
        lines += [
            f'alpha = "{draw(_angle())}"',
            f"d = {_fmt(draw(_length()))}",
            f'theta = "{draw(_angle())}"',
            f"r = {_fmt(draw(_length()))}",
        ]
        frames.append("\n".join(lines))
        head.append(f"payload = {k}")
    if random_gravity and draw(st.booleans()):
        g = [draw(st.integers(-981, 981)) / 100.0 for _ in range(3)]
        head.append("gravity = [" + ", ".join(_fmt(x) for x in g) + "]")
    else:
        head.append("gravity = [0, 0, -9.81]")
    parts = ["\n".join(head)]
    if values:
        parts.append("[values]\n" + "\n".join(f"{k} = {_fmt(v)}" for k, v in sorted(values.items())))
    parts += ["[[frames]]\n" + f for f in frames]
    return "\n\n".join(parts) + "\n"


@st.composite
def mdh_trees(draw, min_frames: int = 2, max_frames: int = 14, *, random_gravity: bool = False,
              payload: bool | None = None) -> str:
    """Robot-file text of a random tree-structured MDH robot (Khalil-Kleinfinger notation for trees).

    Every moving frame ``j`` hangs off any earlier frame (``0 <= ant < j``; about half the frames
    continue the previous one, the others branch anywhere, the base included). A frame that starts
    a branch (``ant != j - 1``) gets gamma and b on about two rows in three (the common normal of
    its axis and its antecedent's is not the antecedent's x axis); the others on one in six. The
    row values are drawn as in :func:`mdh_robots`, and so are the drive subsets, the payload frame
    (fixed, on any moving frame) and the gravity.

    Parameters
    ----------
    min_frames, max_frames : int
        Number of moving frames (inclusive bounds).
    random_gravity, payload : see :func:`mdh_robots`.
    """
    n = draw(st.integers(min_frames, max_frames))
    values: dict[str, float] = {}
    frames: list[str] = []
    for j in range(1, n + 1):
        ant = j - 1 if draw(st.booleans()) else draw(st.integers(0, j - 1))
        sigma = draw(st.sampled_from((0, 0, 0, 1)))
        alpha = draw(_angle(arbitrary_weight=1))
        d = draw(_const_length(values, f"D{j}"))
        if sigma == 0:
            theta = draw(_joint_expr(values, f"TH{j}", kind="angle"))
            r = draw(_const_length(values, f"RL{j}"))
        else:
            theta = f'"{draw(_angle(arbitrary_weight=1))}"'
            r = draw(_joint_expr(values, f"RL{j}", kind="length"))
        lines = [f"j = {j}", f"ant = {ant}", f"sigma = {sigma}"]
        if draw(st.integers(0, 5)) < (4 if ant != j - 1 else 1):
            lines.append(f'gamma = "{draw(_angle(arbitrary_weight=2))}"')
            lines.append(f"b = {draw(_const_length(values, f'B{j}', zero_weight=1))}")
        lines += [f'alpha = "{alpha}"', f"d = {d}", f"theta = {theta}", f"r = {r}"]
        if draw(st.integers(0, 3)) == 0:
            subset = [k for k in DRIVE_KINDS if draw(st.booleans())]
            lines.append("drive = [" + ", ".join(f'"{k}"' for k in subset) + "]")
        frames.append("\n".join(lines))
    head = ['name = "random_tree"', 'source = "hypothesis strategy tests.strategies.mdh_trees"']
    if draw(st.booleans()) if payload is None else payload:
        k = n + 1
        lines = [f"j = {k}", f"ant = {draw(st.integers(1, n))}", "sigma = 2",
                 f'alpha = "{draw(_angle())}"', f"d = {_fmt(draw(_length()))}",
                 f'theta = "{draw(_angle())}"', f"r = {_fmt(draw(_length()))}"]
        frames.append("\n".join(lines))
        head.append(f"payload = {k}")
    if random_gravity and draw(st.booleans()):
        g = [draw(st.integers(-981, 981)) / 100.0 for _ in range(3)]
        head.append("gravity = [" + ", ".join(_fmt(x) for x in g) + "]")
    else:
        head.append("gravity = [0, 0, -9.81]")
    parts = ["\n".join(head)]
    if values:
        parts.append("[values]\n" + "\n".join(f"{k} = {_fmt(v)}" for k, v in sorted(values.items())))
    parts += ["[[frames]]\n" + f for f in frames]
    return "\n\n".join(parts) + "\n"
