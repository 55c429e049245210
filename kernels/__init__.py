"""dynpush.kernels: the Warp kernels of each task in a folder of its own (``push``, ``locomotion``), split by
concern; ``frames`` and ``common`` hold the ``wp.func`` helpers both tasks share."""
