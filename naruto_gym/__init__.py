"""naruto-gym."""
