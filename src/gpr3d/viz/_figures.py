"""Matplotlib without a screen, and atomic PNG writes."""

from __future__ import annotations

from gpr3d.core.atomic import atomic_path

__all__ = ["pyplot", "save_figure"]


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, *, dpi: int = 120, close: bool = True, tight: bool = True) -> None:
    """Lay out ``fig`` and write it to ``path`` as PNG in one atomic step. ``tight=False``: the figure keeps the
    layout its maker gave it (``tight_layout`` draws the whole figure once more to measure its labels: a quarter
    to a third of a figure's time)."""
    try:
        if tight and fig.get_layout_engine() is None:
            fig.tight_layout()
        with atomic_path(path, suffix=".png.part") as tmp:
            fig.savefig(tmp, dpi=dpi, format="png")
    finally:
        if close:
            pyplot().close(fig)


def plot_to_png(path, plot, *args, figsize, dpi: int = 120, **kwargs) -> None:
    """``plot(*args, ax, **kwargs)`` on a new figure, written to ``path`` atomically.

    The figure is closed whether or not the plot succeeds."""
    fig, ax = pyplot().subplots(figsize=figsize)
    try:
        plot(*args, ax, **kwargs)
    except BaseException:
        pyplot().close(fig)
        raise
    save_figure(fig, path, dpi=dpi)
