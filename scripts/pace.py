#!/usr/bin/env python3
"""How fast, and which way round, a robot moves in executed runs.

Reads the file `schrl eval --trajectories FILE.jsonl` writes (one run per line, with
`positions` and `headings` at every control step) and prints, over every run:

- net pace: metres per step covered over 50-step windows (the distance between a
  window's first and last positions, divided by 50);
- per step, the displacement along the direction of travel (the net direction over
  the 10 steps around it) and across it (sway);
- how the direction of travel sits against the robot's heading (its yaw), in 30°
  bins: 0–30° is moving nose first, 150–180° tail first;
- how far the robot strays from the straight segment it is driving (from the waypoint
  it last reached, or its start, to the next): the cross-track distance at every step,
  median, 90th and 99th percentile, and the largest of each hop's (one per waypoint
  driven to). A planner's clearance must cover this. And the same by how far along
  its segment the robot is, in 0.5 m bins, over hops of 3 m or more: whether a robot
  strays most after a turn or the farther it walks;
- the first hop by how the robot starts facing it (the angle between its heading and
  the direction to the first waypoint): runs, and how many failed before reaching it
  (a planner that does not see the start heading plans the same first waypoint
  either way);
- where the runs that collided or fell ended: the hop, how many steps after the last
  waypoint reached, and how far from the segment then.

Windows that move less than 5 cm net are left out of the last two (turning on the
spot has no direction of travel). Standard library only.

    python3 scripts/pace.py runs.jsonl
"""

import json
import math
import sys


def main(path):
    runs = [json.loads(line) for line in open(path)]
    net50, along, across, facing, off_segment, hop_max, by_along = [], [], [], [0] * 6, [], [], {}
    for run in runs:
        p, yaw = run["positions"], run["headings"]
        hops = cross_track(run)
        off_segment += [d for hop in hops for _, d in hop]
        hop_max += [max(d for _, d in hop) for hop in hops if hop]
        for hop, length in zip(hops, hop_lengths(run)):
            if length >= 3.0:
                for a, d in hop:
                    by_along.setdefault(max(-1, min(math.floor(a / 0.5), 9)), []).append(d)
        for i in range(0, len(p) - 50, 50):
            net50.append(math.dist(p[i][:2], p[i + 50][:2]) / 50)
        for i in range(5, len(p) - 6):
            dx, dy = p[i + 5][0] - p[i - 5][0], p[i + 5][1] - p[i - 5][1]
            d = math.hypot(dx, dy)
            if d < 0.05:
                continue
            ux, uy = dx / d, dy / d
            sx, sy = p[i + 1][0] - p[i][0], p[i + 1][1] - p[i][1]
            along.append(sx * ux + sy * uy)
            across.append(abs(sy * ux - sx * uy))
            off = (math.atan2(dy, dx) - yaw[i] + math.pi) % (2 * math.pi) - math.pi
            facing[min(int(abs(math.degrees(off)) // 30), 5)] += 1
    if not along or not net50:
        sys.exit(f"{path}: no run lasted 50 steps and moved 5 cm in 10 of them")
    mean = lambda xs: sum(xs) / len(xs)
    print(f"{len(runs)} runs")
    print(f"net pace over 50-step windows: {mean(net50):.4f} m per step")
    print(f"per step along the travel: {mean(along):.4f} m, across it: {mean(across):.4f} m")
    shares = ", ".join(f"{30 * k}-{30 * k + 30}°: {n / len(along):.2f}" for k, n in enumerate(facing))
    print(f"travel against heading: {shares}")
    if off_segment:
        off_segment.sort()
        q = lambda f: off_segment[int(f * (len(off_segment) - 1))]
        print(f"off the segment driven: median {q(0.5):.3f} m, 90th percentile {q(0.9):.3f} m, 99th {q(0.99):.3f} m")
        hop_max.sort()
        h = lambda f: hop_max[int(f * (len(hop_max) - 1))]
        print(
            f"largest of each of {len(hop_max)} hops: median {h(0.5):.3f} m, 90th percentile {h(0.9):.3f} m, "
            f"99th {h(0.99):.3f} m"
        )
    if by_along:
        print("off the segment by distance along it, hops of 3 m or more (m: median, 90th, 99th percentile):")
        for k, ds in sorted(by_along.items()):
            ds.sort()
            q = lambda f: ds[int(f * (len(ds) - 1))]
            lo = "before" if k < 0 else f"{0.5 * k:.1f}"
            hi = "" if k < 0 else ("+" if k == 9 else f"-{0.5 * k + 0.5:.1f}")
            print(f"  {lo}{hi}: {q(0.5):.3f} {q(0.9):.3f} {q(0.99):.3f} ({len(ds)} steps)")
    print("first hop by the start heading's angle to it: runs, failed before reaching it (collisions)")
    for lo, hi in ((0, 60), (60, 110), (110, 181)):
        sel = [r for r in runs if lo <= start_angle(r) < hi]
        failed = [r for r in sel if r["outcome"] != "satisfied" and not r["reached_at"]]
        collided = sum(r["outcome"] == "collided" for r in failed)
        print(f"  {lo}-{min(hi, 180)}°: {len(sel)}, {len(failed)} ({collided})")
    for run in runs:
        if run["outcome"] not in ("collided", "fell"):
            continue
        hops = cross_track(run)
        reached = len(run["reached_at"])
        since = len(run["positions"]) - (run["reached_at"][-1] if reached else 0)
        x, y = run["positions"][-1][:2]
        along, off = hops[-1][-1] if hops and hops[-1] else (float("nan"), float("nan"))
        print(
            f"{run['outcome']} at ({x:.2f}, {y:.2f}) driving to waypoint {reached + 1}, "
            f"{since} steps after the last reached, {along:.2f} m along the segment and {off:.2f} m off it"
        )


def start_angle(run):
    """Degrees between the start heading and the direction to the first waypoint."""
    (ax, ay), (bx, by) = run["waypoints"][0][:2], run["waypoints"][1][:2]
    off = math.atan2(by - ay, bx - ax) - run["headings"][0]
    return abs(math.degrees((off + math.pi) % (2 * math.pi) - math.pi))


def hop_lengths(run):
    """The length of each planned segment, in the order of `cross_track`'s hops."""
    w = run["waypoints"]
    return [math.dist(a[:2], b[:2]) for a, b in zip(w, w[1:])]


def cross_track(run):
    """Per hop, for each position: how far along the segment the robot is driving then
    (metres from its first waypoint, projected) and its distance from the segment."""
    p, w = run["positions"], run["waypoints"]
    # waypoints[0] is the start; reached_at[k] is the step waypoint k + 1 was reached.
    ends = run["reached_at"] + [len(p)]
    out = []
    for k, end in enumerate(ends):
        if k + 1 >= len(w):
            break
        (ax, ay), (bx, by) = w[k][:2], w[k + 1][:2]
        vx, vy = bx - ax, by - ay
        length2 = vx * vx + vy * vy
        hop = []
        for x, y in (q[:2] for q in p[(ends[k - 1] if k else 0) : end]):
            t = 0.0 if length2 == 0 else max(0.0, min(1.0, ((x - ax) * vx + (y - ay) * vy) / length2))
            along = ((x - ax) * vx + (y - ay) * vy) / math.sqrt(length2) if length2 else 0.0
            hop.append((along, math.hypot(x - ax - t * vx, y - ay - t * vy)))
        out.append(hop)
    return out


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: pace.py FILE.jsonl (from schrl eval --trajectories)")
    main(sys.argv[1])
