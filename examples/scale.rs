//! The scale benchmark: how the cost of `holefill fill` grows with the mesh and with
//! the hole.
//!
//! ```text
//! cargo build --release && cargo run --release --example scale
//! cargo run --release --example scale -- --sizes 100000,1000000 --hole-sizes 50,200
//! cargo run --release --example scale -- gen 10000000 100 /tmp/scan10m.ply
//! ```
//!
//! Every measurement runs the real binary (`target/release/holefill fill`, or the one
//! given with `--bin`) as a child process on a file written to a temporary folder,
//! and prints a markdown table:
//!
//! 1. End-to-end time (read, repair, write: the child's wall clock) and peak memory
//!    (the child's maximum resident set size, from `/usr/bin/time` when present,
//!    else from polling the child's `VmHWM`) against mesh size: a closed bumpy
//!    torus of about 100k, 1M and 10M triangles with 100 holes cut out (disc-shaped,
//!    about 10 to 300 boundary vertices each), written as binary PLY with `f32`
//!    coordinates like a scanner's output, under the default policy.
//! 2. Fill time per method against hole size: a sphere whose north cap is cut off
//!    along a ring of exactly k = 50, 200, 1,000, 10,000 vertices (a band of dense
//!    rings below it, then a coarse cone to the south pole), filled by one method
//!    alone (a policy whose three classes list only that method). The time is the
//!    method's own time from the repair log; a method that fails shows the reason,
//!    one that runs out of the per-hole time limit (`limits.hole_time_ms`, set with
//!    `--time-limit-ms`) shows "> N s". A child that outlives that limit by a wide
//!    margin is killed, so the benchmark never hangs.
//!
//! `gen FACES HOLES OUT` only writes the torus (format from the extension).

use anyhow::{bail, Context, Result};
use glam::DVec3;
use holefill::io::{Encoding, Precision, RawMesh};
use rand::{Rng, SeedableRng};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const METHODS: [&str; 5] = [
    "min_area_fair",
    "advancing_front",
    "wavefront",
    "hpde",
    "lssvm_poisson",
];

/// A closed torus (major radius 1, tube radius 0.35, with a gentle bump pattern) of
/// about `faces` triangles, `f32` coordinates, with `holes` disc-shaped holes cut out.
pub fn torus_scan(faces: usize, holes: usize, seed: u64) -> RawMesh {
    let (big_r, small_r) = (1.0f64, 0.35f64);
    // nu x nv quads, two triangles each; nu / nv = R / r keeps the cells square-ish
    let cells = (faces / 2).max(64) as f64;
    let nv = ((cells * small_r / big_r).sqrt().round() as usize).max(8);
    let nu = ((cells / nv as f64).round() as usize).max(8);
    let pos = |i: usize, j: usize| -> DVec3 {
        let u = std::f64::consts::TAU * i as f64 / nu as f64;
        let v = std::f64::consts::TAU * j as f64 / nv as f64;
        let r = small_r * (1.0 + 0.06 * (5.0 * u + 1.0).sin() * (3.0 * v).cos());
        let p = DVec3::new(
            (big_r + r * v.cos()) * u.cos(),
            (big_r + r * v.cos()) * u.sin(),
            r * v.sin(),
        );
        // stored as f32, like a scanner's output
        p.as_vec3().as_dvec3()
    };
    let mut positions = Vec::with_capacity(nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            positions.push(pos(i, j));
        }
    }
    let id = |i: usize, j: usize| ((i % nu) * nv + (j % nv)) as u32;
    // holes: centres on a jittered lattice of cells, radius a share of the cell
    let mut removed = vec![false; nu * nv];
    let side = (holes as f64).sqrt().ceil().max(1.0) as usize;
    let (cu, cv) = (nu / side, nv / side);
    let edge = std::f64::consts::TAU * big_r / nu as f64;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    for h in 0..holes {
        let (a, b) = (h % side, h / side);
        let ci = a * cu + cu / 4 + rng.random_range(0..(cu / 2).max(1));
        let cj = b * cv + cv / 4 + rng.random_range(0..(cv / 2).max(1));
        // radius: from 2 to 40 edges, but well inside the cell
        let max_cells = (cu.min(cv) as f64 * 0.2).max(1.5);
        let rc = (2.0 + rng.random::<f64>().powi(2) * 38.0).min(max_cells);
        let rho = rc * edge;
        let c = pos(ci, cj);
        let w = rc.ceil() as usize * 3 + 2;
        for di in 0..=2 * w {
            for dj in 0..=2 * w {
                let (i, j) = ((ci + nu + di - w) % nu, (cj + nv + dj - w) % nv);
                if (pos(i, j) - c).length() <= rho {
                    removed[i * nv + j] = true;
                }
            }
        }
    }
    let mut tris = Vec::with_capacity(2 * nu * nv);
    for i in 0..nu {
        for j in 0..nv {
            let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
            for t in [[a, b, c], [a, c, d]] {
                if t.iter().all(|&k| !removed[k as usize]) {
                    tris.push(t);
                }
            }
        }
    }
    RawMesh {
        positions,
        colors: None,
        faces: tris,
        precision: Precision::F32,
        encoding: Encoding::BinaryLittleEndian,
        notes: Vec::new(),
        attrs: Default::default(),
    }
}

