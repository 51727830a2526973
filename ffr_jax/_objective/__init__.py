"""Objectives of the motion `psi = G(t1, y_r, z_r, p) + int F(t, y_r, z_r, p) dt` (paper eq. 20, extended)."""
