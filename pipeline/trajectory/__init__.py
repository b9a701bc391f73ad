"""Stage 4: time-optimal continuous paths and time/energy-optimal point-to-point motion.

Public API (paper 004 section 5, DESIGN.md "Trajectories"):

* :class:`~pipeline.trajectory.dynamics.PlanningModel` ``.from_robot(robot, torque_reserve)``
* CP: :func:`~pipeline.trajectory.design.joint_path_from_cartesian`,
  :func:`~pipeline.trajectory.cp.solve_cp_convex`, :func:`~pipeline.trajectory.cp.solve_cp_refined`,
  :func:`~pipeline.trajectory.cp_smooth.solve_cp_smooth`, :func:`~pipeline.trajectory.solve.plan_cp`
* PtP: :class:`~pipeline.trajectory.ptp.PtpProblem` (compiled once, disk cache),
  :func:`~pipeline.trajectory.solve.plan_ptp`, :func:`~pipeline.trajectory.solve.solve_ptp_verified`
* baselines: :func:`~pipeline.trajectory.baselines.toppra_cp`,
  :func:`~pipeline.trajectory.baselines.ruckig_torque_feasible`
* verification: :func:`~pipeline.trajectory.trajectories.check_trajectory`,
  :func:`~pipeline.trajectory.validate.simulate_on_real`, the plans in the servo simulation
  (:func:`~pipeline.trajectory.measure.verify_in_servo`), the gates
  (:func:`~pipeline.trajectory.validate.quality_gates`)
* outputs: :mod:`~pipeline.trajectory.report`
"""
