"""Generic table helpers of the reports (no domain object, no plotting): number formats, the per-joint error
table, warnings, HTML fragments for Jupyter. Each stage renders its own blocks with them
(:mod:`symoro_gen.identification.render`, :mod:`symoro_gen.diagnostics.render`)."""
from __future__ import annotations

import math
import re
from collections.abc import Sequence

import numpy as np

from .document import Heading, ItemList, Table, render_html_fragment

__all__ = ["POOR_PCT", "fmt_err", "fmt_known", "fmt_pct", "fmt_value", "html_fragment", "is_mass_name", "is_poor",
           "raw_err_table", "rel_err_table", "slug", "unique_in_order", "warnings_block"]

#: %sigma above which a parameter row is marked as poorly identified (the estimators' warning level)
POOR_PCT = 30.0

_MASS = re.compile(r"^M\d+$")


def is_mass_name(name: str) -> bool:
    """``M8`` is a mass; ``MX8`` is a first moment."""
    return bool(_MASS.match(str(name)))


def fmt_value(x) -> str:
    """4 significant digits; scientific notation outside [1e-3, 1e5); ``inf``/``nan`` spelled out."""
    if x is None:
        return "-"
    x = float(x)
    if not math.isfinite(x):
        return "nan" if math.isnan(x) else ("inf" if x > 0 else "-inf")
    if x == 0:
        return "0"
    return f"{x:.4g}" if 1e-3 <= abs(x) < 1e5 else f"{x:.3e}"


def fmt_known(x) -> str:
    """A known (given) value with up to 6 significant digits, as the user wrote it."""
    x = float(x)
    return f"{x:.6g}" if math.isfinite(x) else fmt_value(x)


def fmt_pct(x) -> str:
    """A %sigma with 2 decimals (``inf`` for parameters that are 0 or not identifiable)."""
    if x is None:
        return "-"
    x = float(x)
    if not math.isfinite(x):
        return "nan" if math.isnan(x) else "inf"
    return f"{x:.2f}"


def fmt_err(x) -> str:
    """A relative error norm with 4 decimals."""
    x = float(x)
    return f"{x:.4f}" if math.isfinite(x) else "-"


def is_poor(pct: float) -> bool:
    """A %sigma above :data:`POOR_PCT` (or not finite): a poorly identified parameter."""
    return not (float(pct) <= POOR_PCT)


def rel_err_table(rows: Sequence[tuple[str, Sequence[float]]], n_joints: int,
                  caption: str = "Relative error norms ‖ρ_j‖/‖Y_j‖ per joint") -> Table:
    """One row per data set, one column per joint (LWR4 paper Table III)."""
    head = ("Data",) + tuple(f"joint {j + 1}" for j in range(n_joints))
    body = []
    for label, errs in rows:
        e = list(np.asarray(errs, float).reshape(-1))
        e += [math.nan] * (n_joints - len(e))
        body.append((label,) + tuple(fmt_err(x) for x in e[:n_joints]))
    return Table(head, tuple(body), caption)


def raw_err_table(rows, n_joints: int) -> Table:
    """Raw-torque relative error norms (``rel_err_raw``), its own table with a header saying so."""
    t = rel_err_table(rows, n_joints, caption=(
        "Relative error norms on the raw measured torque: ‖τ_j − τ̂_j‖/‖τ_j‖, the model at full rate on the "
        "filtered states against the unfiltered torque, every sample (no row selection)"))
    return Table(("Data (raw measured torque)",) + tuple(t.header[1:]), t.rows, t.caption)


def warnings_block(warnings: Sequence[str]) -> list:
    """Numbered warnings (as ``summary()`` numbers them)."""
    if not warnings:
        return []
    return [Heading("Warnings", 3), ItemList(tuple(str(w) for w in warnings), ordered=True)]


def unique_in_order(items) -> tuple[str, ...]:
    out: list[str] = []
    for w in items:
        if w not in out:
            out.append(w)
    return tuple(out)


def slug(text: str) -> str:
    """``text`` as a file-name stem: lower case, letters and digits, ``-`` between words."""
    s = "".join(c if c.isalnum() else "-" for c in text.lower())
    while "--" in s:
        s = s.replace("--", "-")
    return s.strip("-") or "figure"


def html_fragment(blocks, css_class: str) -> str:
    """Blocks as an HTML fragment in a ``<div class=...>`` (``_repr_html_`` of the results)."""
    return f'<div class="{css_class}">' + render_html_fragment(blocks) + "</div>"
