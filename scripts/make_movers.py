#!/usr/bin/env python3
"""Writes the project's mover set (issue 41, DESIGN §18): open ground, sim/movers/*.csv, and
the sites, sim/movers/sites/<site>/*.csv (below).

    python3 scripts/make_movers.py sim/movers

Open ground is the paper's 128: every start at the origin, heading 0°, the goals on
eight rays (0°, 45°, …) at 4.5 m and 9 m. A movers file applies to every scenario, so
each file puts its mover on every ray, timed to meet a machine that leaves the origin at
once (its leading axle about 5 m along its ray after 5.5 s). Every mover appears where no
machine can be within its stopping distance then (a person who appears beside a moving
machine gives no warning at all; perception has to see that far):

- person-crossing-w{1,2,4}: a person (r 0.3 m) crossing at 1.4 m/s, across the ray's
  direction u, the point c = a + 5u, 5 m out from the start a of the machine's leading
  axle; seen w seconds before it reaches c, walking on out of sight; it reaches c at 4 s,
  about 1.5 s before the leading axle on its nominal schedule would (a person who steps
  into a machine already there cannot be avoided by stopping: from 1 m/s the stop takes
  1 s and 0.5 m after the perception's latency). The leading axle is the rear one,
  a = the origin − (l_f + l_r)·(cos θ0, sin θ0) = (−1.2, 0), on the rays behind the start
  (135°, 180°, 225°: more than 90° from the start's heading), where the machine reverses
  towards its goal, rear axle first (without movers, 12, 14 and 10 of their 16 goals
  reverse at 0.67–1 m/s through 2–5 s; the others turn round and drive forward, a longer
  way that meets the person later); it is the front one, a = the origin (c on the ray),
  elsewhere (on 90° and 270°, where 6 and 5 goals reverse, the rear axle starts farther
  from c than the front one). So a reversing machine's rear axle gets the warning a
  forward machine's front axle gets: the person's path and timing relative to the
  leading axle are those of a forward ray, translated by a (on 180° c is on the ray, 6.2 m
  out; on 135° and 225° the path is 0.85 m off the ray through the origin, c 5.85 m out
  along it). By the sites' appearance test (below), the w1 person now clears every axle's
  reach by 0.08–0.12 m more than its stopping distance on every ray; with c 5 m out on
  every ray, as before, it did not on 135°, 180° and 225° (by 0.48, 1.07 and 0.80 m): the
  reversing rear axle met the person on 180° 0.3 s after it reached the ray
  (docs/movers.md, section 4.1);
- truck-reversing: a truck (r 1.2 m) reversing at 1 m/s onto each ray 6 m out, parked
  there for 10 s, then driving off;
- person-standing: a person standing on each ray 3 m out from the start for 6 s, then
  walking off sideways;
- crowd128: the set's capacity of 128 movers, for the tick's time (crowd's docstring);
- machine-crossing: four machines (r 1.5 m) at 3 m/s along the sides of a 10 m square
  round the origin, which crosses every ray beyond the 4.5 m goals.

Columns: id,radius,t0,x0,y0,vx,vy,t1 (a circle of `radius` appears at t0 at (x0, y0),
moves at (vx, vy) and vanishes at t1).

Sites (issue 41 on the sites of issue 40): sim/movers/sites/<site>/*.csv, the same four
kinds for quarry, yard, lane and large-pit-40, placed from the site's goal set
(sim/scenarios/site-<site>.csv) and its features (sim/sites/<site>.json) by one rule, not by
hand. A site's scenarios start in many places, and every scenario of a run gets every mover
of the file, so each file holds one mover (the truck: its three rows) per scenario whose
placement passes every test below; a placement that fails one is skipped, not moved (so
a cramped site, the lane, gets few movers: there is no free room beside its way for a
truck, a crossing machine or a person 5.6 m to the side).

For scenario i, start s (front axle), goal g, u the unit vector s → g, L = |g − s|, n = u
turned left (right when the left side fails):

- person-crossing-w{1,2,4}: as on an open-ground ray ahead of the start: the crossing
  point c = s + 5u from the front axle (L ≥ 6.5 m), reached at 4 s at 1.4 m/s across u,
  appearing 1.4·w m before c at t0 = 4 − w, walking on for 6 s (a scenario whose machine
  reverses rear axle first is covered by the appearance test below, which bounds each
  axle's reach: a placement inside the rear axle's stopping distance is skipped);
- truck-reversing (r 1.2 m): parked at p = s + 6u (L ≥ 4.5 m) from 5 s to 15 s, reversing in
  at 1 m/s from p − 5n over 0–5 s, driving off along +n over 15–25 s (back along −n if
  that side is not free);
- person-standing: at s + 3u (L ≥ 4.5 m) for 6 s, then walking off along n at 1.4 m/s
  for 6 s;
- machine-crossing (r 1.5 m, 3 m/s): crossing at c = s + 7u (L ≥ 8.5 m) at 5 s, from 15 m
  to the side at t0 = 0, driving on to 12 s; where its way before c is blocked (a feature,
  a machine at rest), it appears after the last block, at least 6 m (2 s) before c.

Tests (constants below):

- free space: along its whole path (sampled every 0.25 m), a mover's disc stays inside the
  site's bounds and 0.3 m clear of every feature and keep-out; a person or machine that
  would walk into one vanishes just before it (it goes out of sight) — the part up to the
  meeting point (c, p) must be free, else the other side is tried, else the placement is
  skipped;
- rest poses: its path stays 0.5 m clear of the machine's outline (axle discs, r 0.65 m)
  at every scenario's goal and at every start but its own scenario's (a machine at rest
  cannot step aside); where it would come closer after the meeting point, it vanishes;
- appearance: when it appears (t0), it is clear of every machine of the set by the
  machine's stopping distance. Each axle of scenario j's machine can be at most
  R(t0) = t0²/2 (t0 ≤ 1 s), t0 − 0.5 (after) from where it started (a_max = v_max = 1),
  so the mover's disc must be ≥ d(v) + C_stop + u_c·T from each axle's disc grown by
  R(t0): v = min(1, t0) the speed reachable then, T = 0.45 s (perception latency 0.1 + one
  tick 0.2 + the envelope's response lag 0.15), d(v) = v·T + v²/2 the stop (0.95 m from
  1 m/s), C_stop = 0.5 m, u_c the mover's speed towards that axle's start (what it closes
  before the brake acts; walking on into a braking machine is what no stop avoids). This
  is the open-ground files' reasoning made a test, with the reach bound instead of the
  nominal schedule (on which a machine is then about 1.5 s short of the crossing). The
  1 s warning is the tight case by design: the protective field (about 2.5 m at 1 m/s:
  the stop, C_stop and the prediction's growth σ_u) is entered at once and the machine
  stops, it does not reach the person;
- crowding: a mover must stay 1 m clear of every mover already placed in the file at
  every common instant (the scenarios of a loading cycle share their segments).
"""

