"""Reading the user's files and writing output directories."""
