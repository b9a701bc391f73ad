"""The simulated world: the hidden "real" robot (:mod:`~pipeline.sim.truth`), its sensors
(encoders, torque sensors, laser tracker, optical tracker), its transmission and the plant behind
the drives (rigid or two-mass joint dynamics and the servo loop closed around them). With
``truth.engine: mujoco`` the same hidden robot is a MuJoCo model (:mod:`~pipeline.sim.mujoco_robot`);
``python -m pipeline arm play`` drives either engine from motion files (:mod:`~pipeline.sim.player`).

Stages see it only through ``StageContext.real``, which the runner builds; the layer below,
:mod:`pipeline.robot`, holds the nominal model the stages work with.
"""
