"""Triangles to samples: vertex normals (:mod:`.normals`), the numpy rasterizer and depth test
(:mod:`.raster`), and the mesh facts the planner reads (:mod:`.mesh_facts`, compiled in
:mod:`._mesh_kernels`). Imports only :mod:`blinn_phong.model`."""
