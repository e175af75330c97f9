"""Camera calibration: each camera's mounting error from a window of images of every
camera at once (``window_fit``)."""
