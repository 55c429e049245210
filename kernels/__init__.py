"""dynpush.kernels"""
