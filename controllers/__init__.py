"""muvsim: controllers package."""
