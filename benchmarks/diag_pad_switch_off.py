"""Two series-tuned tanks from the state at the gust example's pad switch-off, in the time domain (independent of the
envelope model; docs/mission.md "Pad switch-off (2026-11-28)").

At the step where the pad's V1 ramp reaches 0: I1 = 5.86 A, I2 ~ 0, k = 0.0747, the default link (L1 = 236 uH,
L2 = 18.9 uH, R1 = 0.108 ohm, R2 = 0.0325 ohm, 85 kHz). Four terminations for 400 us, the diodes as
``tanh(i / 50 mA)``:

* free: both tanks shorted (V1 = 0, the inverter's zero vector; V2 = 0, what the loop applied until 2026-11-28);
* inv: the inverter's gates off, its body diodes clamp (v1 = -Vdc sign i1, energy back to the DC bus); V2 = 0;
* rect: V1 = 0; a diode rectifier into the battery clamp (v2 = Vc sign i2, Vc = VL + Vf = 33.5 V);
* both: the two clamps.

Prints |i2|'s peak per 50 us and |i1| at 100 and 400 us. Then the gated SBAR (the project's switching model,
:class:`wpt_receiver.switching.SwitchingLink`, event-exact, ideal devices, Vdc = 1 nV, the battery clamp 33.5 V): the
short window of d T per half period centred on the i2 fundamental's peak (the controller's clock), d = 0, 0.59 (the
policy's duty at most of the gust example's switch-offs), 0.8, 0.97 (~ a full short), peak |i2| over 400 us. Measured 2026-11-28: free 16.95 19.83 17.32 ... A (the
beat, a full transfer in 1/(2 k f) = 79 us); inv 10.5 A falling; rect <= 0.03 A (the emf w Lm I1 = 15.6 V is
below the clamp: the rectifier blocks, I1 decays in R1); both <= 0.02 A. Gated SBAR (2026-11-28, re-run): d = 0
0.00 A (blocks; I1 5.86 -> 5.36 A at 400 us), d = 0.59 9.39 A, d = 0.8 17.30 A, d = 0.97 19.82 A (= the free
case): a short window lets the beat through; only d = 0 (the protection, ``sim.rectify_after_pad_off``) blocks it.

    python benchmarks/diag_pad_switch_off.py
"""
import math

import numpy as np
from scipy.integrate import solve_ivp

L1, L2, R1, R2, F = 236e-6, 18.9e-6, 0.108, 0.0325, 85e3
W = 2 * math.pi * F
C1, C2 = 1 / (W * W * L1), 1 / (W * W * L2)
K, VDC, VC, EPS = 0.0747, 30.0, 33.5, 0.05
LM = K * math.sqrt(L1 * L2)
MINV = np.linalg.inv(np.array([[L1, LM], [LM, L2]]))


def rhs(t, x, mode):
    i1, i2, q1, q2 = x
    v1 = -VDC * np.tanh(i1 / EPS) if mode in ("inv", "both") else 0.0
    v2 = VC * np.tanh(i2 / EPS) if mode in ("rect", "both") else 0.0
    di = MINV @ np.array([v1 - R1 * i1 - q1 / C1, -v2 - R2 * i2 - q2 / C2])
    return [di[0], di[1], i1, i2]


def main():
    for mode in ("free", "inv", "rect", "both"):
        sol = solve_ivp(rhs, (0, 400e-6), [5.86, 0.0, 0.0, 0.0], args=(mode,), max_step=1 / (F * 200), rtol=1e-8,
                        atol=1e-10)
        t, i1, i2 = sol.t, sol.y[0], sol.y[1]

        def env(x, a, b):
            return np.abs(x[(t >= a) & (t < b)]).max()
        print(f"{mode:5s} |i2| peak per 50 us [A]:", " ".join(f"{env(i2, a, a + 50e-6):5.2f}" for a in np.arange(0, 400e-6, 50e-6)),
              f"| |i1| at 100 us {env(i1, 90e-6, 110e-6):.2f} A, at 400 us {env(i1, 380e-6, 400e-6):.2f} A")
    from wpt_receiver.params import LinkParams
    from wpt_receiver.switching.link import SwitchingLink
    sl = SwitchingLink(LinkParams(l1_h=L1, l2_h=L2, lm_h=LM, r1_ohm=R1, r2_ohm=R2, vdc_v=1e-9, vl_v=VC, f_hz=F))
    for d in (0.0, 0.59, 0.8, 0.97):
        env = sl.run(sl.schedule(0.0, 400e-6, d), sl.cir.phasor_state(5.86, 0.0)).envelope()
        print(f"gated SBAR d = {d:4.2f}: peak |i2| {env.i2_env_a.max():5.2f} A, |i1| at 400 us "
              f"{env.i1_env_a.dropna().iloc[-1]:.2f} A")
    print(f"quarter beat 1/(2 k f) = {1e6 / (2 * K * F):.1f} us; primary energy {0.5 * L1 * 5.86 ** 2 * 1e3:.2f} mJ, all of it "
          f"in L2: {5.86 * math.sqrt(L1 / L2):.1f} A")


if __name__ == "__main__":
    main()
