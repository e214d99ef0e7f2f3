//! Wavefront OBJ: `v` (with optional `w` or `r g b` vertex colours) and `f` records.
//!
//! A hand parser rather than `tobj`: `tobj` renumbers vertices in order of first use
//! (both with and without `single_index`), splits the file into models at every
//! `o`/`g`/`usemtl`, drops unreferenced vertices, turns a three-index `l` record into
//! a triangle, reports no line numbers, and allocates a `String` per line. The
//! project's rule "never renumber an input vertex" and the error requirements rule
//! it out. This parser reads the same subset (`v`, `f`, relative indices,
//! `v x y z r g b`, `v x y z w`) in the file's vertex order, ignores `vt`, `vn`, `o`,
//! `g`, `s`, `usemtl`, `mtllib`, `l`, `p` and unknown records, and fans polygons.
//!
//! Speed: the file is read in 8 MiB blocks, each cut at newlines into pieces parsed
//! in parallel (rayon) by a one-pass parser and appended in file order; relative
//! indices are resolved once the vertices before a piece are counted. Whatever that
//! parser does not take (every error, NUL bytes, stray carriage returns) is read
//! from the start of its piece on by the plain line-by-line reader, so results,
//! notes and errors (with their line) are always the line reader's; a test compares
//! the two on generated files.

use super::attrs::{Corners, ObjExtras, ObjState};
use super::text::{has_nul, parse_coord, parse_f64, parse_i64, show, strip_comment, tokens};
use super::text::{Lines, Next, MAX_LINE, UTF8_BOM};
use super::{io_error, malformed, unit_color, Caps, IoError, Precision, RawMesh, MAX_ELEMENTS};
use glam::DVec3;
use rayon::prelude::*;
use std::io::{BufRead, Read, Write};
use std::path::Path;

/// Bytes read from the file at a time; each block is cut at its last newline and
/// parsed in pieces in parallel.
const BLOCK: usize = 8 << 20;
/// Target size of the pieces a block is parsed in (each cut at a newline).
const PIECE: usize = 512 << 10;

/// What the reader has gathered so far: everything the line-by-line reader keeps
/// between lines, so that it can take over at any line the parallel reader reached.
struct State {
    raw: RawMesh,
    colors: Vec<[f32; 3]>,
    uncolored: usize,
    polygons: u64,
    w_scaled: u64,
    skipped_lp: u64,
    /// Largest positive index seen that referred past the vertices read so far
    /// (forward references are resolved at the end), with its line.
    forward: Option<(u64, usize)>,
    /// What the line reader gathers besides positions and faces.
    extra: Extra,
}

/// Texture coordinates, normals, per-corner indices and face states (only the line
/// reader reads them: the parallel parser hands a file over at the first such
/// record).
#[derive(Default)]
struct Extra {
    uv: Vec<[f64; 2]>,
    normals: Vec<[f64; 3]>,
    uv_index: Vec<Option<[u32; 3]>>,
    normal_index: Vec<Option<[u32; 3]>>,
    /// Largest `vt` / `vn` index used (0-based) and its line.
    max_uv: Option<(u64, usize)>,
    max_normal: Option<(u64, usize)>,
    mtllibs: Vec<String>,
    states: Vec<ObjState>,
    state_ids: crate::fasthash::HashMap<ObjState, u32>,
    current: ObjState,
    /// Per face, its state (from the first `usemtl`/`g`/`o`/`s` on).
    face_state: Vec<u32>,
    states_used: bool,
    /// Faces whose corners do not all have a texture coordinate (or a normal).
    partial: u64,
    uvw: u64,
}

impl Extra {
    /// Pads the per-face vectors to `nf` faces (those the parallel parser read,
    /// which have no corners and the default state).
    fn pad(&mut self, nf: usize) {
        if self.uv_index.len() < nf {
            self.uv_index.resize(nf, None);
        }
        if self.normal_index.len() < nf {
            self.normal_index.resize(nf, None);
        }
        if self.states_used && self.face_state.len() < nf {
            self.face_state.resize(nf, 0);
        }
    }
    /// The id of the current state.
    fn state(&mut self) -> u32 {
        if let Some(&id) = self.state_ids.get(&self.current) {
            return id;
        }
        let id = self.states.len() as u32;
        self.states.push(self.current.clone());
        self.state_ids.insert(self.current.clone(), id);
        id
    }
    /// Starts tracking states (the faces so far get the default state, id 0).
    fn use_states(&mut self, nf: usize) {
        if !self.states_used {
            self.states_used = true;
            let default = ObjState::default();
            self.states.push(default.clone());
            self.state_ids.insert(default, 0);
            self.face_state.resize(nf, 0);
        }
    }
}

impl State {
    fn new() -> State {
        State {
            raw: RawMesh {
                precision: Precision::F64,
                ..RawMesh::default()
            },
            colors: Vec::new(),
            uncolored: 0,
            polygons: 0,
            w_scaled: 0,
            skipped_lp: 0,
            forward: None,
            extra: Extra::default(),
        }
    }
}

/// Reads an OBJ file.
///
/// The file is read in blocks of [`BLOCK`] bytes; each block is cut at newlines into
/// pieces that are parsed in parallel ([`Piece::parse`]) and appended in file order
/// ([`State::append`]), indices relative to the vertices read so far resolved with
/// the count of the vertices before the piece. A piece the fast parser does not take
/// (any error, and lines it leaves to the line reader) and everything after it are
/// read by the line-by-line reader ([`read_lines`]) from the state reached, so the
/// result, notes and errors (with their line) are those of the line reader.
pub(crate) fn read<R: BufRead>(path: &Path, reader: R, caps: &Caps) -> Result<RawMesh, IoError> {
    read_in_blocks(path, reader, caps, BLOCK, PIECE)
}

