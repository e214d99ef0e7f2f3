//! The face count a mesh file declares, read without parsing its geometry, for the
//! `max_faces` limit: the PLY header's `element face N`, the OFF header's counts, the
//! binary STL triangle count, and for OBJ and ASCII STL a count of the face lines
//! (an OBJ polygon of n corners counts n - 2 triangles). `None` when the file does not
//! say (the worker then reads it; a malformed file fails there).

use super::sets::Role;
use std::fs::File;
use std::io::{BufRead, BufReader, Read, Seek, SeekFrom};

/// Bytes of a line looked at; the rest of a longer line is skipped unread into memory
/// (header lines are short; a file of one endless line costs no memory).
const LINE_PREFIX: usize = 4096;

/// The number of faces the open file `f` (named `name`, for its extension) declares,
/// when it can be told cheaply. Reads from the start, through its own offset.
pub fn declared_faces(f: &File, name: &str) -> Option<u64> {
    let lower = name.to_ascii_lowercase();
    let mut f = f.try_clone().ok()?;
    f.seek(SeekFrom::Start(0)).ok()?;
    let len = f.metadata().ok()?.len();
    let r = BufReader::new(f);
    if lower.ends_with(".ply") {
        ply(r)
    } else if lower.ends_with(".off") {
        off(r)
    } else if lower.ends_with(".stl") {
        stl(r, len)
    } else if lower.ends_with(".obj") {
        obj(r)
    } else {
        None
    }
}

/// The other files a mesh names, as written, with what each is to it: an OBJ's
/// `mtllib` arguments (the whole rest of each line, trimmed, its `#` comment removed;
/// every line of the file is looked at, streaming, [`LINE_PREFIX`] bytes of each), a
/// PLY header's `comment TextureFile NAME` lines, a glTF document's external buffers
/// and images (`uri`s that are not `data:`, `%XX` decoded; the JSON of a `.gltf`, at
/// most [`MAX_GLTF_JSON`] bytes, or a `.glb`'s JSON chunk). Other formats name none.
/// Reads from the start, through its own offset; `Err` when the file cannot be read.
/// A glTF document that cannot be parsed names none (its repair says what is wrong).
pub fn references(f: &File, name: &str) -> std::io::Result<Vec<(String, Role)>> {
    let lower = name.to_ascii_lowercase();
    let obj = lower.ends_with(".obj");
    if lower.ends_with(".gltf") || lower.ends_with(".glb") {
        return gltf_references(f, lower.ends_with(".glb"));
    }
    if !obj && !lower.ends_with(".ply") {
        return Ok(Vec::new());
    }
    let role = if obj {
        Role::MaterialLibrary
    } else {
        Role::Texture
    };
    let mut f = f.try_clone()?;
    f.seek(SeekFrom::Start(0))?;
    let mut out: Vec<(String, Role)> = Vec::new();
    let mut push = |s: &str| {
        let s = s.trim();
        if !s.is_empty() && !out.iter().any(|o| o.0 == s) {
            out.push((s.to_string(), role));
        }
    };
    let mut lines = 0usize;
    for_each_line(BufReader::new(f), |line| {
        lines += 1;
        let s = String::from_utf8_lossy(line);
        let t = s.trim_start();
        if obj {
            if let Some(rest) = t.strip_prefix("mtllib") {
                if rest.starts_with(char::is_whitespace) {
                    push(rest.split('#').next().unwrap_or(""));
                }
            }
            return true;
        }
        // PLY: the header only
        if lines > 10_000 || t.starts_with("end_header") {
            return false;
        }
        let mut w = t.split_whitespace();
        if let (Some("comment"), Some(k)) = (w.next(), w.next()) {
            if k.eq_ignore_ascii_case("texturefile") {
                if let Some(i) = t.find(k) {
                    push(&t[i + k.len()..]);
                }
            }
        }
        true
    });
    Ok(out)
}

/// The most of a glTF document's JSON read for its references.
pub const MAX_GLTF_JSON: u64 = 256 << 20;

/// The external buffers ([`Role::Buffer`]) and images ([`Role::Texture`]) of the
/// glTF document in `f` (a `.glb`: its first chunk, when it is the JSON chunk).
fn gltf_references(f: &File, glb: bool) -> std::io::Result<Vec<(String, Role)>> {
    let mut f = f.try_clone()?;
    f.seek(SeekFrom::Start(0))?;
    let mut json = Vec::new();
    if glb {
        let mut head = [0u8; 20];
        if f.read_exact(&mut head).is_err() || &head[16..20] != b"JSON" {
            return Ok(Vec::new());
        }
        let len = u32::from_le_bytes([head[12], head[13], head[14], head[15]]);
        (&mut f)
            .take(u64::from(len).min(MAX_GLTF_JSON))
            .read_to_end(&mut json)?;
    } else {
        (&mut f).take(MAX_GLTF_JSON).read_to_end(&mut json)?;
    }
    Ok(holefill::io::attrs::gltf_external(&json)
        .unwrap_or_default()
        .into_iter()
        .map(|r| {
            let role = if r.buffer {
                Role::Buffer
            } else {
                Role::Texture
            };
            (r.name, role)
        })
        .collect())
}

