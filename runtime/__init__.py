"""dynpush.runtime: the lean deployment runtime (numpy, onnxruntime and small I/O packages only).

Motion capture and robot state in, push policy (and optionally a locomotion ONNX) at 50 Hz, joint
targets and the 6D base command out, every tick logged. Modules, one job each:

- ``observation``: the 54-d actor observation (equal to the simulator's kernel); ``actions``: the push
  policy's actions as commands (equal to the simulator's kernel); ``contract``: the ONNX metadata contract
  between training and deployment; ``locomotion_contract``: a locomotion ONNX's contract
- ``config``: the YAML configuration; ``frames``: poses and frame conventions; ``packets``: the UDP
  datagrams; ``udp``: the socket; ``trust``: which senders and datagrams a receiver admits
- ``mocap``: pose sources; ``robot_link``: state in, commands out; ``goals``: object goals
- ``policy``: ONNX sessions and start-up checks; ``locomotion``: a locomotion ONNX
- ``safety``: the state machine and limits; ``controller``: one tick; ``timing``: clocks and the
  ticker; ``tick_log``: the crash-safe log; ``app``: the loop
- ``replay``, ``sim2sim``, ``commands``: ``dynpush replay``, ``dynpush sim2sim``, ``dynpush run``
- ``locomotion_layout``: the locomotion observation's terms and the leg joints; ``errors``: the runtime's errors

Importing or running it never imports torch, warp or newton (``tests/test_runtime_loop.py``).
"""