import csv
import json
import math
import os
import sys

HEADER = "id,radius,t0,x0,y0,vx,vy,t1"
RAYS = [k * math.pi / 4 for k in range(8)]


def fmt(v):
    return f"{v:.6g}"


def row(mid, r, t0, x, y, vx, vy, t1):
    return ",".join([str(mid)] + [fmt(v) for v in (r, t0, x, y, vx, vy, t1)])


OPEN_THETA0 = 0.0  # the paper's 128 all start at the origin heading 0


def leading_axle(a):
    """The start of the axle that leads towards a goal on the ray of bearing a from the
    origin (open ground): the rear axle on the rays behind the start (more than 90° from
    its heading: the machine reverses), else the front axle (the origin)."""
    hx, hy = math.cos(OPEN_THETA0), math.sin(OPEN_THETA0)
    if math.cos(a) * hx + math.sin(a) * hy < -1e-9:
        return -L_WHEELBASE * hx, -L_WHEELBASE * hy  # l_f + l_r (the sites' constants, below)
    return 0.0, 0.0


def crossing(warning, lead=True):
    """Each ray's crossing person, 5 m out from the leading axle's start (the docstring);
    lead=False: 5 m out from the origin on every ray (the crowd's persons, as first written)."""
    rows = []
    for k, a in enumerate(RAYS):
        ax, ay = leading_axle(a) if lead else (0.0, 0.0)
        px, py = ax + 5.0 * math.cos(a), ay + 5.0 * math.sin(a)
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


# ---- sites -----------------------------------------------------------------------------

