"""The tape engine: one native interpreter for every program, the program simplified per octant."""
