"""Report figures made with matplotlib (an optional dependency: the ``plots`` extra), drawn on the
Agg canvas without pyplot (no global backend state, no window), returned as PNG report blocks.

* :func:`torque_figure`: measured and IDM-reconstructed torque, one subplot per joint (Fig. 3 of the
  LWR4 paper);
* :func:`singular_values_figure`: singular values of W with unit-norm columns, and its condition number;
* :func:`residual_figure`: residual before and after an added effect against the signal that revealed it;
* :func:`error_bars_figure`: relative error norms per joint before and after (diagnosis).
"""
from __future__ import annotations

import io
import math
from collections.abc import Sequence

import numpy as np

from ..atomic import mark_png
from ..errors import SymoroError
from .document import Figure

__all__ = ["MissingDependencyError", "figure_and_axes", "figure_png", "require_matplotlib", "torque_figure",
           "singular_values_figure", "residual_figure", "error_bars_figure", "DPI", "WIDTH_IN", "MAX_POINTS", "N_BINS"]

#: resolution of every figure [dots per inch]; with WIDTH_IN the figures are 1100 px wide
DPI = 100
#: width of every figure [in]
WIDTH_IN = 11.0
#: most samples drawn per curve (longer records are shown one sample in k)
MAX_POINTS = 1500
#: bins of the binned-mean curves of residual plots
N_BINS = 30

MEASURED = "#1f77b4"
RECONSTRUCTED = "#d62728"
BEFORE = "#9e9e9e"
AFTER = "#1565c0"
BEFORE_MEAN = "#424242"
AFTER_MEAN = "#e65100"


class MissingDependencyError(SymoroError, ImportError):
    """An optional dependency is not installed (the message names the extra that brings it)."""

    def __init__(self, message: str, hint: str | None = None):
        super().__init__(message)
        self.hint = hint


def require_matplotlib():
    """The matplotlib classes the figures need: ``(Figure, FigureCanvasAgg)``.

    Raises
    ------
    MissingDependencyError
        matplotlib is not installed.
    """
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure as MplFigure
    except ImportError as exc:
        raise MissingDependencyError(
            "report plots need matplotlib, which is not installed (it comes with the optional 'plots' extra)",
            hint="pip install 'symoro_gen[plots]'  (or: pip install matplotlib); `make test` installs it") from exc
    return MplFigure, FigureCanvasAgg


#: margins of the axes grid [in]: left (y tick labels and label), right, between columns
LEFT_IN, RIGHT_IN, WSPACE_IN = 0.8, 0.25, 0.75


def _figure_and_axes(nrows: int, ncols: int, *, ax_h: float, gap: float, top: float, bottom: float, dpi: int,
                     right: float = RIGHT_IN):
    """A figure ``WIDTH_IN`` wide holding an ``nrows x ncols`` grid of axes ``ax_h`` inches high,
    ``gap`` inches apart vertically, with ``top``/``bottom`` inches for titles, labels and legend.

    Fixed margins rather than a layout engine: the same pixels, half the drawing time."""
    MplFigure, FigureCanvasAgg = require_matplotlib()
    height = top + bottom + nrows * ax_h + (nrows - 1) * gap
    fig = MplFigure(figsize=(WIDTH_IN, height), dpi=dpi, facecolor="white")
    FigureCanvasAgg(fig)
    ax_w = (WIDTH_IN - LEFT_IN - right - (ncols - 1) * WSPACE_IN) / ncols
    axes = fig.subplots(nrows, ncols, squeeze=False, gridspec_kw=dict(
        left=LEFT_IN / WIDTH_IN, right=1 - right / WIDTH_IN, top=1 - top / height, bottom=bottom / height,
        hspace=gap / ax_h, wspace=WSPACE_IN / ax_w))
    return fig, axes


def figure_png(fig, dpi: int) -> bytes:
    """The PNG bytes of a matplotlib figure at ``dpi``, white background, marked as symoro-gen's output."""
    buf = io.BytesIO()
    # no matplotlib Software/version text chunk: the same data give the same bytes across matplotlib
    # versions' metadata; symoro-gen's own mark instead (a figure file is then known as its output)
    fig.savefig(buf, format="png", dpi=dpi, facecolor="white", metadata={"Software": None})
    return mark_png(buf.getvalue())


#: the public name of the figure helper other plotting modules share (fleet report)
figure_and_axes = _figure_and_axes


def _stride(m: int, max_points: int) -> int:
    return max(1, int(math.ceil(m / max(int(max_points), 1))))


def _grid(n: int) -> tuple[int, int]:
    ncols = 1 if n <= 3 else 2
    return int(math.ceil(n / ncols)), ncols


