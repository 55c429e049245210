"""dynpush.sim: the Newton push scene and environment."""

import warp as wp

wp.config.log_level = wp.LOG_WARNING  # no per-module "load on device" lines on the console
