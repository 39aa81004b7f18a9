"""``cldet demo``: not yet implemented."""
