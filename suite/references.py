#!/usr/bin/env python3
"""Writes suite/manifest.json: the cases of the stiff and extreme suite with their
references. Closed forms are evaluated here in 50-digit arithmetic (mpmath), their
derivatives by mpmath's high-precision differentiation; cases without a closed form name an
independent tight run of another method, which `mvad` evaluates (C from it, dC/dθ by
central differences of its primal runs). Run it from the repository root after changing a
case: python3 suite/references.py
"""
import json
import os

from mpmath import mp, mpf, sqrt, exp, cos, diff

mp.dps = 50


def grad(f, x, names):
    """{name: ∂f/∂x_i} at x, in 50-digit arithmetic."""
    out = {}
    for i, n in enumerate(names):
        def fi(v, i=i):
            y = list(x)
            y[i] = v
            return f(*y)
        out[n] = float(diff(fi, x[i]))
    return out


def ball_cost(e, g, h0, v0, T):
    """∫₀ᵀ h dt of the bouncing ball, flight by flight (finitely many impacts before T)."""
    t, h, v, c = mpf(0), h0, v0, mpf(0)
    while True:
        s = (v + sqrt(v * v + 2 * g * h)) / g
        if t + s >= T:
            L = T - t
            return c + h * L + v * L**2 / 2 - g * L**3 / 6
        c += h * s + v * s**2 / 2 - g * s**3 / 6
        t += s
        v = -e * (v - g * s)
        h = mpf(0)


def zeno_cost(e, g, h0, v0):
    """∫₀ᵀ h dt of the Zeno ball (t* < T): the first flight plus the geometric series of
    bounces, each of launch speed eᵏV (V = √(v0² + 2 g h0)) and area 2(eᵏV)³/(3g²)."""
    V = sqrt(v0 * v0 + 2 * g * h0)
    t1 = (v0 + V) / g
    first = h0 * t1 + v0 * t1**2 / 2 - g * t1**3 / 6
    return first + 2 * V**3 * e**3 / (3 * g**2 * (1 - e**3))


def relay_cost(tau, rate, lo, hi, T=mpf(3)):
    """∫₀ᵀ y² dt of models/stiff_relay.hyb: on a piece with input w from (u_s, y_s),
    y = A + B s − D e^{−s/τ}, A = y_s + rate (u_s − w) τ, B = rate w, D = rate (u_s − w) τ."""
    t, u, y, up, c = mpf(0), mpf(1), mpf(0), True, mpf(0)
    while True:
        w = mpf(1) if up else mpf(-1)
        target = hi if up else lo
        s = ((target - y) / rate - (u - w) * tau) / w
        last = t + s >= T
        L = T - t if last else s
        A = y + rate * (u - w) * tau
        B = rate * w
        D = rate * (u - w) * tau
        EL = exp(-L / tau)
        poly = A * A * L + A * B * L**2 + B * B * L**3 / 3
        cross = A * tau * (1 - EL) + B * (tau**2 - tau**2 * EL - tau * L * EL)
        c += poly - 2 * D * cross + D * D * tau / 2 * (1 - EL * EL)
        if last:
            return c
        t += s
        y = target
        u = w + (u - w) * exp(-s / tau)
        up = not up


def ceiling_cost(e, g, v0, gap, T=mpf("0.8")):
    """∫₀ᵀ h dt of ceiling_gap.hyb: up to the hit at c = v0²/(2g) − gap, then the fall
    from c at speed −e √(2 g gap)."""
    c = v0 * v0 / (2 * g) - gap
    w = sqrt(v0 * v0 - 2 * g * c)
    th = (v0 - w) / g
    L = T - th
    return v0 * th**2 / 2 - g * th**3 / 6 + c * L - e * w * L**2 / 2 - g * L**3 / 6


def decay_cost(a, k):
    return a * (1 - exp(-k)) / k


def tracking_cost(a, b, T=mpf(10)):
    """∫₀ᵀ x dt of suite/unstable_tracking.hyb: x = b sin t for every a."""
    return b * (1 - cos(T))


def growth_cost(a, x0, T=mpf(10)):
    """∫₀ᵀ x dt of suite/exponential_growth.hyb: x = x0 e^{a t}."""
    return x0 * (exp(a * T) - 1) / a


BALL = ["e", "g", "h0", "v0"]
cases = []


def given(name, model, fn, x, names, about, bound, check, set_=None, t_end=None, **kw):
    ref = {"cost": float(fn(*x)), "gradient": grad(fn, x, names), "source": about}
    case = {"name": name, "model": model, "set": set_ or {}, "check": check,
            "reference": ref, "bound": bound}
    if t_end is not None:
        case["t_end"] = t_end
    case.update(kw)
    cases.append(case)


def tight(method="rosenbrock", rtol=1e-12, atol=1e-14):
    return {"method": method, "rtol": rtol, "atol": atol}


