"""dynpush.sim"""
