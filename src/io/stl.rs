//! STL, binary and ASCII.
//!
//! Detection: binary when the file size is exactly `84 + 50 n` for the triangle
//! count `n` in bytes 80..84; otherwise ASCII when it starts with `solid` and parses.
//! STL stores every triangle corner separately, so corners are welded into vertices
//! by exact position: the key is the bit pattern of each coordinate (as read: the
//! `f32` widened to `f64` for binary, the parsed `f64` for ASCII), with `-0.0`
//! treated as `+0.0`. Vertices are numbered in order of first appearance. Binary
//! files read as precision `F32`; ASCII as `F64` (decimal text parsed exactly).
//! Facet normals and the attribute bytes are ignored on reading and recomputed on
//! writing.

use super::text::{
    has_nul, parse_coord, show, strip_comment, tokens, Lines, Next, MAX_LINE, UTF8_BOM,
};
use super::{io_error, malformed, read_error, Encoding, FastBuild, IoError, Precision, RawMesh};
use super::{Caps, MAX_ELEMENTS};
use glam::DVec3;
use std::collections::HashMap;
use std::io::{BufRead, Read, Write};
use std::path::Path;

/// Welds corners into vertices by exact position. The key is the coordinates' bit
/// pattern, `[u64; 3]` of `f64` (ASCII STL; binary STL uses [`Welder32`]).
struct Welder<K = [u64; 3]> {
    map: HashMap<K, u32, FastBuild>,
    corners: u64,
    max: u64,
}

/// Welds binary STL corners by the bit pattern of their `f32` coordinates, in a
/// compact open-addressing table: 4-byte slots holding vertex numbers (linear
/// probing, at most half full), the keys kept in vertex order. A quarter of the
/// memory of a general hash map per vertex, so the table of a 10M-face scan stays
/// mostly in the processor's cache; the keys of recent vertices, which most corners
/// repeat, are in cache too.
struct Welder32 {
    /// The vertex last found for each of `RECENT` hash classes, checked before the
    /// table: a scan's corners mostly repeat within a few thousand vertices, so most
    /// lookups never touch the large table.
    recent: Vec<u32>,
    slots: Vec<u32>,
    keys: Vec<[u32; 3]>,
    corners: u64,
    max: u64,
}

/// An empty slot (never a vertex number: vertices are fewer than `u32::MAX`).
const EMPTY: u32 = u32::MAX;

/// Entries of [`Welder32::recent`] (16 KiB).
const RECENT: usize = 4096;

impl Welder32 {
    fn new(expected: usize, max: u64) -> Self {
        let cap = (expected.max(8) * 2).next_power_of_two();
        Welder32 {
            recent: vec![EMPTY; RECENT],
            slots: vec![EMPTY; cap],
            keys: Vec::with_capacity(expected),
            corners: 0,
            max: max.min(MAX_ELEMENTS - 1),
        }
    }

    fn hash(k: &[u32; 3]) -> usize {
        let mut h = (u64::from(k[0]) | u64::from(k[1]) << 32).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            ^ u64::from(k[2]).wrapping_mul(0xc2b2_ae3d_27d4_eb4f);
        // murmur3 fmix64: every key bit reaches the low (slot) bits
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        (h ^ (h >> 33)) as usize
    }

    /// The vertex at the (finite) `f32` position `p` (a new one when no earlier
    /// corner had exactly this position; `-0.0` counts as `+0.0`); `None` past the
    /// vertex cap.
    fn vertex32(&mut self, p: [f32; 3], positions: &mut Vec<DVec3>) -> Option<u32> {
        self.corners += 1;
        // `+ 0.0` turns -0.0 into +0.0 and leaves every other value unchanged.
        let key = p.map(|c| (c + 0.0).to_bits());
        let h = Self::hash(&key);
        let r = (h >> 40) % RECENT;
        let s = self.recent[r];
        if s != EMPTY && self.keys[s as usize] == key {
            return Some(s);
        }
        let mask = self.slots.len() - 1;
        let mut i = h & mask;
        loop {
            let s = self.slots[i];
            if s == EMPTY {
                break;
            }
            if self.keys[s as usize] == key {
                self.recent[r] = s;
                return Some(s);
            }
            i = (i + 1) & mask;
        }
        let next = self.keys.len();
        if next as u64 >= self.max {
            return None;
        }
        self.slots[i] = next as u32;
        self.recent[r] = next as u32;
        self.keys.push(key);
        positions.push(DVec3::new(
            f64::from(p[0]),
            f64::from(p[1]),
            f64::from(p[2]),
        ));
        if self.keys.len() * 2 > self.slots.len() {
            self.grow();
        }
        Some(next as u32)
    }

