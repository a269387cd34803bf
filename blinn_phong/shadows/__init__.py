"""Which light reaches which point: shadow maps, planar, ray-traced, soft and volume shadows.

:mod:`.visibility` (numpy, and the dispatch per method); compiled shadow maps:
:mod:`.map_render_kernels` (drawing the depth maps), :mod:`.map_lookup_kernels` (look-ups and
percentage-closer filtering), :mod:`.map_receiver_kernels` (maps rendered only where receivers read
them) and :mod:`.frame_maps` (a frame's maps, looked up in the fused pass); :mod:`.volume` (stencil
shadow volumes); :mod:`.raytrace` (Embree rays), :mod:`.ray_setup_kernels` (their compiled set-up)
and :mod:`.ray_culling` (which rays need tracing).
Imports :mod:`blinn_phong.model` and :mod:`blinn_phong.geometry`."""