/// A unit sphere with its north cap cut off along a ring of exactly `k` vertices
/// (polar angle 45°): `rings` rings of `k` vertices spaced like the ring's edges,
/// then a cone to the south pole. One hole of `k` boundary vertices.
pub fn capped_sphere(k: usize) -> RawMesh {
    let theta0 = std::f64::consts::FRAC_PI_4;
    let step = std::f64::consts::TAU * theta0.sin() / k as f64;
    let rings = 12usize;
    let mut positions = Vec::with_capacity(k * rings + 1);
    for r in 0..rings {
        let th = theta0 + step * r as f64 * 0.866;
        for i in 0..k {
            // alternate rings are offset by half a step: near-equilateral triangles
            let ph = std::f64::consts::TAU * (i as f64 + 0.5 * (r % 2) as f64) / k as f64;
            positions.push(DVec3::new(
                th.sin() * ph.cos(),
                th.sin() * ph.sin(),
                th.cos(),
            ));
        }
    }
    positions.push(DVec3::new(0.0, 0.0, -1.0));
    let south = (k * rings) as u32;
    let id = |r: usize, i: usize| (r * k + i % k) as u32;
    let mut faces = Vec::with_capacity(2 * k * rings);
    for r in 0..rings - 1 {
        for i in 0..k {
            // outward normals (the hole is at the top, +z)
            if r % 2 == 0 {
                faces.push([id(r, i), id(r + 1, i), id(r, i + 1)]);
                faces.push([id(r, i + 1), id(r + 1, i), id(r + 1, i + 1)]);
            } else {
                faces.push([id(r, i), id(r + 1, i), id(r + 1, i + 1)]);
                faces.push([id(r, i), id(r + 1, i + 1), id(r, i + 1)]);
            }
        }
    }
    for i in 0..k {
        faces.push([id(rings - 1, i), south, id(rings - 1, i + 1)]);
    }
    RawMesh {
        positions,
        colors: None,
        faces,
        precision: Precision::F64,
        encoding: Encoding::BinaryLittleEndian,
        notes: Vec::new(),
        attrs: Default::default(),
    }
}

/// What a child run of `holefill fill` cost.
struct Run {
    wall: Duration,
    max_rss_kb: Option<u64>,
    /// User plus system CPU time (from `/usr/bin/time`).
    cpu_s: Option<f64>,
    status: Option<i32>,
    killed: bool,
    stderr: String,
}

