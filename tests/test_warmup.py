"""The install-time compile (estimator.warmup, called by run.sh) runs every estimator loop without
error: a loop whose arguments changed and a warm-up that was not updated raised there silently,
and the loops then compiled inside the first runs and the test suite (36 CPU-s of a fresh clone's
default suite, measured 2026-11-26)."""

from estimator import compiled, warmup


def test_warm_runs_every_compiled_loop():
    assert compiled.available()                  # numba is a dependency (pyproject.toml)
    assert warmup.warm() is True


def test_the_mesh_size_kernel_compiles_on_the_callback_types():
    """gmsh_size.warm (run.sh) compiles the loop gmsh's size callback runs; the compiled size is the
    numpy form's (the callback's own test: tests/test_stl_remesh.py)."""
    import numpy as np

    from flexure import gmsh_size

    gmsh_size.warm()
    k = gmsh_size.kernel()
    assert k is not None and len(k.signatures) >= 1
    assert k(0.0, 0.0, 0.0, 1.0, np.array([2.0, 0.5, 1.0, 0.3]), np.zeros((1, 3)), np.zeros((0, 8)),
             *gmsh_size.pack_spots(np.zeros((0, 4)))) == 0.5
