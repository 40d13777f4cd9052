#!/usr/bin/env python3
"""A run's timeline against its movers, for the analysis in docs/movers.md: reads the
trajectory SVG that `wlnav-sim eval` writes for a scenario (without --no-scenario-plots:
OUT/trajectories/<name>.svg, the MPC's track one point a tick, 0.2 s apart, on pixels
calibrated from the axes' labels), rebuilds the rear axle (it trails the articulation joint
at l_r; the front body's heading is the front axle's direction of travel), and prints each
tick: time, front axle, speed (signed: − reversing), and the nearest mover's clearance to the
default outline (a disc of 0.65 m at each axle), with when each mover appears. Usage:
    python3 scripts/mover_timeline.py SVG SCENARIOS.csv NAME MOVERS.csv [--every K]
Pixel resolution: the plot's metres per pixel (printed); clearances are good to about that
while the machine drives straight. The rear axle is rebuilt as trailing the joint, which is
right driving forward; reversing with the machine articulating, the rear body swings more
than that, and the rear clearance printed is then only indicative (the run's own
min_clearance_moving, from the true state, is the figure).
"""
import csv
import signal
import math
import re
import sys

signal.signal(signal.SIGPIPE, signal.SIG_DFL)  # quiet under head
L_F = L_R = 0.6
R_AXLE = 0.65
DT = 0.2

svg, scen, name, movers_path = sys.argv[1:5]
every = int(sys.argv[sys.argv.index("--every") + 1]) if "--every" in sys.argv else 1
s = open(svg).read()
labels = [(float(x), float(y), float(t)) for x, y, t in
          re.findall(r'<text x="([\d.]+)" y="([\d.]+)"[^>]*>\s*(-?[\d.]+)\s*</text>', s)]
# y-axis labels share one x (left), x-axis labels one y (bottom).
xs_lab = [l for l in labels if l[1] == max(l[1] for l in labels)]
ys_lab = [l for l in labels if l[0] == min(l[0] for l in labels)]


def fit(pairs):
    (p0, v0), (p1, v1) = pairs[0], pairs[-1]
    k = (v1 - v0) / (p1 - p0)
    return lambda p: v0 + (p - p0) * k, abs(k)


fx, kx = fit(sorted((l[0], l[2]) for l in xs_lab))
fy, ky = fit(sorted((l[1], l[2]) for l in ys_lab))
track = max(re.findall(r'<polyline[^>]*stroke="#1F77B4"[^>]*points="([^"]*)"', s), key=len)
pts = [(fx(float(a)), fy(float(b))) for a, b in (p.split(",") for p in track.split())]
sc = next(r for r in csv.DictReader(open(scen)) if r["name"] == name)
th0 = float(sc["theta0"])
movers = [r for r in csv.DictReader(l for l in open(movers_path) if not l.startswith("#"))]
movers = [{k: (int(v) if k == "id" else float(v)) for k, v in m.items()} for m in movers]


def at(m, t):
    if m["t0"] <= t < m["t1"]:
        return (m["x0"] + m["vx"] * (t - m["t0"]), m["y0"] + m["vy"] * (t - m["t0"]))
    return None


print(f"# {name}: {len(pts)} points, {kx:.3f} m/px (x), {ky:.3f} m/px (y)")
# The front body's heading: the direction of travel (or against it, reversing), kept when
# standing; the rear axle trails the joint at l_r (a tractrix), from β = 0 at the start.
th = th0
joint = (pts[0][0] - L_F * math.cos(th), pts[0][1] - L_F * math.sin(th))
rear = (joint[0] - L_R * math.cos(th), joint[1] - L_R * math.sin(th))
appeared = set()
print("t [s] | front axle x, y | v [m/s] | heading [deg] | nearest mover: id, clearance [m] | events")
for k, p in enumerate(pts):
    t = k * DT
    if k > 0:
        d = (p[0] - pts[k - 1][0], p[1] - pts[k - 1][1])
        ds = math.hypot(*d)
        if ds > 0.02:
            a = math.atan2(d[1], d[0])
            fwd = math.cos(a - th) >= 0
            th = a if fwd else a + math.pi
            v = ds / DT if fwd else -ds / DT
        else:
            v = ds / DT
        joint = (p[0] - L_F * math.cos(th), p[1] - L_F * math.sin(th))
        dx, dy = joint[0] - rear[0], joint[1] - rear[1]
        dl = math.hypot(dx, dy)
        rear = (joint[0] - L_R * dx / dl, joint[1] - L_R * dy / dl)
    else:
        v = 0.0
    best = (None, math.inf)
    events = []
    for m in movers:
        c = at(m, t)
        if c is None:
            continue
        if m["id"] not in appeared:
            appeared.add(m["id"])
            events.append(f"mover {m['id']} appears at ({c[0]:.2f}, {c[1]:.2f})")
        for q in (p, rear):
            cl = math.hypot(q[0] - c[0], q[1] - c[1]) - R_AXLE - m["radius"]
            if cl < best[1]:
                best = (m["id"], cl)
    if k % every == 0 or events:
        print(f"{t:5.1f} | {p[0]:7.2f}, {p[1]:7.2f} | {v:+5.2f} | {math.degrees(math.atan2(math.sin(th), math.cos(th))):6.1f} | "
              f"{best[0]}, {best[1]:.2f} | {'; '.join(events)}")
