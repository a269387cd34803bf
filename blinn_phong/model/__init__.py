"""What a scene is: meshes, materials, lights, camera (:mod:`.scene`), primitive meshes
(:mod:`.primitives`), textures (:mod:`.texture`), fog (:mod:`.fog`) and which lights reach and
which casters block each object (:mod:`.linking`). Data and the formulas that belong to it; no
rendering. Imports nothing of the other rooms."""
