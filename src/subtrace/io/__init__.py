"""Readers of the files subtrace consumes: OBJ cages with OpenSubdiv tags."""
