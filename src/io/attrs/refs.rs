//! The other files a mesh names: OBJ material libraries and the images an MTL names,
//! and a glTF document's external buffers and images (percent-escapes decoded).

use crate::io::RawMesh;
use std::path::{Path, PathBuf};

/// The other files an input names (OBJ: its `mtllib` files), resolved against the
/// input's folder; a library that cannot be read is listed, its images are not.
/// Images an MTL names (`map_Kd`, `map_Ka`, `map_Ks`, `map_Bump`, `bump`, `map_d`,
/// `disp`, `norm`, ... : the last token of the line) follow their library.
pub fn referenced_files(raw: &RawMesh, input: &Path) -> Vec<PathBuf> {
    let dir = input.parent().unwrap_or_else(|| Path::new(""));
    let mut out = Vec::new();
    let Some(o) = &raw.attrs.obj else {
        return out;
    };
    for lib in &o.mtllibs {
        let p = dir.join(lib);
        if let Ok(text) = std::fs::read_to_string(&p) {
            for name in mtl_images(&text) {
                let img = p.parent().unwrap_or(dir).join(name);
                if !out.contains(&img) {
                    out.push(img);
                }
            }
        }
        if !out.contains(&p) {
            out.insert(0, p);
        }
    }
    out
}

/// The image file names an MTL file's texture statements name (`map_Kd`, `map_Ka`,
/// `map_Ks`, `map_Ns`, `map_d`, `map_Bump`, `bump`, `disp`, `decal`, `refl`, `norm`,
/// `map_Pr`, ... : every `map_*` but the `map_aat on|off` switch), in order, each once.
///
/// Options come before the name (`-s 1 1 1`, `-o u v w`, `-mm base gain`, `-bm 0.5`,
/// `-clamp on`, `-imfchan r`, `-type sphere`, ...): each is skipped with its arguments
/// (`-o`, `-s`, `-t` take one to three numbers). The rest of the line, trimmed and
/// without its `#` comment, is the name, so a name may hold spaces
/// (`map_Kd -s 2 2 my scan.jpg` names `my scan.jpg`). An unknown option is taken to
/// have one argument.
pub fn mtl_images(mtl: &str) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    for line in mtl.lines() {
        let line = line.split('#').next().unwrap_or("").trim();
        let Some(name) = mtl_texture_name(line) else {
            continue;
        };
        if !out.contains(&name) {
            out.push(name);
        }
    }
    out
}

/// The file name of one MTL texture statement (see [`mtl_images`]); `None` for other
/// statements or a statement without a name.
fn mtl_texture_name(line: &str) -> Option<String> {
    let (kw, mut rest) = split_word(line)?;
    let kw = kw.to_ascii_lowercase();
    let texture = (kw.starts_with("map_") && kw != "map_aat")
        || matches!(kw.as_str(), "bump" | "disp" | "decal" | "refl" | "norm");
    if !texture {
        return None;
    }
    loop {
        let (word, after) = split_word(rest)?;
        if !word.starts_with('-')
            || word.len() < 2
            || word[1..].starts_with(|c: char| c.is_ascii_digit() || c == '.')
        {
            break;
        }
        let (min, max) = match word.to_ascii_lowercase().as_str() {
            "-o" | "-s" | "-t" => (1, 3),
            "-mm" => (2, 2),
            _ => (1, 1),
        };
        rest = after;
        for k in 0..max {
            let (arg, after) = split_word(rest)?;
            if k >= min && arg.parse::<f64>().is_err() {
                break;
            }
            rest = after;
        }
    }
    let name = rest.trim();
    (!name.is_empty()).then(|| name.to_string())
}

/// The first whitespace-separated word of `s` and the text after it.
fn split_word(s: &str) -> Option<(&str, &str)> {
    let s = s.trim_start();
    if s.is_empty() {
        return None;
    }
    let end = s.find(char::is_whitespace).unwrap_or(s.len());
    Some((&s[..end], &s[end..]))
}

/// An external file a glTF document names: a buffer (read with the mesh) or an image
/// (travels with it).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct GltfRef {
    /// The `uri` with its `%XX` escapes decoded (the name the reader opens).
    pub name: String,
    pub buffer: bool,
}

/// The external files a glTF JSON document names (`buffers[].uri`, then
/// `images[].uri`), in order, each once; `data:` URIs are no files. `Err` when the
/// bytes are not a JSON object.
pub fn gltf_external(json: &[u8]) -> Result<Vec<GltfRef>, String> {
    #[derive(serde::Deserialize)]
    struct Uri {
        #[serde(default)]
        uri: Option<String>,
    }
    #[derive(serde::Deserialize)]
    struct Doc {
        #[serde(default)]
        buffers: Vec<Uri>,
        #[serde(default)]
        images: Vec<Uri>,
    }
    let doc: Doc = serde_json::from_slice(json).map_err(|e| e.to_string())?;
    let mut out: Vec<GltfRef> = Vec::new();
    let refs = (doc.buffers.iter().map(|u| (u, true))).chain(doc.images.iter().map(|u| (u, false)));
    for (u, buffer) in refs {
        let Some(uri) = u.uri.as_deref() else {
            continue;
        };
        if uri.starts_with("data:") {
            continue;
        }
        let name = percent_decode(uri);
        if !out.iter().any(|r| r.name == name) {
            out.push(GltfRef { name, buffer });
        }
    }
    Ok(out)
}

/// `%20` and the like in a relative URI.
pub fn percent_decode(s: &str) -> String {
    let b = s.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[i] == b'%' && i + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[i + 1]), hex(b[i + 2])) {
                out.push((h * 16 + l) as u8);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}
