"""The near-incompressible flag depends on the element order: P1 locks from ν = 0.49 and is
flagged there; P2 stays accurate against Lamé up to ν = 0.49999 and is flagged only from there."""

import numpy as np
import pytest

from flexure.material import Material
from flexure.solve import NU_LOCKING
from test_fem_validation import A_IN, lame


def _bore_error(order, k, nu):
    m, s, ur, ur_ex, _ = lame(order, k, Material(70e9, nu, 250e6, "near-incompressible"))
    bore = np.hypot(m.points[:, 0], m.points[:, 1]) < A_IN * (1 + 1e-9)
    return abs(np.mean(ur[bore]) / np.mean(ur_ex[bore]) - 1), s.info["warnings"]


@pytest.mark.parametrize("nu", [0.49, 0.499, 0.4999])
def test_p2_is_accurate_and_not_flagged_up_to_0p4999(nu):
    err, warnings = _bore_error(2, 4, nu)
    assert err < 6e-4, err                       # measured 1.9e-4 / 3.6e-4 / 4.5e-4
    assert "near_incompressible" not in warnings


def test_p2_converges_at_0p4999_and_is_flagged_at_0p49999():
    coarse, _ = _bore_error(2, 2, 0.4999)
    fine, _ = _bore_error(2, 4, 0.4999)
    assert fine < coarse / 3                     # no locking: h² or better on the bore strain
    _, warnings = _bore_error(2, 2, NU_LOCKING[2])
    assert "near_incompressible" in warnings


@pytest.mark.parametrize("nu, flagged", [(0.45, False), (0.49, True), (0.499, True)])
def test_p1_is_flagged_from_0p49_where_it_locks(nu, flagged):
    err, warnings = _bore_error(1, 4, nu)
    assert ("near_incompressible" in warnings) == flagged
    if flagged:
        assert err > 0.05                        # the flagged P1 answer really is wrong (locking)
