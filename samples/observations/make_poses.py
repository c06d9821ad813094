#!/usr/bin/env python3
"""Writes the pose files (no measured columns) of the sample data sets.
Deterministic (fixed seeds); run from this directory: python3 make_poses.py"""
import random

# Paper C Table 3: the 19 measurement configurations (deg).
CONFIGS = [
    (-148, -44, -140, 83, 32, -112), (31, 27, -18, -2, 81, 79), (30, 25, -14, 180, -80, -116),
    (-154, -39, -148, 75, 27, -121), (28, 28, -23, 0, 85, 60), (24, 21, -12, 180, -81, -154),
    (-6, 0, 15, 0, 77, 16), (-5, 0, 17, 180, -74, 203), (174, -23, -168, -180, 79, 397),
    (-20, -5, 28, 137, 30, -3), (-23, -4, 28, -45, -33, -178), (-6, -1, 17, 0, 74, 393),
    (-5, -1, 18, 180, -74, -158), (173, -23, -168, 180, 80, 24), (-40, 7, 16, 114, 45, 15),
    (-40, 7, 15, -66, -45, -175), (140, -30, -163, -75, 42, 29), (-32, 13, -2, 0, 79, 24),
    (-31, 11, 4, 180, -75, -156),
]
# Paper C Table 2: wrench point Jw and measurement points JM1..JM5 (flange frame, mm).
JW = (-14.14, -14.05, 34.87)
JM = [(-20.74, 21.66, 35.11), (-0.68, 29.91, 35.1), (21.55, 20.68, 35.13),
      (29.88, -0.57, 35.12), (21.58, 20.77, 35.14)]


def stiffness_poses():
    rng = random.Random(1600)
    out = ["# IRB 1600 LDBB-style compliance poses: Paper C Table 3 configurations,",
           "# Table 2 points; per configuration one unloaded and two loaded states",
           "id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,mp_x_mm,mp_y_mm,mp_z_mm,"
           "wp_x_mm,wp_y_mm,wp_z_mm,fx_n,fy_n,fz_n"]
    for c, q in enumerate(CONFIGS, 1):
        loads = [(0.0, 0.0, 0.0)]
        for _ in range(2):
            while True:
                v = [rng.gauss(0, 1) for _ in range(3)]
                n = sum(x * x for x in v) ** 0.5
                if n > 0.3:
                    break
            mag = rng.uniform(310.0, 360.0)
            loads.append(tuple(round(mag * x / n, 1) for x in v))
        for li, f in enumerate(loads):
            for k, mp in enumerate(JM, 1):
                qs = ",".join(str(x) for x in q)
                out.append(f"C{c}-L{li}-M{k},{qs},{mp[0]},{mp[1]},{mp[2]},"
                           f"{JW[0]},{JW[1]},{JW[2]},{f[0]},{f[1]},{f[2]}")
    return out


LIMITS = [(-170, 170), (-80, 130), (-200, 55), (-180, 180), (-110, 110), (-300, 300)]


def kinematic_poses(n=60, seed=71, q1=None):
    rng = random.Random(seed)
    out = ["# IRB 1600 kinematic calibration poses (random within the joint limits, no load)",
           "id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg"]
    for i in range(1, n + 1):
        q = [round(rng.uniform(lo, hi), 3) for lo, hi in LIMITS]
        if q1 is not None:
            q[0] = q1
        out.append(f"K{i}," + ",".join(str(x) for x in q))
    return out


def geometry_poses(n=160, seed=230):
    rng = random.Random(seed)
    gx = [0, 200, 400, 600, 800, 1000]
    gy = [0, 100, 200, 300, 400, 500]
    gz = [0, 100, 200, 300, 400, 500]
    out = ["# AFM R-1000 volumetric check: grid targets, random approach directions",
           "id,X_mm,Y_mm,Z_mm,dirX,dirY,dirZ,tool_mm"]
    for i in range(1, n + 1):
        d = [rng.choice((1, -1)) for _ in range(3)]
        out.append(f"G{i},{rng.choice(gx)},{rng.choice(gy)},{rng.choice(gz)},"
                   f"{d[0]},{d[1]},{d[2]},100")
    return out


# Paper B measured mean motor powers of the IRB 1600 (W) at TCP speeds
# 300/750/1200/1350 mm/s, plus 0 W (cold).
P_J1 = [0, 22, 60, 115, 126]
P_J2 = [0, 18, 52, 94, 112]
P_J3 = [0, 9, 20, 35, 38]


def thermal_poses(n=40, states=3, seed=1860):
    """Each pose measured after warming up at `states` power combinations,
    each joint's level drawn independently from the Paper B levels."""
    rng = random.Random(seed)
    out = ["# IRB 1600 thermal: poses at the steady state of Paper B power levels",
           "id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,p1_w,p2_w,p3_w"]
    for i in range(1, n + 1):
        q = [round(rng.uniform(lo, hi), 3) for lo, hi in LIMITS]
        for s in range(states):
            p = [rng.choice(P_J1), rng.choice(P_J2), rng.choice(P_J3)]
            out.append(f"T{i}.{s + 1}," + ",".join(str(x) for x in q + p))
    return out


if __name__ == "__main__":
    for name, lines in [("irb1600-ldbb-poses.csv", stiffness_poses()),
                        ("irb1600-kinematic-poses.csv", kinematic_poses()),
                        ("irb1600-q1fixed-poses.csv", kinematic_poses(40, 72, q1=0.0)),
                        ("afm-r1000-grid-poses.csv", geometry_poses()),
                        ("irb1600-thermal-poses.csv", thermal_poses())]:
        with open(name, "w") as f:
            f.write("\n".join(lines) + "\n")
