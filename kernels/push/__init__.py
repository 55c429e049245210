"""Warp kernels of the push task (paper III): one module per concern, one launch for all worlds. ``views`` holds
the structs that hand the kernels the simulator's arrays and the task's per-world buffers, with the policy's sizes;
``sampling`` draws episodes and domain randomisation, ``actions`` maps the policy output to commands,
``base_tracking`` drives the tracked base, ``contacts`` classifies contacts, ``goal`` is the success rule,
``keypoints``, ``observations``, ``rewards``, ``constraints`` and ``terminations`` compute what their names say.
Helpers both tasks use live one level up (``dynpush.kernels.frames``, ``dynpush.kernels.common``).
"""
