"""Single track with roll and two actuator lags: the steering actuator (dwa follows dw with tau_s) and
an active-suspension valve (q follows u_q with tau_q; nothing measured depends on it)."""
import sympy as sp
from codegen.model import ModelDefinition, SchedulingSignal

vy, r, phi, p, dwa, q, phir, dw, u_q = sp.symbols("vy r phi p dwa q phir dw u_q")
vx = sp.Symbol("vx", positive=True)
m, ms, h, Iz, Ix, lf, lr, Cf, Cr, Kphi, Dphi, g, tau_s, tau_q = sp.symbols(
    "m ms h Iz Ix lf lr Cf Cr Kphi Dphi g tau_s tau_q", positive=True)
Ff = Cf * (dwa - (vy + lf * r) / vx)
Fr = Cr * (lr * r - vy) / vx
ay = (Ff + Fr) / m
MODEL = ModelDefinition(
    name="roll6", states=(vy, r, phi, p, dwa, q), known_inputs=(dw, u_q), unknown_inputs=(phir,),
    dynamics=sp.Matrix([ay - vx * r + g * phir, (lf * Ff - lr * Fr) / Iz, p,
                        (ms * h * ay - Kphi * phi - Dphi * p) / Ix, (dw - dwa) / tau_s, (u_q - q) / tau_q]),
    outputs=(("r", r), ("ay", ay), ("p", p)),
    scheduling=(SchedulingSignal(vx, "m/s"),),
    parameters=(m, ms, h, Iz, Ix, lf, lr, Cf, Cr, Kphi, Dphi, g, tau_s, tau_q),
    units={"vy": "m/s", "r": "rad/s", "phi": "rad", "p": "rad/s", "dwa": "rad", "q": "-", "phir": "rad",
           "dw": "rad", "u_q": "-", "ay": "m/s^2", "vx": "m/s"})
