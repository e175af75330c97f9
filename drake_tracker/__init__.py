"""drake_tracker: probabilistic articulated tracking of a robot arm on Drake.

Implements Garcia Cifuentes et al., "Probabilistic Articulated Real-Time Tracking
for Robot Manipulation" (RA-L 2017): a per-joint Kalman bank on (angle, bias), a
Coordinate Particle Filter depth-image update, six virtual camera joints, and a
delay buffer for late images.
"""

__version__ = "0.1.0"
