"""blinn_phong: a pure numpy local-illumination renderer (no bpy)."""
