"""Spatial (3-D) robots described by URDF: the rigid-body model (pinocchio as the reference, a
compiled recursion for the observer's terms), the 3-D sensor log, the observer and detector on
any tree, contacts located on link surfaces, a simulator, and pictures.

The planar chain (estimator.robot, estimator.observer, …) stays the fast special case; nothing
here is imported by the planar commands. pinocchio, trimesh and pyvista are imported inside the
functions that use them.
"""
