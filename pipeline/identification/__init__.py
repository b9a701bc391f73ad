"""Stage 2: dynamic identification with optimal Fourier excitation (paper 004 §4).

Public entry points:

- :mod:`~pipeline.identification.regressor`: ``RegressorModel`` (``pin.computeJointTorqueRegressor``
  + rotor inertia, viscous and Coulomb friction, torque offsets through the gear matrix),
  ``base_parameters`` (pivoted QR, readable combinations), ``standard_parameters``.
- :mod:`~pipeline.identification.base_set`: ``structural_base_parameters`` (the base set of the
  nominal model, kept for a calibrated/reloaded one).
- :mod:`~pipeline.identification.gates`: the stage's quality gates.
- :mod:`~pipeline.identification.design`: ``FourierTrajectory`` (Swevers, rest to rest),
  ``optimize_excitation`` (CasADi/IPOPT, exact gradient of cond or log det, limits, torques,
  floor and capsule self-collision at every sample), ``random_feasible_trajectories``,
  ``check_trajectory``.
- :mod:`~pipeline.identification.signals`: zero-phase Butterworth, differentiation, decimation,
  period averaging.
- :mod:`~pipeline.identification.measure`: ``simulate_excitation`` (hidden robot), ``load_joint_csv``
  (joint or motor side), ``process_periodic`` / ``process_record``.
- :mod:`~pipeline.identification.estimate`: ``ols``, ``wls`` (Gautier), ``physical_fit``
  (log-Cholesky, IPOPT), ``is_physically_consistent``.
- :mod:`~pipeline.identification.experiment`: the stage's regressors and base set, and its data (the
  user's record, or the optimal excitation run on the hidden robot).
- :mod:`~pipeline.identification.fit`: the stage's fits on all samples (Stribeck and load-dependent
  friction candidates), the HAC covariance, the handed-on robot.
- :mod:`~pipeline.identification.validate`: ISO 9283 validation trajectory, torque RMS, z-scores; the
  stage's validation step and the choice of the handed-on friction model.
- :mod:`~pipeline.identification.tx40`: ``run_tx40`` on the real Stäubli TX40 record (``tx40_wanted``).
- :mod:`~pipeline.identification.outcome`: what the stage's steps hand each other and
  ``identified_robot(robot, p)`` (a ``RobotModel`` with identified inertias, rotor inertia, friction).
- :mod:`~pipeline.identification.report`: summary, arrays, figures and report text.
- :mod:`~pipeline.identification.stage`: the runner stage ``identification`` (its steps in order).
"""
