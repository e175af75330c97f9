"""The robot model, the one source of truth: a URDF, SDF or vendor package loaded into a
MultibodyPlant, with the six virtual camera joints (``build_tracker_model``)."""
