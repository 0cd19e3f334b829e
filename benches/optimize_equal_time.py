#!/usr/bin/env python3
"""The table of benches/optimize_equal_time.sh: per scene and configuration, the parameter error
(ALGORITHMS.md §7.1, `param_error` in history.csv: the mean over the optimised values) at fixed
seconds of iteration wall time (the median over the WINDOW seconds before), the mean error over the last quarter of the run, the time each
run first reached a fixed error and the time from which it stayed there (the median over the
WINDOW seconds before each later iteration at or below it), and seconds per iteration; geometric means over the seeds.

    python3 benches/optimize_equal_time.py OUT [--at 10,20,30,60] [--reach 1e-2,1e-3] [--window 3]
"""

import argparse
import csv
import math
import pathlib
import re
from collections import defaultdict


def history(path):
    rows = list(csv.DictReader(open(path)))
    return [(float(r["time_s"]), float(r["param_error"])) for r in rows]


def error_at(h, t, window):
    """The median error of the iterations that ended in (t − window, t] (None if none did): one
    iteration's error is as noisy as its gradient, the median of a few seconds' is not."""
    chunk = sorted(err for time, err in h if t - window < time <= t)
    return chunk[len(chunk) // 2] if chunk else None


def settled(h, e, window):
    """The first time t from which the median error of the iterations in (t − window, t] stays
    ≤ e to the end of the run (None if it never does): when the run has reached e for good, not
    by one lucky iteration."""
    since = None
    j = 0
    for i, (t, _) in enumerate(h):
        while h[j][0] <= t - window:
            j += 1
        chunk = sorted(err for _, err in h[j : i + 1])
        if chunk[len(chunk) // 2] <= e:
            since = t if since is None else since
        else:
            since = None
    return since


def geomean(values):
    """The geometric mean, or None unless every seed has a value (a cell never covers fewer seeds
    than its row says)."""
    if not values or any(v is None for v in values):
        return None
    return math.exp(sum(math.log(max(v, 1e-30)) for v in values) / len(values))


def fmt(v, digits=2):
    if v is None:
        return "—"
    if v == 0 or 1e-2 <= abs(v) < 1e3:
        return f"{v:.{digits + 1}g}"
    return f"{v:.{digits}e}".replace("e-0", "e-").replace("e+0", "e")


def main():
    p = argparse.ArgumentParser()
    p.add_argument("out")
    p.add_argument("--at", default="10,20,30,60")
    p.add_argument("--reach", default="1e-2,1e-3")
    p.add_argument("--window", type=float, default=3.0, help="seconds of the trailing median behind 'stays'")
    a = p.parse_args()
    at = [float(x) for x in a.at.split(",")]
    reach = [float(x) for x in a.reach.split(",")]
    runs = defaultdict(list)
    order = []
    for d in sorted(pathlib.Path(a.out).iterdir()):
        m = re.fullmatch(r"(\w+)-(.+)-s(\d+)", d.name)
        if not d.is_dir() or not m or not (d / "history.csv").exists():
            continue
        key = (m.group(1), m.group(2))
        if key not in order:
            order.append(key)
        runs[key].append(history(d / "history.csv"))
    configs = ["plain", "adaptive", "paper", "cv", "cv+adaptive", "cv+paper"]
    order.sort(key=lambda k: (k[0], configs.index(k[1]) if k[1] in configs else 99))
    head = ["scene", "configuration", "seeds", "s/iteration"]
    head += [f"error @ {t:g} s" for t in at]
    head[-len(at)] += f" (median of {a.window:g} s)"
    head += ["mean error, last quarter (per seed)"]
    head += [f"first ≤ {e:g} / stays (s, per seed)" for e in reach]
    print("| " + " | ".join(head) + " |")
    print("|" + " --- |" * len(head))
    for key in order:
        hs = runs[key]
        per_it = geomean([h[-1][0] / len(h) for h in hs])
        cells = [key[0], key[1], str(len(hs)), fmt(per_it, 2)]
        cells += [fmt(geomean([error_at(h, t, a.window) for h in hs])) for t in at]
        lasts = []
        for h in hs:
            end = h[-1][0]
            late = [e for t, e in h if t >= 0.75 * end]
            lasts.append(sum(late) / len(late))
        cells.append(f"{fmt(geomean(lasts))} ({', '.join(fmt(v) for v in lasts)})")
        for e in reach:
            firsts = [next((t for t, err in h if err <= e), None) for h in hs]
            stays = [settled(h, e, a.window) for h in hs]
            cells.append(
                ", ".join(
                    ("never" if f is None else f"{f:.1f}") + " / " + ("never" if s is None else f"{s:.1f}")
                    for f, s in zip(firsts, stays)
                )
            )
        print("| " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
