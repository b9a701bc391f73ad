"""Core: errors, YAML 1.2, atomic file I/O, typed configuration, compiled code. No robot, no stage."""
