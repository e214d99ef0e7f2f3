#!/usr/bin/env python3
"""How well each system continues the creases that run into a hole (issue 19).

    scripts/crease_table.py [--meshes fandisk,joint] [--min-angle 30] DIR:SYSTEM ...

Each DIR is a `seeds.py --out` folder (seed-N/ with holes/ and runs/); a SYSTEM is read
from the DIR given with it, so systems of different runs can share one table (the same
hole seeds give the same holes). A *crease hole* is a synthetic hole whose true
surface (its ground-truth faces) has an interior edge with a dihedral angle of at least
`--min-angle` degrees; its crease angle is the largest one. For each crease hole a
system closed, with the bench's own matching of patch faces to holes:
  - APE: the bench's per-hole distance to the true surface (per mille of the diagonal);
  - kept: the patch's largest dihedral angle between two of its faces over the crease
    angle (1: the crease is as sharp as it was; near 0: rounded off; a patch that
    folds can pass 1);
  - normal: the area-weighted mean angle (degrees) between a patch face's normal and
    the normal of the true surface at the face's centroid (a rounded crease tilts the
    faces near it).
Prints, per mesh, the number of crease holes and their mean crease angle, then per
system the means over the crease holes it closed. BENCH (default ../shared/bench) must
hold the bench's Python modules (run with its venv's Python)."""
import sys, os, json, argparse
import numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import perhole  # noqa: E402  (adds BENCH to the path)
import metrics, mio, topo  # noqa: E402


def face_normals(V, F):
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    a = np.linalg.norm(N, axis=1)
    return N / np.maximum(a[:, None], 1e-300), a / 2


def max_dihedral(V, F):
    """Largest angle (degrees) between the normals of two faces of F sharing an edge."""
    if len(F) < 2:
        return 0.0
    ang = perhole.dihedral_angles(V, F, face_normals(V, F)[0])
    return float(ang.max()) if len(ang) else 0.0


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", default="fandisk,joint")
    ap.add_argument("--min-angle", type=float, default=30.0)
    ap.add_argument("specs", nargs="+", help="DIR:SYSTEM")
    a = ap.parse_args()
    specs = [s.rsplit(":", 1) for s in a.specs]
    systems = [s for _, s in specs]
    meshes = a.meshes.split(",")
    # (mesh) -> list of crease angles; (mesh, system) -> lists of per-hole values
    angles = {m: [] for m in meshes}
    vals = {}
    seeds = sorted({d for base, _ in specs for d in os.listdir(base) if d.startswith("seed-")},
                   key=lambda d: int(d[5:]))
    for sd in seeds:
        for name in meshes:
            hd = None
            for base, _ in specs:
                p = os.path.join(base, sd, "holes", name)
                if os.path.isdir(p):
                    hd = p
                    break
            if hd is None:
                continue
            man = json.load(open(os.path.join(hd, "manifest.json")))
            if man["natural"]:
                continue
            diag, holes = man["diag"], man["holes"]
            Vin, Fin = mio.read_mesh(os.path.join(hd, "holed.obj"))
            Vg, Fg = mio.read_mesh(os.path.join(hd, "gt.obj"))
            gids = np.loadtxt(os.path.join(hd, "gt_hole_ids.txt"), dtype=np.int64)
            crease = {}
            for h in holes:
                ang = max_dihedral(Vg, Fg[gids == h["id"]])
                if ang >= a.min_angle:
                    crease[h["id"]] = ang
            if not crease:
                continue
            angles[name] += list(crease.values())
            A = topo.vertex_adjacency(Fin, len(Vin))
            hole_of_v = -np.ones(len(Vin), np.int64)
            for h in holes:
                hole_of_v[h["loop"]] = h["id"]
            VR = np.concatenate([Vg, Vin])
            for base, s in specs:
                got = perhole.patch_points(os.path.join(base, sd), s, name, Vin, Fin, diag, hole_of_v)
                if got is None:
                    continue
                Vout, newF, flab, P, plab = got
                for hid, ang in crease.items():
                    h = next(x for x in holes if x["id"] == hid)
                    sel = plab == hid
                    fsel = flab == hid
                    if not sel.any() or not fsel.any():
                        continue
                    FR = perhole.reference(Vin, Fin, Vg, Fg, gids, A, h)
                    d, _ = metrics.surface_distance(VR, FR, P[sel])
                    PF = newF[fsel]
                    Nn, area = face_normals(Vout, PF)
                    cen = Vout[PF].mean(1)
                    # the true normal at each centroid: that of the nearest true face
                    FT = Fg[gids == hid]
                    NT, _ = face_normals(Vg, FT)
                    ct = Vg[FT].mean(1)
                    near = np.argmin(((cen[:, None, :] - ct[None, :, :]) ** 2).sum(2), 1)
                    cos = np.abs((Nn * NT[near]).sum(1))
                    normal = float(np.average(np.degrees(np.arccos(np.clip(cos, -1, 1))),
                                              weights=np.maximum(area, 1e-300)))
                    v = vals.setdefault((name, s), {"ape": [], "kept": [], "normal": []})
                    v["ape"].append(1000 * d.mean() / diag)
                    v["kept"].append(max_dihedral(Vout, PF) / ang)
                    v["normal"].append(normal)
    print(f"Crease holes: a true surface with a dihedral angle of at least {a.min_angle:g} deg; "
          "means over the crease holes each system closed.\n")
    print("| mesh | crease holes | crease angle | " + " | ".join(systems) + " |")
    print("|---|---|---|" + "---|" * len(systems))
    for m in meshes:
        if not angles[m]:
            continue
        cells = []
        for s in systems:
            v = vals.get((m, s))
            if not v:
                cells.append("-")
                continue
            cells.append(f"{np.mean(v['ape']):.2f} / {np.mean(v['kept']):.2f} / "
                         f"{np.mean(v['normal']):.1f} ({len(v['ape'])})")
        print(f"| {m} | {len(angles[m])} | {np.mean(angles[m]):.0f} | " + " | ".join(cells) + " |")
    print("\nCells: APE (per mille) / kept (patch's sharpest fold over the crease angle) / "
          "normal error (deg) (holes closed).")


if __name__ == "__main__":
    main()
