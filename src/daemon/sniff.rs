//! The face count a mesh file declares, read without parsing its geometry, for the
//! `max_faces` limit: the PLY header's `element face N`, the OFF header's counts, the
//! binary STL triangle count, and for OBJ and ASCII STL a count of the face lines
//! (an OBJ polygon of n corners counts n - 2 triangles). `None` when the file does not
//! say (the worker then reads it; a malformed file fails there).

use std::fs::File;
use std::io::{BufRead, BufReader, Read};
use std::path::Path;

/// The number of faces `path` declares, when it can be told cheaply.
pub fn declared_faces(path: &Path) -> Option<u64> {
    let lower = path.file_name()?.to_str()?.to_ascii_lowercase();
    let f = File::open(path).ok()?;
    if lower.ends_with(".ply") {
        ply(BufReader::new(f))
    } else if lower.ends_with(".off") {
        off(BufReader::new(f))
    } else if lower.ends_with(".stl") {
        let len = f.metadata().ok()?.len();
        stl(BufReader::new(f), len)
    } else if lower.ends_with(".obj") {
        obj(BufReader::new(f))
    } else {
        None
    }
}

/// Lines as bytes (lossy), at most `max` bytes each, stopping at the first read error.
fn lines<R: BufRead>(r: R) -> impl Iterator<Item = Vec<u8>> {
    r.split(b'\n').map_while(Result::ok)
}

fn ply<R: BufRead>(r: R) -> Option<u64> {
    for (i, line) in lines(r).enumerate() {
        if i > 10_000 {
            return None;
        }
        let s = String::from_utf8_lossy(&line);
        let mut t = s.split_whitespace();
        match (t.next(), t.next(), t.next()) {
            (Some("element"), Some("face"), Some(n)) => return n.parse().ok(),
            (Some("end_header"), _, _) => return None,
            _ => {}
        }
    }
    None
}

fn off<R: BufRead>(r: R) -> Option<u64> {
    let mut seen_magic = false;
    for (i, line) in lines(r).enumerate() {
        if i > 10_000 {
            return None;
        }
        let s = String::from_utf8_lossy(&line);
        let s = s.split('#').next().unwrap_or("").trim();
        if s.is_empty() {
            continue;
        }
        let mut rest = s;
        if !seen_magic {
            seen_magic = true;
            if let Some(w) = s.split_whitespace().next().filter(|w| w.ends_with("OFF")) {
                rest = s[w.len()..].trim();
                if rest.is_empty() {
                    continue;
                }
            }
        }
        let nums: Vec<u64> = rest
            .split_whitespace()
            .take(2)
            .filter_map(|w| w.parse().ok())
            .collect();
        return nums.get(1).copied();
    }
    None
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
    for line in lines(std::io::Cursor::new(text).chain(r)) {
        let s = String::from_utf8_lossy(&line);
        if s.trim_start().starts_with("facet") {
            count += 1;
        }
    }
    Some(count)
}

fn obj<R: BufRead>(r: R) -> Option<u64> {
    let mut count = 0u64;
    for line in lines(r) {
        let t = line
            .iter()
            .position(|c| !c.is_ascii_whitespace())
            .map(|i| &line[i..])
            .unwrap_or(&[]);
        if t.len() > 1 && t[0] == b'f' && t[1].is_ascii_whitespace() {
            let corners = t[1..]
                .split(|c| c.is_ascii_whitespace())
                .filter(|w| !w.is_empty())
                .count() as u64;
            count += corners.saturating_sub(2);
        }
    }
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
}
