"""Stage 1: optimal measurement configurations and geometric calibration with a laser tracker.

Public entry points:

- :func:`pipeline.calibration.stage.calibrate` (``robot, real, Config, rng``) -> ``CalibrationOutcome``
  (identifiability report, candidates, selection, measurements, estimate, validation, calibrated
  ``RobotModel``); the runner stage is :mod:`pipeline.calibration.stage` (``NAME = "calibration"``).
  With ``measurements_csv`` the simulated robot is never used: validation only on ``validation_csv``
  (else no held-out validation: null ``heldout_*`` keys), fit residuals and covariance prediction.
- :mod:`~pipeline.calibration.error_model`: ``MeasurementModel`` (exact CasADi tracker model and
  Jacobian), ``identifiability`` (SVD + ordered QR + correlations), ``mdh_basis``.
- :mod:`~pipeline.calibration.candidates`: grid / random candidates, batched filtering,
  ``nominal_jacobian``; their batched forward kinematics: :mod:`~pipeline.calibration.batch_kinematics`.
- :mod:`~pipeline.calibration.indices`: O1..O5, Od, Oc, D/A/E, TCP-covariance A-criterion.
- :mod:`~pipeline.calibration.design`: ``remove_and_replace``, ``detmax``, ``bsaa``, ``random_design``.
- :mod:`~pipeline.calibration.gradient_design`: CasADi/IPOPT design of n configurations.
- :mod:`~pipeline.calibration.measure`: simulated tracker or CSV files; :mod:`.estimate`:
  registration, Levenberg-Marquardt, covariance, ``calibrated_robot``; :mod:`.validate`.
- The calibration studies (paper reproductions, ``python -m pipeline study calib-...``) live in
  :mod:`pipeline.papers` (``calib_000`` ... ``calib_design``).
"""
