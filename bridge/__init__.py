"""muvsim: bridge package."""
