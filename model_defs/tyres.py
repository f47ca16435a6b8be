"""Tyre force laws written once: the truth plants, the Kalman peers and the nonlinear-tyre observer use them."""
import sympy as sp


def magic_formula_axle(alpha, cornering_stiffness, fz, mu, C, E):
    """Pacejka magic formula of Nguyen et al. 2021 eq. (2) for one axle.

    F_y = D sin(C atan((1 - E) B alpha + E atan(B alpha))) with peak D = mu F_z and B from
    B C D = ``cornering_stiffness``, so the small-slip slope equals the observer's linear tyre.
    """
    D = mu * fz
    B = cornering_stiffness / (C * D)
    return D * sp.sin(C * sp.atan((1 - E) * B * alpha + E * sp.atan(B * alpha)))


def fiala_slip_force(t, cornering_stiffness, mu_fz, clamp=True):
    """Fiala (brush, parabolic pressure) lateral axle force in the slip variable t = tan(alpha).

    ``F = C t - C^2/(3 mu F_z) |t| t + C^3/(27 mu^2 F_z^2) t^3`` for |t| <= t_sl = 3 mu F_z / C, and
    ``mu F_z sign(t)`` beyond (full sliding, dF/dt = 0); Pacejka, *Tire and Vehicle Dynamics*, 3rd
    ed., Sec. 3.2; Hindiyeh & Gerdes (2014). Its slope is dF/dt = C (1 - |t|/t_sl)^2: C at t = 0,
    0 at full sliding. ``clamp=False`` gives the polynomial alone, equal to the clamped law on
    |t| <= t_sl (used for Jacobian bounds over a set that stays inside that range). ``mu_fz`` is
    the axle's lateral force capacity: mu F_z for pure cornering, less when the axle also
    carries a longitudinal force (:func:`friction_circle_capacity`).
    """
    t_slide = 3 * mu_fz / cornering_stiffness
    if clamp:
        t = _symbolic(sp.Min, _symbolic(sp.Max, t, -t_slide), t_slide)
    c = cornering_stiffness
    return c * t - c ** 2 / (3 * mu_fz) * sp.Abs(t) * t + c ** 3 / (27 * mu_fz ** 2) * t ** 3


def fiala_sliding_slip(cornering_stiffness, mu_fz):
    """t_sl = 3 mu F_z / C: the slip (tan alpha) at which the Fiala axle reaches full sliding."""
    return 3 * mu_fz / cornering_stiffness


def friction_circle_capacity(mu_fz, f_x, floor):
    """Lateral force capacity of an axle that also carries the longitudinal force ``f_x``.

    The friction circle (combined slip, Pacejka 2012 Sec. 3.3; Hindiyeh & Gerdes 2014 use the
    same reduction): sqrt((mu F_z)^2 - F_x^2). ``floor`` (a fraction of mu F_z) is what the
    lateral capacity never drops below: a longitudinal force estimated from a_x with static loads
    can exceed mu F_z on one axle (hard braking moves load forward), and a capacity of 0 would
    make the sliding slip 0. Pure cornering (f_x = 0) gives mu F_z exactly.
    """
    return sp.sqrt(_symbolic(sp.Max, mu_fz ** 2 - f_x ** 2, (floor * mu_fz) ** 2))


def _symbolic(minmax, *args):
    """``minmax(*args)`` unevaluated when an argument holds a symbol: sympy's Min/Max constructor then
    runs its general simplifier (0.3 s per import of a model with two axles) and leaves arguments
    like these as they are; with numbers only, the number."""
    return minmax(*args, evaluate=not any(sp.sympify(a).free_symbols for a in args))
