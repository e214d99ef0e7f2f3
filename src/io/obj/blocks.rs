//! The parallel reader: blocks of the file cut at newlines into pieces, each parsed
//! by a one-pass parser and appended in file order; what it does not take goes to the
//! line reader ([`super::read_lines`]).

use super::{finish, read_lines, State};
use crate::io::text::{parse_f64, Lines, MAX_LINE, UTF8_BOM};
use crate::io::{io_error, Caps, IoError, RawMesh, MAX_ELEMENTS};
use glam::DVec3;
use rayon::prelude::*;
use std::io::{BufRead, Read};
use std::path::Path;

/// Bytes read from the file at a time; each block is cut at its last newline and
/// parsed in pieces in parallel.
pub(super) const BLOCK: usize = 8 << 20;
/// Target size of the pieces a block is parsed in (each cut at a newline).
pub(super) const PIECE: usize = 512 << 10;

pub(super) fn read_in_blocks<R: BufRead>(
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
pub(super) struct Piece {
    positions: Vec<DVec3>,
    /// Colours of the vertices with colour, in order.
    colors: Vec<[f64; 3]>,
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
    pub(super) fn parse(&mut self, bytes: &[u8], at_start: bool) -> bool {
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
            6 => self.colors.push([a, bb, c]),
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
pub(super) fn index(b: &[u8], i: &mut usize) -> Option<i64> {
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
pub(super) fn real(b: &[u8], i: &mut usize) -> Option<f64> {
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
