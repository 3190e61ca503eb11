"""The gauge read-out integrates the FE strain exactly over the grid's footprint
(flexure.gauges.read_footprint): checked against a dense midpoint rule of the same FE field, and
against the analytic mean of a field the elements represent exactly."""

import numpy as np
import pytest

from flexure.gauges import Gauge, footprint_pieces, read, read_footprint
from flexure.mesh import box_mesh, to_quadratic
from flexure.post import strain_at


def _setup(order: int, seed: int = 0):
    # a 10 × 10 × 2 mm plate, 5 × 5 × 1 cells: a 3 × 2 mm grid spans parts of several elements
    mesh = box_mesh(5, 5, 1, size=(0.01, 0.01, 0.002))
    # jitter the interior of the top face so that element boundaries cross the grid obliquely
    rng = np.random.default_rng(seed)
    p = mesh.points.copy()
    inner = (p[:, 0] > 1e-9) & (p[:, 0] < 0.01 - 1e-9) & (p[:, 1] > 1e-9) & (p[:, 1] < 0.01 - 1e-9)
    p[inner, :2] += rng.uniform(-4e-4, 4e-4, (inner.sum(), 2))
    mesh = type(mesh)(p, mesh.tets)
    if order == 2:
        mesh = to_quadratic(mesh)
    U = rng.normal(size=(mesh.n_nodes, 3)) * 1e-6       # a rough field: strain jumps across faces
    g = Gauge((0.0051, 0.0047, 0.002), (0.6, 0.8, 0.0), (0.0, 0.0, 1.0), 0.003, 0.002, 1)
    return mesh, U, g


def _dense_mean(mesh, U, g, n: int = 120) -> float:
    """Midpoint rule on an n × n grid of the FE strain over the footprint (converges as 1/n)."""
    c, a, b, nrm = g.frame()
    s = (np.arange(n) + 0.5) / n - 0.5
    S, T = np.meshgrid(s * g.length_m, s * g.width_m, indexing="ij")
    pts = c + S.ravel()[:, None] * a + T.ravel()[:, None] * b - 1e-7 * nrm
    eps = strain_at(mesh, U, pts)
    return float(np.einsum("i,kij,j->k", a, eps, a).mean())


@pytest.mark.parametrize("order", [1, 2])
def test_footprint_equals_the_area_integral_of_the_fe_strain(order):
    mesh, U, g = _setup(order)
    pieces = footprint_pieces(g, mesh)
    assert pieces is not None and len(pieces[0]) >= 4          # the grid spans several elements
    exact = float(read_footprint([g], mesh, U)[0])
    dense = _dense_mean(mesh, U, g)
    gauss = float(read([g], lambda p: strain_at(mesh, U, p))[0])
    scale = np.abs(dense)
    assert abs(exact - dense) < 0.02 * abs(gauss - dense) + 1e-3 * scale   # midpoint rule's own error
    assert abs(gauss - dense) > 5 * abs(exact - dense)          # the fixed Gauss rule does not integrate it


def test_footprint_is_exact_for_a_field_the_elements_represent():
    """u quadratic → P2 strain linear: the area mean is the strain at the grid centre (read a
    hair, 1e-4 × the grid width, inside the solid)."""
    mesh, _, g = _setup(2)
    x = mesh.points
    U = 1e-4 * np.column_stack([x[:, 0] ** 2 + x[:, 1] * x[:, 2], x[:, 0] * x[:, 1], x[:, 2] ** 2 - x[:, 0] * x[:, 1]])
    c, a, _, n = g.frame()
    c = c - 1e-4 * g.width_m * n
    H = 1e-4 * np.array([[2 * c[0], c[2], c[1]], [c[1], c[0], 0.0], [-c[1], -c[0], 2 * c[2]]])
    expected = a @ (0.5 * (H + H.T)) @ a
    assert float(read_footprint([g], mesh, U)[0]) == pytest.approx(expected, rel=1e-9)


def test_grid_off_flat_faces_falls_back_to_the_gauss_rule():
    mesh, U, g = _setup(2)
    tilted = Gauge(g.centre_m, g.axis, (0.0, 0.6, 0.8), g.length_m, g.width_m, 1)   # not the face's plane
    assert footprint_pieces(tilted, mesh) is None
