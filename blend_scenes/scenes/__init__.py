"""One module per scene; each exposes ``build(out_dir) -> SceneSpec`` (bpy, deterministic)."""

SCENES = ("teapot", "chess", "lab", "hall", "valley", "village", "artist")
