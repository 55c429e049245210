"""dynpush.sim: the Newton push scene and environment."""
