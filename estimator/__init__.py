"""Planar rigid-body dynamics, momentum observer, contact detection, isolation and localization."""