fn read_in_blocks<R: BufRead>(
    path: &Path,
    mut reader: R,
    caps: &Caps,
    block: usize,
    piece: usize,
) -> Result<RawMesh, IoError> {
    let mut st = State::new();
    let mut buf: Vec<u8> = Vec::new();
    // The pieces' buffers, reused from block to block.
    let mut pool: Vec<Piece> = Vec::new();
    // Lines before buf[0].
    let mut line = 0usize;
    let mut eof = false;
    loop {
        // Fill the buffer to `block` bytes (it holds the unfinished last line of the
        // previous block).
        let mut io_err = None;
        if !eof && buf.len() < block {
            let want = (block - buf.len()) as u64;
            match (&mut reader).take(want).read_to_end(&mut buf) {
                Ok(k) => eof = (k as u64) < want,
                Err(e) => io_err = Some(e),
            }
        }
        let last_block = eof || io_err.is_some();
        let cut = if eof {
            buf.len()
        } else {
            match memchr::memrchr(b'\n', &buf) {
                Some(i) => i + 1,
                // A line longer than a block (or a read error inside the first
                // line of the block): the line reader takes over.
                None => 0,
            }
        };
        if cut == 0 && !eof {
            if let Some(e) = io_err {
                return Err(io_error(path, e));
            }
            let mut lines = Lines::starting_at(buf.as_slice().chain(reader), line);
            read_lines(path, &mut lines, caps, &mut st)?;
            return finish(path, st);
        }
        let bytes = buf.get(..cut).unwrap_or(&buf);
        let ranges = split_pieces(bytes, piece);
        if pool.len() < ranges.len() {
            pool.resize_with(ranges.len(), Piece::default);
        }
        let work = pool.get_mut(..ranges.len()).unwrap_or_default();
        let parse = |(p, &(a, b)): (&mut Piece, &(usize, usize))| {
            p.parse(bytes.get(a..b).unwrap_or(&[]), line == 0 && a == 0)
        };
        let ok: Vec<bool> = if ranges.len() > 1 {
            work.par_iter_mut().zip(&ranges).map(parse).collect()
        } else {
            work.iter_mut().zip(&ranges).map(parse).collect()
        };
        for ((&(a, _), p), ok) in ranges.iter().zip(pool.iter_mut()).zip(ok) {
            let taken = if ok {
                st.append(p, line, caps)
            } else {
                Err(())
            };
            match taken {
                Ok(n) => line += n,
                Err(()) => {
                    // The line reader takes over at the start of this piece.
                    let rest = buf.get(a..cut).unwrap_or(&[]);
                    if let Some(e) = io_err {
                        read_lines(path, &mut Lines::starting_at(rest, line), caps, &mut st)?;
                        return Err(io_error(path, e));
                    }
                    let rest = buf.get(a..).unwrap_or(&[]);
                    let mut lines = Lines::starting_at(rest.chain(reader), line);
                    read_lines(path, &mut lines, caps, &mut st)?;
                    return finish(path, st);
                }
            }
        }
        if let Some(e) = io_err {
            return Err(io_error(path, e));
        }
        if last_block {
            return finish(path, st);
        }
        buf.drain(..cut);
    }
}

/// Splits `bytes` (whole lines) into pieces of about `piece` bytes, each ending
/// just after a newline (the last one at the end of `bytes`).
fn split_pieces(bytes: &[u8], piece: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::with_capacity(bytes.len() / piece.max(1) + 1);
    let mut a = 0;
    while a < bytes.len() {
        let target = a.saturating_add(piece.max(1));
        let b = if target >= bytes.len() {
            bytes.len()
        } else {
            match bytes.get(target..).and_then(|t| memchr::memchr(b'\n', t)) {
                Some(i) => target + i + 1,
                None => bytes.len(),
            }
        };
        out.push((a, b));
        a = b;
    }
    out
}

/// A corner index of a face as a piece reads it.
#[derive(Clone, Copy)]
enum Corner {
    /// 0-based index into the file's vertices.
    Abs(u32),
    /// A relative (negative) index resolved against the piece's own vertices: the
    /// index is this plus the number of vertices before the piece (negative when it
    /// refers to a vertex of an earlier piece).
    Rel(i64),
}

/// What [`Piece::parse`] read from a piece of whole lines.
#[derive(Default)]
struct Piece {
    positions: Vec<DVec3>,
    /// Colours of the vertices with colour, in order.
    colors: Vec<[f32; 3]>,
    uncolored: usize,
    faces: Vec<[u32; 3]>,
    /// Corners (`3 * face + k`) holding a relative index, and that index resolved
    /// against the piece's vertices.
    rel: Vec<(usize, i64)>,
    polygons: u64,
    w_scaled: u64,
    skipped_lp: u64,
    /// Largest positive (0-based) index and the piece line (1-based) where it first
    /// appears.
    max_index: Option<(u64, usize)>,
    lines: usize,
}

impl Piece {
    /// Parses a piece of whole lines into `self` (cleared first) the way
    /// [`read_lines`] does; false (and `self` left in any state) on anything that
    /// [`read_lines`] must decide: every error, a NUL byte, a carriage return other
    /// than the one of a CRLF ending, a piece over [`MAX_LINE`] / 2. `at_start`: the
    /// piece starts the file (a byte order mark is skipped).
    fn parse(&mut self, bytes: &[u8], at_start: bool) -> bool {
        self.clear();
        self.parse_lines(bytes, at_start).is_some()
    }

    fn clear(&mut self) {
        self.positions.clear();
        self.colors.clear();
        self.uncolored = 0;
        self.faces.clear();
        self.rel.clear();
        self.polygons = 0;
        self.w_scaled = 0;
        self.skipped_lp = 0;
        self.max_index = None;
        self.lines = 0;
    }

    fn parse_lines(&mut self, bytes: &[u8], at_start: bool) -> Option<()> {
        if bytes.len() as u64 > MAX_LINE / 2 {
            return None;
        }
        let mut bytes = bytes;
        if at_start {
            bytes = bytes.strip_prefix(UTF8_BOM).unwrap_or(bytes);
        }
        if memchr::memchr3(0, b'\r', b'#', bytes).is_none() {
            // Without NUL, CR or '#' anywhere, the lines are parsed in place.
            let mut i = 0;
            while i < bytes.len() {
                self.lines += 1;
                i = self.line(bytes, i)?;
            }
            return Some(());
        }
        let mut rest = bytes;
        while !rest.is_empty() {
            let (mut line, next) = match memchr::memchr(b'\n', rest) {
                Some(i) => (rest.get(..i)?, rest.get(i + 1..)?),
                None => (rest, &[][..]),
            };
            rest = next;
            self.lines += 1;
            if let Some(t) = line.strip_suffix(b"\r") {
                line = t;
            }
            if let Some(i) = memchr::memchr3(0, b'\r', b'#', line) {
                if line.get(i) != Some(&b'#') || line.contains(&0) || line.contains(&b'\r') {
                    return None;
                }
                line = line.get(..i)?;
            }
            self.line(line, 0)?;
        }
        Some(())
    }
}

/// Token separators inside a line: ASCII whitespace ([`tokens`] splits at it) but
/// the newline, which ends the line (a carriage return never reaches here).
fn is_space(b: u8) -> bool {
    b == b' ' || b == b'\t' || b == b'\x0C'
}

/// Ends a token: a separator, the newline or the end of the line.
fn ends_token(b: Option<&u8>) -> bool {
    match b {
        None => true,
        Some(&b) => b == b'\n' || is_space(b),
    }
}

