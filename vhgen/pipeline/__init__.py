"""Job planning (pure), frame generation (GL) and the Ray driver (Ray imported lazily)."""
