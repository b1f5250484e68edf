"""The Render Budget GPU render engine: its properties, the engine (final renders and the viewport) and
its Render Properties panels (registered by the add-on's ``register()``, in that order)."""
