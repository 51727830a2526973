"""Independent Rayleigh–Ritz model of the spin-up beam of Kane, Ryan and Banerjee (1987), in NumPy/SciPy.

A uniform Euler–Bernoulli cantilever (length `L`, mass per length `rho A`, bending stiffnesses `EI_v` in the plane of
rotation and `EI_w` across it) is clamped at the hub axis and turned about the inertial `z` axis by the prescribed
angle `theta(t)`. In the hub frame a point of the neutral axis is at `(x + u, v, w)`, with the chordwise (in-plane)
and flapwise (out-of-plane) deflections `v = sum_i phi_i(x) a_i`, `w = sum_i phi_i(x) b_i` and the foreshortening of
the inextensible axis `u = -1/2 int_0^x (v'^2 + w'^2) d xi` (Kane et al.'s geometric-stiffening term). Its velocity in
hub axes is `(u' - theta' v, v' + theta' (x + u), w')` (dots: time), so to second order in `(a, b)`

`T = 1/2 int rho A [v.^2 + w.^2 + theta'^2 v^2 + 2 theta' x v. + theta'^2 x^2 + 2 theta'^2 x u] dx`,

and `int rho A x u dx = -1/2 int N_1 (v'^2 + w'^2) dx` with `N_1(x) = rho A (L^2 - x^2) / 2`, the axial force per
unit `theta'^2`. With gravity `g` along `-z` (potential `int rho A g w dx`) and the strain energy
`1/2 int (EI_v v''^2 + EI_w w''^2) dx`, Lagrange's equations are, linear in `(a, b)`:

`M a.. + (K_v + theta'^2 (s G - M)) a = -theta'' S`,   `M b.. + (K_w + s theta'^2 G) b = -g F`,

`M_ij = int rho A phi_i phi_j`, `K_ij = int EI phi_i'' phi_j''`, `G_ij = int N_1 phi_i' phi_j'`, `S_i = int rho A x
phi_i`, `F_i = int rho A phi_i`; `s = 1` with geometric stiffening, `s = 0` without (the "linear" model whose
chordwise deflection diverges once `theta' > omega_1`). The Ritz functions are the clamped-free beam eigenfunctions
(written in a form without the cancellation of `cosh - sinh` at large arguments), the integrals by 200-point
Gauss–Legendre quadrature (exact to round-off for these smooth functions), the motion by `scipy.integrate.solve_ivp`
(DOP853, rtol 1e-11). This file shares no code with `ffr_jax`.

The spin-up law: `theta' = Omega_s / T (t - T / (2 pi) sin(2 pi t / T))` for `t < T`, `Omega_s` afterwards.

References:
- T. R. Kane, R. R. Ryan, A. K. Banerjee, "Dynamics of a cantilever beam attached to a moving base", J. Guidance,
  Control, and Dynamics 10 (1987) 139–151.
"""

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

# Kane, Ryan and Banerjee's beam and spin-up manoeuvre (their Sect. on the spin-up, as cited by later benchmarks).
KANE_BEAM = dict(length=10.0, area=4e-4, inertia=2e-7, youngs=7e10, density=3000.0)
KANE_SPIN_UP = dict(omega_s=6.0, t_s=15.0)


def spin_up(t, omega_s, t_s):
    """`(theta, theta', theta'')` of the spin-up law at time `t` (scalars)."""
    if t < t_s:
        c = 2.0 * np.pi / t_s
        theta = omega_s / t_s * (t * t / 2.0 + (np.cos(c * t) - 1.0) / c**2)
        return theta, omega_s / t_s * (t - np.sin(c * t) / c), omega_s / t_s * (1.0 - np.cos(c * t))
    return omega_s * t_s / 2.0 + omega_s * (t - t_s), omega_s, 0.0


def _cantilever_roots(n):
    """The first `n` roots of `cos(beta) cosh(beta) = -1`."""
    f = lambda b: np.cos(b) + np.exp(-b) / (1.0 + np.exp(-2.0 * b)) * 2.0  # cos b + 1/cosh b
    return np.array([brentq(f, (k + 0.5) * np.pi - 1.0, (k + 0.5) * np.pi + 1.0) for k in range(n)])