/// The index of the first byte at or after `i` that is not a separator.
fn skip_space(b: &[u8], mut i: usize) -> usize {
    while b.get(i).is_some_and(|&c| is_space(c)) {
        i += 1;
    }
    i
}

/// The index of the end of the token starting at `i`.
fn token_end(b: &[u8], mut i: usize) -> usize {
    while !ends_token(b.get(i)) {
        i += 1;
    }
    i
}

impl Piece {
    /// The line starting at `b[i]` (it ends at a newline or at the end of `b`);
    /// the index after it, `None` on any error.
    fn line(&mut self, b: &[u8], i: usize) -> Option<usize> {
        let start = skip_space(b, i);
        let end = token_end(b, start);
        let i = match b.get(start..end)? {
            b"v" => self.vertex(b, end)?,
            b"f" | b"fo" => self.face(b, end)?,
            // attributes: the line reader reads them (and the rest of the file)
            b"vt" | b"vn" | b"usemtl" | b"mtllib" | b"g" | b"o" | b"s" => return None,
            kw => {
                if kw == b"l" || kw == b"p" {
                    self.skipped_lp += 1;
                }
                match b.get(end..).and_then(|t| memchr::memchr(b'\n', t)) {
                    Some(k) => end + k,
                    None => b.len(),
                }
            }
        };
        // `i` is at the newline or the end.
        Some(i + 1)
    }

    /// The numbers of a `v` line from `b[i]`; the index of its end.
    fn vertex(&mut self, b: &[u8], mut i: usize) -> Option<usize> {
        let mut vals = [0.0f64; 6];
        let mut n = 0usize;
        loop {
            i = skip_space(b, i);
            if ends_token(b.get(i)) {
                break;
            }
            let v = real(b, &mut i).filter(|v| v.is_finite())?;
            *vals.get_mut(n)? = v;
            n += 1;
        }
        let [x, y, z, a, bb, c] = vals;
        let mut p = DVec3::new(x, y, z);
        match n {
            3 => self.uncolored += 1,
            4 => {
                if a == 0.0 {
                    return None;
                }
                if a != 1.0 {
                    p /= a;
                    self.w_scaled += 1;
                    if !p.is_finite() {
                        return None;
                    }
                }
                self.uncolored += 1;
            }
            6 => self.colors.push([a as f32, bb as f32, c as f32]),
            _ => return None,
        }
        self.positions.push(p);
        Some(i)
    }

    /// The indices of an `f` line from `b[i]`; the index of its end.
    fn face(&mut self, b: &[u8], mut i: usize) -> Option<usize> {
        let nv = self.positions.len() as i64;
        let mut first = Corner::Abs(0);
        let mut prev = Corner::Abs(0);
        let mut count = 0usize;
        loop {
            i = skip_space(b, i);
            if ends_token(b.get(i)) {
                break;
            }
            let k = index(b, &mut i)?;
            let c = if k > 0 {
                let i = (k - 1) as u64;
                if i >= MAX_ELEMENTS {
                    return None;
                }
                if self.max_index.is_none_or(|(m, _)| i > m) {
                    self.max_index = Some((i, self.lines));
                }
                Corner::Abs(i as u32)
            } else if k < 0 {
                Corner::Rel(nv + k)
            } else {
                return None;
            };
            count += 1;
            match count {
                1 => first = c,
                2 => prev = c,
                _ => {
                    let f = self.faces.len();
                    let mut face = [0u32; 3];
                    for (k, (slot, c)) in face.iter_mut().zip([first, prev, c]).enumerate() {
                        match c {
                            Corner::Abs(i) => *slot = i,
                            Corner::Rel(r) => self.rel.push((3 * f + k, r)),
                        }
                    }
                    self.faces.push(face);
                    prev = c;
                }
            }
        }
        if count < 3 {
            return None;
        }
        if count > 3 {
            self.polygons += 1;
        }
        Some(i)
    }
}

/// The vertex index of the face token at `b[*i]` (the part before a `/`), read as
/// [`parse_i64`] reads it; `*i` moves to the end of the token.
fn index(b: &[u8], i: &mut usize) -> Option<i64> {
    let neg = match b.get(*i) {
        Some(b'-') => {
            *i += 1;
            true
        }
        Some(b'+') => {
            *i += 1;
            false
        }
        _ => false,
    };
    let start = *i;
    // Accumulate negatively so that i64::MIN parses.
    let mut v: i64 = 0;
    while let Some(&d) = b.get(*i).filter(|d| d.is_ascii_digit()) {
        v = v.checked_mul(10)?.checked_sub(i64::from(d - b'0'))?;
        *i += 1;
    }
    if *i == start {
        return None;
    }
    match b.get(*i) {
        // corner indices: the line reader reads them
        Some(b'/') => return None,
        c if ends_token(c) => {}
        _ => return None,
    }
    if neg {
        Some(v)
    } else {
        v.checked_neg()
    }
}

/// The real number of the token at `b[*i]`, exactly as [`parse_f64`]
/// (`str::parse::<f64>`) reads it; `*i` moves to the end of the token.
///
/// Plain decimals `[+-]digits[.digits]` of at most 19 digits whose digits, read as
/// an integer `m`, are at most 2^53 and that have at most 22 digits after the point
/// are read in one pass by Clinger's fast path: `m` and `10^k` are exact `f64`s, so
/// the one IEEE division `m / 10^k` is the correctly rounded value, the one the
/// standard library (correctly rounded, and taking the same path) returns. Every
/// other token goes to [`parse_f64`].
fn real(b: &[u8], i: &mut usize) -> Option<f64> {
    let start = *i;
    let mut j = start;
    let neg = b.get(j) == Some(&b'-');
    if neg || b.get(j) == Some(&b'+') {
        j += 1;
    }
    let mut m = 0u64;
    let int = j;
    while let Some(d) = b.get(j).map(|c| c.wrapping_sub(b'0')).filter(|&d| d <= 9) {
        m = m.wrapping_mul(10).wrapping_add(u64::from(d));
        j += 1;
    }
    let int_digits = j - int;
    let mut frac_digits = 0;
    let mut dot_ok = true;
    if b.get(j) == Some(&b'.') {
        j += 1;
        let frac = j;
        while let Some(d) = b.get(j).map(|c| c.wrapping_sub(b'0')).filter(|&d| d <= 9) {
            m = m.wrapping_mul(10).wrapping_add(u64::from(d));
            j += 1;
        }
        frac_digits = j - frac;
        dot_ok = frac_digits > 0;
    }
    if ends_token(b.get(j))
        && int_digits > 0
        && dot_ok
        && int_digits + frac_digits <= 19
        && m <= 1 << 53
    {
        if let Some(&p) = POW10.get(frac_digits) {
            *i = j;
            let v = m as f64 / p;
            return Some(if neg { -v } else { v });
        }
    }
    let end = token_end(b, start);
    *i = end;
    parse_f64(b.get(start..end)?)
}

