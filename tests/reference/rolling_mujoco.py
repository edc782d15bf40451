"""Independent peer of shakeflow's rolling model: the caster cart as a MuJoCo multibody with real
wheel-floor contacts, on the same floor records.

The cart is built from bodies and joints, not from shakeflow's equations: a platform on a free
joint (its centre of mass at axle height), per caster a swivel hinge at the platform corner
(order (+a,+b), (-a,+b), (-a,-b), (+a,-b)) carrying a wheel on a spin hinge, its centre a trail
`d` behind the swivel axis. Each wheel touches the floor with a sphere of the wheel's radius
(one contact point under the centre; the spin hinge lets it roll only along its heading, so
sideways motion must slide against the contact friction) and carries a uniform cylinder's inertia.
No-slip rolling comes from a high contact friction (mu = 2, elliptic cone, impratio 100) and
MuJoCo's no-slip solver. The floor only translates, so it is driven exactly by setting gravity to
(-ax, -ay, -g) at every step (a moving mocap floor would carry no velocity into the friction).

Friction: MuJoCo's joint friction is Coulomb (velocity-independent, exact stick), so the cart
gets Coulomb friction: rolling resistance as a spin-joint friction torque mu_roll N r (a force
mu_roll N at the wheel centre), swivel friction as a swivel-joint torque mu_sw N rho, with
N = (m_w + m_p/4) g. mu_roll and mu_sw are the means of Table 4's static and kinetic values.

Usage: rolling_mujoco.py --floor FLOOR.csv --units PS1,MC2 [--timestep S] [--t-end S] [--every K] --out OUT.json
OUT.json: per unit, the parameters, the peak displacement and yaw over all samples, and the state
at every K-th sample (rounded to 0.1 µm / 0.1 µrad).
"""
import argparse
import json
import time

import mujoco
import numpy as np

G = 9.80665
PIVOT_SIGNS = [(1, 1), (-1, 1), (-1, -1), (1, -1)]
# Table 4 (SEED-SUMMARY.md): 2a, 2b, m_p, yaw0, D, e_w, m_w, steer0, mu_s roll, mu_s swivel,
# mu_k roll, mu_k swivel.
TABLE4 = {
    "PS1": (2.20, 1.00, 234, 6, 0.20, 0.045, 1.0, [80, 0, 0, 80], 0.045, 0.00049, 0.00049, 2.45e-5),
    "PB2": (2.36, 1.05, 350, 8, 0.20, 0.055, 1.5, [-35, 0, 0, 35], 0.012, 0.00132, 6.0e-4, 1.2e-4),
    "MC2": (0.65, 0.90, 154, 15, 0.125, 0.030, 0.5, [0, 0, 0, 0], 0.044, 0.044, 0.0044, 0.0044),
    "UI3": (0.70, 0.55, 180, 0, 0.15, 0.030, 0.5, [0, 0, 0, 0], 0.025, 0.001, 0.001, 5.0e-5),
}
SWIVEL_ARM_M = 0.02


def unit_spec(unit):
    l, w, mp, yaw, dw, ew, mw, steer, msr, mss, mkr, mks = TABLE4[unit]
    mu_roll, mu_swivel = (msr + mkr) / 2, (mss + mks) / 2
    return {
        "length_m": l, "width_m": w, "platform_mass_kg": mp, "yaw0_deg": yaw, "wheel_diameter_m": dw,
        "wheel_width_m": ew, "wheel_mass_kg": mw, "steer0_deg": steer, "mu_s_roll": mu_roll, "mu_k_roll": mu_roll,
        "mu_s_swivel": mu_swivel, "mu_k_swivel": mu_swivel, "beta_spm": 0.0, "gamma_n": 0.0, "p": 1.0,
        "trail_m": max(0.3 * dw, 0.005), "swivel_arm_m": SWIVEL_ARM_M,
    }


