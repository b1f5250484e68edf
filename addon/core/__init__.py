"""Pure logic of the add-on: no bpy imports, testable in plain Python."""
