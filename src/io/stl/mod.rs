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
//!
//! Speed (binary): records are read 1 MB at a time and welded in batches of 32
//! triangles: the table lookups of a batch are loaded first so that their memory
//! waits overlap, then the corners are welded one by one in file order (the same
//! numbering as one at a time; a test compares with a plain hash-map weld). The
//! output arrays and the table are mapped by rayon's threads before the weld.

#[cfg(test)]
mod tests;
mod writer;

pub(crate) use writer::write;

use super::attrs::StlExtras;
use super::text::{
    has_nul, parse_coord, show, strip_comment, tokens, Lines, Next, MAX_LINE, UTF8_BOM,
};
use super::{io_error, malformed, read_error, Encoding, IoError, Precision, RawMesh};
use super::{Caps, MAX_ELEMENTS};
use crate::fasthash::FxBuild;
use glam::DVec3;
use rayon::prelude::*;
use std::collections::HashMap;
use std::io::{BufRead, Read};
use std::path::Path;

/// Welds corners into vertices by exact position. The key is the coordinates' bit
/// pattern, `[u64; 3]` of `f64` (ASCII STL; binary STL uses [`Welder32`]).
struct Welder<K = [u64; 3]> {
    map: HashMap<K, u32, FxBuild>,
    corners: u64,
    max: u64,
}

/// Welds binary STL corners by the bit pattern of their `f32` coordinates, in an
/// open-addressing table (linear probing, at most half full) whose 16-byte slots hold
/// the key and the vertex number, so that a lookup touches one cache line.
///
/// Corners come in batches ([`Welder32::prefetch`] then [`Welder32::vertex32`] for
/// each corner in order): a scan's table is far larger than the processor's caches,
/// and a lookup there waits for memory; loading the slots of a whole batch first lets
/// those waits overlap, then the corners are welded one by one exactly as without the
/// batch (the loads only warm the cache).
struct Welder32 {
    /// The vertex last found for each of `RECENT` hash classes (key and number + 1,
    /// zero when empty), checked before the table: a scan's corners mostly repeat
    /// within a few thousand vertices, so most lookups never touch the large table.
    recent: Vec<[u32; 4]>,
    /// Key and vertex number + 1; a zero number marks an empty slot.
    slots: Vec<[u32; 4]>,
    vertices: usize,
    corners: u64,
    max: u64,
    /// What the prefetching loads read (kept so that they are not optimised away).
    sink: u32,
}

/// Entries of [`Welder32::recent`] (256 KiB).
const RECENT: usize = 16384;

/// A freshly allocated, zeroed vector with its pages mapped by rayon's threads: a
/// write per page maps it (a zeroed allocation is only reserved until touched, and
/// in this workplace's virtual machines mapping costs about as much as reading the
/// same bytes from the page cache), so the reading thread does not map them one at
/// a time.
fn touched<T: Copy + Default + Send>(mut v: Vec<T>) -> Vec<T> {
    let per_page = (4096 / std::mem::size_of::<T>().max(1)).max(1);
    v.par_chunks_mut(per_page * 64).for_each(|c| {
        for x in c.iter_mut().step_by(per_page) {
            *x = T::default();
        }
    });
    v
}

/// A corner's weld key: the bit pattern of its coordinates, with `-0.0` as `+0.0`.
fn key32(p: [f32; 3]) -> [u32; 3] {
    // `+ 0.0` turns -0.0 into +0.0 and leaves every other value unchanged.
    p.map(|c| (c + 0.0).to_bits())
}

