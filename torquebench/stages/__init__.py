"""The stage graph: every stage is one declaration (torquebench.stages.declaration.Stage) in the
module of its group, found by torquebench.stages.registry (a module here that defines ``STAGES``).

    flexure.py      flexure_fem
    sensor.py       sensor_chain
    calibration.py  calibration_session, calibration_fit, calibrated_torques
    simulation.py   simulation, raw_counts, sensor_log, static_holds
    estimates.py    estimates, localization_error, predicted_error
    paper.py        paper_scores
    error_map.py    error_map
    report.py       report (views of the scene's own results + its summary)

and the machinery that reads only the declarations: planner.py (plan, execute), cachekey.py (the
key: canonical inputs, upstream keys, code), codedeps.py (a stage's code, derived from the import
graph), registry.py; plus the shared scoring.py, noise.py and summary.py (a run's results as JSON).
Kept import-light: nothing here is imported by importing the package (a stage's derived code
stays its own).
"""
