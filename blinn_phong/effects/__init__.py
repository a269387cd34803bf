"""Transparency and what bends or dims light: order-independent transparency (:mod:`.oit`), the
transparency models (:mod:`.transparency`) and refraction (:mod:`.refraction`). Imports the rooms
below it (model, geometry, shadows)."""
