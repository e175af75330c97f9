"""Depth rendering of the robot for many particles at once: meshes, kinematics, rasteriser, level
of detail, and Drake's RenderEngineVtk as the reference.
"""
