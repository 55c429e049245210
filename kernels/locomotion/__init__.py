"""Warp kernels of the locomotion task: a legged robot tracks the 6D base command of the push policy,
split by concern as the push task's (``dynpush.kernels.push``). ``views`` holds the structs (simulator state,
per-world buffers, parameters, limits) and sizes; ``sampling`` starts episodes, draws commands and disturbances,
``actions`` turns the policy's leg offsets into joint targets and applies the arm targets and the end-effector
force, ``contacts`` tracks the feet, ``observations``, ``rewards``, ``constraints`` and ``terminations`` compute
what their names say. Helpers both tasks use live one level up (``dynpush.kernels.frames``,
``dynpush.kernels.common``).
"""
