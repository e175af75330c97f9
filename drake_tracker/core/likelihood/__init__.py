"""The occlusion-robust depth-pixel likelihood (paper eqs. 1-2) and the per-image occlusion
estimate.
"""
