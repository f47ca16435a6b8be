"""Tyre force laws shared by the truth plants (validation only; observers use linear tyres)."""
import sympy as sp


def magic_formula_axle(alpha, cornering_stiffness, fz, mu, C, E):
    """Pacejka magic formula of Nguyen et al. 2021 eq. (2) for one axle.

    F_y = D sin(C atan((1 - E) B alpha + E atan(B alpha))) with peak D = mu F_z and B from
    B C D = ``cornering_stiffness``, so the small-slip slope equals the observer's linear tyre.
    """
    D = mu * fz
    B = cornering_stiffness / (C * D)
    return D * sp.sin(C * sp.atan((1 - E) * B * alpha + E * sp.atan(B * alpha)))
