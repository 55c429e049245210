"""dynpush.policies"""
