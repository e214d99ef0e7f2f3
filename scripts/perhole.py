#!/usr/bin/env python3
"""Per-hole distances of a seeds.py run (issue 19's per-hole study).

    scripts/perhole.py SEEDS_OUT SYSTEM[,SYSTEM...] > holes.csv

For every synthetic hole of every seed under SEEDS_OUT (a `seeds.py --out` folder):
its size class and rim features (flat shares of the edges within 2 rings at 0.5, 2
and 5 degrees, ...), and per system the bench's per-hole APE (per mille of the bbox
diagonal, the bench's own matching of patch pieces to holes) and its point count
(`SYSTEM_w`: a mesh's APE is the point-weighted mean of its holes'). BENCH (default
../shared/bench) must hold the bench's Python modules and venv; PERHOLE_MESHES=a,b
keeps those meshes only."""
import sys, os, json, csv
import numpy as np
sys.path.insert(0, os.environ.get("BENCH", os.path.join(os.path.dirname(__file__), "..", "..", "shared", "bench")))
import metrics, mio, topo

def dihedral_angles(V, F, Nn):
    """Angles (degrees) between the unit normals `Nn` of each two faces of F that
    share an edge."""
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    fid = np.tile(np.arange(len(F)), 3)
    key = np.minimum(e[:, 0], e[:, 1]) * (len(V) + 1) + np.maximum(e[:, 0], e[:, 1])
    o = np.argsort(key); ks = key[o]
    same = np.nonzero(ks[1:] == ks[:-1])[0]
    f1 = fid[o][same]; f2 = fid[o][same + 1]
    return np.degrees(np.arccos(np.clip((Nn[f1] * Nn[f2]).sum(1), -1, 1)))

def feats(Vin, Fin, A, loop):
    loop = np.asarray(loop)
    P = Vin[loop]
    c = P.mean(0)
    w, v = np.linalg.eigh(np.cov((P - c).T))
    # rim rings
    ring = loop.copy(); rings = [ring]
    for _ in range(3):
        ring = np.unique(np.concatenate([ring, A[ring].indices])); rings.append(ring)
    near = np.zeros(len(Vin), bool); near[rings[2]] = True
    F = Fin[near[Fin].all(1)]
    N = np.cross(Vin[F[:, 1]] - Vin[F[:, 0]], Vin[F[:, 2]] - Vin[F[:, 0]])
    area = np.linalg.norm(N, axis=1); Nn = N / np.maximum(area[:, None], 1e-300)
    # dihedral angles of interior edges among F
    ang = dihedral_angles(Vin, F, Nn)
    navg = (Nn * area[:, None]).sum(0); navg /= max(np.linalg.norm(navg), 1e-300)
    dev = np.degrees(np.arccos(np.clip(Nn @ navg, -1, 1)))
    perim = np.linalg.norm(np.roll(P, -1, 0) - P, axis=1).sum()
    return dict(n=len(loop), planar=float(np.sqrt(max(w[0], 0)) / perim),
                elong=float(np.sqrt(max(w[1], 0) / max(w[2], 1e-300))),
                flat05=float(np.mean(ang < 0.5)), flat2=float(np.mean(ang < 2)), flat5=float(np.mean(ang < 5)),
                sharp20=float(np.mean(ang > 20)), sharp40=float(np.mean(ang > 40)), angmean=float(ang.mean()),
                angmax=float(ang.max()), ndev=float(np.average(dev, weights=area)), ndevmax=float(dev.max()))

