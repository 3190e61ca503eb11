"""`flexure --sweep --png`: the trade-off plot's tick labels never overlap (their rendered
bounding boxes, from matplotlib's renderer), over a narrow range (within a decade, where
matplotlib labels the log axis' minor ticks) and over several decades."""

import numpy as np
import pytest

from flexure.analysis import sweep_figure


def rows(stiffness, sensitivity):
    return [{"spoke_width_mm": float(w), "error": None, "torsional_stiffness_Nm_per_rad": float(k),
             "sensitivity_mV_per_V_per_Nm": float(s), "safety_factor": 2.0}
            for w, k, s in zip(np.linspace(3, 5, len(stiffness)), stiffness, sensitivity)]


def visible_label_boxes(fig, axis):
    renderer = fig.canvas.get_renderer()
    lo, hi = sorted(axis.get_view_interval())
    boxes = []
    for tick in axis.get_major_ticks() + axis.get_minor_ticks():
        label = tick.label1
        if label.get_visible() and label.get_text() and lo <= tick.get_loc() <= hi:
            boxes.append(label.get_window_extent(renderer))
    return boxes


def overlapping(boxes):
    return [(a, b) for i, a in enumerate(boxes) for b in boxes[i + 1:] if a.overlaps(b)]


@pytest.mark.parametrize("k_range, s_range", [
    ((1500.0, 2600.0), (0.09, 0.16)),        # a spoke-width sweep: within a decade on both axes
    ((1712.0, 1716.0), (0.1149, 0.1151)),    # designs that barely differ
    ((30.0, 9.0e4), (0.002, 3.0)),           # several decades
])
def test_tick_labels_do_not_overlap(k_range, s_range):
    import matplotlib.pyplot as plt

    fig = sweep_figure(rows(np.geomspace(*k_range, 7), np.geomspace(*s_range, 7)[::-1]), ["spoke_width_mm"])
    try:
        fig.canvas.draw()
        ax = fig.axes[0]
        for axis in (ax.xaxis, ax.yaxis):
            boxes = visible_label_boxes(fig, axis)
            assert len(boxes) >= 2, "an axis needs at least two labelled ticks to be read"
            assert overlapping(boxes) == []
    finally:
        plt.close(fig)