SITES = ["quarry", "yard", "lane", "large-pit-40"]
FEATURE_MARGIN = 0.3   # a mover's disc keeps this clear of features and bounds [m]
REST_MARGIN = 0.5      # ... and of a machine at rest at a start or goal
MOVER_GAP = 1.0        # ... and of the file's other movers
AXLE_R = 0.65          # the default outline's axle discs
L_WHEELBASE = 1.2      # l_f + l_r
T_RESP = 0.45          # perception latency + one tick + response lag [s]
C_STOP = 0.5
STEP = 0.25            # path sampling [m]


def reach(t):
    """How far an axle can be from its start at t (from rest, a_max = v_max = 1)."""
    return t * t / 2 if t <= 1 else t - 0.5


def seg_dist(p, a, b):
    ax, ay = b[0] - a[0], b[1] - a[1]
    l2 = ax * ax + ay * ay
    s = 0.0 if l2 == 0 else max(0.0, min(1.0, ((p[0] - a[0]) * ax + (p[1] - a[1]) * ay) / l2))
    return math.hypot(p[0] - a[0] - s * ax, p[1] - a[1] - s * ay)


def inside(p, ring):
    c = False
    for i in range(len(ring)):
        a, b = ring[i], ring[i - 1]
        if (a[1] > p[1]) != (b[1] > p[1]):
            x = a[0] + (p[1] - a[1]) * (b[0] - a[0]) / (b[1] - a[1])
            if p[0] < x:
                c = not c
    return c


def ring_dist(p, ring):
    return min(seg_dist(p, ring[i - 1], ring[i]) for i in range(len(ring)))


class Site:
    def __init__(self, path):
        d = json.load(open(path))
        self.bounds = d["bounds"]
        self.features = []  # (kind, data, bbox)
        for o in d["obstacles"] + d.get("keepout", []):
            if "circle" in o:
                x, y, r = o["circle"]
                self.features.append(("c", (x, y, r), (x - r, y - r, x + r, y + r)))
            elif "polygon" in o:
                ring = o["polygon"]
                xs, ys = [v[0] for v in ring], [v[1] for v in ring]
                self.features.append(("p", ring, (min(xs), min(ys), max(xs), max(ys))))
            else:
                line, w = o["polyline"], o["width"] / 2
                xs, ys = [v[0] for v in line], [v[1] for v in line]
                self.features.append(("l", (line, w), (min(xs) - w, min(ys) - w, max(xs) + w, max(ys) + w)))

    def free(self, p, r):
        """The disc (p, r + FEATURE_MARGIN) inside the bounds and off every feature."""
        m = r + FEATURE_MARGIN
        if not inside(p, self.bounds) or ring_dist(p, self.bounds) < m:
            return False
        for kind, f, (x0, y0, x1, y1) in self.features:
            if p[0] < x0 - m or p[0] > x1 + m or p[1] < y0 - m or p[1] > y1 + m:
                continue
            if kind == "c":
                if math.hypot(p[0] - f[0], p[1] - f[1]) - f[2] < m:
                    return False
            elif kind == "p":
                if inside(p, f) or ring_dist(p, f) < m:
                    return False
            else:
                line, w = f
                if min(seg_dist(p, line[i - 1], line[i]) for i in range(1, len(line))) - w < m:
                    return False
        return True


class Mover:
    """One row: (id, r, t0, start, velocity, t1)."""

    def __init__(self, mid, r, t0, p, v, t1):
        self.id, self.r, self.t0, self.p, self.v, self.t1 = mid, r, t0, p, v, t1

    def at(self, t):
        s = t - self.t0
        return (self.p[0] + self.v[0] * s, self.p[1] + self.v[1] * s)

    def samples(self):
        speed = math.hypot(*self.v)
        n = 1 if speed == 0 else max(1, math.ceil(speed * (self.t1 - self.t0) / STEP))
        return [(self.t0 + (self.t1 - self.t0) * k / n, self.at(self.t0 + (self.t1 - self.t0) * k / n))
                for k in range(n + 1)]

    def row(self):
        return row(self.id, self.r, self.t0, self.p[0], self.p[1], self.v[0], self.v[1], self.t1)


def axles(x, y, th):
    return [(x, y), (x - L_WHEELBASE * math.cos(th), y - L_WHEELBASE * math.sin(th))]


