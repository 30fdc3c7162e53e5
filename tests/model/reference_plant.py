"""An independent plain-numpy/scipy transcription of the thesis' plant (eq. 3.1-3.18, 4.9-4.14
and the pins of docs/model.md), integrated with solve_ivp(Radau) as the tests' reference. It shares
no code with clutch_model.plant.kernels on purpose."""
from __future__ import annotations

import math

import numpy as np
from scipy.integrate import quad, solve_ivp
from scipy.special import erf, erfc


class ReferencePlant:
    def __init__(self, raw: dict):
        g, s, v, th, fr = raw["geometry"], raw["surface"], raw["viscosity"], raw["thermal"], raw["friction"]
        self.ro, self.ri = g["r_outer"], g["r_inner"]
        self.nf, self.nsp, self.ared = g["friction_surfaces"], g["separator_plates"], g["non_grooved_fraction"]
        self.sigma, self.E, self.N, self.beta = s["rms_roughness"], s["youngs_modulus"], s["asperity_density"], s["asperity_tip_radius"]
        self.K, self.d, self.chi = s["permeability"], s["lining_thickness"], s["beavers_joseph_chi"]
        self.a0, self.a1 = v["alpha0"], v["alpha1"]
        self.cp, self.b, self.htf_min = th["plate_heat_capacity"], th["b"], th["htf_min"]
        self.i, self.a = fr["i"], np.asarray(fr["a"], float)
        self.h0 = raw["initial"]["film_thickness"]
        self.AN = math.pi * (self.ro ** 2 - self.ri ** 2)
        self.Q = self.ro ** 2 + self.ri ** 2 + (self.ro ** 2 - self.ri ** 2) / math.log(self.ri / self.ro)

    # eq. 3.7 by numerical quadrature (independent of the closed form)
    @staticmethod
    def fe_quad(x):
        val, _ = quad(lambda s: (s - x) * math.exp(-s * s / 2), x, np.inf, epsabs=1e-14, epsrel=1e-12)
        return val / math.sqrt(2 * math.pi)

    @staticmethod
    def fe(x):
        return math.exp(-x * x / 2) / math.sqrt(2 * math.pi) - x * 0.5 * erfc(x / math.sqrt(2))

    def pa(self, h):
        return self.E * math.pi * self.N * self.beta * self.sigma * self.fe(h / self.sigma)

    def mu(self, theta):
        return self.a0 * max(theta, 1.0) ** (-self.a1)

    def mu_f(self, w, P, theta):
        P = min(max(P, 0.0), 20.0)
        th = min(max(theta, 0.0), 230.0)
        a = self.a
        poly = [a[k] + a[k + 1] * P + a[k + 2] * P * P + a[k + 3] * th + a[k + 4] * th * th for k in (0, 5, 10, 15)]
        mc, ms, ws, kv = poly
        ws = max(ws, 1e-6)
        return max(mc + (ms - mc) * math.exp(-abs(w / ws) ** self.i) + kv * abs(w), 0.0)

    def dhdt(self, h, F, theta):
        H = h / self.sigma
        phi = 1 - 0.9 * math.exp(-0.56 * H)
        xi = F - self.AN * self.pa(h)
        eta = 1 / (1 + self.chi * h / math.sqrt(self.K))
        delta = (h ** 3 * (1 + 3 * eta) + 12 * self.K * self.d) / h ** 3
        g = 0.5 * (1 + erf(h / (math.sqrt(2) * self.sigma)))
        gamma = -1 / (6 * self.mu(theta) * self.AN * self.Q)
        return phi * xi * delta / (g * self.ared) * gamma * h ** 3

    def torque(self, h, theta, F, w):
        H = h / self.sigma
        phif = 1 + 0.5 * math.exp(-0.8 * H)
        phifs = 11.1 * H ** 2.31 * math.exp(-2.38 * H + 0.11 * H * H) if H <= 5 else 0.0
        th = self.nf * w * (phif + phifs) / h * self.mu(theta) * (self.ro ** 4 - self.ri ** 4) / 2 * math.pi * self.ared
        P = F / self.AN * 1e-6
        ta = math.copysign(1.0, w) * self.nf * self.mu_f(w, P, theta) * self.pa(h) * (self.ro ** 3 - self.ri ** 3) / 3 * 2 * math.pi
        return ta + th

    def rhs(self, t, y, F, w, sump):
        h, theta, E = y
        T = self.torque(h, theta, F, w)
        Fkn = F * 1e-3
        htf = max(self.b[0] + self.b[1] * abs(w) + self.b[2] * Fkn + self.b[3] * abs(w) * Fkn, self.htf_min)
        power = abs(w * T)
        dtheta = (power / self.nsp - htf * self.AN * (theta - sump)) / self.cp
        return [self.dhdt(h, F, theta), dtheta, power]

    def simulate(self, t, F, w, sump, rtol=1e-8):
        """Zero-order-hold inputs; torque at each sample from the state there and that sample's
        inputs. F is taken as already clamped (>= 0, below the force limit)."""
        y = np.array([self.h0, sump[0], 0.0])
        torque = np.empty(t.size)
        theta = np.empty(t.size)
        k = 0
        n = t.size
        while k < n:
            j = k
            while j + 1 < n and F[j + 1] == F[k] and w[j + 1] == w[k] and sump[j + 1] == sump[k]:
                j += 1
            # inputs constant on rows k..j; integrate from t_k to t_{j+1}
            t_end = t[j + 1] if j + 1 < n else t[j]
            ts = t[k:j + 2] if j + 1 < n else t[k:j + 1]
            if t_end > t[k]:
                sol = solve_ivp(self.rhs, (t[k], t_end), y, method="Radau", rtol=rtol, atol=[1e-14, 1e-9, 1e-6],
                                t_eval=ts, args=(F[k], w[k], sump[k]))
                assert sol.success, sol.message
                states = sol.y.T
            else:
                states = y[None, :]
            for m in range(k, j + 1):
                hm, thm, _ = states[m - k]
                torque[m] = self.torque(hm, thm, F[m], w[m])
                theta[m] = thm
            y = states[-1].copy()
            k = j + 1
        return torque, theta