/// Calls `f` with the first [`LINE_PREFIX`] bytes of each line (without the newline)
/// until it returns false or the input ends (or fails). Memory: one prefix.
fn for_each_line<R: BufRead>(mut r: R, mut f: impl FnMut(&[u8]) -> bool) {
    let mut line: Vec<u8> = Vec::with_capacity(256);
    loop {
        let buf = match r.fill_buf() {
            Ok(b) if !b.is_empty() => b,
            _ => break,
        };
        let (chunk, end) = match memchr::memchr(b'\n', buf) {
            Some(i) => (&buf[..i], Some(i + 1)),
            None => (buf, None),
        };
        let room = LINE_PREFIX.saturating_sub(line.len());
        line.extend_from_slice(&chunk[..chunk.len().min(room)]);
        let used = end.unwrap_or(buf.len());
        r.consume(used);
        if end.is_some() {
            if !f(&line) {
                return;
            }
            line.clear();
        }
    }
    if !line.is_empty() {
        f(&line);
    }
}

fn ply<R: BufRead>(r: R) -> Option<u64> {
    let mut out = None;
    let mut i = 0;
    for_each_line(r, |line| {
        i += 1;
        if i > 10_000 {
            return false;
        }
        let s = String::from_utf8_lossy(line);
        let mut t = s.split_whitespace();
        match (t.next(), t.next(), t.next()) {
            (Some("element"), Some("face"), Some(n)) => {
                out = n.parse().ok();
                false
            }
            (Some("end_header"), _, _) => false,
            _ => true,
        }
    });
    out
}

fn off<R: BufRead>(r: R) -> Option<u64> {
    let mut seen_magic = false;
    let mut out = None;
    let mut i = 0;
    for_each_line(r, |line| {
        i += 1;
        if i > 10_000 {
            return false;
        }
        let s = String::from_utf8_lossy(line);
        let s = s.split('#').next().unwrap_or("").trim();
        if s.is_empty() {
            return true;
        }
        let mut rest = s;
        if !seen_magic {
            seen_magic = true;
            if let Some(w) = s.split_whitespace().next().filter(|w| w.ends_with("OFF")) {
                rest = s[w.len()..].trim();
                if rest.is_empty() {
                    return true;
                }
            }
        }
        let nums: Vec<u64> = rest
            .split_whitespace()
            .take(2)
            .filter_map(|w| w.parse().ok())
            .collect();
        out = nums.get(1).copied();
        false
    });
    out
}

fn stl<R: BufRead>(mut r: R, len: u64) -> Option<u64> {
    let mut head = [0u8; 84];
    let mut got = 0;
    while got < 84 {
        match r.read(&mut head[got..]) {
            Ok(0) => break,
            Ok(n) => got += n,
            Err(_) => return None,
        }
    }
    if got == 84 {
        let n = u32::from_le_bytes([head[80], head[81], head[82], head[83]]) as u64;
        if 84 + 50 * n == len {
            return Some(n);
        }
    }
    if !head[..got].starts_with(b"solid") {
        return None;
    }
    let mut count = 0;
    let text = head[..got].to_vec();
    for_each_line(std::io::Cursor::new(text).chain(r), |line| {
        let t = line
            .iter()
            .position(|c| !c.is_ascii_whitespace())
            .map_or(&[][..], |i| &line[i..]);
        if t.starts_with(b"facet") {
            count += 1;
        }
        true
    });
    Some(count)
}