    fn grow(&mut self) {
        let cap = self.slots.len() * 2;
        let mask = cap - 1;
        let mut slots = vec![EMPTY; cap];
        for (v, k) in self.keys.iter().enumerate() {
            let mut i = Self::hash(k) & mask;
            while slots[i] != EMPTY {
                i = (i + 1) & mask;
            }
            slots[i] = v as u32;
        }
        self.slots = slots;
    }

    fn note(&self, raw: &mut RawMesh) {
        note_weld(self.corners, raw);
    }
}

fn note_weld(corners: u64, raw: &mut RawMesh) {
    let welded = corners.saturating_sub(raw.positions.len() as u64);
    raw.notes.push(format!(
        "welded {corners} STL triangle corners into {} vertices by exact position ({welded} merged)",
        raw.positions.len()
    ));
}

impl<K: std::hash::Hash + Eq> Welder<K> {
    fn new(capacity: usize, max: u64) -> Self {
        Welder {
            map: HashMap::with_capacity_and_hasher(capacity, FastBuild::default()),
            corners: 0,
            max: max.min(MAX_ELEMENTS),
        }
    }

    /// The vertex with key `key` at `p` (a new one when no earlier corner had it).
    fn vertex_with(&mut self, key: K, p: DVec3, positions: &mut Vec<DVec3>) -> Option<u32> {
        self.corners += 1;
        let next = positions.len();
        match self.map.entry(key) {
            std::collections::hash_map::Entry::Occupied(e) => Some(*e.get()),
            std::collections::hash_map::Entry::Vacant(e) => {
                if next as u64 >= self.max {
                    return None;
                }
                positions.push(p);
                Some(*e.insert(next as u32))
            }
        }
    }

    fn note(&self, raw: &mut RawMesh) {
        note_weld(self.corners, raw);
    }
}

impl Welder<[u64; 3]> {
    /// The vertex at `p` (a new one when no earlier corner had exactly this position).
    fn vertex(&mut self, p: DVec3, positions: &mut Vec<DVec3>) -> Option<u32> {
        // `+ 0.0` turns -0.0 into +0.0 and leaves every other value unchanged.
        let key = [
            (p.x + 0.0).to_bits(),
            (p.y + 0.0).to_bits(),
            (p.z + 0.0).to_bits(),
        ];
        self.vertex_with(key, p, positions)
    }
}

/// True when the first bytes are ASCII STL text: no NUL byte, and the line after
/// `solid name` starts with `facet` or `endsolid`. Used when an ASCII file happens
/// to have the size of a binary one (binary headers often start with "solid" too).
fn text_facets_follow(head: &[u8]) -> bool {
    if head.contains(&0) {
        return false;
    }
    let Some(nl) = head.iter().position(|&b| b == b'\n') else {
        return false;
    };
    let rest = head.get(nl + 1..).unwrap_or(b"").trim_ascii_start();
    let starts = |w: &[u8]| {
        rest.get(..w.len())
            .is_some_and(|s| s.eq_ignore_ascii_case(w))
    };
    starts(b"facet") || starts(b"endsolid")
}

/// Reads an STL file of `len` bytes.
pub(crate) fn read<R: BufRead>(
    path: &Path,
    mut reader: R,
    len: u64,
    caps: &Caps,
) -> Result<RawMesh, IoError> {
    let mut head = Vec::with_capacity(84);
    (&mut reader)
        .take(84)
        .read_to_end(&mut head)
        .map_err(|e| io_error(path, e))?;
    let count = match head.get(80..84) {
        Some(&[a, b, c, d]) => Some(u32::from_le_bytes([a, b, c, d])),
        _ => None,
    };
    let is_solid = head
        .strip_prefix(UTF8_BOM)
        .unwrap_or(&head)
        .trim_ascii_start()
        .get(..5)
        .is_some_and(|s| s.eq_ignore_ascii_case(b"solid"));
    if let Some(n) = count {
        if 84 + 50 * u64::from(n) == len && !(is_solid && text_facets_follow(&head)) {
            return read_binary(path, reader, n, caps);
        }
    }
    if is_solid {
        let chained = std::io::Read::chain(head.as_slice(), reader);
        return read_ascii(path, chained, caps).map_err(|e| match (e, count) {
            (
                IoError::Malformed {
                    path,
                    line,
                    message,
                },
                Some(n),
            ) => IoError::Malformed {
                path,
                line,
                message: format!(
                    "{message} (read as ASCII STL; as binary STL its count of {n} triangles \
                     would need {} bytes, the file has {len})",
                    84 + 50 * u64::from(n)
                ),
            },
            (e, _) => e,
        });
    }
    match count {
        Some(n) => Err(malformed(
            path,
            None,
            format!(
                "binary STL header says {n} triangles, which needs 84 + 50 × {n} = {} bytes, \
                 but the file has {len} bytes",
                84 + 50 * u64::from(n)
            ),
        )),
        None => Err(malformed(
            path,
            None,
            format!("not an STL file: {len} bytes is too short for binary STL and it does not start with 'solid'"),
        )),
    }
}

