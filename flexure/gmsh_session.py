"""gmsh plumbing shared by every gmsh user (flexure.cad, flexure.gmsh_mesh, flexure.project): the
precision of gmsh's size integral along curves, and OpenCASCADE's chatter kept off stdout."""

from __future__ import annotations

import os
from contextlib import contextmanager

#: relative accuracy of gmsh's integral ∫ ds / h along each curve, which places the curve's nodes
#: (gmsh's default 1e-9). Its adaptive quadrature calls the size callback (Python) at every
#: sample: at 1e-9 that was 70–90 % of the meshing time, 333k of 339k calls on the thick disc at
#: h × 1 (11.5 s), 691k on a 47k-triangle STL (39 s of 39 s). At 1e-4: 18k calls and 4.6 s, 58k calls
#: and 15 s; node placement along a curve changes by < 1e-4 of an element.
LC_INTEGRATION_PRECISION = 1e-4


def open_session(gmsh) -> None:
    """``gmsh.initialize`` on a clean slate: a session left open (flexure.project.CadProjector keeps
    its CAD model open between projections) is finalized first, so that no other model is current."""
    if gmsh.isInitialized():
        gmsh.finalize()
    gmsh.initialize(interruptible=False)


@contextmanager
def _quiet_stdout():
    """OpenCASCADE prints its transfer statistics on file descriptor 1: keep them off stdout
    (the ``--json`` contract) by pointing fd 1 at /dev/null for the duration."""
    import sys

    sys.stdout.flush()
    saved = os.dup(1)
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    try:
        yield
    finally:
        os.dup2(saved, 1)
        os.close(saved)
        os.close(devnull)