def patch_points(base, system, name, Vin, Fin, diag, hole_of_v):
    """The patch of `system`'s output for mesh `name` as the bench sees it: output
    vertices, new faces, each new face's hole, the points measured (new vertices, then
    area samples) and each point's hole; None without an output."""
    ps = [os.path.join(base, "runs", system, name + e) for e in (".obj", ".off", ".ply")]
    ps = [p for p in ps if os.path.exists(p)]
    if not ps: return None
    Vout, Fout = mio.read_mesh(ps[0])
    vmap = metrics.match_vertices(Vin, Vout, diag)
    n = len(Vin) + 1
    mapped = vmap[Fout]; known = np.all(mapped >= 0, 1)
    kin = metrics.face_keys(Fin, n); kout = np.full(len(Fout), -1, np.int64)
    kout[known] = metrics.face_keys(mapped[known], n)
    new = ~(known & np.isin(kout, kin)); newF = Fout[new]
    used = np.unique(Fout); new_v = used[vmap[used] < 0]
    rng = np.random.default_rng(0)
    S, sf = metrics.sample_surface(Vout, newF, metrics.N_SAMPLES, rng, return_faces=True)
    P = np.concatenate([Vout[new_v], S])
    flab = metrics.patch_hole_labels(newF, vmap, hole_of_v, len(Vout))
    vlab = np.full(len(Vout), -1, np.int64); vlab[newF.reshape(-1)] = np.repeat(flab, 3)
    plab = np.concatenate([vlab[new_v], flab[sf]])
    return Vout, newF, flab, P, plab

def reference(Vin, Fin, Vg, Fg, gids, A, h):
    """The true surface around hole h, as the bench takes it: its ground truth and the
    input faces within 3 rings of its loop (vertices: Vg then Vin)."""
    ring = np.asarray(h["loop"])
    for _ in range(3): ring = np.unique(np.concatenate([ring, A[ring].indices]))
    near = np.zeros(len(Vin), bool); near[ring] = True
    return np.concatenate([Fg[gids == h["id"]], Fin[near[Fin].any(1)] + len(Vg)])

def main():
    out, systems = sys.argv[1], sys.argv[2].split(",")
    wr = None
    for sd in sorted(os.listdir(out)):
        if not sd.startswith("seed-"): continue
        seed = int(sd[5:]); base = os.path.join(out, sd)
        for name in sorted(os.listdir(os.path.join(base, "holes"))):
            hd = os.path.join(base, "holes", name)
            man = json.load(open(os.path.join(hd, "manifest.json")))
            if man["natural"]: continue
            only = os.environ.get("PERHOLE_MESHES")
            if only and name not in only.split(","): continue
            diag = man["diag"]; holes = man["holes"]
            Vin, Fin = mio.read_mesh(os.path.join(hd, "holed.obj"))
            Vg, Fg = mio.read_mesh(os.path.join(hd, "gt.obj"))
            gids = np.loadtxt(os.path.join(hd, "gt_hole_ids.txt"), dtype=np.int64)
            A = topo.vertex_adjacency(Fin, len(Vin))
            hole_of_v = -np.ones(len(Vin), np.int64)
            for h in holes: hole_of_v[h["loop"]] = h["id"]
            VR = np.concatenate([Vg, Vin])
            FRs = {h["id"]: reference(Vin, Fin, Vg, Fg, gids, A, h) for h in holes}
            ftab = {h["id"]: feats(Vin, Fin, A, h["loop"]) for h in holes}
            ape = {}
            for s in systems:
                got = patch_points(base, s, name, Vin, Fin, diag, hole_of_v)
                if got is None: continue
                _, _, _, P, plab = got
                for h in holes:
                    sel = plab == h["id"]
                    if not sel.any(): continue
                    d, _ = metrics.surface_distance(VR, FRs[h["id"]], P[sel])
                    ape[(s, h["id"])] = 1000 * d.mean() / diag
                    ape[(s + "_w", h["id"])] = int(sel.sum())
            for h in holes:
                row = dict(seed=seed, mesh=name, hole=h["id"], cat=h["category"])
                row.update(ftab[h["id"]])
                for s in systems: row[s] = ape.get((s, h["id"]), "")
                for s in systems: row[s + "_w"] = ape.get((s + "_w", h["id"]), "")
                if wr is None:
                    wr = csv.DictWriter(sys.stdout, fieldnames=list(row)); wr.writeheader()
                wr.writerow(row); sys.stdout.flush()

if __name__ == "__main__":
    main()
