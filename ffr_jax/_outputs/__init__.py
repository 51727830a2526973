"""Outputs of the motion recovered from the minimal-coordinate solution: accelerations, constraint
multipliers and joint forces (one concept per file)."""
