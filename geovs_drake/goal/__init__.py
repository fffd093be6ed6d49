"""The loop's model at the goal, in one room: what a run derives about its goal before it
starts, for :func:`~geovs_drake.loop.resolver` to compute once.

* :mod:`~geovs_drake.goal.linear_model`: the closed-form A of each carrier and plant at
  the goal (the NF's Hessian through the chart), the moving target's lag and transfer,
  and the sampled-data model a camera makes of it;
* :mod:`~geovs_drake.goal.arm`: an arm's model (its plant, IK, joints at the goal and at
  the start) and its goal model M(q*), J_C(q*);
* :mod:`~geovs_drake.goal.camera_fit`: the gains against the camera's rate and latency;
* :mod:`~geovs_drake.goal.effort_fit`: the dynamic arm's torques against its effort limits;
* :mod:`~geovs_drake.goal.step_limit`: the integrator's step against the goal's
  stability bound.

It sits above :mod:`geovs_drake.scenario` and below :mod:`geovs_drake.loop`.
"""
