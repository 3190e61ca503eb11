"""Wheatstone bridge, amplifier and ADC models; the torque → counts → torque sensor chain."""
