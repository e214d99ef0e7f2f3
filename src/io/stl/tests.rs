use super::*;
use crate::io::ReadLimits;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn ascii_text_is_recognised_in_the_first_bytes() {
    assert!(text_facets_follow(b"solid cube\n  facet normal 0 0 1\n"));
    assert!(text_facets_follow(b"solid\r\nendsolid\r\n"));
    let mut binary = b"solid exported by some tool".to_vec();
    binary.resize(84, 0);
    assert!(!text_facets_follow(&binary));
    assert!(!text_facets_follow(
        b"solid name without newline in 84 bytes"
    ));
}

#[test]
fn welder_merges_signed_zeros_only() {
    let mut pos = Vec::new();
    let mut w = Welder::new(4, MAX_ELEMENTS);
    let a = w.vertex(DVec3::new(0.0, 1.0, 2.0), &mut pos);
    let b = w.vertex(DVec3::new(-0.0, 1.0, 2.0), &mut pos);
    let c = w.vertex(DVec3::new(f64::from(0.1f32), 1.0, 2.0), &mut pos);
    let d = w.vertex(DVec3::new(0.1, 1.0, 2.0), &mut pos);
    assert_eq!((a, b), (Some(0), Some(0)));
    assert_eq!((c, d), (Some(1), Some(2)));
    assert_eq!(pos.len(), 3);
}

/// The binary reader as it was before batching: one record at a time, welded
/// through the general hash map on the `f64` bit pattern (the `f32` widened
/// exactly). The reference [`read_binary`] is compared with.
fn read_binary_reference(src: &[u8], n: u32, caps: &Caps) -> Result<RawMesh, IoError> {
    let path = Path::new("t.stl");
    let mut reader = src;
    let mut raw = RawMesh {
        precision: Precision::F32,
        encoding: Encoding::BinaryLittleEndian,
        ..RawMesh::default()
    };
    let mut welder = Welder::new(16, caps.vertices().min(MAX_ELEMENTS - 1));
    let mut rec = [0u8; 50];
    for t in 0..n {
        reader
            .read_exact(&mut rec)
            .map_err(|e| read_error(path, e, &format!("triangle {t}")))?;
        let mut face = [0u32; 3];
        for (k, slot) in face.iter_mut().enumerate() {
            let c = |o: usize| f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]]);
            let o = 12 + 12 * k;
            let p = [c(o), c(o + 4), c(o + 8)];
            if !p.iter().all(|c| c.is_finite()) {
                let p = glam::Vec3::from_array(p);
                return Err(malformed(
                    path,
                    None,
                    format!("triangle {t}: non-finite coordinate {p} (NaN and infinity are not allowed)"),
                ));
            }
            let p = glam::Vec3::from_array(p).as_dvec3();
            *slot = welder
                .vertex(p, &mut raw.positions)
                .ok_or_else(|| malformed(path, None, caps.vertex_msg(None)))?;
        }
        raw.faces.push(face);
    }
    welder.note(&mut raw);
    Ok(raw)
}

/// Random binary STL records: corners drawn from a pool of positions (so that
/// many repeat, as in a scan, some far apart), with `-0.0` and `+0.0`, values that
/// differ in the last bit, and with `bad`, one non-finite coordinate.
fn random_records(rng: &mut ChaCha8Rng, n: usize, pool: usize, bad: bool) -> Vec<u8> {
    let pool: Vec<[f32; 3]> = (0..pool.max(1))
        .map(|_| {
            let mut c = || match rng.random_range(0..10) {
                0 => 0.0,
                1 => -0.0,
                2 => f32::from_bits(0x3f80_0001),
                3 => 1.0,
                _ => rng.random_range(-1.0f32..1.0),
            };
            [c(), c(), c()]
        })
        .collect();
    let bad_at = rng.random_range(0..3 * n.max(1));
    let mut out = Vec::with_capacity(50 * n);
    for t in 0..n {
        out.extend_from_slice(&[0u8; 12]); // normal (ignored)
        for k in 0..3 {
            // Mostly recent pool entries, sometimes any.
            let i = if rng.random_bool(0.8) {
                (t / 2 + rng.random_range(0..4)) % pool.len()
            } else {
                rng.random_range(0..pool.len())
            };
            let mut p = pool[i];
            if bad && 3 * t + k == bad_at {
                p[rng.random_range(0..3)] =
                    [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][rng.random_range(0..3)];
            }
            for c in p {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        out.extend_from_slice(&[0u8; 2]); // attribute bytes
    }
    out
}

#[test]
fn binary_reader_matches_reference() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let mut checked = 0;
    for case in 0..200 {
        let n = match case % 5 {
            0 => rng.random_range(1..5),
            1 => rng.random_range(30..100),
            // Past one read of READ_TRIANGLES.
            2 if case % 20 == 2 => rng.random_range(READ_TRIANGLES..READ_TRIANGLES + 3000),
            _ => rng.random_range(100..3000),
        };
        // A small pool welds a lot; a pool of 3n all-distinct corners makes the
        // table grow past its first estimate.
        let pool = if case % 7 == 0 {
            3 * n
        } else {
            rng.random_range(1..n + 3)
        };
        let mut src = random_records(&mut rng, n, pool, case % 4 == 1);
        if case % 9 == 0 {
            // Truncated: the header's count says more than the data holds.
            src.truncate(rng.random_range(0..src.len()));
        }
        let caps = if case % 6 == 0 {
            Caps::new(&ReadLimits {
                max_vertices: rng.random_range(1..(pool as u64 + 2)),
                ..ReadLimits::default()
            })
        } else {
            Caps::none()
        };
        let want = read_binary_reference(&src, n as u32, &caps);
        let got = read_binary(Path::new("t.stl"), src.as_slice(), n as u32, &caps);
        match (&got, &want) {
            (Ok(a), Ok(b)) => {
                let bits = |m: &RawMesh| -> Vec<u64> {
                    m.positions
                        .iter()
                        .flat_map(|p| p.to_array())
                        .map(f64::to_bits)
                        .collect()
                };
                assert_eq!(bits(a), bits(b), "case {case}");
                assert_eq!(a.faces, b.faces, "case {case}");
                assert_eq!(a.notes, b.notes, "case {case}");
                assert_eq!((a.precision, a.encoding), (b.precision, b.encoding));
                checked += 1;
            }
            (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string(), "case {case}"),
            (a, b) => panic!(
                "case {case}: {:?} vs {:?}",
                a.as_ref().err(),
                b.as_ref().err()
            ),
        }
    }
    assert!(checked > 80, "{checked}");
}
