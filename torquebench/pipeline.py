"""The stage graph's public names in one import (``from torquebench import pipeline as P``).

Everything lives in torquebench.stages: each stage is ONE declaration in the module of its group
(torquebench.stages.declaration.Stage); the planner, the cache key and ``--explain`` read only
those declarations (torquebench.stages.planner, .cachekey, .codedeps: a stage's code is derived
from the import graph). This module only re-exports.
"""

from __future__ import annotations

from torquebench.stages import registry
from torquebench.stages.calibration import (load_calibration, run_calibrated_torques,  # noqa: F401
                                            run_calibration_fit, run_calibration_session)
from torquebench.stages.cachekey import canon, design_hash, file_hash, stage_key  # noqa: F401
from torquebench.stages.error_map import bound_maps, calibration_noise, run_error_map  # noqa: F401
from torquebench.stages.estimates import (run_estimates, run_localization_error,  # noqa: F401
                                          run_predicted_error)
from torquebench.stages.noise import scene_noise_model  # noqa: F401
from torquebench.stages.paper import run_paper_scores  # noqa: F401
from torquebench.stages.planner import (DEFAULT_OUTPUTS, Step, default_outputs, execute,  # noqa: F401
                                        feasible, given, plan, scene_seed)
from torquebench.stages.report import (REPORT_INPUTS, report_areas, report_dir, run_report,  # noqa: F401
                                       scene_summary, summary_name)
from torquebench.stages.scoring import (METHODS, collision_phase_errors,  # noqa: F401
                                        collision_phase_mask, contact_free_mask)
from torquebench.stages.flexure import run_flexure_fem  # noqa: F401
from torquebench.stages.sensor import adc_bits, run_sensor_chain  # noqa: F401
from torquebench.stages.simulation import (run_raw_counts, run_sensor_log, run_simulation,  # noqa: F401
                                           run_static_holds)


def __getattr__(name):
    """STAGES (in execution order) and BY_GIVES, read from the registry when asked (a stage
    registered at run time is in them)."""
    if name == "STAGES":
        return registry.stages()
    if name == "BY_GIVES":
        return registry.by_gives()
    raise AttributeError(name)
