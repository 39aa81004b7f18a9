"""``cldet annotate``: not yet implemented."""