/// Counts the triangles of the face lines (`f` then whitespace, after leading
/// whitespace): corners - 2 each. Streams the bytes: no line is held in memory.
fn obj<R: BufRead>(mut r: R) -> Option<u64> {
    #[derive(Clone, Copy)]
    enum St {
        Lead,
        F,
        Face { corners: u64, in_word: bool },
        Other,
    }
    let mut count = 0u64;
    let mut st = St::Lead;
    let end_line = |st: St, count: &mut u64| {
        if let St::Face { corners, .. } = st {
            *count += corners.saturating_sub(2);
        }
    };
    loop {
        let buf = match r.fill_buf() {
            Ok(b) if !b.is_empty() => b,
            Ok(_) => break,
            Err(_) => return None,
        };
        for &c in buf {
            if c == b'\n' {
                end_line(st, &mut count);
                st = St::Lead;
                continue;
            }
            let ws = c.is_ascii_whitespace();
            st = match st {
                St::Lead if ws => St::Lead,
                St::Lead if c == b'f' => St::F,
                St::F if ws => St::Face {
                    corners: 0,
                    in_word: false,
                },
                St::Face { corners, .. } if ws => St::Face {
                    corners,
                    in_word: false,
                },
                St::Face {
                    corners,
                    in_word: false,
                } => St::Face {
                    corners: corners + 1,
                    in_word: true,
                },
                St::Face { .. } => st,
                _ => St::Other,
            };
        }
        let n = buf.len();
        r.consume(n);
    }
    end_line(st, &mut count);
    Some(count)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Cursor;

    #[test]
    fn counts() {
        assert_eq!(
            ply(Cursor::new(
                "ply\nformat ascii 1.0\nelement vertex 8\nelement face 12\nend_header\n"
            )),
            Some(12)
        );
        assert_eq!(ply(Cursor::new("ply\nend_header\nelement face 12\n")), None);
        assert_eq!(off(Cursor::new("OFF\n# c\n8 6 0\n")), Some(6));
        assert_eq!(off(Cursor::new("OFF 8 7 0\n")), Some(7));
        assert_eq!(off(Cursor::new("COFF\n4 2 0\n")), Some(2));
        assert_eq!(
            obj(Cursor::new(
                "v 0 0 0\nf 1 2 3\nf 1/1 2/2 3/3 4/4\n  f 1 2 3\nfoo\n"
            )),
            Some(4)
        );
        let mut bin = vec![0u8; 80];
        bin.extend_from_slice(&3u32.to_le_bytes());
        bin.extend(std::iter::repeat_n(0u8, 150));
        assert_eq!(stl(Cursor::new(bin.clone()), bin.len() as u64), Some(3));
        let ascii = "solid x\nfacet normal 0 0 1\nouter loop\nendloop\nendfacet\nfacet normal 0 0 1\nendfacet\nendsolid\n";
        assert_eq!(stl(Cursor::new(ascii), ascii.len() as u64), Some(2));
        assert_eq!(stl(Cursor::new("garbage"), 7), None);
    }

    #[test]
    fn references_of_obj_and_ply() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.obj");
        std::fs::write(
            &p,
            "# mtllib not.mtl\nmtllib a.mtl # c\nv 0 0 0\n  mtllib  b c.mtl\nmtllibx y\nmtllib a.mtl\n",
        )
        .unwrap();
        let f = File::open(&p).unwrap();
        let names = |r: Vec<(String, Role)>| r.into_iter().map(|(n, _)| n).collect::<Vec<_>>();
        assert_eq!(
            names(references(&f, "a.obj").unwrap()),
            vec!["a.mtl", "b c.mtl"]
        );
        let p = d.path().join("b.PLY");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\ncomment TextureFile tex 1.png\ncomment other\nelement vertex 0\nend_header\ncomment TextureFile late.png\n",
        )
        .unwrap();
        let f = File::open(&p).unwrap();
        assert_eq!(
            references(&f, "b.PLY").unwrap(),
            vec![("tex 1.png".to_string(), Role::Texture)]
        );
        assert!(references(&f, "b.stl").unwrap().is_empty());
    }

    #[test]
    fn references_of_gltf_and_glb() {
        let d = tempfile::tempdir().unwrap();
        let json = r#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":4,"uri":"s%20a.bin"},
            {"byteLength":1,"uri":"data:application/octet-stream;base64,AA=="},{"byteLength":4,"uri":"s%20a.bin"}],
            "images":[{"uri":"tex.png"},{"bufferView":0,"mimeType":"image/png"},{"uri":"../x.png"}]}"#;
        let p = d.path().join("s.gltf");
        std::fs::write(&p, json).unwrap();
        let want = vec![
            ("s a.bin".to_string(), Role::Buffer),
            ("tex.png".to_string(), Role::Texture),
            ("../x.png".to_string(), Role::Texture),
        ];
        assert_eq!(
            references(&File::open(&p).unwrap(), "s.gltf").unwrap(),
            want
        );
        // the same JSON as a GLB's first chunk
        let mut glb = b"glTF".to_vec();
        glb.extend_from_slice(&2u32.to_le_bytes());
        glb.extend_from_slice(&((20 + json.len()) as u32).to_le_bytes());
        glb.extend_from_slice(&(json.len() as u32).to_le_bytes());
        glb.extend_from_slice(b"JSON");
        glb.extend_from_slice(json.as_bytes());
        let p = d.path().join("s.GLB");
        std::fs::write(&p, glb).unwrap();
        assert_eq!(references(&File::open(&p).unwrap(), "s.GLB").unwrap(), want);
        // not JSON: nothing named (the repair says what is wrong)
        std::fs::write(&p, "glTF garbage").unwrap();
        assert!(references(&File::open(&p).unwrap(), "s.glb")
            .unwrap()
            .is_empty());
    }
}
