"""Single track with roll: lateral speed, yaw rate, roll angle, roll rate; road bank angle unknown (via g*phi_r small angle)."""
import sympy as sp
from codegen.model import ModelDefinition, SchedulingSignal

vy, r, phi, p, phir, dw = sp.symbols("vy r phi p phir dw")
vx = sp.Symbol("vx", positive=True)
m, ms, h, Iz, Ix, lf, lr, Cf, Cr, Kphi, Dphi, g = sp.symbols("m ms h Iz Ix lf lr Cf Cr Kphi Dphi g", positive=True)
Ff = Cf * (dw - (vy + lf * r) / vx)
Fr = Cr * (lr * r - vy) / vx
ay = (Ff + Fr) / m
MODEL = ModelDefinition(
    name="roll_bank", states=(vy, r, phi, p), known_inputs=(dw,), unknown_inputs=(phir,),
    dynamics=sp.Matrix([ay - vx * r + g * phir, (lf * Ff - lr * Fr) / Iz, p,
                        (ms * h * ay - Kphi * phi - Dphi * p) / Ix]),
    outputs=(("r", r), ("ay", ay), ("p", p)),
    scheduling=(SchedulingSignal(vx, "m/s"),),
    parameters=(m, ms, h, Iz, Ix, lf, lr, Cf, Cr, Kphi, Dphi, g),
    units={"vy": "m/s", "r": "rad/s", "phi": "rad", "p": "rad/s", "phir": "rad", "dw": "rad", "ay": "m/s^2", "vx": "m/s",
           "m": "kg", "ms": "kg", "h": "m", "Kphi": "N m", "Dphi": "N m s", "g": "m/s^2"})
