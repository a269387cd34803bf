"""Which light reaches which point: shadow maps, planar, ray-traced, soft and volume shadows.

:mod:`.visibility` (numpy, and the dispatch per method), :mod:`.kernels` (compiled map look-ups
and shadow-ray set-up), :mod:`.volume` (stencil shadow volumes, built by :mod:`.volume_mesh`,
counted by :mod:`.volume_counting` with :mod:`.volume_setup` and :mod:`.volume_kernels`),
:mod:`.raytrace` (Embree rays), :mod:`.ray_culling` (which rays need tracing) and
:mod:`.frame_maps` (a frame's maps, compiled). Imports :mod:`blinn_phong.model` and
:mod:`blinn_phong.geometry`."""