def torque_figure(name: str, title: str, measured: np.ndarray, reconstructed: np.ndarray, joint: np.ndarray,
                  n_joints: int, *, rel_err: Sequence[float] | None = None, ylabel: str = "torque [N·m]",
                  caption: str | None = None, max_points: int = MAX_POINTS, dpi: int = DPI,
                  panels: Sequence[str] | None = None) -> Figure:
    """Measured and reconstructed torque, one subplot per joint, against the sample number.

    Parameters
    ----------
    measured, reconstructed : ndarray, shape (r,)
        ``Y`` (scaled by identified gains) and ``W chi``, rows grouped per joint.
    joint : ndarray of int, shape (r,)
        0-based joint of each row.
    n_joints : int
    rel_err : sequence of float, optional
        ``||rho_j||/||Y_j||`` shown in each subplot's title.
    caption : str, optional
        Default: the title and what the curves are.
    max_points : int
        Most samples drawn per curve.
    panels : sequence of str, optional
        Each subplot's name (default ``joint j``; a floating-base robot's row names).

    Returns
    -------
    Figure
        ``WIDTH_IN * dpi`` pixels wide.
    """
    measured = np.asarray(measured, float).reshape(-1)
    reconstructed = np.asarray(reconstructed, float).reshape(-1)
    joint = np.asarray(joint, int).reshape(-1)
    nrows, ncols = _grid(n_joints)
    fig, axes = _figure_and_axes(nrows, ncols, ax_h=1.25, gap=0.6, top=0.6, bottom=0.85, dpi=dpi)
    strides = []
    for j in range(nrows * ncols):
        ax = axes[j // ncols][j % ncols]
        if j >= n_joints:
            ax.set_visible(False)
            continue
        rows = np.flatnonzero(joint == j)
        k = _stride(rows.size, max_points)
        strides.append(k)
        idx = np.arange(rows.size)[::k]
        ax.plot(idx, measured[rows][::k], color=MEASURED, lw=1.0, label="measured")
        ax.plot(idx, reconstructed[rows][::k], color=RECONSTRUCTED, lw=1.0, ls="--", label="reconstructed (IDM)")
        t = panels[j] if panels is not None else f"joint {j + 1}"
        if rel_err is not None and j < len(rel_err) and np.isfinite(rel_err[j]):
            t += f"   ‖ρ‖/‖Y‖ = {rel_err[j]:.4f}"
        ax.set_title(t, fontsize=10, loc="left")
        ax.grid(True, color="#e0e0e0", lw=0.6)
        ax.tick_params(labelsize=8)
        if j % ncols == 0:
            ax.set_ylabel(ylabel, fontsize=8)
        if j >= n_joints - ncols:
            ax.set_xlabel("sample (decimated)", fontsize=8, labelpad=1)
    fig.suptitle(title, fontsize=11, y=1 - 0.12 / fig.get_figheight(), va="top")
    _figure_legend(fig, axes[0][0])
    png = figure_png(fig, dpi)
    every = max(strides) if strides else 1
    cap = (f"{title}. Blue: measured; red dashed: reconstructed by the inverse dynamic model with the identified "
           f"parameters; x axis: decimated samples of each joint, experiments one after the other"
           + (f" (one sample in {every} drawn)" if every > 1 else "") + ".")
    return Figure(name, png, cap if caption is None else caption, figure=fig)


def _figure_legend(fig, ax, markerscale: float = 1.0) -> None:
    """One legend for the figure, at the bottom, outside the axes."""
    handles, labels = ax.get_legend_handles_labels()
    fig.legend(handles, labels, loc="lower center", bbox_to_anchor=(0.5, 0.04 / fig.get_figheight()),
               ncol=len(labels), fontsize=8, frameon=False, markerscale=markerscale)


def singular_values_figure(name: str, s: np.ndarray, *, title: str, caption: str | None = None,
                           dpi: int = DPI) -> Figure:
    """Singular values of W with unit-norm columns, largest first, on a log scale.

    Parameters
    ----------
    s : ndarray, shape (c,)
        Singular values (any order; zeros allowed).
    """
    s = np.sort(np.asarray(s, float).reshape(-1))[::-1]
    fig, axes = _figure_and_axes(1, 1, ax_h=2.4, gap=0.0, top=0.35, bottom=0.55, dpi=dpi)
    ax = axes[0][0]
    pos = s > 0
    floor = s[pos].min() * 0.1 if pos.any() else 1e-16
    ax.semilogy(np.arange(1, s.size + 1), np.where(pos, s, floor), "o-", color=AFTER, ms=3.5, lw=1.0)
    ax.set_xlabel("index of the singular value", fontsize=9)
    ax.set_ylabel("singular value", fontsize=9)
    ax.grid(True, which="both", color="#e0e0e0", lw=0.6)
    ax.tick_params(labelsize=8)
    ax.set_title(title, fontsize=10, loc="left")
    return Figure(name, figure_png(fig, dpi), title if caption is None else caption, figure=fig)


def _binned(x: np.ndarray, r: np.ndarray, n_bins: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean of r in bins of x holding equal numbers of samples."""
    if x.size < 2 * n_bins:
        n_bins = max(1, x.size // 2)
    order = np.argsort(x, kind="stable")
    parts = np.array_split(order, n_bins)
    xm = np.array([x[p].mean() for p in parts if p.size])
    rm = np.array([r[p].mean() for p in parts if p.size])
    return xm, rm


def residual_figure(name: str, title: str, panels: Sequence[tuple[str, np.ndarray, np.ndarray, np.ndarray]],
                    xlabel: str, *, ylabel: str = "residual [N·m]", caption: str | None = None,
                    max_points: int = MAX_POINTS, n_bins: int = N_BINS, dpi: int = DPI) -> Figure:
    """Residual before and after an added effect against the signal that revealed it.

    Parameters
    ----------
    panels : sequence of (label, x, before, after)
        One subplot each (e.g. identification and validation data); ``x``, ``before`` and ``after``
        have the same shape (m,).
    """
    fig, axes = _figure_and_axes(1, max(len(panels), 1), ax_h=2.3, gap=0.0, top=0.65, bottom=0.95, dpi=dpi)
    axes = axes[0]
    for ax, (label, x, before, after) in zip(axes, panels):
        x = np.asarray(x, float).reshape(-1)
        before = np.asarray(before, float).reshape(-1)
        after = np.asarray(after, float).reshape(-1)
        k = _stride(x.size, max_points)
        ax.scatter(x[::k], before[::k], s=7, color=BEFORE, alpha=0.6, lw=0, label="before")
        ax.scatter(x[::k], after[::k], s=7, color=AFTER, alpha=0.6, lw=0, label="after")
        for r, c, lab in ((before, BEFORE_MEAN, "before, binned mean"), (after, AFTER_MEAN, "after, binned mean")):
            xm, rm = _binned(x, r, n_bins)
            ax.plot(xm, rm, color=c, lw=1.8, label=lab)
        ax.axhline(0.0, color="#000000", lw=0.6)
        ax.set_title(label, fontsize=10, loc="left")
        ax.set_xlabel(xlabel, fontsize=9)
        ax.grid(True, color="#e0e0e0", lw=0.6)
        ax.tick_params(labelsize=8)
    axes[0].set_ylabel(ylabel, fontsize=9)
    fig.suptitle(title, fontsize=11, y=1 - 0.12 / fig.get_figheight(), va="top")
    _figure_legend(fig, axes[0], markerscale=2.5)
    cap = (f"{title}. Grey: residual of the model before the effect was added; blue: after; lines: means in "
           f"{n_bins} bins of equal counts")
    return Figure(name, figure_png(fig, dpi), cap if caption is None else caption, figure=fig)


def error_bars_figure(name: str, title: str, series: Sequence[tuple[str, Sequence[float]]], *,
                      dpi: int = DPI) -> Figure:
    """Grouped bars of relative error norms per joint (e.g. validation before / after).

    Parameters
    ----------
    series : sequence of (label, values (n_joints,))
    """
    fig, axes = _figure_and_axes(1, 1, ax_h=2.2, gap=0.0, top=0.35, bottom=0.45, dpi=dpi, right=2.1)
    ax = axes[0][0]
    n = max(len(np.asarray(v).reshape(-1)) for _, v in series)
    width = 0.8 / max(len(series), 1)
    colors = ("#bdbdbd", "#64b5f6", "#616161", "#0d47a1")  # light: identification, dark: validation
    for k, (label, values) in enumerate(series):
        v = np.asarray(values, float).reshape(-1)
        ax.bar(np.arange(v.size) + (k - (len(series) - 1) / 2) * width, np.nan_to_num(v), width,
               label=label, color=colors[k % len(colors)])
    ax.set_xticks(np.arange(n), [f"joint {j + 1}" for j in range(n)], fontsize=8)
    ax.set_ylabel("‖ρ_j‖/‖Y_j‖", fontsize=9)
    ax.tick_params(labelsize=8)
    ax.grid(True, axis="y", color="#e0e0e0", lw=0.6)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.0, 1.0), frameon=False)
    ax.set_title(title, fontsize=10, loc="left")
    return Figure(name, figure_png(fig, dpi), title, figure=fig)
