"""Simulators of the paper's experiments: floating base on spring-dampers, fixed base (stiff
spring emulation of the FT sensor, or a rigid weld), PD joint control (continuous or zero-order
hold), poke forces, a foot–ground contact, sensor models and integrators.

Entry points: :func:`simulate` (one scene, returns the sensor log and the truth),
:func:`static_readings` (vectorized static equilibria, for posture sweeps and hung masses),
:func:`check_stability` (discrete closed-loop eigenvalues of the linearized joint dynamics).
"""

from estimator.sim.config import Controller, Ground, Poke, Sensors, SimConfig
from estimator.sim.core import SimResult, simulate, simulate_batch
from estimator.sim.stability import StabilityReport, check_stability
from estimator.sim.static import static_readings

__all__ = ["Controller", "Ground", "Poke", "Sensors", "SimConfig", "SimResult", "simulate", "simulate_batch",
           "StabilityReport", "check_stability", "static_readings"]
