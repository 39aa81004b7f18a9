"""``cldet results``: not yet implemented."""