/// Powers of ten exactly representable as `f64`.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

impl State {
    /// Appends a piece that starts after `line` lines; its number of lines, or
    /// `Err` when the piece cannot be taken as read (a cap reached, a relative index
    /// before the first vertex): the line reader then reads it.
    fn append(&mut self, p: &mut Piece, line: usize, caps: &Caps) -> Result<usize, ()> {
        let nv = self.raw.positions.len();
        let nf = self.raw.faces.len();
        if (nv + p.positions.len()) as u64 > caps.vertices()
            || (nf + p.faces.len()) as u64 > caps.faces()
        {
            return Err(());
        }
        let faces = &mut p.faces;
        for &(corner, r) in &p.rel {
            let i = u32::try_from(r + nv as i64).map_err(|_| ())?;
            let slot = faces
                .get_mut(corner / 3)
                .and_then(|f| f.get_mut(corner % 3));
            *slot.ok_or(())? = i;
        }
        // The line reader's forward reference: the first line with the largest index.
        if let Some((i, l)) = p.max_index {
            if self.forward.is_none_or(|(m, _)| i > m) && i >= nv as u64 {
                self.forward = Some((i, line + l));
            }
        }
        self.raw.positions.extend_from_slice(&p.positions);
        self.raw.faces.extend_from_slice(faces);
        // Colours decide only through: any vertex with colour, the count of those
        // without, and (when all have one) the colours in order.
        self.colors.extend_from_slice(&p.colors);
        self.uncolored += p.uncolored;
        self.polygons += p.polygons;
        self.w_scaled += p.w_scaled;
        self.skipped_lp += p.skipped_lp;
        Ok(p.lines)
    }
}

/// The line-by-line reader: reads `lines` to the end into `st`.
fn read_lines<R: BufRead>(
    path: &Path,
    lines: &mut Lines<R>,
    caps: &Caps,
    st: &mut State,
) -> Result<(), IoError> {
    let State {
        raw,
        colors,
        uncolored,
        polygons,
        w_scaled,
        skipped_lp,
        forward,
        extra,
    } = st;
    // a face's corners: vertex, texture coordinate, normal (0-based)
    let mut corners: Vec<(u32, Option<u32>, Option<u32>)> = Vec::new();
    loop {
        let (ln, line) = match lines.next_line(MAX_LINE).map_err(|e| io_error(path, e))? {
            Next::Line(ln, l) => (ln, l),
            Next::Eof => return Ok(()),
            Next::Bad(ln, why) => return Err(malformed(path, Some(ln), why)),
        };
        let bad = |msg: String| malformed(path, Some(ln), msg);
        if has_nul(line) {
            return Err(bad("binary data (NUL byte) in a text OBJ file".into()));
        }
        let mut toks = tokens(strip_comment(line));
        match toks.next() {
            Some(b"v") => {
                if raw.positions.len() as u64 >= caps.vertices() {
                    return Err(bad(caps.vertex_msg(None)));
                }
                let mut vals = [0.0f64; 6];
                let mut n = 0usize;
                for t in toks {
                    let slot = vals.get_mut(n).ok_or_else(|| {
                        bad("too many numbers on a 'v' line (expected 3, 4 or 6)".into())
                    })?;
                    *slot = if n < 3 {
                        parse_coord(t).map_err(&bad)?
                    } else {
                        parse_f64(t)
                            .filter(|v| v.is_finite())
                            .ok_or_else(|| bad(format!("'{}' is not a finite number", show(t))))?
                    };
                    n += 1;
                }
                let [x, y, z, a, b, c] = vals;
                let mut p = DVec3::new(x, y, z);
                match n {
                    3 => *uncolored += 1,
                    4 => {
                        // Homogeneous coordinate w.
                        if a == 0.0 {
                            return Err(bad("vertex with w = 0".into()));
                        }
                        if a != 1.0 {
                            p /= a;
                            *w_scaled += 1;
                            if !p.is_finite() {
                                return Err(bad("vertex overflows when divided by w".into()));
                            }
                        }
                        *uncolored += 1;
                    }
                    6 => {
                        if colors.len() < raw.positions.len() {
                            // Earlier vertices had no colour: colours are dropped below.
                            colors.resize(raw.positions.len(), [0.0; 3]);
                        }
                        colors.push([a as f32, b as f32, c as f32]);
                    }
                    _ => {
                        return Err(bad(format!(
                            "a 'v' line needs 3, 4 or 6 numbers, found {n}"
                        )))
                    }
                }
                raw.positions.push(p);
            }
            Some(b"f") | Some(b"fo") => {
                let nv = raw.positions.len() as i64;
                corners.clear();
                for t in toks {
                    let mut parts = t.split(|&b| b == b'/');
                    let vtok = parts.next().unwrap_or(t);
                    let k = parse_i64(vtok)
                        .ok_or_else(|| bad(format!("'{}' is not a vertex index", show(t))))?;
                    let i = match k {
                        0 => return Err(bad("vertex index 0 (OBJ indices start at 1)".into())),
                        k if k > 0 => k - 1,
                        k => {
                            let i = nv + k;
                            if i < 0 {
                                return Err(bad(format!(
                                    "relative vertex index {k} refers before the first vertex ({nv} vertices so far)"
                                )));
                            }
                            i
                        }
                    };
                    if i as u64 >= MAX_ELEMENTS {
                        return Err(bad(format!("vertex index {k} out of range")));
                    }
                    if i >= nv && forward.is_none_or(|(m, _)| (i as u64) > m) {
                        *forward = Some((i as u64, ln));
                    }
                    let tt = parts.next().filter(|p| !p.is_empty());
                    let nt = parts.next().filter(|p| !p.is_empty());
                    let ti = match tt {
                        Some(p) => Some(
                            attr_index(
                                p,
                                extra.uv.len(),
                                "texture coordinate",
                                ln,
                                &mut extra.max_uv,
                            )
                            .map_err(&bad)?,
                        ),
                        None => None,
                    };
                    let ni = match nt {
                        Some(p) => Some(
                            attr_index(p, extra.normals.len(), "normal", ln, &mut extra.max_normal)
                                .map_err(&bad)?,
                        ),
                        None => None,
                    };
                    corners.push((i as u32, ti, ni));
                }
                let count = corners.len();
                if count < 3 {
                    return Err(bad(format!(
                        "a face needs at least 3 vertices, found {count}"
                    )));
                }
                if count > 3 {
                    *polygons += 1;
                }
                if raw.faces.len() as u64 + (count as u64 - 2) > caps.faces() {
                    return Err(bad(caps.face_msg(None)));
                }
                let all_t = corners.iter().all(|c| c.1.is_some());
                let all_n = corners.iter().all(|c| c.2.is_some());
                let any = corners.iter().any(|c| c.1.is_some() || c.2.is_some());
                if any && !(all_t || corners.iter().all(|c| c.1.is_none()))
                    || any && !(all_n || corners.iter().all(|c| c.2.is_none()))
                {
                    extra.partial += 1;
                }
                let state = if extra.states_used {
                    Some(extra.state())
                } else {
                    None
                };
                extra.pad(raw.faces.len());
                for j in 2..count {
                    let (Some(a), Some(b), Some(c)) =
                        (corners.first(), corners.get(j - 1), corners.get(j))
                    else {
                        continue;
                    };
                    raw.faces.push([a.0, b.0, c.0]);
                    extra.uv_index.push(match (all_t, a.1, b.1, c.1) {
                        (true, Some(x), Some(y), Some(z)) => Some([x, y, z]),
                        _ => None,
                    });
                    extra.normal_index.push(match (all_n, a.2, b.2, c.2) {
                        (true, Some(x), Some(y), Some(z)) => Some([x, y, z]),
                        _ => None,
                    });
                    if let Some(s) = state {
                        extra.face_state.push(s);
                    }
                }
            }
            Some(b"vt") => {
                let mut vals = [0.0f64; 2];
                let mut n = 0;
                for t in toks {
                    let v = parse_f64(t)
                        .ok_or_else(|| bad(format!("'{}' is not a number", show(t))))?;
                    if let Some(slot) = vals.get_mut(n) {
                        *slot = v;
                    }
                    n += 1;
                }
                if n == 0 || n > 3 {
                    return Err(bad(format!("a 'vt' line needs 1 to 3 numbers, found {n}")));
                }
                if n == 3 {
                    extra.uvw += 1;
                }
                extra.uv.push(vals);
            }
            Some(b"vn") => {
                let mut vals = [0.0f64; 3];
                let mut n = 0;
                for t in toks {
                    let v = parse_f64(t)
                        .ok_or_else(|| bad(format!("'{}' is not a number", show(t))))?;
                    if let Some(slot) = vals.get_mut(n) {
                        *slot = v;
                    }
                    n += 1;
                }
                if n != 3 {
                    return Err(bad(format!("a 'vn' line needs 3 numbers, found {n}")));
                }
                extra.normals.push(vals);
            }
            Some(b"mtllib") => {
                let rest = rest_of(strip_comment(line), b"mtllib");
                if !rest.is_empty() {
                    extra.mtllibs.push(rest);
                }
            }
            Some(kw @ (b"usemtl" | b"g" | b"o" | b"s")) => {
                extra.use_states(raw.faces.len());
                let rest = rest_of(strip_comment(line), kw);
                let v = (!rest.is_empty()).then_some(rest);
                match kw {
                    b"usemtl" => extra.current.material = v,
                    b"g" => extra.current.group = v,
                    b"o" => extra.current.object = v,
                    _ => extra.current.smoothing = v,
                }
            }
            Some(b"l") | Some(b"p") => *skipped_lp += 1,
            // vt, vn, vp, o, g, s, usemtl, mtllib, comments and unknown records.
            _ => {}
        }
    }
}

