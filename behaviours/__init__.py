"""py_trees behaviours wrapping skills, condition checks and recovery composites."""
