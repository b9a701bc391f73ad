"""Files shared with the outside world: ROS 2 bags, CSV for controllers, URDF and joint limits. One reader or writer per format."""
