//! Huge and hard holes: fill time with the default policy (or `--policy FILE`).
//!
//!     cargo run --release --example hole_bench              # every case
//!     cargo run --release --example hole_bench -- slot10k   # some cases
//!     cargo run --release --example hole_bench -- --write DIR [cases]  # OBJ files only
//!
//! The meshes are generated (tests/common/holes.rs, shared with tests/hard_holes.rs).
//! For each case it prints the boundary loops, then per hole: size, method, status,
//! added faces, time; the whole fill time (what `holefill fill` prints as
//! FILL_TIME_S); for the cylinder slots the largest distance of a new vertex to the
//! cylinder, for the round holes on a dense sphere (`sphere1k`, `sphere10k`: a cap of
//! 46 degrees cut along a ring of 1,000 or 10,000 vertices) the mean and largest
//! distance to the sphere. The cases whose hole spans the whole part (the cylinder
//! slots and ends, the big sphere caps) get a small second part beside them, so that
//! the default `[border]` rule does not take the hole for a scan's outer border.

#[path = "../tests/common/holes.rs"]
mod holes;

use holefill::io::RawMesh;
use holefill::policy::Policy;
use holes::Soup;
use std::time::Instant;

/// A named generator.
type Case = (&'static str, fn() -> Soup);

fn cases() -> Vec<Case> {
    vec![
        ("slot10k", || {
            holes::with_companion(holes::cylinder_slot(48, 4, 5000))
        }),
        ("round10k", || {
            holes::with_companion(holes::cylinder_end(10_000, 4))
        }),
        ("sphere10k", || {
            holes::with_companion(holes::dense_sphere_cap(10_000, 0.8, 3))
        }),
        ("sphere1k", || {
            holes::with_companion(holes::dense_sphere_cap(1000, 0.8, 3))
        }),
        ("slot1k", || {
            holes::with_companion(holes::cylinder_slot(48, 4, 496))
        }),
        ("round1k", || {
            holes::with_companion(holes::cylinder_end(1000, 4))
        }),
        ("cap1k", || {
            holes::with_companion(holes::sphere_cap(7, 1.15))
        }),
        ("cap200", || holes::sphere_cap(6, 0.55)),
        ("cap50", || holes::sphere_cap(4, 0.55)),
        ("spiral", || holes::spiral(2, 2, 16)),
        ("near_touch", || holes::near_touch(60, 0.05)),
        ("sliver", || holes::sliver_hole(10.0)),
        ("flat5k", || holes::flat_annulus(5000, 3, 1e-3)),
        ("saddle", || holes::saddle(0.8, 80)),
        ("saddle2k", || holes::saddle(0.8, 1000)),
        ("wrap", || {
            holes::with_companion(holes::cylinder_slot(48, 40, 1000))
        }),
    ]
}

/// CPU time (user + system) of this process so far, in seconds, from
/// `/proc/self/stat` (clock ticks of 10 ms); `None` where that file is missing. On a
/// machine shared with other jobs the wall clock overstates the cost, this does not.
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // fields after the command name (which is in parentheses and may hold spaces)
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // utime and stime are fields 14 and 15 of the line, 12 and 13 after the name
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

fn raw(s: &Soup) -> RawMesh {
    RawMesh {
        positions: s.v.iter().map(|p| glam::DVec3::from(*p)).collect(),
        faces: s.f.iter().map(|f| f.map(|i| i as u32)).collect(),
        ..Default::default()
    }
}

fn main() -> anyhow::Result<()> {
    let mut args: Vec<String> = std::env::args().skip(1).collect();
    let mut write_dir = None;
    let mut policy = Policy::default();
    while let Some(i) = args.iter().position(|a| a.starts_with("--")) {
        let flag = args.remove(i);
        let val = if i < args.len() {
            args.remove(i)
        } else {
            anyhow::bail!("{flag} needs a value")
        };
        match flag.as_str() {
            "--write" => write_dir = Some(std::path::PathBuf::from(val)),
            "--policy" => {
                policy = Policy::from_file(val.as_ref()).map_err(|e| anyhow::anyhow!("{e}"))?;
            }
            _ => anyhow::bail!("unknown flag {flag}"),
        }
    }
    for (name, make) in cases() {
        if !args.is_empty() && !args.iter().any(|a| a == name) {
            continue;
        }
        let s = make();
        let loops = holes::boundary_loop_sizes(&s);
        println!(
            "== {name}: {} vertices, {} faces, boundary loops {:?}",
            s.v.len(),
            s.f.len(),
            loops
        );
        if let Some(dir) = &write_dir {
            std::fs::create_dir_all(dir)?;
            std::fs::write(dir.join(format!("{name}.obj")), s.obj_text())?;
            continue;
        }
        let input = raw(&s);
        let cpu0 = cpu_seconds();
        let t = Instant::now();
        let (out, rep) = holefill::repair(&input, &policy)?;
        let wall = t.elapsed().as_secs_f64();
        let cpu = cpu_seconds().zip(cpu0).map(|(b, a)| b - a);
        for h in &rep.holes {
            let tried: Vec<String> = h
                .tried
                .iter()
                .map(|a| format!("{}:{:?} {:.0}ms", a.method.name(), a.outcome, a.ms))
                .collect();
            println!(
                "   hole {:>3} {:>6} verts  {:<16} {:<8} +{}f  {:.1} ms  [{}]{}",
                h.id,
                h.boundary_vertices,
                h.method.map(|m| m.name()).unwrap_or("-"),
                format!("{:?}", h.status),
                h.added_faces,
                h.ms,
                tried.join(", "),
                if h.reason.is_empty() {
                    String::new()
                } else {
                    format!(" ({})", h.reason)
                }
            );
            if let Some(q) = &h.quality {
                println!(
                    "       q>1.39 {:.1} %  min angle {:.2} deg",
                    100.0 * q.q_good_share,
                    q.min_angle_deg
                );
            }
        }
        println!(
            "   FILL_TIME_S={:.3}  (repair {:.3} s wall, {} CPU)",
            rep.timings.fill_ms / 1000.0,
            wall,
            cpu.map_or("?".to_string(), |c| format!("{c:.2} s"))
        );
        if name.starts_with("sphere") {
            let n0 = input.positions.len();
            let d: Vec<f64> = out.positions[n0..]
                .iter()
                .map(|p| holes::sphere_distance(p.to_array()))
                .collect();
            let worst = d.iter().copied().fold(0.0f64, f64::max);
            let mean = d.iter().sum::<f64>() / d.len().max(1) as f64;
            println!(
                "   sphere: distance of the new vertices to the unit sphere: mean {mean:.2e}, largest {worst:.2e}"
            );
        }
        if name.starts_with("slot") {
            let n0 = input.positions.len();
            let worst = out.positions[n0..]
                .iter()
                .map(|p| holes::cylinder_distance(p.to_array()))
                .fold(0.0f64, f64::max);
            let edge = std::f64::consts::TAU / 48.0;
            println!(
                "   slot: largest distance of a new vertex to the cylinder {:.2e} ({:.3} edge lengths)",
                worst,
                worst / edge
            );
        }
    }
    Ok(())
}