# Tolerances 1e-2 ... 1e-14 on E1 (the bouncing ball, closed form).
for r in [1e-2, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-14]:
    x = [mpf("0.8"), mpf("9.81"), mpf(2), mpf(0)]
    given(f"ball rtol {r:.0e}", "ball.hyb", lambda e, g, h0, v0: ball_cost(e, g, h0, v0, mpf(2)),
          x, BALL, "closed form: flight by flight", {"cost": max(10 * r, 1e-13), "gradient": max(10 * r, 1e-12)},
          {"method": "auto", "rtol": r, "atol": r * 1e-2}, fast=True,
          sweep=[1e-2, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12, 1e-14] if r == 1e-8 else [])

# Zeno for e in {0.1, 0.5, 0.9}, and e -> 0 (T past t* = t1 (1 + 2e/(1 - e)), 12.1 s for 0.9).
for e, T in [("0.1", 3.0), ("0.5", 3.0), ("0.9", 15.0), ("1e-6", 3.0)]:
    x = [mpf(e), mpf("9.81"), mpf(2), mpf(0)]
    given(f"zeno e={e}", "zeno_ball.hyb", zeno_cost, x, BALL,
          "closed form: first flight + geometric series of bounces 2(e^k V)^3/(3g^2)",
          {"cost": 1e-10, "gradient": 1e-10}, {"method": "auto", "rtol": 1e-10, "atol": 1e-12},
          set_={"e": float(e)}, t_end=T, require=["zeno"], fast=True)
cases.append({"name": "zeno e=0.5, C = int v", "model": "zeno_velocity.hyb",
              "check": {"method": "auto", "rtol": 1e-10, "atol": 1e-12},
              "reference": {"cost": -2.0, "gradient": {"e": 0.0, "g": 0.0, "h0": -1.0, "v0": 0.0},
                            "source": "exact: C = h(T) - h(0) = -h0 with the ball at rest"},
              "bound": {"cost": 1e-10, "gradient": 1e-10}, "require": ["zeno"], "fast": True})

# e -> 1: thousands of bounces; e = 1: a horizon of 10^4 bounces.
x = [1 - mpf("1e-6"), mpf("9.81"), mpf(2), mpf(0)]
given("restitution 1-1e-6, 1566 bounces", "ball.hyb",
      lambda e, g, h0, v0: ball_cost(e, g, h0, v0, mpf(2000)), x, BALL,
      "closed form: flight by flight", {"cost": 1e-7, "gradient": 1e-6},
      {"method": "auto", "rtol": 1e-10, "atol": 1e-12}, set_={"e": 1 - 1e-6}, t_end=2000.0,
      sweep=[1e-6, 1e-8, 1e-10, 1e-12])
x = [mpf(1), mpf("9.81"), mpf(2), mpf(0)]
T4 = 1e4 * 2 * float(sqrt(mpf(4) / mpf("9.81"))) + 0.3
given("horizon of 1e4 bounces (e = 1)", "ball.hyb",
      lambda e, g, h0, v0: ball_cost(e, g, h0, v0, mpf(T4)), x, BALL,
      "closed form: flight by flight", {"cost": 1e-7, "gradient": 1e-6},
      {"method": "auto", "rtol": 1e-10, "atol": 1e-12}, set_={"e": 1.0}, t_end=T4,
      sweep=[1e-6, 1e-8, 1e-10, 1e-12])

# The stiff relay at rtol 1e-3 ... 1e-12, default options otherwise.
for r in [1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12]:
    x = [mpf("1e-8"), mpf(1), mpf("-0.5"), mpf("0.5")]
    given(f"stiff relay rtol {r:.0e}", "stiff_relay.hyb", relay_cost, x,
          ["tau", "rate", "lo", "hi"], "closed form: exponential pieces between switches",
          {"cost": 10 * r, "gradient": 10 * r}, {"method": "auto", "rtol": r}, fast=True,
          sweep=[1e-3, 1e-4, 1e-6, 1e-8, 1e-10, 1e-12] if r == 1e-8 else [])

# Grazing sweep: the ceiling gap down to 1e-12.
for gap in ["1e-2", "1e-4", "1e-6", "1e-8", "1e-10", "1e-12"]:
    x = [mpf("0.8"), mpf("9.81"), mpf("4.4"), mpf(gap)]
    given(f"grazing gap {gap}", "ceiling_gap.hyb", ceiling_cost, x, ["e", "g", "v0", "gap"],
          "closed form: rise, hit at the ceiling, fall", {"cost": 1e-8, "gradient": 1e-6},
          {"method": "auto", "rtol": 1e-10, "atol": 1e-12}, set_={"gap": float(gap)},
          excuse=["grazing"], fast=True, sweep=[1e-6, 1e-8, 1e-10, 1e-12])

