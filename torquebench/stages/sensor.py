"""The sensor: the bridge/ADC chain at the flexure's (or the scene's) strain per N·m.

    sensor_chain   strain per N·m, [sensor]    → chain (bridge/ADC model; sensitivity, σ_τ)
"""

from __future__ import annotations

from torquebench.stages.cachekey import file_hash
from torquebench.stages.declaration import Stage


def run_sensor_chain(scene, inp, seed=None):
    """The ONE sensor model: SensorChain(config of [sensor].file or the paper's, strain per N·m)."""
    from bridge.chain import PAPER_STRAIN_PER_NM, SensorChain
    from bridge.config import SensorConfig, load_sensor_config

    c = scene.chain
    config, spn = (load_sensor_config(c.sensor_file) if c.sensor_file else (SensorConfig(), None))
    if inp.get("flexure"):
        spn = inp["flexure"]["gauge_strain_per_Nm"]
    elif c.strain_per_Nm is not None:
        spn = c.strain_per_Nm
    return SensorChain(config, spn or PAPER_STRAIN_PER_NM)



def adc_bits(scene) -> int:
    """The converter's width: the scene's [sensor] file's [adc] bits, else the default sensor's
    (bridge.config.SensorConfig: the one place the width is written)."""
    from bridge.config import SensorConfig, load_sensor_config

    c = scene.chain
    return (load_sensor_config(c.sensor_file)[0] if c.sensor_file else SensorConfig()).bits



STAGES = (
    Stage("sensor_chain", "chain", "bridge/amplifier/ADC model at the strain per N·m",
          run_sensor_chain, needs=("flexure?",), reads=("flexure.strain_per_Nm", "sensor.file"),
          params=lambda scene, seed: {"spn": scene.chain.strain_per_Nm,
                                      "sensor": file_hash(scene.chain.sensor_file)},
          aliases=("sensitivity", "noise_budget")),
)
