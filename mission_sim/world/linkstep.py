"""One exact ZOH step of a single envelope link with its exact energy integrals (pure Python, hot loop).

For ``dx/dt = A x + B u`` (paper eq. 4, ``x = [I1, I2]``, ``u = [V1, V2]`` held over the step):

* ``x1 = Ad x0 + Bd u`` (closed-form 2x2 matrix exponential, as :func:`wpt_receiver.zoh_discretise`);
* ``S = int x dt = A^-1 (x1 - x0 - B u dt)`` exactly;
* ``P = int x x^T dt`` from the Lyapunov identity ``A P + P A^T = x1 x1^T - x0 x0^T - B u S^T - S u^T B^T``
  (3 unknowns, solved with a precomputed 3x3 inverse).

Energies of the step [J] (powers of the envelope model are ``V I / 2``):
source ``V1 S1 / 2``, coil losses ``(R1 P11 + R2 P22) / 2``, rectifier ``V2 S2 / 2``; with
``W = (L1 I1^2 + L2 I2^2) / 2`` they satisfy ``source = dW + losses + rectifier`` identically
(weighted trace of the Lyapunov identity), so the balance closes to rounding.
"""

from __future__ import annotations

import math

__all__ = ["LinkStepper"]


class LinkStepper:
    """Single-link exact stepping with cached discretisations keyed by ``(lm_h, dt_s)``."""

    def __init__(self, l1_h, l2_h, r1_ohm, r2_ohm, omega_rad_s):
        self.l1, self.l2, self.r1, self.r2, self.w = l1_h, l2_h, r1_ohm, r2_ohm, omega_rad_s
        self.b0 = 1.0 / (2 * l1_h)
        self.b1 = -1.0 / (2 * l2_h)
        self._cache = {}
        self._lyap = {}
        self.last_p = (0.0, 0.0)

    def matrices(self, lm_h):
        wlm = self.w * lm_h
        return (-self.r1 / (2 * self.l1), -wlm / (2 * self.l1), wlm / (2 * self.l2), -self.r2 / (2 * self.l2))

    def disc(self, lm_h, dt_s):
        """Cached ``(Ad, Bd, Ainv, s-gains)`` as flat tuples of floats."""
        key = (lm_h, dt_s)
        c = self._cache.get(key)
        if c is not None:
            return c
        a00, a01, a10, a11 = self.matrices(lm_h)
        s = 0.5 * (a00 + a11)
        det = a00 * a11 - a01 * a10
        q2 = s * s - det
        q = math.sqrt(abs(q2))
        qt = q * dt_s
        e = math.exp(s * dt_s)
        if qt < 1e-8:
            ec, es = e, e * dt_s
        elif q2 < 0:
            ec, es = e * math.cos(qt), e * math.sin(qt) / q
        else:  # real poles s -/+ q (both negative): e^{st} cosh(qt) without overflowing cosh for long steps
            ep, em = math.exp((s + q) * dt_s), math.exp((s - q) * dt_s)
            ec, es = 0.5 * (ep + em), 0.5 * (ep - em) / q
        d00, d01 = ec + es * (a00 - s), es * a01
        d10, d11 = es * a10, ec + es * (a11 - s)
        i00, i01, i10, i11 = a11 / det, -a01 / det, -a10 / det, a00 / det
        # M = Ainv (Ad - I); Bd = M B
        m00 = i00 * (d00 - 1) + i01 * d10
        m01 = i00 * d01 + i01 * (d11 - 1)
        m10 = i10 * (d00 - 1) + i11 * d10
        m11 = i10 * d01 + i11 * (d11 - 1)
        bd00, bd10 = m00 * self.b0, m10 * self.b0
        bd01, bd11 = m01 * self.b1, m11 * self.b1
        # S2 = [M x0]_2 + g1 v1 + g2 v2 with g = Ainv (Bd - B dt)
        g1 = i10 * (bd00 - self.b0 * dt_s) + i11 * bd10
        g2 = i10 * bd01 + i11 * (bd11 - self.b1 * dt_s)
        c = ((d00, d01, d10, d11), (bd00, bd01, bd10, bd11), (i00, i01, i10, i11), (m10, m11, g1, g2))
        if len(self._cache) > 4096:
            self._cache.clear()
        self._cache[key] = c
        return c

    def s2_affine(self, lm_h, dt_s, x0, v1):
        """``(s0, s1)`` with ``int I2 dt = s0 + s1 V2`` over the step."""
        _, _, _, (m10, m11, g1, g2) = self.disc(lm_h, dt_s)
        return m10 * x0[0] + m11 * x0[1] + g1 * v1, g2

    def _lyap_inv(self, lm_h):
        """Rows 1 and 3 of the inverse of the 3x3 Lyapunov map (p11, p12, p22) -> (q11, q12, q22)."""
        li = self._lyap.get(lm_h)
        if li is None:
            a00, a01, a10, a11 = self.matrices(lm_h)
            # M = [[2a00, 2a01, 0], [a10, a00+a11, a01], [0, 2a10, 2a11]]; inverse by cofactors
            m00, m01, m02 = 2 * a00, 2 * a01, 0.0
            m10, m11, m12 = a10, a00 + a11, a01
            m20, m21, m22 = 0.0, 2 * a10, 2 * a11
            c00 = m11 * m22 - m12 * m21
            c01 = -(m10 * m22 - m12 * m20)
            c02 = m10 * m21 - m11 * m20
            det = m00 * c00 + m01 * c01 + m02 * c02
            inv = [[c00, -(m01 * m22 - m02 * m21), m01 * m12 - m02 * m11],
                   [c01, m00 * m22 - m02 * m20, -(m00 * m12 - m02 * m10)],
                   [c02, -(m00 * m21 - m01 * m20), m00 * m11 - m01 * m10]]
            li = tuple(v / det for row in inv for v in row)
            if len(self._lyap) > 4096:
                self._lyap.clear()
            self._lyap[lm_h] = li
        return li

    def step(self, lm_h, dt_s, x0, v1, v2, disc=None):
        """Advance ``x0 = (I1, I2)``; returns ``(x1, e_src_j, e_coil_j, e_rect_j, int_i2)``.

        ``disc`` may pass ``self.disc(lm_h, dt_s)`` when the caller already has it.
        """
        (d00, d01, d10, d11), (bd00, bd01, bd10, bd11), (i00, i01, i10, i11), _ = \
            self.disc(lm_h, dt_s) if disc is None else disc
        a0, a1 = x0
        y0 = d00 * a0 + d01 * a1 + bd00 * v1 + bd01 * v2
        y1 = d10 * a0 + d11 * a1 + bd10 * v1 + bd11 * v2
        bu0, bu1 = self.b0 * v1, self.b1 * v2
        r0 = y0 - a0 - bu0 * dt_s
        r1 = y1 - a1 - bu1 * dt_s
        s0 = i00 * r0 + i01 * r1
        s1 = i10 * r0 + i11 * r1
        q11 = y0 * y0 - a0 * a0 - 2 * bu0 * s0
        q12 = y0 * y1 - a0 * a1 - (bu0 * s1 + s0 * bu1)
        q22 = y1 * y1 - a1 * a1 - 2 * bu1 * s1
        l = self._lyap_inv(lm_h)
        p11 = l[0] * q11 + l[1] * q12 + l[2] * q22
        p22 = l[6] * q11 + l[7] * q12 + l[8] * q22
        self.last_p = (p11, p22)  # int I1^2 dt, int I2^2 dt of this step (device-loss split)
        e_src = 0.5 * v1 * s0
        e_coil = 0.5 * (self.r1 * p11 + self.r2 * p22)
        e_rect = 0.5 * v2 * s1
        return (y0, y1), e_src, e_coil, e_rect, s1

    def stored_j(self, x):
        """Stored energy of the envelope model ``(L1 I1^2 + L2 I2^2) / 2`` [J]."""
        return 0.5 * (self.l1 * x[0] * x[0] + self.l2 * x[1] * x[1])

    def i2_samples(self, lm_h, dt_s, x0, v1, v2, m: int = 4):
        """I2 at ``m - 1`` equally spaced interior points of the step (for peak detection)."""
        h = dt_s / m
        (d00, d01, d10, d11), (bd00, bd01, bd10, bd11), _, _ = self.disc(lm_h, h)
        a0, a1 = x0
        out = []
        for _ in range(m - 1):
            a0, a1 = (d00 * a0 + d01 * a1 + bd00 * v1 + bd01 * v2, d10 * a0 + d11 * a1 + bd10 * v1 + bd11 * v2)
            out.append(a1)
        return out
