"""Prints the README's methods table from a shared-bench output folder.

    python scripts/methods_table.py BENCH_OUT default METHOD...

Reads BENCH_OUT/results.csv (one row per system and mesh) and the repair logs the
holefill runs wrote next to their outputs (BENCH_OUT/runs/<system>/<mesh>.obj.json).
Distances are per mille of the bounding-box diagonal. APE S/M/L: mean over the meshes
with ground truth of each mesh's per-class mean; q>1.39 % and val6 %: mean over all
meshes; selfx / flip / nm / F lost: sums; fill s: sum over all meshes. A mesh whose
run failed (a hole left open) has no APE, so its APE is left out of the means. "by method" counts the holes whose repair log
names the forced method (or fan for a small hole): it must equal the holes closed.
"""
import csv
import json
import os
import sys

out, systems = sys.argv[1], sys.argv[2:]
rows = list(csv.DictReader(open(os.path.join(out, "results.csv"))))
order = systems + ["cgal_fair", "meshlib_nicely"]


def num(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return None


def mean(xs):
    xs = [x for x in xs if x is not None]
    return sum(xs) / len(xs) if xs else None


def fmt(x, d=3):
    return "-" if x is None else f"{x:.{d}f}"


print("| system | holes closed | by method | APE S | APE M | APE L | q>1.39 % | val6 % | selfx / flip / nm / F lost | fill s |")
print("|---|---|---|---|---|---|---|---|---|---|")
for s in order:
    rs = [r for r in rows if r["system"] == s]
    if not rs:
        continue
    # holes per mesh from any row that has them (a failed run has none)
    per = {}
    for r in rows:
        if r["holes_in"]:
            per[r["dataset"]] = max(per.get(r["dataset"], 0), int(r["holes_in"]))
    hin = sum(per.get(r["dataset"], 0) for r in rs)
    left = 0
    for r in rs:
        logp = os.path.join(out, "runs", s, r["dataset"] + ".obj.json")
        if r["status"] == "ok":
            left += int(r["holes_left"] or 0)
        elif os.path.exists(logp):
            left += sum(1 for h in json.load(open(logp))["holes"] if h["status"] != "filled")
        else:
            left += per.get(r["dataset"], 0)
    gt = [r for r in rs if num(r["ape"]) is not None]
    ape = [mean(num(r[c]) for r in gt) for c in ("ape_small", "ape_middle", "ape_large")]
    ape = [None if a is None else 1000 * a for a in ape]
    q = mean(num(r["q_good_pct"]) for r in rs)
    v6 = mean(num(r["val6_pct"]) for r in rs)
    sx = "/".join(
        str(sum(int(num(r[c]) or 0) for r in rs))
        for c in ("selfx_faces", "flipped_edges", "nm_edges", "in_faces_lost")
    )
    fill = sum(num(r["fill_s"]) or 0 for r in rs)
    by = "-"
    if s in systems:
        n, named = 0, 0
        for r in rs:
            p = os.path.join(out, "runs", s, r["dataset"] + ".obj.json")
            if not os.path.exists(p):
                continue
            for h in json.load(open(p))["holes"]:
                if h["status"] != "filled":
                    continue
                n += 1
                want = {"fan"} if h["class"] == "small" else {s}
                if s == "default" or h["method"] in want:
                    named += 1
        by = f"{named}/{n}"
    print(f"| {s} | {hin - left}/{hin} | {by} | {fmt(ape[0])} | {fmt(ape[1])} | {fmt(ape[2])} "
          f"| {fmt(q, 0)} | {fmt(v6, 0)} | {sx} | {fmt(fill)} |")
