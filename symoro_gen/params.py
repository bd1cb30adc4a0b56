"""The one place that defines the standard-parameter order and names.

Per moving link j, in frame j at its origin (Khalil-Kleinfinger)::

    XXj XYj XZj YYj YZj ZZj MXj MYj MZj Mj IAj FVj FSj OFFj

IA, FV, FS, OFF are the drive-chain terms of joint j (rotor inertia, viscous and
Coulomb friction, offset); a robot file may exclude some of them per joint.
A payload (fixed link, sigma = 2) has only the 10 inertial ones.
"""
from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence

from .errors import IdentificationError

INERTIAL_KINDS: tuple[str, ...] = ("XX", "XY", "XZ", "YY", "YZ", "ZZ", "MX", "MY", "MZ", "M")
DRIVE_KINDS: tuple[str, ...] = ("IA", "FV", "FS", "OFF")
PARAM_KINDS: tuple[str, ...] = INERTIAL_KINDS + DRIVE_KINDS

#: index of each inertial kind inside the 10-vector (conversions: :mod:`symoro_gen.description.inertia`)
INERTIAL_INDEX = {k: i for i, k in enumerate(INERTIAL_KINDS)}


def param_name(kind: str, frame: int) -> str:
    """SYMORO-style name of a standard parameter.

    Examples
    --------
    >>> param_name("XX", 2)
    'XX2'
    >>> [param_name(k, 7) for k in DRIVE_KINDS]
    ['IA7', 'FV7', 'FS7', 'OFF7']
    >>> param_name("ZZR", 1)
    Traceback (most recent call last):
    ...
    ValueError: unknown parameter kind 'ZZR'; expected one of ('XX', 'XY', 'XZ', 'YY', 'YZ', 'ZZ', 'MX', 'MY', 'MZ', 'M', 'IA', 'FV', 'FS', 'OFF')
    """
    if kind not in PARAM_KINDS:
        raise ValueError(f"unknown parameter kind {kind!r}; expected one of {PARAM_KINDS}")
    return f"{kind}{frame}"


def split_name(name: str) -> tuple[str, int, bool]:
    """Inverse of :func:`param_name`, also for regrouped names (``R`` suffix).

    Examples
    --------
    >>> split_name("XX2R")
    ('XX', 2, True)
    >>> split_name("M10"), split_name("MX3")
    (('M', 10, False), ('MX', 3, False))
    >>> split_name("Q1")
    Traceback (most recent call last):
    ...
    ValueError: not a standard parameter name: 'Q1'
    """
    base = name[:-1] if name.endswith("R") else name
    regrouped = name.endswith("R")
    for kind in sorted(PARAM_KINDS, key=len, reverse=True):
        if base.startswith(kind) and base[len(kind):].isdigit():
            return kind, int(base[len(kind):]), regrouped
    raise ValueError(f"not a standard parameter name: {name!r}")


def parse_payload(items: Iterable[str] | None) -> dict[str, float]:
    """``--payload NAME=VALUE ...`` as a mapping (the message names the item at fault)."""
    out: dict[str, float] = {}
    for it in items or ():
        if not isinstance(it, str) or "=" not in it:
            raise IdentificationError(f"--payload {it!r}: expected NAME=VALUE, e.g. M8=4.6136")
        k, v = it.split("=", 1)
        k = k.strip()
        try:
            out[k] = float(v)
        except ValueError:
            raise IdentificationError(f"--payload {k}={v!r}: value is not a number") from None
    return out


def payload_mapping(payload: Mapping[str, float] | Iterable[str] | str | None) -> dict[str, float]:
    """Known payload parameters given from Python: a mapping ``{name: value}``, or the command's ``NAME=VALUE``
    items (a list of them, or one string of them separated by blanks) read by :func:`parse_payload`."""
    if isinstance(payload, Mapping):
        return dict(payload)
    return parse_payload(payload.split() if isinstance(payload, str) else payload)


def check_payload(payload: Mapping[str, float] | None, names: Sequence[str]) -> dict[str, float]:
    """Known payload parameters, each a payload parameter of the robot (the message names the one that is not)."""
    out = {}
    for k, v in (payload or {}).items():
        if k not in names:
            raise IdentificationError(f"--payload {k}: not a payload parameter of this robot "
                                      f"({', '.join(names) or 'none'})")
        out[k] = float(v)
    return out
