"""bpy generators for the test scenes (teapot, chess, lab, hall, valley, village) and their driver."""
