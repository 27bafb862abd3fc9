"""A python-control user's session with gainlink, as it would run in a notebook.

The user has a plant in python-control, computes their own gains (LQI by augmentation with
``control.dlqr``, a Kalman predictor with ``control.dlqe``), hands them to gainlink, checks margins
and the step response in python-control, and replays a record through the C loop.

Run it: ``python examples/notebook_style.py`` (the tests run it as it is).
"""

import control as ct
import gainlink as gl
import numpy as np

# The seed's cart pendulum, linearised about upright (M = 1 kg, m = 0.1 kg, l = 0.5 m).
plant = ct.ss(
    [[0, 1, 0, 0], [0, 0, -0.981, 0], [0, 0, 0, 1], [0, 0, 21.582, 0]],
    [[0], [1], [0], [-2]],
    [[1, 0, 0, 0], [0, 0, 1, 0]],
    [[0], [0]],
    states=["x", "x_dot", "theta", "theta_dot"],
    inputs=["F"],
    outputs=["x", "theta"],
)
Ts = 0.01
plant_d = ct.c2d(plant, Ts)

# LQI: integrate the cart-position error, z+ = z + Ts (r - x), and weight it like the states.
Ci = np.array([[1.0, 0.0]])
Aa = np.block([[plant_d.A, np.zeros((4, 1))], [-Ts * Ci @ plant_d.C, np.eye(1)]])
Ba = np.vstack([plant_d.B, np.zeros((1, 1))])
Ka, _, _ = ct.dlqr(Aa, Ba, np.diag([10.0, 1.0, 100.0, 1.0, 5.0]), np.eye(1))
K, Ki = Ka[:, :4], Ka[:, 4:]

# Kalman predictor: noise on the velocities, ~1 mm / 1 mrad sensors.
L, _, _ = ct.dlqe(plant_d.A, np.eye(4), plant_d.C, np.diag([1e-6, 1e-4, 1e-6, 1e-4]), np.diag([1e-6, 1e-6]))

art = gl.from_gains(plant_d, K=K, Ki=Ki, Ci=Ci, L=L, u_min=[-20.0], u_max=[20.0], name="my_pendulum")
print(f"artifact {art.name}: sha256 {art.sha256[:16]}, gains {art.provenance['gains']}")

# Margins at the actuator, in python-control: the loop broken at the plant input.
ctrl = art.controller()
loop = -ctrl[["F"], ["x", "theta"]] * plant_d
w = np.logspace(-2, np.log10(np.pi / Ts), 5000)
gm, pm, wcg, wcp = ct.margin(ct.frd(loop, w))
print(
    f"python-control: phase margin {pm:.1f} deg at {wcp:.2f} rad/s; "
    f"gainlink design check: {art.checks['margins'][0]['phase_margin_deg']:.1f} deg"
)

# Closed-loop step of the cart-position reference.
cl = art.closed_loop()
step = ct.step_response(cl[["x"], ["r_x"]], T=15.0)
print(f"step in r_x: x settles at {step.outputs[-1]:.4f}")

# A record of the loop, replayed through the host C build (float32) and the float64 reference.
sim = gl.simulate(art, steps=600, x0=[0.0, 0.0, 0.05, 0.0], reference=[0.5], noise_std=1e-3, seed=1)
native = gl.replay(art, sim.y, sim.r, engine="native")
reference = gl.replay(art, sim.y, sim.r, engine="reference")
print(
    f"C loop vs float64 law on the first 50 steps: max |du| = {np.max(np.abs(native.u[:50] - reference.u[:50])):.2e} N"
)
