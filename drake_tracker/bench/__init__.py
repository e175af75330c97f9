"""``drake-tracker bench``: the throughput of the tracker's hot paths on this machine."""
