"""muvsim: tm package."""
