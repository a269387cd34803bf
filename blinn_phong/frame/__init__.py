"""One frame, in stage order: prepared scene (:mod:`.prepared`) → visibility (:mod:`.visibility`)
→ shading with the lighting equation (:mod:`.lighting`, :mod:`.shading`) → texturing
(:mod:`.texturing`) → resolve (:mod:`.resolve`) → passes (:mod:`.id_passes`,
:mod:`.light_groups`, :mod:`.deep_fragments`), run by :mod:`.pipeline` and :func:`.render.render`.
:mod:`.fast` holds the compiled twins and the fused pass. The top room: it imports every other."""
