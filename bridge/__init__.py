"""Wheatstone bridge, amplifier and ADC models; the torque → counts → torque sensor chain.

Modules: ``wheatstone`` (exact/linear bridge outputs and inverses), ``adc`` (range, LSB, ENOB
definitions, quantization), ``config`` (SensorConfig, TOML loading and validation), ``budget``
(noise budget, paper eq. 11, minimum detectable strain/torque), ``chain`` (vectorized
SensorChain, ``paper_chain``, ADCSaturationWarning); the strain warnings are in ``wheatstone``.
"""