fn read_binary<R: Read>(
    path: &Path,
    mut reader: R,
    n: u32,
    caps: &Caps,
) -> Result<RawMesh, IoError> {
    if u64::from(n) > caps.faces() {
        return Err(malformed(path, None, caps.face_msg(Some(u64::from(n)))));
    }
    let mut raw = RawMesh {
        precision: Precision::F32,
        encoding: Encoding::BinaryLittleEndian,
        ..RawMesh::default()
    };
    // The count was checked against the file size: these reservations are backed
    // by data (a closed surface has about half as many vertices as triangles).
    raw.faces.reserve(n as usize);
    raw.positions.reserve(n as usize / 2 + 3);
    let mut welder = Welder32::new(n as usize / 2 + 3, caps.vertices());
    let mut rec = [0u8; 50];
    let f = |rec: &[u8; 50], o: usize| -> f32 {
        match rec.get(o..o + 4) {
            Some(&[a, b, c, d]) => f32::from_le_bytes([a, b, c, d]),
            _ => f32::NAN,
        }
    };
    for t in 0..n {
        reader
            .read_exact(&mut rec)
            .map_err(|e| read_error(path, e, &format!("triangle {t}")))?;
        let mut face = [0u32; 3];
        for (k, slot) in face.iter_mut().enumerate() {
            let o = 12 + 12 * k;
            let p = [f(&rec, o), f(&rec, o + 4), f(&rec, o + 8)];
            if !p.iter().all(|c| c.is_finite()) {
                let p = glam::Vec3::from_array(p);
                return Err(malformed(
                    path,
                    None,
                    format!("triangle {t}: non-finite coordinate {p} (NaN and infinity are not allowed)"),
                ));
            }
            *slot = welder
                .vertex32(p, &mut raw.positions)
                .ok_or_else(|| malformed(path, None, caps.vertex_msg(None)))?;
        }
        raw.faces.push(face);
    }
    welder.note(&mut raw);
    Ok(raw)
}

