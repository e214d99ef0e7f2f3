//! Reading speed of the mesh readers against a plain read of the same file.
//!
//! `cargo run --release --example readspeed [-- FACES]` writes a scan-like mesh of
//! about `FACES` triangles (default 1,000,000; a wavy height field with `f32`
//! coordinates) as OBJ, binary PLY and binary STL into a temporary folder, then, for
//! each file, after a warm-up read (so the file is in the page cache), times
//!
//! - the plain read: `std::fs::read` of the whole file into memory (a fresh buffer,
//!   so page faults included), the physical limit the readers are compared with,
//! - `cat`: the file through one reused 1 MiB buffer, like `cat file > /dev/null`
//!   (no page faults: an upper bound on what any reader can reach), and
//! - `holefill::read` of the file (parse, checks; STL also welds corners): the
//!   function `holefill fill` reads its input with (there under the policy's
//!   limits, which change no work),
//!
//! each the best of several runs, and prints MB/s and the ratio read / plain, with
//! rayon's thread count and the load average (the OBJ reader parses in parallel, so
//! on a shared machine its numbers depend on what other processes leave free).

use glam::DVec3;
use holefill::io::{Encoding, Format, Precision, RawMesh};
use std::path::Path;
use std::time::{Duration, Instant};

fn scan_like(faces: usize) -> RawMesh {
    // n × n vertices give 2 (n-1)^2 triangles.
    let n = ((faces as f64 / 2.0).sqrt() as usize + 1).max(2);
    let mut positions = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f64 / n as f64 * 0.3, j as f64 / n as f64 * 0.3);
            let z = 0.01 * (40.0 * x).sin() * (31.0 * y).cos() + 0.002 * (x * 977.0).sin();
            // Stored as f32, like a scanner's output.
            positions.push(DVec3::new(x, y, z).as_vec3().as_dvec3());
        }
    }
    let mut tris = Vec::with_capacity(2 * (n - 1) * (n - 1));
    for j in 0..n - 1 {
        for i in 0..n - 1 {
            let v = (j * n + i) as u32;
            let (r, u, ru) = (v + 1, v + n as u32, v + n as u32 + 1);
            tris.push([v, r, ru]);
            tris.push([v, ru, u]);
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

fn best_of<T>(runs: usize, mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut best = Duration::MAX;
    let mut last = None;
    for _ in 0..runs {
        let t = Instant::now();
        let r = f();
        best = best.min(t.elapsed());
        last = Some(r);
    }
    match last {
        Some(r) => (best, r),
        None => (best, f()),
    }
}

/// Reads the file through one reused 1 MiB buffer; returns the byte count.
fn cat(path: &Path) -> std::io::Result<u64> {
    use std::io::Read;
    let mut f = std::fs::File::open(path)?;
    let mut buf = vec![0u8; 1 << 20];
    let mut n = 0u64;
    loop {
        match f.read(&mut buf)? {
            0 => return Ok(n),
            k => n += k as u64,
        }
    }
}

fn mbps(bytes: u64, d: Duration) -> f64 {
    bytes as f64 / 1e6 / d.as_secs_f64().max(1e-9)
}

fn main() -> anyhow::Result<()> {
    let faces: usize = match std::env::args().nth(1) {
        Some(s) => s.parse()?,
        None => 1_000_000,
    };
    let runs = 5;
    let raw = scan_like(faces);
    let dir = tempfile::tempdir()?;
    println!(
        "mesh: {} vertices, {} faces; best of {runs} runs after a warm-up",
        raw.positions.len(),
        raw.faces.len()
    );
    // The OBJ reader parses on rayon's threads, the STL reader maps memory on them:
    // what other processes leave of the cores shows in the numbers.
    let load = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|s| s.split_whitespace().next().map(str::to_string))
        .unwrap_or_else(|| "unknown".into());
    println!(
        "threads: {} (rayon) on {} cores; load average (1 min): {load}",
        rayon::current_num_threads(),
        std::thread::available_parallelism().map_or(1, |n| n.get())
    );
    println!(
        "{:<11} {:>7} {:>11} {:>9} {:>10} {:>8} {:>12} {:>10}",
        "format", "MB", "plain MB/s", "cat MB/s", "read MB/s", "read s", "read/plain", "read/cat"
    );
    for (name, format) in [
        ("obj", Format::Obj),
        ("ply (bin)", Format::Ply),
        ("stl (bin)", Format::Stl),
    ] {
        let path = dir.path().join(format!("mesh.{}", format.name()));
        holefill::write(&path, &raw, Some(format))?;
        let bytes = std::fs::metadata(&path)?.len();
        // Warm-up: the file in the page cache, the allocator primed.
        std::hint::black_box(std::fs::read(&path)?);
        let (plain, data) = best_of(runs, || std::fs::read(&path));
        std::hint::black_box(data?);
        let (cat, n) = best_of(runs, || cat(&path));
        assert_eq!(n?, bytes);
        let (read, mesh) = best_of(runs, || holefill::read(Path::new(&path), Some(format)));
        let mesh = mesh?;
        assert_eq!(mesh.faces.len(), raw.faces.len());
        println!(
            "{:<11} {:>7.1} {:>11.0} {:>9.0} {:>10.0} {:>8.3} {:>11.1}x {:>9.1}x",
            name,
            bytes as f64 / 1e6,
            mbps(bytes, plain),
            mbps(bytes, cat),
            mbps(bytes, read),
            read.as_secs_f64(),
            read.as_secs_f64() / plain.as_secs_f64().max(1e-9),
            read.as_secs_f64() / cat.as_secs_f64().max(1e-9)
        );
    }
    Ok(())
}
