"""Files shared with the outside world: ROS 2 bags, CSV for controllers, URDF and joint limits.

One reader and one writer per format.

API (SI units everywhere; arrays (N,) and (N, n) in the order of ``joint_names``):

- :mod:`~pipeline.exchange.motion`: the samples. ``SampledMotion(joint_names, t_s, q_rad, qd_rad_s,
  qdd_rad_s2, tau_ff_Nm)``, ``JointStates(joint_names, t_s, q_rad, qd_rad_s, effort_Nm)``,
  ``TrackerPoints(t_s, xyz_m, frame_id)``.
- :mod:`~pipeline.exchange.ros2_bag`: rosbag2 (SQLite3 default, MCAP) via ``rosbags``.
  ``write_joint_trajectory(path, motion, topic, bag_format="sqlite3")`` /
  ``read_joint_trajectory(path, topic=None)``; ``write_joint_states(path, states, topic="/joint_states",
  bag_format=...)`` / ``read_joint_states(path, joint_names=None, name_map=None, topic=None)``;
  ``write_points(path, points, topic, msgtype=PointStamped|PoseStamped|TransformStamped)`` /
  ``read_points(path, topic=None)``. Readers take a bag folder, a bare ``.db3`` or a ``.mcap``.
- :mod:`~pipeline.exchange.motion_csv`: ``write_motion_csv`` / ``read_motion_csv``,
  ``write_joint_states_csv`` / ``read_joint_states_csv`` (one header line, units in column names),
  ``is_joint_state_csv``.
- :mod:`~pipeline.exchange.joint_limits`: MoveIt ``joint_limits.yaml`` and the URDF with the source's
  joint types and the joint friction.
- :mod:`~pipeline.exchange.parameter_table`: identified parameters as CSV (``parameter,value,std,unit``).
- :mod:`~pipeline.exchange.joint_names`: a recording's joints matched to the model's by name.
"""