/// The checks and notes after the last line.
fn finish(path: &Path, st: State) -> Result<RawMesh, IoError> {
    let State {
        mut raw,
        mut colors,
        uncolored,
        polygons,
        w_scaled,
        skipped_lp,
        forward,
        mut extra,
    } = st;
    let n = raw.positions.len() as u64;
    for (max, count, what) in [
        (extra.max_uv, extra.uv.len(), "texture coordinate"),
        (extra.max_normal, extra.normals.len(), "normal"),
    ] {
        if let Some((i, ln)) = max {
            if i >= count as u64 {
                return Err(malformed(
                    path,
                    Some(ln),
                    format!("{what} index {} out of range (the file has {count})", i + 1),
                ));
            }
        }
    }
    let nf = raw.faces.len();
    extra.pad(nf);
    if extra.uv_index.iter().any(Option::is_some) || !extra.uv.is_empty() {
        raw.attrs.uv = Some(Corners {
            values: std::mem::take(&mut extra.uv),
            index: std::mem::take(&mut extra.uv_index),
        });
    }
    if extra.normal_index.iter().any(Option::is_some) || !extra.normals.is_empty() {
        raw.attrs.normals = Some(Corners {
            values: std::mem::take(&mut extra.normals),
            index: std::mem::take(&mut extra.normal_index),
        });
    }
    if extra.states_used || !extra.mtllibs.is_empty() {
        raw.attrs.obj = Some(ObjExtras {
            mtllibs: std::mem::take(&mut extra.mtllibs),
            states: std::mem::take(&mut extra.states),
            face_state: std::mem::take(&mut extra.face_state),
        });
    }
    if extra.partial > 0 {
        raw.notes.push(format!(
            "{} OBJ faces have texture coordinates or normals on some corners only: those faces keep none of that kind",
            extra.partial
        ));
    }
    if extra.uvw > 0 {
        raw.notes.push(format!(
            "dropped the third (w) texture coordinate of {} OBJ 'vt' records",
            extra.uvw
        ));
    }
    if let Some((i, ln)) = forward {
        if i >= n {
            return Err(malformed(
                path,
                Some(ln),
                format!(
                    "vertex index {} out of range (the file has {n} vertices)",
                    i + 1
                ),
            ));
        }
    }
    if !colors.is_empty() {
        if uncolored == 0 && colors.len() == raw.positions.len() {
            if colors.iter().flatten().any(|&c| c > 1.0) {
                for c in colors.iter_mut().flatten() {
                    *c /= 255.0;
                }
                raw.notes
                    .push("OBJ vertex colours above 1 read as 0..255 and divided by 255".into());
            }
            for c in colors.iter_mut().flatten() {
                *c = unit_color(f64::from(*c));
            }
            raw.colors = Some(colors);
        } else {
            raw.notes.push(format!(
                "OBJ vertex colours dropped: {uncolored} of {} vertices have none",
                raw.positions.len()
            ));
        }
    }
    if polygons > 0 {
        raw.notes.push(format!(
            "fanned {polygons} OBJ polygons with more than 3 vertices into triangles"
        ));
    }
    if w_scaled > 0 {
        raw.notes.push(format!(
            "divided {w_scaled} OBJ vertices by their w coordinate"
        ));
    }
    if skipped_lp > 0 {
        raw.notes.push(format!(
            "ignored {skipped_lp} OBJ line/point ('l'/'p') records"
        ));
    }
    Ok(raw)
}