/// Runs `bin args...`, killing it after `timeout`; measures its wall time and peak
/// resident memory.
fn run_child(bin: &Path, args: &[&str], timeout: Duration) -> Result<Run> {
    let use_time = Path::new("/usr/bin/time").exists();
    let rss_file = tempfile::NamedTempFile::new()?;
    let mut cmd = if use_time {
        let mut c = Command::new("/usr/bin/time");
        c.arg("-f")
            .arg("%M %U %S")
            .arg("-o")
            .arg(rss_file.path())
            .arg(bin);
        c
    } else {
        Command::new(bin)
    };
    cmd.args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .stdin(Stdio::null());
    let t = Instant::now();
    let mut child = cmd
        .spawn()
        .with_context(|| format!("starting {}", bin.display()))?;
    let mut stderr = child.stderr.take();
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        if let Some(e) = stderr.as_mut() {
            let _ = std::io::Read::read_to_string(e, &mut s);
        }
        s
    });
    let mut hwm = None;
    let mut killed = false;
    let status = loop {
        if let Some(s) = child.try_wait()? {
            break s;
        }
        if !use_time {
            // the high-water mark only grows: the last poll is the closest
            hwm = vm_hwm_kb(child.id()).or(hwm);
        }
        if t.elapsed() > timeout && !killed {
            let _ = child.kill();
            killed = true;
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    let wall = t.elapsed();
    let stderr = err_reader.join().unwrap_or_default();
    // "%M %U %S" on the last line (a killed child adds a line before it)
    let timed: Vec<String> = std::fs::read_to_string(rss_file.path())
        .ok()
        .and_then(|s| s.lines().last().map(str::to_string))
        .map(|l| l.split_whitespace().map(str::to_string).collect())
        .unwrap_or_default();
    let max_rss_kb = if use_time {
        timed.first().and_then(|v| v.parse().ok())
    } else {
        hwm
    };
    let cpu_s = match (timed.get(1), timed.get(2)) {
        (Some(u), Some(s)) => match (u.parse::<f64>(), s.parse::<f64>()) {
            (Ok(u), Ok(s)) => Some(u + s),
            _ => None,
        },
        _ => None,
    };
    Ok(Run {
        wall,
        max_rss_kb,
        cpu_s,
        status: status.code(),
        killed,
        stderr,
    })
}

fn vm_hwm_kb(pid: u32) -> Option<u64> {
    let s = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn human(n: usize) -> String {
    if n >= 1_000_000 && n % 1_000_000 == 0 {
        format!("{}M", n / 1_000_000)
    } else if n >= 1000 && n % 1000 == 0 {
        format!("{}k", n / 1000)
    } else {
        n.to_string()
    }
}

fn parse_list(s: &str) -> Result<Vec<usize>> {
    s.split(',')
        .filter(|t| !t.is_empty())
        .map(|t| {
            let t = t.trim().to_ascii_lowercase();
            let (num, mul) = if let Some(n) = t.strip_suffix('m') {
                (n, 1_000_000)
            } else if let Some(n) = t.strip_suffix('k') {
                (n, 1000)
            } else {
                (t.as_str(), 1)
            };
            Ok(num.parse::<usize>().with_context(|| format!("'{t}'"))? * mul)
        })
        .collect()
}

fn default_bin() -> PathBuf {
    // target/release/examples/scale -> target/release/holefill
    std::env::current_exe()
        .ok()
        .and_then(|p| Some(p.parent()?.parent()?.join("holefill")))
        .unwrap_or_else(|| PathBuf::from("target/release/holefill"))
}

fn mesh_table(bin: &Path, sizes: &[usize], dir: &Path) -> Result<()> {
    println!(
        "| faces | holes | file MB | end-to-end s (wall) | CPU s (user + sys) | peak memory MB | filled / holes |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---|");
    for &n in sizes {
        let raw = torus_scan(n, 100, 1);
        let input = dir.join(format!("torus-{n}.ply"));
        holefill::write(&input, &raw, None)?;
        let nfaces = raw.faces.len();
        drop(raw);
        let bytes = std::fs::metadata(&input)?.len();
        let output = dir.join(format!("torus-{n}-out.ply"));
        let report = dir.join(format!("torus-{n}.json"));
        let args = [
            "fill",
            input.to_str().context("path")?,
            output.to_str().context("path")?,
            "--quiet",
            "--report",
            report.to_str().context("path")?,
        ];
        // warm the page cache (a scan pipeline reads files it just received)
        std::hint::black_box(std::fs::read(&input)?);
        let run = run_child(bin, &args, Duration::from_secs(600))?;
        let summary = std::fs::read_to_string(&report)
            .ok()
            .and_then(|s| serde_json::from_str::<serde_json::Value>(&s).ok())
            .map(|v| {
                let s = &v["summary"];
                format!("{} / {}", s["filled"], s["holes"])
            })
            .unwrap_or_else(|| format!("exit {:?}: {}", run.status, run.stderr.trim()));
        println!(
            "| {} ({nfaces}) | 100 | {:.0} | {:.2} | {} | {} | {} |",
            human(n),
            bytes as f64 / 1e6,
            run.wall.as_secs_f64(),
            run.cpu_s
                .map(|c| format!("{c:.2}"))
                .unwrap_or_else(|| "?".into()),
            run.max_rss_kb
                .map(|k| format!("{:.0}", k as f64 / 1024.0))
                .unwrap_or_else(|| "?".into()),
            summary
        );
        let _ = std::fs::remove_file(&input);
        let _ = std::fs::remove_file(&output);
    }
    Ok(())
}

fn hole_table(bin: &Path, ks: &[usize], limit_ms: u64, dir: &Path) -> Result<()> {
    print!("| method |");
    for &k in ks {
        print!(" k = {} |", human(k));
    }
    println!();
    print!("|---|");
    for _ in ks {
        print!("---:|");
    }
    println!();
    let inputs: Vec<PathBuf> = ks
        .iter()
        .map(|&k| {
            let p = dir.join(format!("cap-{k}.ply"));
            holefill::write(&p, &capped_sphere(k), None).map(|_| p)
        })
        .collect::<Result<_, _>>()?;
    for m in METHODS {
        let policy = dir.join(format!("{m}.toml"));
        std::fs::write(
            &policy,
            format!(
                "[dispatch]\nsmall = [\"{m}\"]\nmiddle = [\"{m}\"]\nlarge = [\"{m}\"]\n\
                 [border]\nmax_bbox_share = 0.0\n[limits]\nhole_time_ms = {limit_ms}\n"
            ),
        )?;
        print!("| {m} |");
        for input in &inputs {
            let output = dir.join("cap-out.ply");
            let report = dir.join("cap.json");
            let _ = std::fs::remove_file(&report);
            let args = [
                "fill",
                input.to_str().context("path")?,
                output.to_str().context("path")?,
                "--quiet",
                "--policy",
                policy.to_str().context("path")?,
                "--report",
                report.to_str().context("path")?,
            ];
            // the method stops itself at the limit; the kill is the backstop
            let backstop = Duration::from_millis(limit_ms * 3 + 30_000);
            let run = run_child(bin, &args, backstop)?;
            print!(" {} |", cell(&run, &report, limit_ms));
            use std::io::Write;
            std::io::stdout().flush()?;
        }
        println!();
    }
    Ok(())
}

/// The table cell of one method on one hole.
fn cell(run: &Run, report: &Path, limit_ms: u64) -> String {
    if run.killed {
        return format!("> {} s (killed)", run.wall.as_secs());
    }
    let Some(v) = std::fs::read_to_string(report)
        .ok()
        .and_then(|s| serde_json::from_str::<serde_json::Value>(&s).ok())
    else {
        let msg = run.stderr.lines().last().unwrap_or("").trim().to_string();
        return format!("failed: exit {:?} {msg}", run.status);
    };
    let Some(h) = v["holes"].as_array().and_then(|a| a.first()) else {
        return "failed: no hole found".into();
    };
    let ms = h["ms"].as_f64().unwrap_or(0.0);
    match h["status"].as_str() {
        Some("filled") => {
            if ms >= 1000.0 {
                format!("{:.1} s", ms / 1000.0)
            } else {
                format!("{ms:.0} ms")
            }
        }
        _ => {
            let reason = h["reason"].as_str().unwrap_or("").to_string();
            if reason.contains("time limit") {
                format!("> {} s", limit_ms as f64 / 1000.0)
            } else {
                let short: String = reason.chars().take(60).collect();
                format!("failed: {short}")
            }
        }
    }
}

/// CPU time of this thread (from /proc/thread-self/schedstat), else wall time.
fn cpu_now() -> Duration {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .map(Duration::from_nanos)
        .unwrap_or_else(|| Instant::now().elapsed())
}

/// Times the stages of a repair that do not depend on the holes (CPU time of the
/// main thread and wall time), for profiling the pipeline on huge scans.
fn phases(file: &Path) -> Result<()> {
    let mut t = (Instant::now(), cpu_now());
    let mut lap = |what: &str| {
        let now = (Instant::now(), cpu_now());
        println!(
            "{what:<28} {:>8.3} s wall {:>8.3} s cpu",
            (now.0 - t.0).as_secs_f64(),
            (now.1.saturating_sub(t.1)).as_secs_f64()
        );
        t = (Instant::now(), cpu_now());
    };
    let raw = holefill::read(file, None)?;
    lap("read");
    let (mesh, _) = holefill::mesh::Mesh::from_raw(&raw);
    lap("Mesh::from_raw");
    mesh.validate().map_err(anyhow::Error::msg)?;
    lap("Mesh::validate");
    let loops = mesh.topo.boundary_loops();
    lap("boundary_loops");
    let checker = holefill::check::Checker::new(&mesh);
    lap("Checker::new");
    drop(checker);
    let out = mesh.to_raw(&raw);
    lap("Mesh::to_raw");
    let dir = tempfile::tempdir()?;
    let ext = file.extension().and_then(|e| e.to_str()).unwrap_or("ply");
    holefill::write(&dir.path().join(format!("out.{ext}")), &out, None)?;
    lap("write");
    println!("{} loops", loops.len());
    Ok(())
}

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("gen") {
        let [_, faces, holes, out] = args.as_slice() else {
            bail!("usage: scale gen FACES HOLES OUT");
        };
        let t = Instant::now();
        let raw = torus_scan(parse_list(faces)?[0], holes.parse()?, 1);
        holefill::write(Path::new(out), &raw, None)?;
        eprintln!(
            "{out}: {} vertices, {} faces ({:.1} s)",
            raw.positions.len(),
            raw.faces.len(),
            t.elapsed().as_secs_f64()
        );
        return Ok(());
    }
    if args.first().map(String::as_str) == Some("phases") {
        let [_, file] = args.as_slice() else {
            bail!("usage: scale phases FILE");
        };
        return phases(Path::new(file));
    }
    let mut sizes = vec![100_000, 1_000_000, 10_000_000];
    let mut ks = vec![50, 200, 1000, 10_000];
    let mut limit_ms = 60_000u64;
    let mut bin = default_bin();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut val = || it.next().context("a value after the option");
        match a.as_str() {
            "--sizes" => sizes = parse_list(val()?)?,
            "--hole-sizes" => ks = parse_list(val()?)?,
            "--time-limit-ms" => limit_ms = val()?.parse()?,
            "--bin" => bin = PathBuf::from(val()?),
            other => bail!("unknown argument {other}"),
        }
    }
    if !bin.exists() {
        bail!(
            "{} not found: run cargo build --release first",
            bin.display()
        );
    }
    let dir = tempfile::tempdir()?;
    println!(
        "holefill scale benchmark, {} cores\n",
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    if !sizes.is_empty() {
        println!("End-to-end `holefill fill` (read, fill, write; binary PLY, default policy):\n");
        mesh_table(&bin, &sizes, dir.path())?;
        println!();
    }
    if !ks.is_empty() {
        println!(
            "Fill time of one hole of k boundary vertices, one method alone \
             (hole_time_ms = {limit_ms}):\n"
        );
        hole_table(&bin, &ks, limit_ms, dir.path())?;
    }
    Ok(())
}