impl Welder32 {
    fn new(expected: usize, max: u64) -> Self {
        let cap = (expected.max(8) * 2).next_power_of_two();
        Welder32 {
            recent: vec![[0; 4]; RECENT],
            slots: touched(vec![[0; 4]; cap]),
            vertices: 0,
            corners: 0,
            max: max.min(MAX_ELEMENTS - 1),
            sink: 0,
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

    fn recent_index(h: usize) -> usize {
        (h >> 40) % RECENT
    }

    /// True when the recent vertices hold the key (then [`Welder32::vertex32`]
    /// needs no table lookup).
    fn is_recent(&self, key: &[u32; 3], h: usize) -> bool {
        // Without branches (whether a corner is recent is not predictable).
        self.recent
            .get(Self::recent_index(h))
            .is_some_and(|r| (r[3] != 0) & (r[0] == key[0]) & (r[1] == key[1]) & (r[2] == key[2]))
    }

    /// Loads the table slots of the hashes `hs` into the cache.
    fn prefetch(&mut self, hs: impl Iterator<Item = usize>) {
        let mask = self.slots.len() - 1;
        let mut sink = self.sink;
        for h in hs {
            sink = sink.wrapping_add(self.slots.get(h & mask).map_or(0, |s| s[3]));
        }
        self.sink = sink;
    }

    /// The vertex at the (finite) `f32` position `p` with key `key` and hash `h` (a
    /// new one when no earlier corner had exactly this key, stored at its number in
    /// `positions`, which may be longer: see [`read_binary`]); `None` past the
    /// vertex cap.
    fn vertex32(
        &mut self,
        p: [f32; 3],
        key: [u32; 3],
        h: usize,
        positions: &mut Vec<DVec3>,
    ) -> Option<u32> {
        self.corners += 1;
        let entry = |v: u32| [key[0], key[1], key[2], v];
        let ri = Self::recent_index(h);
        let r = self.recent.get(ri).copied().unwrap_or_default();
        if r[3] != 0 && r[..3] == key[..] {
            return Some(r[3] - 1);
        }
        let mask = self.slots.len() - 1;
        let mut i = h & mask;
        loop {
            let s = *self.slots.get(i)?;
            if s[3] == 0 {
                break;
            }
            if s[..3] == key[..] {
                *self.recent.get_mut(ri)? = s;
                return Some(s[3] - 1);
            }
            i = (i + 1) & mask;
        }
        let next = self.vertices;
        if next as u64 >= self.max {
            return None;
        }
        let e = entry(next as u32 + 1);
        *self.slots.get_mut(i)? = e;
        *self.recent.get_mut(ri)? = e;
        self.vertices += 1;
        let p = DVec3::new(f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        match positions.get_mut(next) {
            Some(slot) => *slot = p,
            None => positions.push(p),
        }
        if self.vertices * 2 > self.slots.len() {
            self.grow();
        }
        Some(next as u32)
    }

    fn grow(&mut self) {
        let cap = self.slots.len() * 2;
        let mask = cap - 1;
        let mut slots = vec![[0u32; 4]; cap];
        for e in self.slots.iter().filter(|e| e[3] != 0) {
            let key = [e[0], e[1], e[2]];
            let mut i = Self::hash(&key) & mask;
            while slots.get(i).is_some_and(|s| s[3] != 0) {
                i = (i + 1) & mask;
            }
            if let Some(s) = slots.get_mut(i) {
                *s = *e;
            }
        }
        self.slots = slots;
    }

    fn note(&self, raw: &mut RawMesh) {
        std::hint::black_box(self.sink);
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
            map: HashMap::with_capacity_and_hasher(capacity, FxBuild::default()),
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
            let mut raw = read_binary(path, reader, n, caps)?;
            if let (Some(h), Some(stl)) = (head.get(..80), raw.attrs.stl.as_mut()) {
                stl.header.copy_from_slice(h);
            }
            return Ok(raw);
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

/// Triangles read from the file at a time (1 MB).
const READ_TRIANGLES: usize = 20_000;
/// Triangles whose table slots are loaded together (see [`Welder32`]).
const BATCH: usize = 32;

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
    // The count was checked against the file size: these allocations are backed
    // by data (a closed surface has about half as many vertices as triangles). Both
    // are mapped in parallel up front and written by index; `positions` is cut to
    // the vertex count at the end.
    let expected = n as usize / 2 + 3;
    raw.faces = touched(vec![[0u32; 3]; n as usize]);
    raw.positions
        .par_extend(rayon::iter::repeat_n(DVec3::ZERO, expected));
    let mut welder = Welder32::new(expected, caps.vertices());
    let f = |rec: &[u8], o: usize| -> f32 {
        match rec.get(o..o + 4) {
            Some(&[a, b, c, d]) => f32::from_le_bytes([a, b, c, d]),
            _ => f32::NAN,
        }
    };
    let mut buf = Vec::with_capacity(50 * READ_TRIANGLES);
    // Each facet's attribute bytes (kept only when one is not zero).
    let mut attribute: Vec<u16> = Vec::new();
    // Triangles read so far.
    let mut t = 0usize;
    let mut corners = [([0f32; 3], [0u32; 3], 0usize); 3 * BATCH];
    while t < n as usize {
        buf.clear();
        let want = (50 * (n as usize - t).min(READ_TRIANGLES)) as u64;
        let got = (&mut reader).take(want).read_to_end(&mut buf);
        let whole = buf.len() / 50 * 50;
        for (k, rec) in buf
            .get(..whole)
            .unwrap_or_default()
            .chunks_exact(50)
            .enumerate()
        {
            if let Some(&[a, b]) = rec.get(48..50) {
                if (a, b) != (0, 0) && attribute.is_empty() {
                    attribute = vec![0; n as usize];
                }
                if let Some(slot) = attribute.get_mut(t + k) {
                    *slot = u16::from_le_bytes([a, b]);
                }
            }
        }
        for batch in buf.get(..whole).unwrap_or_default().chunks(50 * BATCH) {
            let recs = batch.chunks_exact(50);
            for (c, (rec, k)) in corners
                .iter_mut()
                .zip(recs.flat_map(|rec| (0..3).map(move |k| (rec, k))))
            {
                let o = 12 + 12 * k;
                let p = [f(rec, o), f(rec, o + 4), f(rec, o + 8)];
                let key = key32(p);
                *c = (p, key, Welder32::hash(&key));
            }
            let used = corners.get(..3 * (batch.len() / 50)).unwrap_or_default();
            let mut misses = [0usize; 3 * BATCH];
            let mut m = 0;
            for &(_, key, h) in used {
                if let Some(slot) = misses.get_mut(m) {
                    *slot = h;
                    m += usize::from(!welder.is_recent(&key, h));
                }
            }
            welder.prefetch(misses.iter().take(m).copied());
            for tri in corners.chunks_exact(3).take(batch.len() / 50) {
                let mut face = [0u32; 3];
                for (slot, &(p, key, h)) in face.iter_mut().zip(tri) {
                    if !p.iter().all(|c| c.is_finite()) {
                        let p = glam::Vec3::from_array(p);
                        return Err(malformed(
                            path,
                            None,
                            format!("triangle {t}: non-finite coordinate {p} (NaN and infinity are not allowed)"),
                        ));
                    }
                    *slot = welder
                        .vertex32(p, key, h, &mut raw.positions)
                        .ok_or_else(|| malformed(path, None, caps.vertex_msg(None)))?;
                }
                if let Some(f) = raw.faces.get_mut(t) {
                    *f = face;
                }
                t += 1;
            }
        }
        let what = format!("triangle {t}");
        match got {
            Err(e) => return Err(read_error(path, e, &what)),
            Ok(_) if (whole as u64) < want => {
                let eof = std::io::Error::from(std::io::ErrorKind::UnexpectedEof);
                return Err(read_error(path, eof, &what));
            }
            Ok(_) => {}
        }
    }
    raw.positions.truncate(welder.vertices);
    welder.note(&mut raw);
    raw.attrs.stl = Some(StlExtras {
        header: [0; 80],
        attribute,
    });
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
