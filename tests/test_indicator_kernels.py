"""The compiled element loops of the error estimators (flexure._indicator_kernels) against the numpy
forms they replace (flexure.dwr.energy_indicators, flexure.bank_weiser.face_rhs without numba), and the
enriched assembly's block places (flexure._enriched_kernels.block_pattern_slots) against the pattern: on a
distorted curved mesh, the same numbers to round-off, independent of the thread count."""

import numpy as np
import pytest

from flexure import enriched_assembly

pytestmark = pytest.mark.skipif(not enriched_assembly.available(), reason="numba not installed")


def _numpy(monkeypatch):
    from estimator import compiled

    monkeypatch.setattr(compiled, "ENABLED", False)


def _case():
    from test_enriched_speed import AL, _curved_box

    mesh, u = _curved_box()
    rng = np.random.default_rng(3)
    V = np.stack([u, 2.0 * u[::-1], rng.normal(size=u.shape) * 1e-3], axis=2)
    ce, cf = rng.normal(size=(mesh.n_elements, 6, 3)), rng.normal(size=(mesh.n_elements, 4, 3))
    return mesh, AL, u, V, ce, cf


def test_compiled_energy_indicators_equal_the_numpy_form(monkeypatch):
    from flexure import dwr, threads

    mesh, mat, _, V, ce, cf = _case()
    got = {}
    for n in (1, 2):
        with threads.limited(n):
            got[n] = dwr.energy_indicators(mesh, mat, V, ce, cf)
    assert np.array_equal(got[1], got[2])
    _numpy(monkeypatch)
    ref = dwr.energy_indicators(mesh, mat, V, ce, cf, chunk=50)          # several chunks
    scale = np.abs(ref).max(axis=0)
    assert np.all(scale > 0)
    assert np.all(np.abs(got[1] - ref).max(axis=0) <= 1e-12 * scale)


def test_compiled_face_term_equals_the_numpy_form(monkeypatch):
    from flexure import bank_weiser, threads

    mesh, mat, u, _, _, _ = _case()
    got = {}
    for n in (1, 2):
        with threads.limited(n):
            got[n] = bank_weiser.face_rhs(mesh, mat, u)
    assert np.array_equal(got[1], got[2])
    _numpy(monkeypatch)
    ref = bank_weiser.face_rhs(mesh, mat, u, chunk=50)
    assert np.abs(ref).max() > 0
    assert np.abs(got[1] - ref).max() <= 1e-12 * np.abs(ref).max()


def test_face_pairs_are_the_shared_faces():
    from flexure.bank_weiser import _face_pairs
    from flexure.mesh import TET_FACES

    mesh, *_ = _case()
    glob = mesh.corner_tets.astype(np.int64)[:, TET_FACES]
    p = _face_pairs(glob, mesh.n_nodes)
    inner = np.flatnonzero(p >= 0)
    assert len(inner) and (p < 0).any()
    assert np.array_equal(p[p[inner]], inner)                            # an involution
    key = np.sort(glob.reshape(-1, 3), axis=1)
    assert np.array_equal(key[inner], key[p[inner]]) and np.all(inner // 4 != p[inner] // 4)
    assert len(np.unique(key, axis=0)) == len(key) - len(inner) // 2   # every shared face paired


def test_element_slots_are_the_blocks_places():
    from flexure import _enriched_kernels as ek
    from flexure import enriched

    mesh, mat, u, *_ = _case()
    cons = np.zeros(mesh.n_nodes, bool)
    cons[mesh.points[:, 2] < 0.1] = True
    nk, Gk, tets = enriched_assembly._free_functions(mesh, enriched.surplus_numbering(mesh, cons))
    for R, n_rows in ((Gk, nk), (tets, mesh.n_nodes)):
        bptr, bcol = ek.block_pattern(R, Gk, n_rows, nk, 1)
        for n in (1, 3):
            b2, c2, S = ek.block_pattern_slots(R, Gk, n_rows, nk, n)
            assert np.array_equal(b2, bptr) and np.array_equal(c2, bcol)
            miss = (R[:, :, None] < 0) | (Gk[:, None, :] < 0)
            assert miss.any() and np.all(S[miss] == -1)
            e, a, b = np.nonzero(~miss)
            p = S[e, a, b]
            assert np.all((bptr[R[e, a]] <= p) & (p < bptr[R[e, a] + 1])) and np.array_equal(bcol[p], Gk[e, b])
