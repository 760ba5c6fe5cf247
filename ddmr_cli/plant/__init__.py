"""The plants the engine drives: the contract of a plant stepped from Python (base), the default wheel plant
inlined in the compiled loop (wheel) and the rigid-body robot on a heightfield (mujoco, mujoco_model)."""
