"""muvsim: analysis package."""
