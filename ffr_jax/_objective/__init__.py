"""Integral objectives `psi = int F(t, y_r, p) dt` (paper eq. 20)."""
