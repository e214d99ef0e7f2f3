use super::blocks::{index, real, Piece};
use super::*;
use crate::io::text::UTF8_BOM;
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

/// Writes `m` (read from `text`, three vertices): its `v` lines are those of `text`,
/// and reading it back gives the same colours and attributes.
fn vertex_lines_round_trip(text: &str, m: &RawMesh) {
    let mut out = Vec::new();
    write(&mut out, m).unwrap();
    let out = String::from_utf8(out).unwrap();
    let v: Vec<&str> = out.lines().filter(|l| l.starts_with("v ")).collect();
    assert_eq!(v, text.lines().take(3).collect::<Vec<_>>());
    let back = parse(&out).unwrap();
    assert_eq!(back.colors, m.colors);
    assert_eq!(back.attrs, m.attrs);
}

#[test]
fn unit_colours_with_more_digits_than_f32_are_written_back_as_read() {
    let text =
        "v 0 0 0 0.123456789 0.5 0.25\nv 1 0 0 0.1 0.2 0.3\nv 0 1 0 0 1 0.987654321\nf 1 2 3\n";
    let m = parse(text).unwrap();
    let o = m.attrs.obj.as_ref().unwrap();
    assert!(o.exact_colors && !o.byte_colors);
    assert!(matches!(
        m.attrs.vertex[0].data,
        PropData::Scalar(Values::F64(_))
    ));
    assert_eq!(m.colors.as_ref().unwrap()[0][0], 0.123456789f64 as f32);
    vertex_lines_round_trip(text, &m);
    // colours an f32 keeps exactly stay plain 0..1 colours
    let m = parse("v 0 0 0 0.5 0.25 1\nv 1 0 0 0 0 0\nv 0 1 0 1 1 1\nf 1 2 3\n").unwrap();
    assert!(m.attrs.obj.is_none() && m.attrs.vertex.is_empty());
}

#[test]
fn byte_colours_are_written_back_as_read() {
    let text = "v 0 0 0 255 128 0\nv 1 0 0 10 20 30\nv 0 1 0 0 0 0\nf 1 2 3\n";
    let m = parse(text).unwrap();
    // the 0..1 colours for other formats, the values as written for OBJ
    assert_eq!(m.colors.as_ref().unwrap()[0], [1.0, 128.0 / 255.0, 0.0]);
    assert!(m.attrs.obj.as_ref().unwrap().byte_colors);
    assert_eq!(m.attrs.vertex.len(), 3);
    assert!(matches!(
        m.attrs.vertex[0].data,
        PropData::Scalar(Values::U8(_))
    ));
    vertex_lines_round_trip(text, &m);
    // reals above 1 keep their text (stored as double)
    let m = parse("v 0 0 0 127.5 0 3\nv 1 0 0 1 2 3\nv 0 1 0 0 0 0\nf 1 2 3\n").unwrap();
    assert!(matches!(
        m.attrs.vertex[0].data,
        PropData::Scalar(Values::F64(_))
    ));
    let mut out = Vec::new();
    write(&mut out, &m).unwrap();
    let out = String::from_utf8(out).unwrap();
    assert!(out.lines().any(|l| l == "v 0 0 0 127.5 0 3"), "{out}");
    // 0..1 colours stay as they were: no properties, written as reals
    let m = parse("v 0 0 0 1 0.5 0\nv 1 0 0 0 0 1\nv 0 1 0 0 1 0\nf 1 2 3\n").unwrap();
    assert!(m.attrs.vertex.is_empty() && m.attrs.obj.is_none());
    let mut out = Vec::new();
    write(&mut out, &m).unwrap();
    assert!(String::from_utf8(out)
        .unwrap()
        .contains("v 0 0 0 1 0.5 0\n"));
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
