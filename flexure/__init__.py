"""Flexure geometry, tetrahedral meshing, linear-elastic FEM and gauge read-out."""
