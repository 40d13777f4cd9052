#!/usr/bin/env python3
"""Writes the project's mover set for open ground (issue 41, DESIGN §18): sim/movers/*.csv.

    python3 scripts/make_movers.py sim/movers

Open ground is the paper's 128: every start at the origin, the goals on eight rays
(0°, 45°, …) at 4.5 m and 9 m. A movers file applies to every scenario, so each file
puts its mover on every ray, timed to meet a machine that leaves the origin at once
(about 5 m along its ray after 5.5 s). Every mover appears where no machine can be
within its stopping distance then (a person who appears beside a moving machine gives
no warning at all; perception has to see that far):

- person-crossing-w{1,2,4}: a person (r 0.3 m) crossing each ray 5 m out at 1.4 m/s,
  seen w seconds before it reaches the ray, walking on out of sight; it reaches the ray
  at 4 s, about 1.5 s before a machine on its nominal schedule would, and 0.3 s before
  the rear of one that reverses there at once (a person who steps into a machine
  already there cannot be avoided by stopping: from 1 m/s the stop takes 1 s and 0.5 m
  after the perception's latency);
- truck-reversing: a truck (r 1.2 m) reversing at 1 m/s onto each ray 6 m out, parked
  there for 10 s, then driving off;
- person-standing: a person standing on each ray 3 m out from the start for 6 s, then
  walking off sideways;
- machine-crossing: four machines (r 1.5 m) at 3 m/s along the sides of a 10 m square
  round the origin, which crosses every ray beyond the 4.5 m goals.

Columns: id,radius,t0,x0,y0,vx,vy,t1 (a circle of `radius` appears at t0 at (x0, y0),
moves at (vx, vy) and vanishes at t1).
"""

import math
import os
import sys

HEADER = "id,radius,t0,x0,y0,vx,vy,t1"
RAYS = [k * math.pi / 4 for k in range(8)]


def fmt(v):
    return f"{v:.6g}"


def row(mid, r, t0, x, y, vx, vy, t1):
    return ",".join([str(mid)] + [fmt(v) for v in (r, t0, x, y, vx, vy, t1)])


def crossing(warning):
    rows = []
    for k, a in enumerate(RAYS):
        px, py = 5.0 * math.cos(a), 5.0 * math.sin(a)
        nx, ny = -math.sin(a), math.cos(a)
        d = 1.4 * warning
        t0 = max(0.0, 4.0 - warning)
        rows.append(row(k + 1, 0.3, t0, px - d * nx, py - d * ny, 1.4 * nx, 1.4 * ny, t0 + warning + 6.0))
    return rows


def truck():
    rows = []
    for k, a in enumerate(RAYS):
        ux, uy = math.cos(a), math.sin(a)
        nx, ny = -math.sin(a), math.cos(a)
        px, py = 6.0 * ux, 6.0 * uy
        # Reversing in from 5 m to the side over 5 s, parked 10 s, off the other way.
        rows.append(row(100 + k, 1.2, 0.0, px - 5 * nx, py - 5 * ny, nx, ny, 5.0))
        rows.append(row(200 + k, 1.2, 5.0, px, py, 0.0, 0.0, 15.0))
        rows.append(row(300 + k, 1.2, 15.0, px, py, nx, ny, 25.0))
    return rows


def standing():
    rows = []
    for k, a in enumerate(RAYS):
        px, py = 3.0 * math.cos(a), 3.0 * math.sin(a)
        nx, ny = -math.sin(a), math.cos(a)
        rows.append(row(k + 1, 0.3, 0.0, px, py, 0.0, 0.0, 6.0))
        rows.append(row(100 + k, 0.3, 6.0, px, py, 1.4 * nx, 1.4 * ny, 12.0))
    return rows


def machines():
    # Sides x = ±5, y = ±5, each driven at 3 m/s, passing its side's middle at 5 s.
    rows = []
    for k, (x, y, vx, vy) in enumerate([(5, -15, 0, 3), (-5, 15, 0, -3), (15, 5, -3, 0), (-15, -5, 3, 0)]):
        rows.append(row(k + 1, 1.5, 0.0, x, y, vx, vy, 12.0))
    return rows


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "sim/movers"
    os.makedirs(out, exist_ok=True)
    files = {f"person-crossing-w{w}": crossing(w) for w in (1, 2, 4)}
    files["truck-reversing"] = truck()
    files["person-standing"] = standing()
    files["machine-crossing"] = machines()
    for name, rows in files.items():
        path = os.path.join(out, name + ".csv")
        with open(path, "w") as f:
            f.write(f"# written by scripts/make_movers.py ({name}); see its docstring\n")
            f.write(HEADER + "\n")
            f.write("\n".join(rows) + "\n")
        print(f"wrote {path} ({len(rows)} movers)")


if __name__ == "__main__":
    main()
