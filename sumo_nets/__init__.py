"""muvsim: sumo_nets package."""
