"""dynpush.runtime"""
