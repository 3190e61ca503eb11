"""A sweep warns when the change between neighbouring designs is within the discretization error."""

from flexure.analysis import SWEEP_FIGURES, sweep_warnings


def _row(width, thick, value, err):
    row = {"spoke_width_mm": width, "thickness_mm": thick, "error": None}
    for k in SWEEP_FIGURES:
        row[k], row[f"{k}_error_estimate"] = value(width, thick), err
    return row


def test_change_within_the_error_is_warned_and_a_resolved_change_is_not():
    params = [("spoke_width_mm", [3.0, 3.5, 4.5]), ("thickness_mm", [2.0, 3.0])]
    # figure = width (steps of 0.5 and 1.0) + 0.01·thickness: resolved along width with error 0.1,
    # unresolved along thickness (change 0.01 < 0.1 + 0.1)
    rows = [_row(w, t, lambda w, t: w + 0.01 * t, 0.1) for w, t in
            [(3.0, 2.0), (3.0, 3.0), (3.5, 2.0), (3.5, 3.0), (4.5, 2.0), (4.5, 3.0)]]
    warnings = sweep_warnings(rows, params)
    assert warnings and all("thickness_mm=2 to 3" in w for w in warnings)
    assert len(warnings) == 3 * len(SWEEP_FIGURES)          # one per width value and figure


def test_no_error_estimate_no_warning_and_failed_rows_are_skipped():
    params = [("spoke_width_mm", [3.0, 3.5])]
    rows = [{"spoke_width_mm": 3.0, "error": None, **{k: 1.0 for k in SWEEP_FIGURES}},
            {"spoke_width_mm": 3.5, "error": None, **{k: 1.0 for k in SWEEP_FIGURES}}]
    assert sweep_warnings(rows, params) == []
    rows = [_row(3.0, 0.0, lambda w, t: 1.0, 0.5), {"spoke_width_mm": 3.5, "error": "infeasible"}]
    assert sweep_warnings(rows, [("spoke_width_mm", [3.0, 3.5])]) == []
