"""Magnetometer calibration: the fit (:mod:`.magfit`), the samples of a log (:mod:`.samples`)
and the autopilot's own calibration in a log (:mod:`.autopilot`). The CLI command is
``cf-estimator calibrate-mag`` (:mod:`cf_estimator.cli.calibrate_mag_cmd`); the node, the
replay and ``estimate`` apply the result before the filter (:mod:`cf_estimator.core.magcal`).
"""
