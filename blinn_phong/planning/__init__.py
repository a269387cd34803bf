"""What a frame needs and why: the planner (:mod:`.planner`), the frame plan a render follows
(:mod:`.frame_plan`) and the measured error and cost models (:mod:`.calibration`,
``calibration.json``). Imports the rooms below it; the frame imports it."""