class Placer:
    """The tests of the docstring for one site and one file."""

    def __init__(self, site, scenarios):
        self.site = site
        self.sc = scenarios
        self.placed = []

    def blocked(self, t, p, r, own):
        """Why the disc (p, r) at t is not allowed on a mover's path (None: it is)."""
        if not self.site.free(p, r):
            return "feature"
        for j, s in enumerate(self.sc):
            poses = [(s["x_goal"], s["y_goal"], s["theta_goal"])]
            if j != own:
                poses.append((s["x0"], s["y0"], s["theta0"]))
            for pose in poses:
                for q in axles(*pose):
                    if math.hypot(p[0] - q[0], p[1] - q[1]) < r + AXLE_R + REST_MARGIN:
                        return "rest"
        for o in self.placed:
            if o.t0 <= t < o.t1:
                q = o.at(t)
                if math.hypot(p[0] - q[0], p[1] - q[1]) < r + o.r + MOVER_GAP:
                    return "crowd"
        return None

    def truncate(self, m, t_meet, own):
        """The mover cut where its path is first blocked after t_meet (it goes out of
        sight); None if it is blocked up to t_meet."""
        for t, p in m.samples():
            why = self.blocked(t, p, m.r, own)
            if why:
                if t <= t_meet + 1e-9:
                    return None
                t1 = max(t_meet, t - STEP / max(1e-9, math.hypot(*m.v)))
                # Too short a leg to be one (a walk blocked as it starts): none.
                return Mover(m.id, m.r, m.t0, m.p, m.v, t1) if t1 >= m.t0 + 0.1 else None
        return m

    def ok(self, legs, own):
        # Appearance: the first leg appears; the later legs continue it (seen all along).
        m = legs[0]
        v = min(1.0, m.t0)
        d = v * T_RESP + v * v / 2
        for s in self.sc:
            for q in axles(s["x0"], s["y0"], s["theta0"]):
                dx, dy = q[0] - m.p[0], q[1] - m.p[1]
                dist = math.hypot(dx, dy)
                u_c = max(0.0, (m.v[0] * dx + m.v[1] * dy) / dist) if dist > 0 else math.hypot(*m.v)
                need = d + C_STOP + u_c * T_RESP
                if dist - AXLE_R - reach(m.t0) - m.r < need:
                    return False
        return True

    def place(self, candidates, own):
        """The first candidate (a list of legs, or a function giving them, per side) that
        passes; placed and returned, or None."""
        for legs in candidates:
            if legs is None:
                continue
            if self.ok(legs, own):
                self.placed.extend(legs)
                return legs
        return None


def load_scenarios(path):
    out = []
    for r in csv.DictReader(open(path)):
        out.append({k: (r[k] if k in ("name", "obstacles") else float(r[k])) for k in r})
    return out


def frame(s):
    dx, dy = s["x_goal"] - s["x0"], s["y_goal"] - s["y0"]
    L = math.hypot(dx, dy)
    u = (dx / L, dy / L)
    return (s["x0"], s["y0"]), u, (-u[1], u[0]), L


def placed(site, scenarios, min_len, along, sides):
    """One file: for each scenario at least `min_len` long, the first candidate that
    passes of those `sides(pl, i, point, nn)` gives for its point `along` its segment and
    each side nn (left first)."""
    pl = Placer(site, scenarios)
    for i, s in enumerate(scenarios):
        o, u, n, L = frame(s)
        if L < min_len:
            continue
        point = (o[0] + along * u[0], o[1] + along * u[1])
        cands = []
        for sgn in (1, -1):
            cands += sides(pl, i, point, (sgn * n[0], sgn * n[1]))
        pl.place(cands, i)
    return pl.placed


def crossing_at(w):
    def sides(pl, i, c, nn):
        t0 = 4.0 - w
        m = Mover(i + 1, 0.3, t0, (c[0] - 1.4 * w * nn[0], c[1] - 1.4 * w * nn[1]),
                  (1.4 * nn[0], 1.4 * nn[1]), t0 + w + 6.0)
        m = pl.truncate(m, 4.0, i)
        return [None if m is None else [m]]
    return sides


def truck_at(pl, i, p, nn):
    legs = [Mover(100 + i, 1.2, 0.0, (p[0] - 5 * nn[0], p[1] - 5 * nn[1]), nn, 5.0),
            Mover(200 + i, 1.2, 5.0, p, (0.0, 0.0), 15.0)]
    if pl.truncate(legs[0], 5.0, i) is not legs[0] or pl.blocked(5.0, p, 1.2, i):
        return [None]
    cands = []
    for off in (nn, (-nn[0], -nn[1])):
        leave = pl.truncate(Mover(300 + i, 1.2, 15.0, p, off, 25.0), 15.0, i)
        if leave is not None:
            cands.append(legs + [leave])
    return cands


