"""Compile the estimator's numba loops once, so that the first estimate, log read or CUSUM
calibration does not pay the compilation (numba writes the machine code to its cache beside each
module). ``run.sh`` calls ``warm()`` when it installs the project (and then runs one planar and one
3-D estimate of the shipped logs, which compile the bound, release and spatial loops on their
real inputs); no module imports this one.
"""

from __future__ import annotations

import numpy as np

from estimator import compiled, cusum_calibration, localization_loops, log_reader, model_kernels
from estimator import observer, outframe, plausibility
from estimator.localization import weight_blocks
from estimator.model_error import ModelTerm
from estimator.robot import paper_leg


def warm() -> bool:
    """Run every compiled loop once on a two-sample paper leg; False without numba."""
    if not compiled.available():
        return False
    robot = observer.full_robot(paper_leg())
    q = np.zeros((2, 5))
    PT, uT = observer.momentum_terms_T(robot, q, q, q)
    _warm_model(robot)
    for q_now in (q, None):         # the estimator passes the current posture; localize alone not
        localization_loops.localize(robot, q, uT.T + 1.0, weight_blocks(5, 2), q_now,
                                    min_force_N=0.05, max_condition=20.0, ambiguity_tol=1e-3,
                                    position_tol_m=0.005, bound_tol=0.05)
    for base in (3, 0):             # the log reader's loops: floating and fixed base
        width = 1 + 2 * (base + 2) + 5
        log_reader.split_rows(np.zeros((width, 3)).T, base, 2)          # column-major blocks
        log_reader.split_rows(np.zeros((width, 4)).T[1:], base, 2)      # and slices of them
        valid, t, *_, rows = log_reader.split_rows(np.zeros((3, width)), base, 2)
        log_reader.check_steps(t + np.arange(3), rows, None, 1.0, 0.01, True)
        log_reader.check_steps(t + np.arange(3), rows, (-1.0, -1), 1.0, 0.01, True)
    outframe.format_rows(outframe._empty_part())
    observer.first_order(np.ones(2), np.ones(2), np.zeros((2, 2)), np.zeros((2, 3)), 0, 2)
    sums = plausibility.Checker("warm", False, 2).sums          # the checker's own running sums
    plausibility.plausibility_rows(t, np.zeros((3, 5)), np.zeros((3, 5)), 0, 2, 6.3, None, sums)
    plausibility.plausibility_rows(t, np.zeros((3, 5)), np.zeros((3, 5)), 3, 2, 6.3,
                                   (-1.0, np.zeros((1, 2)), np.zeros((1, 2))), sums)
    cusum_calibration.warm()
    _warm_episode(robot)
    _warm_spatial()
    return True


def _warm_episode(robot) -> None:
    """The episode localizer's loop (estimator.episode.binned_terms) on two samples, with writable
    and with read-only noise blocks (a noise model read back from the stage cache is read-only:
    numba compiles each case apart)."""
    from estimator import episode

    T, n = 2, robot.n_links + 3
    x, W, S = np.zeros((T, n)), np.tile(np.eye(n), (1, 1, 1)), np.zeros((1, n, n))
    for writable in (True, False):
        S0, S1 = S.copy(), S.copy()
        S0.setflags(write=writable)
        S1.setflags(write=writable)
        episode.binned_terms(robot, x, x, x, np.ones(T, np.int64), W, S0, S1, np.zeros(T, np.int64),
                             np.ones(T, bool), np.zeros(T, np.int64), 1, None)


def _warm_spatial() -> None:
    """The 3-D tree's whitened-statistic loop (estimator.spatial.tree; the shipped 3-D estimate
    run at install compiles its other loops, not this one)."""
    from estimator.spatial import tree

    tree.whitened_statistic(np.zeros((2, 3)), [0, 1], np.eye(2)[None], np.zeros(2, np.int64))


def _warm_model(robot) -> None:
    """The inertial-parameter model's loops (estimator.model_kernels) on a two-sample chain."""
    if not model_kernels.available():
        return
    q = np.zeros((2, robot.n_links + 3))
    model_kernels.momentum_regressor(robot, q, q)
    args = (np.arange(2) * 1e-3, q, q, np.zeros((robot.n_links + 3, 2)), np.eye(robot.n_links + 3)[None],
            np.zeros(2, np.int64))
    term = ModelTerm(robot, np.eye(len(robot.parameter_names)), 100.0, 1e-3)
    term.statistic(*args)           # the planar chain's fused loop (it calls the statistic on column slices)
    term = ModelTerm(robot, np.eye(len(robot.parameter_names)), 100.0, 1e-3)
    term.fused = None
    term.statistic(*args)           # the statistic alone on contiguous blocks, as a 3-D robot's term calls it