# Two guards 1e-12 apart and exactly together.
for name, b, req in [("two guards 1e-12 apart", 0.5 + 1e-12, []),
                     ("two guards together", 0.5, ["simultaneous_events"])]:
    cases.append({"name": name, "model": "two_guards.hyb", "set": {"a": 0.5, "b": b},
                  "check": {"method": "auto", "rtol": 1e-10, "atol": 1e-12},
                  "reference": {"cost": 1.0 - (b - 0.5), "gradient": {"a": -1.0, "b": -1.0},
                                "source": "exact: C = (T - a) + (T - b)"},
                  "bound": {"cost": 1e-10, "gradient": 1e-10}, "require": req, "fast": True})

# Parameters at scales 1e-9 ... 1e9, atol scaled with the state (atol = 1e-10 a: an
# absolute tolerance above the state's size controls it only to that absolute level).
for a, k in [("1e-9", "1"), ("1e9", "1"), ("1", "1e-9"), ("1", "1e9"), ("1e9", "1e-9"), ("1e-9", "1e9")]:
    x = [mpf(a), mpf(k)]
    given(f"scales a={a} k={k}", "scaled_decay.hyb", decay_cost, x, ["a", "k"],
          "closed form: a (1 - exp(-k)) / k", {"cost": 1e-7, "gradient": 1e-7},
          {"method": "auto", "rtol": 1e-9, "atol": 1e-10 * float(a)},
          set_={"a": float(a), "k": float(k)}, fast=True)

# Local error control does not bound the error at T (issue 11): perturbations of the tracked
# solution x = b sin t grow like e^{a t}, so the steps' errors reach T amplified e^{a (T - t)};
# the run must say so (`ill_conditioned`). With a = 0.5 the amplification e^5 stays within the
# bound, and exponential growth x' = a x amplifies errors only as much as the solution itself.
for a, fire in [("2", True), ("0.5", False)]:
    given(f"unstable tracking a={a}", "unstable_tracking.hyb", tracking_cost, [mpf(a), mpf(1)],
          ["a", "b"], "closed form: x = b sin t, C = b (1 - cos T)",
          {"cost": 1e-6, "gradient": 1e-6}, {"method": "auto", "rtol": 1e-8, "atol": 1e-10},
          set_={"a": float(a)}, fast=True, sweep=[1e-6, 1e-8, 1e-10, 1e-12],
          **({"require": ["ill_conditioned"], "excuse": ["ill_conditioned"]} if fire else {}))
given("exponential growth a=2", "exponential_growth.hyb", growth_cost, [mpf(2), mpf(1)],
      ["a", "x0"], "closed form: x0 (e^{aT} - 1) / a", {"cost": 1e-6, "gradient": 1e-6},
      {"method": "auto", "rtol": 1e-8, "atol": 1e-10}, fast=True, sweep=[1e-6, 1e-8, 1e-10, 1e-12])

# Stiff models without a closed form: an independent tight run (Rodas5P at rtol 1e-12 for
# C; central differences of its primal runs for dC/dθ), the check under `auto`.
# The thermostat's tau = 1e-6 cannot be differenced (its step would be 1e-11): its reference
# gradient is the tight run's own.
FD = "Rodas5P at rtol 1e-12, atol 1e-14; dC/dθ by central differences (step 1e-5)"
OWN = "Rodas5P at rtol 1e-12, atol 1e-14, C and dC/dθ (MV-AD) of that run"
for name, model, set_, fast, step in [
        ("van der pol mu=1e3", "van_der_pol.hyb", {"mu": 1e3}, True, 1e-5),
        ("van der pol mu=1e6", "van_der_pol.hyb", {"mu": 1e6}, False, 1e-5),
        ("robertson with a dose", "robertson_dose.hyb", {}, True, 1e-5),
        ("thermostat with a fast sensor lag", "thermostat_lag.hyb", {}, True, None)]:
    ref = {"run": tight(), "source": FD if step else OWN}
    if step:
        ref["fd_step"] = step
    case = {"name": name, "model": model, "set": set_,
            "check": {"method": "auto", "rtol": 1e-8, "atol": 1e-10},
            "reference": ref,
            "bound": {"cost": 1e-6, "gradient": 1e-4}, "fast": fast,
            "sweep": [1e-4, 1e-6, 1e-8, 1e-10]}
    if model == "van_der_pol.hyb":
        # The fold at t ≈ 0.73 (y1 = 1): the steps' errors in S, made while S ≈ f t' is up
        # to 10⁶ times its size at T, are not damped on landing; the error of dC/dθ is
        # 10²–10⁴ times the tolerance and the run must say so (`ill_conditioned`).
        case["excuse"] = ["ill_conditioned"]
        if set_["mu"] == 1e6:
            case["require"] = ["ill_conditioned"]
    cases.append(case)

here = os.path.dirname(os.path.abspath(__file__))
with open(os.path.join(here, "manifest.json"), "w") as f:
    json.dump({"cases": cases}, f, indent=1)
    f.write("\n")
print(f"{len(cases)} cases")