def standing_at(pl, i, p, nn):
    stand = Mover(i + 1, 0.3, 0.0, p, (0.0, 0.0), 6.0)
    walk = pl.truncate(Mover(100 + i, 0.3, 6.0, p, (1.4 * nn[0], 1.4 * nn[1]), 12.0), 6.0, i)
    return [None if walk is None or pl.truncate(stand, 6.0, i) is None else [stand, walk]]


def machine_at(pl, i, c, nn):
    m = Mover(i + 1, 1.5, 0.0, (c[0] - 15 * nn[0], c[1] - 15 * nn[1]), (3 * nn[0], 3 * nn[1]), 12.0)
    # Where its way is blocked before the crossing, it appears after the last block (at
    # least 6 m, 2 s, before c); after it, it vanishes.
    pts = m.samples()
    first = 0
    for k, (t, p) in enumerate(pts):
        if t > 5.0:
            break
        if pl.blocked(t, p, m.r, i):
            first = k + 1
    if first >= len(pts) or pts[first][0] > 3.0:
        return [None]
    m = pl.truncate(Mover(i + 1, 1.5, pts[first][0], pts[first][1], m.v, 12.0), 5.0, i)
    return [None if m is None else [m]]


def site_files(site, scenarios):
    files = {f"person-crossing-w{w}": placed(site, scenarios, 6.5, 5.0, crossing_at(w)) for w in (1, 2, 4)}
    files["truck-reversing"] = placed(site, scenarios, 4.5, 6.0, truck_at)
    files["person-standing"] = placed(site, scenarios, 4.5, 3.0, standing_at)
    files["machine-crossing"] = placed(site, scenarios, 8.5, 7.0, machine_at)
    return files


def crowd():
    """128 movers (the live-obstacle set's capacity), for the tick's time with a full set:
    120 people (r 0.3 m) and vehicles (r 1.2 m) milling about 12-40 m out at up to 1.5 m/s
    for 60 s (seeded), and 8 crossing persons as person-crossing-w2 first had them (5 m out
    from the origin on every ray: the crowd is for the tick's time, kept as measured)."""
    import random

    rnd = random.Random(1)
    rows = []
    for i in range(120):
        r, a = rnd.uniform(12, 40), rnd.uniform(0, 2 * math.pi)
        h, sp = rnd.uniform(0, 2 * math.pi), rnd.uniform(0, 1.5)
        radius = rnd.choice([0.3, 0.3, 0.3, 1.2])
        rows.append(row(i + 1, radius, 0.0, r * math.cos(a), r * math.sin(a), sp * math.cos(h), sp * math.sin(h), 60.0))
    for k, line in enumerate(crossing(2, lead=False)):
        rows.append(f"{200 + k}," + line.split(",", 1)[1])
    return rows


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "sim/movers"
    os.makedirs(out, exist_ok=True)
    files = {f"person-crossing-w{w}": crossing(w) for w in (1, 2, 4)}
    files["truck-reversing"] = truck()
    files["person-standing"] = standing()
    files["machine-crossing"] = machines()
    files["crowd128"] = crowd()
    for name, rows in files.items():
        path = os.path.join(out, name + ".csv")
        with open(path, "w") as f:
            f.write(f"# written by scripts/make_movers.py ({name}); see its docstring\n")
            f.write(HEADER + "\n")
            f.write("\n".join(rows) + "\n")
        print(f"wrote {path} ({len(rows)} movers)")
    root = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
    for name in SITES:
        site = Site(os.path.join(root, "sim/sites", name + ".json"))
        scenarios = load_scenarios(os.path.join(root, "sim/scenarios", f"site-{name}.csv"))
        d = os.path.join(out, "sites", name)
        os.makedirs(d, exist_ok=True)
        for kind, movers in site_files(site, scenarios).items():
            path = os.path.join(d, kind + ".csv")
            with open(path, "w") as f:
                f.write(f"# written by scripts/make_movers.py ({name}, {kind}); see its docstring\n")
                f.write(HEADER + "\n")
                f.write("".join(m.row() + "\n" for m in movers))
            print(f"wrote {path} ({len(movers)} rows)")


if __name__ == "__main__":
    main()
