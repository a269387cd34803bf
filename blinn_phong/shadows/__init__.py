"""Which light reaches which point: one module per shadow method behind one registry.

:mod:`.methods` is the registry (``METHODS``, ``light_visibility``, ``frame_visibility``) of the
methods, each a :class:`.method.ShadowMethod`: :mod:`.planar`, :mod:`.maps` (shadow maps;
compiled in :mod:`.map_render_kernels`, :mod:`.map_lookup_kernels`, :mod:`.map_receiver_kernels`,
and looked up inside the fused frame by :mod:`.frame_maps`), :mod:`.ray_traced` (with
:mod:`.raytrace`, Embree's rays, :mod:`.ray_setup_kernels` and :mod:`.ray_culling`),
:mod:`.soft` and :mod:`.volume` (stencil shadow volumes, built by :mod:`.volume_mesh`, counted by
:mod:`.volume_counting` with :mod:`.volume_setup` and :mod:`.volume_kernels`).
:mod:`.transmittance` gives the coloured shadows of transparent casters. Imports
:mod:`blinn_phong.model` and :mod:`blinn_phong.geometry`."""