fn read_ascii<R: BufRead>(path: &Path, reader: R, caps: &Caps) -> Result<RawMesh, IoError> {
    let mut raw = RawMesh {
        precision: Precision::F64,
        encoding: Encoding::Ascii,
        ..RawMesh::default()
    };
    let mut lines = Lines::new(reader);
    let mut welder = Welder::new(1024, caps.vertices());
    let mut in_facet = false;
    let mut in_loop = false;
    let mut corners: Vec<u32> = Vec::with_capacity(4);
    let mut polygons = 0u64;
    loop {
        let (ln, line) = match lines.next_line(MAX_LINE).map_err(|e| io_error(path, e))? {
            Next::Line(ln, l) => (ln, l),
            Next::Eof => break,
            Next::Bad(ln, why) => return Err(malformed(path, Some(ln), why)),
        };
        let bad = |m: String| malformed(path, Some(ln), m);
        if has_nul(line) {
            return Err(bad("binary data (NUL byte) in an ASCII STL file".into()));
        }
        let mut t = tokens(strip_comment(line));
        let Some(kw) = t.next() else { continue };
        let is = |s: &[u8]| kw.eq_ignore_ascii_case(s);
        if is(b"solid") {
            if in_facet {
                return Err(bad("'solid' inside a facet".into()));
            }
        } else if is(b"facet") {
            if in_facet {
                return Err(bad("'facet' inside a facet (missing 'endfacet')".into()));
            }
            in_facet = true;
            corners.clear();
        } else if is(b"outer") {
            if !in_facet || in_loop {
                return Err(bad("'outer loop' outside a facet".into()));
            }
            in_loop = true;
        } else if is(b"vertex") {
            if !in_loop {
                return Err(bad("'vertex' outside 'outer loop'".into()));
            }
            let mut c = [0.0f64; 3];
            let mut n = 0;
            for tok in t {
                let slot = c
                    .get_mut(n)
                    .ok_or_else(|| bad("a vertex needs exactly 3 coordinates".into()))?;
                *slot = parse_coord(tok).map_err(&bad)?;
                n += 1;
            }
            if n != 3 {
                return Err(bad(format!(
                    "a vertex needs exactly 3 coordinates, found {n}"
                )));
            }
            let v = welder
                .vertex(DVec3::from_array(c), &mut raw.positions)
                .ok_or_else(|| bad(caps.vertex_msg(None)))?;
            corners.push(v);
        } else if is(b"endloop") {
            if !in_loop {
                return Err(bad("'endloop' without 'outer loop'".into()));
            }
            in_loop = false;
        } else if is(b"endfacet") {
            if !in_facet || in_loop {
                return Err(bad("'endfacet' without a complete facet".into()));
            }
            in_facet = false;
            let (&a, rest) = corners
                .split_first()
                .ok_or_else(|| bad("a facet needs at least 3 vertices, found 0".into()))?;
            if rest.len() < 2 {
                return Err(bad(format!(
                    "a facet needs at least 3 vertices, found {}",
                    corners.len()
                )));
            }
            if rest.len() > 2 {
                polygons += 1;
            }
            for w in rest.windows(2) {
                if let [b, c] = *w {
                    if raw.faces.len() as u64 >= caps.faces() {
                        return Err(bad(caps.face_msg(None)));
                    }
                    raw.faces.push([a, b, c]);
                }
            }
        } else if is(b"endsolid") {
            if in_facet {
                return Err(bad("'endsolid' inside a facet".into()));
            }
        } else {
            return Err(bad(format!("unexpected '{}' in ASCII STL", show(kw))));
        }
    }
    if in_facet {
        return Err(malformed(
            path,
            Some(lines.line()),
            "truncated file: it ends inside a facet",
        ));
    }
    welder.note(&mut raw);
    if polygons > 0 {
        raw.notes.push(format!(
            "fanned {polygons} STL facets with more than 3 vertices into triangles"
        ));
    }
    Ok(raw)
}

/// Unit normal of a triangle (zero when degenerate).
fn normal(raw: &RawMesh, f: &[u32; 3]) -> DVec3 {
    let p = |i: u32| {
        raw.positions
            .get(i as usize)
            .copied()
            .unwrap_or(DVec3::ZERO)
    };
    let (a, b, c) = (p(f[0]), p(f[1]), p(f[2]));
    (b - a).cross(c - a).normalize_or_zero()
}

/// Writes binary STL when `raw.encoding` is binary (always little-endian `f32`),
/// else ASCII STL. Normals are computed from the triangles.
pub(crate) fn write<W: Write>(w: &mut W, raw: &RawMesh) -> std::io::Result<()> {
    let pos = |i: u32| {
        raw.positions
            .get(i as usize)
            .copied()
            .unwrap_or(DVec3::ZERO)
    };
    if raw.encoding == Encoding::Ascii {
        let f32 = raw.precision == Precision::F32;
        w.write_all(b"solid holefill\n")?;
        for f in &raw.faces {
            let n = normal(raw, f).as_vec3();
            writeln!(w, "facet normal {} {} {}\n  outer loop", n.x, n.y, n.z)?;
            for &i in f {
                let p = pos(i);
                w.write_all(b"    vertex ")?;
                super::write_real(w, p.x, f32)?;
                w.write_all(b" ")?;
                super::write_real(w, p.y, f32)?;
                w.write_all(b" ")?;
                super::write_real(w, p.z, f32)?;
                w.write_all(b"\n")?;
            }
            w.write_all(b"  endloop\nendfacet\n")?;
        }
        w.write_all(b"endsolid holefill\n")?;
    } else {
        let mut header = [b' '; 80];
        let text = b"binary STL written by holefill";
        for (h, t) in header.iter_mut().zip(text) {
            *h = *t;
        }
        w.write_all(&header)?;
        let n = u32::try_from(raw.faces.len()).unwrap_or(u32::MAX);
        w.write_all(&n.to_le_bytes())?;
        let mut rec = [0u8; 50];
        for f in &raw.faces {
            let n = normal(raw, f).as_vec3();
            let vals = [
                n,
                pos(f[0]).as_vec3(),
                pos(f[1]).as_vec3(),
                pos(f[2]).as_vec3(),
            ];
            for (chunk, v) in rec
                .chunks_exact_mut(4)
                .zip(vals.iter().flat_map(|v| v.to_array()))
            {
                chunk.copy_from_slice(&v.to_le_bytes());
            }
            w.write_all(&rec)?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
}
