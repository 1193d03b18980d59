"""OpenGL rendering (imports moderngl lazily; nothing here is imported by ``import vhgen``)."""
