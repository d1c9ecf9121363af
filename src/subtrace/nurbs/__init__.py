"""Free-form surfaces: trimmed (rational) NURBS as OBJ files carry them.

Placeholder: the interface is described in full once the model tables exist.
"""
