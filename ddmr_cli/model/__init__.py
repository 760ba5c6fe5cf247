"""The model: the robot and its wheel-space plant, kinematics, terrain, scenarios and reference trajectories
(docs/model.md sections 1-5). Plain Python and numpy, no Hydra."""