/// A `vt`/`vn` index of a face corner (1-based, or negative: relative to the
/// `count` read so far), 0-based; the largest one is kept with its line for the
/// range check at the end.
fn attr_index(
    tok: &[u8],
    count: usize,
    what: &str,
    ln: usize,
    max: &mut Option<(u64, usize)>,
) -> Result<u32, String> {
    let k = parse_i64(tok).ok_or_else(|| format!("'{}' is not a {what} index", show(tok)))?;
    let i = match k {
        0 => return Err(format!("{what} index 0 (OBJ indices start at 1)")),
        k if k > 0 => k - 1,
        k => {
            let i = count as i64 + k;
            if i < 0 {
                return Err(format!(
                    "relative {what} index {k} refers before the first one"
                ));
            }
            i
        }
    };
    let i = u32::try_from(i).map_err(|_| format!("{what} index {k} out of range"))?;
    if max.is_none_or(|(m, _)| u64::from(i) > m) {
        *max = Some((u64::from(i), ln));
    }
    Ok(i)
}

/// The text of a line after its keyword, trimmed (`usemtl`, `g`, `mtllib`, ...).
fn rest_of(line: &[u8], kw: &[u8]) -> String {
    let t = line.trim_ascii_start();
    let t = t.strip_prefix(kw).unwrap_or(t);
    String::from_utf8_lossy(t.trim_ascii()).into_owned()
}

/// Writes an OBJ file: `mtllib`, `v x y z [r g b]`, `vt`, `vn`, the face states
/// (`o`, `g`, `usemtl`, `s` where they change) and `f a[/t][/n] ...` (1-based).
pub(crate) fn write<W: Write>(w: &mut W, raw: &RawMesh) -> std::io::Result<()> {
    let f32 = raw.precision == Precision::F32;
    writeln!(
        w,
        "# written by holefill\n# {} vertices, {} triangles",
        raw.positions.len(),
        raw.faces.len()
    )?;
    let a = &raw.attrs;
    if let Some(o) = &a.obj {
        for m in &o.mtllibs {
            writeln!(w, "mtllib {}", one_line(m))?;
        }
    }
    let colors = raw.colors.as_deref();
    for (i, p) in raw.positions.iter().enumerate() {
        w.write_all(b"v ")?;
        super::write_real(w, p.x, f32)?;
        w.write_all(b" ")?;
        super::write_real(w, p.y, f32)?;
        w.write_all(b" ")?;
        super::write_real(w, p.z, f32)?;
        if let Some(c) = colors.and_then(|c| c.get(i)) {
            write!(w, " {} {} {}", c[0], c[1], c[2])?;
        }
        w.write_all(b"\n")?;
    }
    if let Some(uv) = &a.uv {
        for t in &uv.values {
            w.write_all(b"vt ")?;
            super::write_real(w, t[0], false)?;
            w.write_all(b" ")?;
            super::write_real(w, t[1], false)?;
            w.write_all(b"\n")?;
        }
    }
    if let Some(n) = &a.normals {
        for t in &n.values {
            w.write_all(b"vn ")?;
            super::write_real(w, t[0], false)?;
            w.write_all(b" ")?;
            super::write_real(w, t[1], false)?;
            w.write_all(b" ")?;
            super::write_real(w, t[2], false)?;
            w.write_all(b"\n")?;
        }
    }
    let states = a.obj.as_ref().filter(|o| !o.face_state.is_empty());
    let default = ObjState::default();
    let mut last = &default;
    let uv = a.uv.as_ref();
    let nrm = a.normals.as_ref();
    for (k, f) in raw.faces.iter().enumerate() {
        if let Some(o) = states {
            let s = o
                .face_state
                .get(k)
                .and_then(|&s| o.states.get(s as usize))
                .unwrap_or(&default);
            if s.object != last.object {
                writeln!(w, "o {}", one_line(s.object.as_deref().unwrap_or("")))?;
            }
            if s.group != last.group {
                writeln!(w, "g {}", one_line(s.group.as_deref().unwrap_or("")))?;
            }
            if s.material != last.material {
                if let Some(m) = &s.material {
                    writeln!(w, "usemtl {}", one_line(m))?;
                }
            }
            if s.smoothing != last.smoothing {
                writeln!(w, "s {}", one_line(s.smoothing.as_deref().unwrap_or("off")))?;
            }
            last = s;
        }
        let t = uv.and_then(|c| c.index.get(k).copied().flatten());
        let n = nrm.and_then(|c| c.index.get(k).copied().flatten());
        w.write_all(b"f")?;
        for c in 0..3 {
            write!(w, " {}", u64::from(f[c]) + 1)?;
            match (t, n) {
                (Some(t), Some(n)) => {
                    write!(w, "/{}/{}", u64::from(t[c]) + 1, u64::from(n[c]) + 1)?
                }
                (Some(t), None) => write!(w, "/{}", u64::from(t[c]) + 1)?,
                (None, Some(n)) => write!(w, "//{}", u64::from(n[c]) + 1)?,
                (None, None) => {}
            }
        }
        w.write_all(b"\n")?;
    }
    Ok(())
}

