//! What the fuzz targets check, shared by the cargo-fuzz targets
//! (`fuzz_targets/*.rs`) and the stable-Rust fuzzer (`examples/fuzz_stable.rs`),
//! which include this file with `#[path]`.
//!
//! A failed check panics (that is how both fuzzers see a finding).
#![allow(dead_code)]

use glam::DVec3;
use holefill::io::{Encoding, Format, Precision, RawMesh, ReadLimits};
use holefill::mesh::Mesh;
use holefill::policy::Policy;
use std::path::Path;

/// libFuzzer's panic hook aborts on every panic, even one that is caught; the
/// library catches faer's sparse-LU panic on a zero pivot (`fill/fair.rs`) and fails
/// the method over, so, like the `holefill` binary, the targets let those through
/// and keep every other panic fatal.
pub fn allow_caught_faer_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let from_faer = info.location().is_some_and(|l| l.file().contains("/faer-"));
            if !from_faer {
                previous(info);
            }
        }));
    });
}

/// Meshes up to this many faces read by a reader target are also repaired.
const REPAIR_FACES: usize = 300;

/// Reads `data` as `format`; a mesh that reads must satisfy what the readers promise
/// (faces, indices in range, finite coordinates, a colour per vertex), and a small
/// one goes through the whole repair too.
pub fn check_read(format: Format, data: &[u8]) {
    allow_caught_faer_panics();
    let path = Path::new("fuzz-input");
    let Ok(raw) = holefill::io::read_bytes(path, data, format, &ReadLimits::default()) else {
        return;
    };
    assert!(!raw.faces.is_empty(), "a mesh read without faces");
    let n = raw.positions.len();
    for f in &raw.faces {
        assert!(
            f.iter().all(|&i| (i as usize) < n),
            "index out of range: {f:?}"
        );
    }
    assert!(
        raw.positions.iter().all(|p| p.is_finite()),
        "non-finite coordinate read"
    );
    if let Some(c) = &raw.colors {
        assert_eq!(c.len(), n, "colour count");
        assert!(
            c.iter().flatten().all(|v| (0.0..=1.0).contains(v)),
            "colour outside [0, 1]: {:?}",
            c.iter()
                .find(|c| c.iter().any(|v| !(0.0..=1.0).contains(v)))
        );
    }
    if raw.faces.len() <= REPAIR_FACES {
        check_repair_of(&raw);
    }
}

/// Builds a small mesh from the bytes and repairs it.
pub fn check_repair(data: &[u8]) {
    allow_caught_faer_panics();
    if let Some(raw) = mesh_from_bytes(data) {
        check_repair_of(&raw);
    }
}

/// Repairs `raw` under the default policy (shorter time limit per hole); the result
/// must rebuild into a valid mesh and keep the input vertices first and bit-exact.
pub fn check_repair_of(raw: &RawMesh) {
    let policy = Policy::default_policy()
        .edit(|s| s.limits.hole_time_ms = 2_000)
        .expect("a valid time limit");
    let Ok((out, _report)) = holefill::repair(raw, &policy) else {
        return;
    };
    let n = out.positions.len();
    for f in &out.faces {
        assert!(
            f.iter().all(|&i| (i as usize) < n),
            "repair: index out of range {f:?}"
        );
    }
    assert!(
        out.positions.iter().all(|p| p.is_finite()),
        "repair: non-finite coordinate"
    );
    if !policy.smooth.enabled {
        assert!(n >= raw.positions.len(), "repair dropped input vertices");
        for (i, (a, b)) in raw.positions.iter().zip(&out.positions).enumerate() {
            assert!(
                a.to_array().map(f64::to_bits) == b.to_array().map(f64::to_bits),
                "repair moved input vertex {i}: {a} -> {b}"
            );
        }
    }
    let (mesh, _) = Mesh::from_raw(&out);
    if let Err(e) = mesh.validate() {
        panic!("repair result does not validate: {e}");
    }
}

/// A small mesh from bytes. First byte: mode (even: a grid with holes, odd: a free
/// triangle soup). Grid: side 3..=10 vertices, one bit per face removed (holes),
/// one byte per vertex moving it along z (and sometimes in x/y). Soup: up to 24
/// vertices on a coarse lattice (coincident and collinear points are likely), up to
/// 48 faces from index triples.
pub fn mesh_from_bytes(data: &[u8]) -> Option<RawMesh> {
    let (&mode, rest) = data.split_first()?;
    let mut bytes = rest.iter().copied();
    let mut next = move || bytes.next().unwrap_or(0);
    let mut positions = Vec::new();
    let mut faces = Vec::new();
    if mode % 2 == 0 {
        let k = 3 + usize::from(mode / 2) % 8;
        for j in 0..k {
            for i in 0..k {
                let b = next();
                let z = f64::from(b as i8) / 64.0;
                let (dx, dy) = if b % 7 == 0 {
                    (
                        f64::from(next() as i8) / 300.0,
                        f64::from(next() as i8) / 300.0,
                    )
                } else {
                    (0.0, 0.0)
                };
                positions.push(DVec3::new(i as f64 + dx, j as f64 + dy, z));
            }
        }
        let mut bits = 0u8;
        for c in 0..(k - 1) * (k - 1) * 2 {
            if c % 8 == 0 {
                bits = next();
            }
            let keep = bits & (1 << (c % 8)) == 0;
            let (q, second) = (c / 2, c % 2 == 1);
            let (i, j) = (q % (k - 1), q / (k - 1));
            let v = (j * k + i) as u32;
            let (r, u, ru) = (v + 1, v + k as u32, v + k as u32 + 1);
            if keep {
                faces.push(if second { [v, ru, u] } else { [v, r, ru] });
            }
        }
    } else {
        let nv = 3 + usize::from(next()) % 22;
        for _ in 0..nv {
            let (a, b, c) = (next(), next(), next());
            positions.push(DVec3::new(
                f64::from(a % 8) / 2.0,
                f64::from(b % 8) / 2.0,
                f64::from(c as i8) / 32.0,
            ));
        }
        let nf = 1 + usize::from(next()) % 48;
        for _ in 0..nf {
            let f = [next(), next(), next()].map(|x| u32::from(x) % nv as u32);
            faces.push(f);
        }
    }
    if faces.is_empty() {
        return None;
    }
    Some(RawMesh {
        positions,
        colors: None,
        faces,
        precision: Precision::F64,
        encoding: Encoding::Ascii,
        notes: Vec::new(),
        attrs: Default::default(),
    })
}
