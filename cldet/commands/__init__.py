"""The commands of the ``cldet`` CLI, one module per command (or family of commands)."""