/// A name on one line (a line break inside would start a record of its own).
fn one_line(s: &str) -> String {
    s.replace(['\n', '\r'], " ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::ReadLimits;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn parse(s: &str) -> Result<RawMesh, IoError> {
        read(Path::new("t.obj"), s.as_bytes(), &Caps::none())
    }

    #[test]
    fn relative_indices_and_fanning() {
        let m = parse("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n").unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2], [0, 2, 3]]);
        assert!(m.notes.iter().any(|n| n.contains("fanned 1")));
    }

    #[test]
    fn slashes_comments_and_ignored_records() {
        let m = parse(
            "# c\nmtllib a.mtl\no x\nv 0 0 0 # inline\nv 1 0 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n\
             usemtl m\ns off\nf 1/1/1 2//1 3/1\nl 1 2 3\n",
        )
        .unwrap();
        assert_eq!(m.faces, vec![[0, 1, 2]]);
        assert!(m.colors.is_none());
    }

    #[test]
    fn vertex_colours_and_order_kept() {
        let m = parse("v 5 0 0 1 0 0\nv 0 0 0 0 1 0\nv 0 1 0 0 0 1\nf 3 1 2\n").unwrap();
        assert_eq!(m.positions[0], DVec3::new(5.0, 0.0, 0.0));
        assert_eq!(m.faces, vec![[2, 0, 1]]);
        assert_eq!(m.colors.unwrap()[1], [0.0, 1.0, 0.0]);
    }

    #[test]
    fn forward_reference_is_allowed_but_range_checked() {
        assert!(parse("f 1 2 3\nv 0 0 0\nv 1 0 0\nv 0 1 0\n").is_ok());
        let e = parse("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n").unwrap_err();
        assert!(e.to_string().contains("t.obj:4"), "{e}");
    }

    #[test]
    fn errors_name_file_and_line() {
        for (src, line) in [
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", 4),
            ("v 0 0 0\nv 1 0 0\nf 1 2\n", 3),
            ("v 0 0 nan\n", 1),
            ("v 0 inf 0\n", 1),
            ("v 0 0\n", 1),
            ("v 0 0 0\nf -2 -1 1\n", 2),
            ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 x\n", 4),
            ("v 0 0 0\x00\n", 1),
        ] {
            let e = parse(src).unwrap_err();
            assert!(e.is_malformed());
            assert!(
                e.to_string().starts_with(&format!("t.obj:{line}:")),
                "{src:?}: {e}"
            );
        }
    }

    #[test]
    fn repeated_index_is_not_an_error() {
        assert!(parse("v 0 0 0\nv 1 0 0\nf 1 2 2\n").is_ok());
    }

    /// The line-by-line reader over the whole file: the reference the block reader
    /// is compared with.
    fn read_serial(src: &[u8], caps: &Caps) -> Result<RawMesh, IoError> {
        let mut st = State::new();
        read_lines(Path::new("t.obj"), &mut Lines::new(src), caps, &mut st)?;
        finish(Path::new("t.obj"), st)
    }

    /// Same result, bit for bit (coordinates and colours by their bits, faces,
    /// notes, and the error text with its line).
    fn same(a: &Result<RawMesh, IoError>, b: &Result<RawMesh, IoError>) -> Result<(), String> {
        match (a, b) {
            (Ok(a), Ok(b)) => {
                let bits = |m: &RawMesh| -> Vec<u64> {
                    m.positions
                        .iter()
                        .flat_map(|p| p.to_array())
                        .map(f64::to_bits)
                        .collect()
                };
                let cbits = |m: &RawMesh| -> Option<Vec<u32>> {
                    m.colors
                        .as_ref()
                        .map(|c| c.iter().flatten().map(|v| v.to_bits()).collect())
                };
                if bits(a) != bits(b) {
                    return Err("positions differ".into());
                }
                if cbits(a) != cbits(b) {
                    return Err("colours differ".into());
                }
                if a.faces != b.faces {
                    return Err("faces differ".into());
                }
                if a.attrs != b.attrs {
                    return Err("attributes differ".into());
                }
                if a.notes != b.notes || a.precision != b.precision || a.encoding != b.encoding {
                    return Err(format!("notes differ: {:?} vs {:?}", a.notes, b.notes));
                }
                Ok(())
            }
            (Err(a), Err(b)) if a.to_string() == b.to_string() => Ok(()),
            (a, b) => Err(format!(
                "{:?} vs {:?}",
                a.as_ref().map(|m| m.faces.len()).map_err(|e| e.to_string()),
                b.as_ref().map(|m| m.faces.len()).map_err(|e| e.to_string())
            )),
        }
    }

    /// A number as OBJ writers print it, in one of many forms (most of them plain
    /// decimals, which take the fast path).
    fn number(rng: &mut ChaCha8Rng) -> String {
        let v: f64 = rng.random_range(-2.0..2.0) * 10f64.powi(rng.random_range(-3..4));
        match rng.random_range(0..12) {
            0 => format!("{}", v as f32),
            1 => format!("{v:e}"),
            2 => format!("{}", rng.random_range(-50i32..50)),
            3 => format!("{v:.25}"),
            4 => format!("+{}", v.abs()),
            5 => format!("{}.", rng.random_range(0..100)),
            6 => format!(".{}", rng.random_range(0..100)),
            7 => "-0".into(),
            8 => format!("{}", rng.random::<f64>() * 1e-300),
            9 => format!("9007199254740993.{}", rng.random_range(0..9)),
            _ => format!("{v}"),
        }
    }

    /// A random OBJ file with what files in the wild hold: a byte order mark, CRLF
    /// or mixed line ends, comments (whole lines and after data), blank lines,
    /// ignored records, `w` and colour vertices, polygons, `v/vt/vn` corners,
    /// relative and forward indices, odd whitespace; with `bad`, one malformed line.
    fn random_obj(rng: &mut ChaCha8Rng, bad: bool, attrs: bool) -> Vec<u8> {
        let mut out = Vec::new();
        if rng.random_bool(0.2) {
            out.extend_from_slice(UTF8_BOM);
        }
        let crlf = rng.random_range(0..3); // 0: LF, 1: CRLF, 2: mixed
        let colour = rng.random_range(0..4); // 0: none, 1: all, 2: some, 3: 0..255
        let lines = rng.random_range(1..120);
        let bad_at = rng.random_range(0..lines);
        let mut nv = 0i64;
        for l in 0..lines {
            let mut line = String::new();
            let sp = |rng: &mut ChaCha8Rng| match rng.random_range(0..8) {
                0 => "\t",
                1 => "  ",
                2 => " \x0C",
                _ => " ",
            };
            if rng.random_bool(0.05) {
                line.push_str(sp(rng));
            }
            match rng.random_range(0..20) {
                0..=6 => {
                    line.push('v');
                    for _ in 0..3 {
                        line.push_str(sp(rng));
                        line.push_str(&number(rng));
                    }
                    let extra = match colour {
                        1 => 3,
                        2 if rng.random_bool(0.5) => 3,
                        3 => 3,
                        _ if rng.random_bool(0.05) => 1,
                        _ => 0,
                    };
                    for _ in 0..extra {
                        line.push_str(sp(rng));
                        if extra == 1 {
                            line.push_str(&format!("{}", rng.random_range(1..4) as f64 * 0.5));
                        } else if colour == 3 {
                            line.push_str(&format!("{}", rng.random_range(0..256)));
                        } else {
                            line.push_str(&format!("{}", rng.random::<f32>()));
                        }
                    }
                    nv += 1;
                }
                7..=13 if nv > 0 => {
                    line.push_str(if rng.random_bool(0.05) { "fo" } else { "f" });
                    let n = if rng.random_bool(0.8) {
                        3
                    } else {
                        rng.random_range(4..7)
                    };
                    for _ in 0..n {
                        line.push_str(sp(rng));
                        let i = rng.random_range(0..nv);
                        let idx = match rng.random_range(0..10) {
                            0..=2 => -(nv - i),
                            3 => nv + rng.random_range(1..4), // forward
                            _ => i + 1,
                        };
                        line.push_str(&idx.to_string());
                        match if attrs { rng.random_range(0..6) } else { 6 } {
                            0 => line.push_str("/1"),
                            1 => line.push_str("//2"),
                            2 => line.push_str("/3/4"),
                            _ => {}
                        }
                    }
                }
                14 => line.push_str("# a comment"),
                15 => {}
                16 if attrs => line.push_str(
                    ["vt 0 1", "vn 0 0 1", "o part", "g grp", "s off", "usemtl m"]
                        [rng.random_range(0..6)],
                ),
                17 => line.push_str(["l 1 2", "p 1"][rng.random_range(0..2)]),
                _ => line.push_str("v 1 2 3"),
            }
            if line == "v 1 2 3" {
                if colour == 1 || colour == 3 {
                    line.push_str(" 0.5 0.5 0.5");
                }
                nv += 1;
            }
            if rng.random_bool(0.05) {
                line.push_str(sp(rng));
            }
            if rng.random_bool(0.05) {
                line.push_str(" # after data");
            }
            if bad && l == bad_at {
                line = [
                    "f 0 1 2",
                    "f -999999 1 2",
                    "f 1 2",
                    "f 1 2 x",
                    "f 1 2 99999999999999999999",
                    "f 1 2 4294967297",
                    "v 0 0 nan",
                    "v 0 inf 0",
                    "v 1 2",
                    "v 1 2 3 4 5",
                    "v 1 2 3 4 5 6 7",
                    "v 1 2 3 0",
                    "v 1e308 1 1 1e-308",
                    "v 1 2 3\u{0}",
                    "v 1 2\r3",
                    "v 1,5 2 3",
                    "f 1/ 2 3/",
                    "f 999999 1 1",
                ][rng.random_range(0..18)]
                .to_string();
            }
            out.extend_from_slice(line.as_bytes());
            if l + 1 < lines || rng.random_bool(0.7) {
                let cr = crlf == 1 || (crlf == 2 && rng.random_bool(0.5));
                out.extend_from_slice(if cr { b"\r\n" } else { b"\n" });
            }
        }
        out
    }

    #[test]
    fn block_reader_matches_line_reader() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let mut fast_ok = 0;
        let mut errors = 0;
        for case in 0..1500 {
            let bad = case % 3 == 0;
            // files with texture coordinates, normals, corners and states: read by
            // the line reader from the first such record on
            let attrs = case % 2 == 0;
            let src = random_obj(&mut rng, bad, attrs);
            let caps = match case % 10 {
                0 => Caps::new(&ReadLimits {
                    max_vertices: rng.random_range(1..40),
                    ..ReadLimits::default()
                }),
                1 => Caps::new(&ReadLimits {
                    max_faces: rng.random_range(1..40),
                    ..ReadLimits::default()
                }),
                _ => Caps::none(),
            };
            let want = read_serial(&src, &caps);
            errors += usize::from(want.is_err());
            for (block, piece) in [
                (BLOCK, PIECE),
                (4096, 1),
                (257, 64),
                (64, 16),
                (1 << 16, 300),
            ] {
                let got = read_in_blocks(Path::new("t.obj"), src.as_slice(), &caps, block, piece);
                if let Err(why) = same(&got, &want) {
                    panic!(
                        "case {case}, block {block}, piece {piece}: {why}\n{}",
                        String::from_utf8_lossy(&src)
                    );
                }
            }
            // The fast parser takes every valid file (the comparison above is not
            // only the line reader against itself).
            if !bad && case % 10 > 1 && !attrs {
                let mut p = Piece::default();
                assert!(p.parse(&src, true), "{}", String::from_utf8_lossy(&src));
                fast_ok += 1;
            }
        }
        assert!(fast_ok > 250 && errors > 300, "{fast_ok} {errors}");
    }

    #[test]
    fn real_matches_std() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut toks: Vec<String> = [
            "0",
            "-0",
            "+0",
            "0.0",
            "-0.0",
            "1.",
            ".5",
            "-.5",
            "+.5",
            ".",
            "-",
            "+",
            "",
            "1e5",
            "1E-5",
            "1e",
            "e5",
            "inf",
            "-inf",
            "NaN",
            "infinity",
            "1_0",
            "0x10",
            "1.2.3",
            "9007199254740992",
            "9007199254740993",
            "9007199254740992.5",
            "1234567890123456789",
            "12345678901234567890",
            "0.0000000000000000000001",
            "0.00000000000000000000001",
            "00000000000000000001.5",
            "-1.7976931348623157e308",
            "4.9e-324",
            "2.2250738585072014e-308",
            "0.1",
            "0.2",
            "0.3",
            "123.456",
            "--1",
            "1-",
            "1+1",
            "١",
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        for _ in 0..20000 {
            let v = f64::from_bits(rng.random());
            let w: f64 = rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-25..25));
            toks.push(format!("{v}"));
            toks.push(format!("{w}"));
            toks.push(format!("{}", w as f32));
            toks.push(format!("{w:.prec$}", prec = rng.random_range(0..24)));
            let digits: String = (0..rng.random_range(1..22))
                .map(|_| char::from(b'0' + rng.random_range(0..10u8)))
                .collect();
            let cut = rng.random_range(0..=digits.len());
            toks.push(format!("{}.{}", &digits[..cut], &digits[cut..]));
        }
        for t in &toks {
            let mut i = 0;
            let got = real(t.as_bytes(), &mut i);
            let want = t.parse::<f64>().ok();
            assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "{t:?}");
            assert_eq!(i, t.len(), "{t:?}");
        }
    }

    #[test]
    fn index_matches_parse_i64() {
        for t in [
            "1",
            "-1",
            "+1",
            "0",
            "-0",
            "12/3/4",
            "5//6",
            "7/",
            "-",
            "+",
            "/1",
            "1a",
            "--1",
            "9223372036854775807",
            "-9223372036854775808",
            "9223372036854775808",
            "-9223372036854775809",
            "00012",
            "1/x/y",
        ] {
            let mut i = 0;
            let got = index(t.as_bytes(), &mut i);
            // corner indices (`v/t/n`) are left to the line reader
            let want = if t.contains('/') {
                None
            } else {
                parse_i64(t.as_bytes())
            };
            assert_eq!(got, want, "{t:?}");
            if got.is_some() {
                assert_eq!(i, t.len(), "{t:?}");
            }
        }
    }
}
