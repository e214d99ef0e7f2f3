"""Prints the README's methods table from a shared-bench output folder.

    python scripts/methods_table.py BENCH_OUT default METHOD...

BENCH_OUT is one run of the bench (results.csv) or a seeds.py folder (seed-N/, one run
per hole seed). Reads each run's results.csv (one row per system and mesh) and the
repair logs the holefill runs wrote next to their outputs
(runs/<system>/<mesh>.obj.json). A natural scan has the same holes under every seed,
so only the first seed's run of it counts. Distances are per mille of the
bounding-box diagonal. APE S/M/L: mean over the runs with ground truth of each run's
per-class mean; q>1.39 % and val6 %: mean over all runs; selfx / flip / nm / F lost:
sums; fill s: sum over all runs. The runs that left a hole open are listed under the
table. A mesh whose
run failed (a hole left open) has no APE, so its APE is left out of the means. "by method" counts the holes whose repair log
names the forced method (or fan for a small hole): it must equal the holes closed.
"holes closed": holefill's repair logs (filled or stitched, over the holes not
skipped by a rule such as the outer-border rule, counted apart); a peer's, the bench's
count of the input's loops left open.
"""
import csv
import glob
import json
import os
import sys

out, systems = sys.argv[1], sys.argv[2:]
dirs = sorted(glob.glob(os.path.join(out, "seed-*")),
              key=lambda d: int(d.rsplit("-", 1)[1])) or [out]
rows = []
for d in dirs:
    for r in csv.DictReader(open(os.path.join(d, "results.csv"))):
        man = os.path.join(d, "holes", r["dataset"], "manifest.json")
        natural = os.path.exists(man) and json.load(open(man)).get("natural", False)
        if natural and d != dirs[0]:
            continue
        r["_dir"] = d
        r["_run"] = r["dataset"] if len(dirs) == 1 else f"{r['dataset']} seed {d.rsplit('-', 1)[1]}"
        rows.append(r)
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


open_runs = []
print("| system | holes closed | skipped | by method | APE S | APE M | APE L | q>1.39 % | val6 % | selfx / flip / nm / F lost | fill s |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for s in order:
    rs = [r for r in rows if r["system"] == s]
    if not rs:
        continue
    # holes per mesh from any row that has them (a failed run has none)
    per = {}
    for r in rows:
        if r["holes_in"]:
            per[r["_run"]] = max(per.get(r["_run"], 0), int(r["holes_in"]))
    # holefill: its repair logs (closed = filled or stitched; a loop skipped by a named
    # rule, an outer border, is neither closed nor open); a peer: the bench's count
    closed = total = skipped = 0
    for r in rs:
        logp = os.path.join(r["_dir"], "runs", s, r["dataset"] + ".obj.json")
        if s in systems and os.path.exists(logp):
            hs = json.load(open(logp))["holes"]
            ok = sum(1 for h in hs if h["status"] in ("filled", "stitched"))
            sk = sum(1 for h in hs if h["status"] == "skipped")
            n = len(hs) - ok - sk
            closed += ok
            skipped += sk
            total += ok + n
        else:
            hin = per.get(r["_run"], 0)
            n = int(r["holes_left"] or 0) if r["status"] == "ok" else hin
            closed += hin - n
            total += hin
        if n:
            open_runs.append(f"{s}: {r['_run']} ({n} open)")
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
            p = os.path.join(r["_dir"], "runs", s, r["dataset"] + ".obj.json")
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
    sk = str(skipped) if s in systems else "-"
    print(f"| {s} | {closed}/{total} | {sk} | {by} | {fmt(ape[0])} | {fmt(ape[1])} | {fmt(ape[2])} "
          f"| {fmt(q, 0)} | {fmt(v6, 0)} | {sx} | {fmt(fill)} |")
if open_runs:
    print()
    print("Runs that left a hole open: " + "; ".join(open_runs) + ".")
