"""The sensor streams as the tracker reads them: camera intrinsics, depth frames and units, time
stamps and the reading gate.
"""
