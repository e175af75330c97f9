"""Robot models shipped with drake_tracker (Drake primitives and generated OBJ meshes)."""
