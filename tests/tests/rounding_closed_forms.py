# Closed forms of the rounding tests (tests/tests/rounding.rs), in 40-digit arithmetic (mpmath):
#   python3 rounding_closed_forms.py sampled 900.005   # C and dC/dperiod of rounding_sampled.hyb
#   python3 rounding_closed_forms.py ball 20000        # C, dC/de, dC/dc of rounding_ball.hyb
# The sampled loop: per sample interval of length L from x_j with u_j = -k x_j held,
# x(s) = x_j e^{-as} + (1 + u_j)(1 - e^{-as})/a; the ball: flights of 2V/g with
# V <- e V + c, each adding 2V^3/(3g^2) to the integral of h. dC/dθ by mpmath.diff at
# a fixed number of samples/bounces (the count is locally constant).
import sys
from mpmath import mp, mpf, exp, sqrt, floor, diff
mp.dps = 40

def sampled(P, a=mpf(1), k=mpf(2), T=mpf('900.005'), N=None):
    # N: index of the last sample (fixed locally)
    x = mpf(0); C = mpf(0)
    for j in range(N + 1):
        L = P if j < N else T - N * P
        E = exp(-a * L)
        uj = -k * x
        C += x * (1 - E) / a + (1 + uj) / a * (L - (1 - E) / a)
        x = x * E + (1 + uj) / a * (1 - E)
    return C

def ball(e, c=mpf(2), g=mpf(9.81), h0=mpf(1), T=mpf(20000), nb=None):
    t1 = sqrt(2 * h0 / g)
    C = h0 * t1 - g * t1**3 / 6
    t = t1
    V = e * sqrt(2 * g * h0) + c
    for n in range(nb):
        d = 2 * V / g
        C += 2 * V**3 / (3 * g**2)
        t += d
        V = e * V + c
    L = T - t
    assert 0 < L < 2 * V / g
    C += V * L**2 / 2 - g * L**3 / 6
    return C

def ball_count(e, c=mpf(2), g=mpf(9.81), h0=mpf(1), T=mpf(20000)):
    t = sqrt(2 * h0 / g); V = e * sqrt(2 * g * h0) + c; n = 0
    while t + 2 * V / g < T:
        t += 2 * V / g; V = e * V + c; n += 1
    return n, t

if __name__ == "__main__":
    which = sys.argv[1]
    if which == "sampled":
        T = mpf(sys.argv[2]); P = mpf(0.01)
        N = int(floor(T / P))
        print("N", N, "C", sampled(P, T=T, N=N))
        print("dC/dP", diff(lambda q: sampled(q, T=T, N=N), P))
    else:
        T = mpf(sys.argv[2]); e = mpf(sys.argv[3]) if len(sys.argv) > 3 else mpf('0.8')
        nb, tl = ball_count(e, T=T)
        print("bounces", nb + 1, "last", tl, "C", ball(e, T=T, nb=nb))
        print("dC/de", diff(lambda q: ball(q, T=T, nb=nb), e))
        print("dC/dc", diff(lambda q: ball(e, c=q, T=T, nb=nb), mpf(2)))
