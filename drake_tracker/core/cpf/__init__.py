"""The Coordinate Particle Filter image update (paper IV-B): particles, annealed sweeps, moment
matching.
"""
