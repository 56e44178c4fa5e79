"""Figure layout in inches: margins and gaps fixed where ``bbox_inches="tight"`` or a layout engine
would measure them (drawing the figure once more, ~1 s for the trajectory figure's 21 axes).

The figure modules import :class:`matplotlib.figure.Figure` in the functions that make one, not
at the top: ``matplotlib.figure`` (axes, text, the backends' base) takes ~0.3 s to import, and the
command, which hands its figures to a worker process (:mod:`optlight.viz.drawing`), builds their
jobs without ever drawing one.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.figure import Figure


def set_margins(
    fig: Figure,
    left: float,
    right: float,
    top: float,
    bottom: float,
    *,
    rows: int = 1,
    columns: int = 1,
    gap_x: float = 0.0,
    gap_y: float = 0.0,
) -> None:
    """Place the subplots of a ``rows`` × ``columns`` figure with the margins and the gaps between
    axes given in inches."""
    width, height = fig.get_size_inches()
    axes_width = (width - left - right - (columns - 1) * gap_x) / columns
    axes_height = (height - top - bottom - (rows - 1) * gap_y) / rows
    fig.subplots_adjust(
        left=left / width,
        right=1 - right / width,
        top=1 - top / height,
        bottom=bottom / height,
        wspace=gap_x / axes_width,
        hspace=gap_y / axes_height,
    )
