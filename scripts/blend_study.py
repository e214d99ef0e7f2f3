#!/usr/bin/env python3
"""What blending two methods' patches would give, per hole (issue 19, `[blend]`).

    scripts/blend_study.py SEEDS_OUT A B > blend.csv

For every middle and large synthetic hole: the points of system A's patch (its new
vertices and 20k area samples, as the bench takes them) moved by t = 0, 0.25, ... 1
toward the closest point of system B's patch of the same hole, and their mean
distance to the true surface around the hole (per mille of the bbox diagonal), with
the point count `w`. t = 0 is A's own per-hole APE. BENCH as for perhole.py."""
import sys, os, json, csv
import numpy as np
sys.path.insert(0, os.environ.get("BENCH", os.path.join(os.path.dirname(__file__), "..", "..", "shared", "bench")))
import metrics, mio, topo
TS = [0.0, 0.25, 0.5, 0.75, 1.0]
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from perhole import patch_points, reference
out = sys.argv[1]; A_, B_ = sys.argv[2], sys.argv[3]
wr = csv.writer(sys.stdout); wr.writerow(["seed", "mesh", "hole", "cat", "w"] + ["t%.2f" % t for t in TS])
for sd in sorted(os.listdir(out)):
    if not sd.startswith("seed-"): continue
    seed = int(sd[5:]); base = os.path.join(out, sd)
    for name in sorted(os.listdir(os.path.join(base, "holes"))):
        hd = os.path.join(base, "holes", name)
        man = json.load(open(os.path.join(hd, "manifest.json")))
        if man["natural"]: continue
        diag = man["diag"]; holes = man["holes"]
        Vin, Fin = mio.read_mesh(os.path.join(hd, "holed.obj"))
        Vg, Fg = mio.read_mesh(os.path.join(hd, "gt.obj"))
        gids = np.loadtxt(os.path.join(hd, "gt_hole_ids.txt"), dtype=np.int64)
        A = topo.vertex_adjacency(Fin, len(Vin))
        hole_of_v = -np.ones(len(Vin), np.int64)
        for h in holes: hole_of_v[h["loop"]] = h["id"]
        VR = np.concatenate([Vg, Vin])
        Va, Fa, fla, Pa, pla = patch_points(base, A_, name, Vin, Fin, diag, hole_of_v)
        Vb, Fb, flb, Pb, plb = patch_points(base, B_, name, Vin, Fin, diag, hole_of_v)
        for h in holes:
            if h["category"] == "small": continue
            i = h["id"]
            FR = reference(Vin, Fin, Vg, Fg, gids, A, h)
            P = Pa[pla == i]; FB = Fb[flb == i]
            if len(P) == 0 or len(FB) == 0: continue
            _, f = metrics.surface_distance(Vb, FB, P)
            T = Vb[FB[f]]
            C = metrics.closest_point_on_triangles(P, T[:, 0], T[:, 1], T[:, 2])
            res = []
            for t in TS:
                d, _ = metrics.surface_distance(VR, FR, P + t * (C - P))
                res.append(1000 * d.mean() / diag)
            wr.writerow([seed, name, i, h["category"], len(P)] + ["%.4f" % x for x in res]); sys.stdout.flush()