def cantilever_functions(beta, xi):
    """`(phi, phi', phi'')` of the clamped-free eigenfunction with root `beta` at `xi = x / L` (derivatives in `xi`),
    scaled to `phi(1) = 2 (-1)^(n+1)` (the usual normalisation).

    `phi = cosh x - cos x - sigma (sinh x - sin x)`, `x = beta xi`, with `cosh x - sigma sinh x` written as
    `(1 - sigma) e^x / 2 + (1 + sigma) e^-x / 2` and `(1 - sigma) e^x` evaluated as `e^(x - beta) c`.
    """
    sb, cb = np.sin(beta), np.cos(beta)
    em = np.exp(-beta)
    denominator = 1.0 - em * em + 2.0 * sb * em  # 2 e^-beta (sinh beta + sin beta)
    sigma = (1.0 + em * em + 2.0 * cb * em) / denominator  # (cosh + cos) / (sinh + sin)
    x = beta * xi
    e1 = np.exp(x - beta) * (-em + sb - cb) / denominator  # (1 - sigma) e^x / 2
    e2 = np.exp(-x) * (1.0 + sigma) / 2.0
    phi = e1 + e2 - np.cos(x) + sigma * np.sin(x)
    d1 = beta * (e1 - e2 + np.sin(x) + sigma * np.cos(x))
    d2 = beta**2 * (e1 + e2 + np.cos(x) - sigma * np.sin(x))
    return phi, d1, d2


class RitzBeam:
    """The Ritz matrices of the module docstring for `n` functions per direction.

    **Arguments:** `n`; the beam: `length`, `area`, `density`, `youngs`, `inertia` (in-plane `I`) and
    `inertia_flap` (out-of-plane `I`, default the in-plane one).
    """

    def __init__(self, n, *, length, area, density, youngs, inertia, inertia_flap=None):
        self.length = float(length)
        rho_a = density * area
        ei_v, ei_w = youngs * inertia, youngs * (inertia if inertia_flap is None else inertia_flap)
        nodes, weights = np.polynomial.legendre.leggauss(200)
        xi = 0.5 * (nodes + 1.0)
        w = 0.5 * weights * length  # dx = L d xi
        x = xi * length
        self.betas = _cantilever_roots(n)
        phi, d1, d2 = (np.stack(f) for f in zip(*(cantilever_functions(b, xi) for b in self.betas)))
        d1, d2 = d1 / length, d2 / length**2
        self.tip = np.array([cantilever_functions(b, 1.0)[0] for b in self.betas])
        self.mass = rho_a * (phi * w) @ phi.T
        self.stiffness_v = ei_v * (d2 * w) @ d2.T
        self.stiffness_w = ei_w * (d2 * w) @ d2.T
        self.geometric = (d1 * (w * rho_a * (length**2 - x**2) / 2.0)) @ d1.T
        self.moment = phi @ (w * rho_a * x)
        self.load = phi @ (w * rho_a)

    def coordinates(self, ts, *, omega_s, t_s, stiffening, gravity=0.0, rtol=1e-11, atol=1e-13):
        """The Ritz coordinates `a(t)` (chordwise) and `b(t)` (flapwise) at the times `ts` (the beam starts undeformed
        and at rest). **Returns:** `(a, b)`, each `(len(ts), n)`."""
        n = self.mass.shape[0]
        s = 1.0 if stiffening else 0.0
        m_inv = np.linalg.inv(self.mass)

        def rhs(t, y):
            a, b, da, db = y[:n], y[n:2 * n], y[2 * n:3 * n], y[3 * n:]
            _, rate, accel = spin_up(t, omega_s, t_s)
            fa = -(self.stiffness_v + rate**2 * (s * self.geometric - self.mass)) @ a - accel * self.moment
            fb = -(self.stiffness_w + s * rate**2 * self.geometric) @ b - gravity * self.load
            return np.concatenate([da, db, m_inv @ fa, m_inv @ fb])

        ts = np.asarray(ts, dtype=float)
        # The law's third derivative jumps at t_s: integrate the two pieces separately (dense output, 7th order).
        ends = (min(t_s, ts.max()),) + ((ts.max(),) if ts.max() > t_s else ())
        pieces, y, t0 = [], np.zeros(4 * n), 0.0
        for t_end in ends:
            sol = solve_ivp(rhs, (t0, t_end), y, method="DOP853", dense_output=True, rtol=rtol, atol=atol)
            if not sol.success:
                raise RuntimeError(sol.message)
            pieces.append(sol.sol)
            y, t0 = sol.y[:, -1], t_end
        out = pieces[0](np.minimum(ts, t_s)).T
        if len(pieces) == 2:
            out = np.where((ts <= t_s)[:, None], out, pieces[1](np.maximum(ts, t_s)).T)
        return out[:, :n], out[:, n:2 * n]

    def tip_deflections(self, ts, **motion):
        """Chordwise `v(L, t)` and flapwise `w(L, t)` at the times `ts`; keywords as [`coordinates`][].

        **Returns:** `(v, w)`, each `(len(ts),)`.
        """
        a, b = self.coordinates(ts, **motion)
        return a @ self.tip, b @ self.tip
