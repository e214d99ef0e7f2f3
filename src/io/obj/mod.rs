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

mod blocks;
#[cfg(test)]
mod tests;
mod writer;

pub(crate) use writer::write;

use super::attrs::{Corners, ObjExtras, ObjState, PropData, Property, ScalarType, Values};
use super::text::{has_nul, parse_coord, parse_f64, parse_i64, show, strip_comment, tokens};
use super::text::{Lines, Next, MAX_LINE};
use super::{io_error, malformed, unit_color, Caps, IoError, Precision, RawMesh, MAX_ELEMENTS};
use blocks::{read_in_blocks, BLOCK, PIECE};
use glam::DVec3;
use std::io::BufRead;
use std::path::Path;

/// What the reader has gathered so far: everything the line-by-line reader keeps
/// between lines, so that it can take over at any line the parallel reader reached.
struct State {
    raw: RawMesh,
    /// Vertex colours as written (0..1, or 0..255 when any is above 1).
    colors: Vec<[f64; 3]>,
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
                        colors.push([a, b, c]);
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
                let (vals, n) =
                    leading_reals::<2, _>(toks, |t| bad(format!("'{}' is not a number", show(t))))?;
                if n == 0 || n > 3 {
                    return Err(bad(format!("a 'vt' line needs 1 to 3 numbers, found {n}")));
                }
                if n == 3 {
                    extra.uvw += 1;
                }
                extra.uv.push(vals);
            }
            Some(b"vn") => {
                let (vals, n) =
                    leading_reals::<3, _>(toks, |t| bad(format!("'{}' is not a number", show(t))))?;
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
        colors,
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
            byte_colors: false,
            exact_colors: false,
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
            // the file's scale: 0..255 when any component is above 1
            let bytes = colors.iter().flatten().any(|&c| c as f32 > 1.0);
            let scale = if bytes { 255.0 } else { 1.0 };
            raw.colors = Some(
                colors
                    .iter()
                    .map(|c| c.map(|x| unit_color(f64::from(x as f32 / scale))))
                    .collect(),
            );
            if bytes {
                raw.notes
                    .push("OBJ vertex colours above 1 read as 0..255 and divided by 255".into());
                byte_colors(&mut raw, &colors, true);
            } else if colors.iter().flatten().any(|&c| f64::from(c as f32) != c) {
                // more digits than the f32 colours keep: the values as written
                byte_colors(&mut raw, &colors, false);
            }
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

/// Vertex colours kept as written, 0..255 (`scale255`) or 0..1 with more digits than
/// an f32 keeps: the vertex properties `red green blue` (`uchar` when written 0..255
/// and every value is an integer in 0..=255, else `double`), which the writer writes
/// back in place of [`RawMesh::colors`] (new vertices get theirs interpolated in the
/// same scale).
fn byte_colors(raw: &mut RawMesh, colors: &[[f64; 3]], scale255: bool) {
    let bytes = scale255
        && colors
            .iter()
            .flatten()
            .all(|&c| c.fract() == 0.0 && (0.0..=255.0).contains(&c));
    let ty = if bytes {
        ScalarType::U8
    } else {
        ScalarType::F64
    };
    for (k, name) in ["red", "green", "blue"].into_iter().enumerate() {
        let mut v = Values::new(ty, colors.len());
        for c in colors {
            v.push_f64(c[k]);
        }
        raw.attrs.vertex.push(Property {
            name: name.into(),
            data: PropData::Scalar(v),
        });
    }
    let o = raw.attrs.obj.get_or_insert_with(ObjExtras::default);
    if scale255 {
        o.byte_colors = true;
    } else {
        o.exact_colors = true;
    }
}

/// The first `N` numbers of a record's tokens (zeros where it has fewer) and how many
/// it has; a token that is not a number is the error `bad` makes of it.
fn leading_reals<'t, const N: usize, E>(
    toks: impl Iterator<Item = &'t [u8]>,
    bad: impl Fn(&[u8]) -> E,
) -> Result<([f64; N], usize), E> {
    let mut vals = [0.0f64; N];
    let mut n = 0;
    for t in toks {
        let v = parse_f64(t).ok_or_else(|| bad(t))?;
        if let Some(slot) = vals.get_mut(n) {
            *slot = v;
        }
        n += 1;
    }
    Ok((vals, n))
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