def model_xml(spec, timestep):
    a, b = spec["length_m"] / 2, spec["width_m"] / 2
    r, half_width = spec["wheel_diameter_m"] / 2, spec["wheel_width_m"] / 2
    mp, mw, d = spec["platform_mass_kg"], spec["wheel_mass_kg"], spec["trail_m"]
    normal = (mw + mp / 4) * G
    izz = mp * (a * a + b * b) / 3
    i_axle, i_diam = mw * r * r / 2, mw * (3 * r * r + (2 * half_width) ** 2) / 12
    casters = []
    for i, (sx, sy) in enumerate(PIVOT_SIGNS):
        casters.append(f"""
      <body name="fork{i}" pos="{sx * a} {sy * b} 0">
        <joint name="swivel{i}" type="hinge" axis="0 0 1" frictionloss="{spec['mu_s_swivel'] * normal * SWIVEL_ARM_M}"/>
        <inertial pos="0 0 0" mass="1e-6" diaginertia="1e-9 1e-9 1e-9"/>
        <body name="wheel{i}" pos="{-d} 0 0">
          <joint name="spin{i}" type="hinge" axis="0 1 0" frictionloss="{spec['mu_s_roll'] * normal * r}"/>
          <inertial pos="0 0 0" mass="{mw}" diaginertia="{i_diam} {i_axle} {i_diam}"/>
          <geom type="sphere" size="{r}" mass="0" friction="2 0 0" condim="3"/>
        </body>
      </body>""")
    return f"""
<mujoco>
  <option timestep="{timestep}" integrator="implicitfast" cone="elliptic" impratio="100" noslip_iterations="30"
          gravity="0 0 {-G}"/>
  <worldbody>
    <geom type="plane" size="100 100 0.1" friction="2 0 0"/>
    <body name="platform" pos="0 0 {r}">
      <freejoint/>
      <inertial pos="0 0 0" mass="{mp}" diaginertia="{izz / 2} {izz / 2} {izz}"/>{''.join(casters)}
    </body>
  </worldbody>
</mujoco>"""


def simulate(spec, floor, timestep, t_end):
    model = mujoco.MjModel.from_xml_string(model_xml(spec, timestep))
    data = mujoco.MjData(model)
    yaw0 = np.radians(spec["yaw0_deg"])
    data.qpos[3:7] = [np.cos(yaw0 / 2), 0, 0, np.sin(yaw0 / 2)]
    swivels = [model.joint(f"swivel{i}").qposadr[0] for i in range(4)]
    for adr, steer in zip(swivels, spec["steer0_deg"]):
        data.qpos[adr] = np.radians(steer)
    # Let the wheels settle onto the floor (no horizontal load), then start from rest there.
    for _ in range(int(0.2 / timestep)):
        mujoco.mj_step(model, data)
    data.qvel[:] = 0
    x0, y0 = data.qpos[0], data.qpos[1]
    keep = floor[:, 0] <= floor[0, 0] + t_end + 1e-9
    time_s, ax, ay = floor[keep, 0], floor[keep, 1], floor[keep, 2]
    substeps = int(round((time_s[1] - time_s[0]) / timestep))
    out = {"x_m": [], "y_m": [], "yaw_rad": [], "delta_rad": [[] for _ in range(4)]}
    yaw_prev = yaw0

    def record():
        nonlocal yaw_prev
        w, qx, qy, qz = data.qpos[3:7]
        yaw = np.arctan2(2 * (w * qz + qx * qy), 1 - 2 * (qy * qy + qz * qz))
        yaw = yaw_prev + (yaw - yaw_prev + np.pi) % (2 * np.pi) - np.pi
        yaw_prev = yaw
        out["x_m"].append(data.qpos[0] - x0)
        out["y_m"].append(data.qpos[1] - y0)
        out["yaw_rad"].append(yaw)
        for i, adr in enumerate(swivels):
            out["delta_rad"][i].append(data.qpos[adr])

    record()
    for k in range(len(time_s) - 1):
        for s in range(substeps):
            f = (s + 0.5) / substeps
            model.opt.gravity[:] = [-(ax[k] + f * (ax[k + 1] - ax[k])), -(ay[k] + f * (ay[k + 1] - ay[k])), -G]
            mujoco.mj_step(model, data)
        record()
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--floor", required=True)
    ap.add_argument("--units", required=True)
    ap.add_argument("--timestep", type=float, default=1e-4)
    ap.add_argument("--t-end", type=float, default=float("inf"))
    ap.add_argument("--every", type=int, default=1)
    ap.add_argument("--out", required=True)
    args = ap.parse_args()
    floor = np.loadtxt(args.floor, delimiter=",", skiprows=1)
    result = {"generator": f"tests/reference/rolling_mujoco.py (mujoco {mujoco.__version__}, timestep {args.timestep} s)",
              "floor": args.floor.split("/")[-1], "units": {}}
    for unit in args.units.split(","):
        spec = unit_spec(unit)
        started = time.perf_counter()
        states = simulate(spec, floor, args.timestep, args.t_end)
        wall = time.perf_counter() - started
        x, y, yaw = (np.array(states[k]) for k in ("x_m", "y_m", "yaw_rad"))
        thin = lambda v: np.round(np.asarray(v)[:: args.every], 7).tolist()
        result["units"][unit] = {
            "params": spec,
            "wall_s": wall,
            "peak_displacement_m": float(np.hypot(x, y).max()),
            "peak_yaw_rad": float(np.abs(yaw - yaw[0]).max()),
            "sample": list(range(0, len(x), args.every)),
            "x_m": thin(x),
            "y_m": thin(y),
            "yaw_rad": thin(yaw),
            "delta_rad": [thin(d) for d in states["delta_rad"]],
        }
    with open(args.out, "w") as f:
        json.dump(result, f)


if __name__ == "__main__":
    main()
