"""``cldet convert``: not yet implemented."""
