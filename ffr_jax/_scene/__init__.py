"""Scene elements: bodies, constraints (joints and drivers), force elements and effects."""
