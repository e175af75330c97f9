"""The Kalman side of the method: the per-joint (angle, bias) bank, the delay buffer, image pseudo-
observations and the output estimate.
"""
