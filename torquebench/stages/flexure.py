"""The flexure: its FEM figures (``torquebench flexure``'s answer).

    flexure_fem    [flexure].design  → flexure (FEM: strain per N·m, stiffness, safety)
"""

from __future__ import annotations

from torquebench.stages.cachekey import design_hash
from torquebench.stages.declaration import Stage
from userio.errors import InputError


def run_flexure_fem(scene, inp, seed=None):
    """The design's figures as ``torquebench flexure`` gives them: the answer on the finest of three
    mesh levels, each figure with its discretisation error estimate (flexure.convergence)."""
    from flexure.convergence import design_figures   # the ONE call into the flexure package

    fx = design_figures(scene.chain.flexure_design)
    if fx.get("nan_reason"):
        raise InputError(f"{scene.path}: flexure.design: no trustworthy gauge strain ({fx['nan_reason']})")
    return fx


def _no_design(scene):
    c = scene.chain
    return None if c.flexure_design is not None else \
        "no [flexure].design" + (" (strain_per_Nm given)" if c.strain_per_Nm else "")


STAGES = (
    Stage("flexure_fem", "flexure", "tetrahedral FEM of the flexure design (three mesh levels, error estimates)",
          run_flexure_fem, reads=("flexure.design",),
          params=lambda scene, seed: {"design": design_hash(scene.chain.flexure_design)},
          feasible=lambda scene: None if scene.chain.flexure_design is not None else "no [flexure].design",
          given=_no_design, scene_output=True),
)
