"""The layout of a saved figure: tight, and no two tick labels of an axis on one another."""

from __future__ import annotations

#: The steps of matplotlib's default tick locator (ticks at 1, 2, 2.5 or 5 times a power of
#: ten), kept when an axis gets fewer ticks.
TICK_STEPS = (1, 2, 2.5, 5, 10)
#: Least room between two tick labels, as a fraction of their font size.
LABEL_GAP = 0.5


def _shown_labels(axis) -> list:
    """The tick labels ``axis`` draws: those of the major ticks inside its view interval."""
    lo, hi = sorted(axis.get_view_interval())
    slack = 1e-10 * (hi - lo)  # a tick at an end of the view is drawn
    locs = axis.get_majorticklocs()
    return [
        text
        for loc, tick in zip(locs, axis.get_major_ticks(len(locs)), strict=True)
        if lo - slack <= loc <= hi + slack
        for text in (tick.label1, tick.label2)
        if text.get_visible() and text.get_text()
    ]


def _crowded(axis, renderer) -> bool:
    """Whether two of the labels ``axis`` draws overlap or come closer than
    :data:`LABEL_GAP` (with more than two of them: two are the fewest an axis keeps)."""
    labels = _shown_labels(axis)
    if len(labels) <= 2:
        return False
    boxes = []
    for text in labels:
        pad = 0.5 * LABEL_GAP * text.get_fontsize() * renderer.points_to_pixels(1.0)
        boxes.append(text.get_window_extent(renderer).padded(pad))
    return any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1 :])


def tidy_layout(fig) -> None:
    """``fig.tight_layout()``, then fewer ticks on every axis of ``fig`` (a colour bar's too)
    whose tick labels overlap (long labels on a short axis, such as a heat map's beside its
    colour bar), as drawn: each such axis gets a ``MaxNLocator`` with one tick less at
    least, on :data:`TICK_STEPS`, until its labels stand apart or two are left.

    Args:
        fig: a ``matplotlib.figure.Figure`` on a canvas that can draw (Agg).
    """
    from matplotlib.ticker import MaxNLocator

    fig.tight_layout()
    nbins: dict = {}  # axis -> the intervals its locator may have, fewer at each pass
    while True:
        fig.draw_without_rendering()  # places the ticks and their labels
        renderer = fig.canvas.get_renderer()
        crowded = [axis for ax in fig.axes for axis in (ax.xaxis, ax.yaxis)
                   if nbins.get(axis, 2) > 1 and _crowded(axis, renderer)]  # fmt: skip
        if not crowded:
            return
        for axis in crowded:  # n labels: at most n - 1 ticks (nbins + 1) in the view
            shown = len(_shown_labels(axis))
            nbins[axis] = min(shown - 2, nbins.get(axis, shown) - 1)
            axis.set_major_locator(MaxNLocator(nbins=nbins[axis], steps=TICK_STEPS))
        fig.tight_layout()
