"""dynpush: dynamic object goal pushing with a quadrupedal mobile manipulator.

Subpackages: ``dynpush.kernels`` (Warp kernels), ``dynpush.sim`` (Newton push environment),
``dynpush.policies`` (CaT-PPO training, ONNX export), ``dynpush.runtime`` (deployment loop),
``dynpush.assets_usd`` (USD robot, objects and ground).
"""

__version__ = "0.1.0"
