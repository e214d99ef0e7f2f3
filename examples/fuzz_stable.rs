//! A stable-Rust fuzzer for machines without nightly / cargo-fuzz: seeded random
//! mutation of the corpus files, calling the same checks as the cargo-fuzz targets
//! (`fuzz/common.rs`), catching panics with `catch_unwind`. No coverage feedback:
//! it finds what mutation of good and bad seeds reaches, and inputs that read are
//! kept as new seeds.
//!
//! ```text
//! cargo run --example fuzz_stable -- TARGET [SECONDS] [SEED]
//! ```
//! TARGET: `obj`, `ply`, `stl`, `off` (a reader, then the repair of what it read)
//! or `repair` (the repair of small meshes built from bytes). Seeds: every file of
//! `tests/data/` and `tests/data/malformed/` with the target's extension (all files
//! for `repair`) and `fuzz/corpus/TARGET/` when present. A panic, or one call
//! slower than 10 s, writes the input to `fuzz/artifacts/TARGET/` and is reported;
//! the exit status is 1 when anything was found.

#[path = "../fuzz/common.rs"]
mod common;

use holefill::io::Format;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

const SLOW: Duration = Duration::from_secs(10);
const MAX_INPUT: usize = 64 * 1024;
const MAX_POOL: usize = 2_000;

/// Tokens that readers treat specially.
const TOKENS: &[&[u8]] = &[
    b"0",
    b"1",
    b"-1",
    b"3",
    b"255",
    b"256",
    b"65535",
    b"-2147483648",
    b"2147483647",
    b"4294967295",
    b"4294967296",
    b"18446744073709551615",
    b"nan",
    b"inf",
    b"-inf",
    b"1e308",
    b"1e-320",
    b"-0",
    b"0.5",
    b"\n",
    b"\r\n",
    b"\r",
    b" ",
    b"\t",
    b"\0",
    b"#",
    b"/",
    b"//",
    b"f ",
    b"v ",
    b"vt ",
    b"l ",
    b"element vertex ",
    b"element face ",
    b"property float x\n",
    b"property list uchar int vertex_indices\n",
    b"end_header\n",
    b"format ascii 1.0\n",
    b"format binary_little_endian 1.0\n",
    b"format binary_big_endian 1.0\n",
    b"property double ",
    b"property uchar ",
    b"property list int int ",
    b"solid ",
    b"facet normal 0 0 1\n",
    b"outer loop\n",
    b"vertex 0 0 0\n",
    b"endloop\n",
    b"endfacet\n",
    b"endsolid\n",
    b"OFF\n",
    b"COFF",
    b"NOFF",
    b"STOFF",
    b"\xEF\xBB\xBF",
    b"\xff\xff\xff\xff",
    b"\x00\x00\x80\x7f",
];

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let target = args
        .first()
        .map(String::as_str)
        .unwrap_or("obj")
        .to_string();
    let seconds: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(60);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let format = match target.as_str() {
        "repair" => None,
        t => match Format::from_name(t) {
            Some(f) => Some(f),
            None => {
                eprintln!("unknown target {t}: expected obj, ply, stl, off or repair");
                std::process::exit(2);
            }
        },
    };
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut pool = seeds(root, &target, format);
    if pool.is_empty() {
        pool.push(vec![0u8; 64]);
    }
    eprintln!("{target}: {} seeds, {seconds} s, seed {seed}", pool.len());
    let artifacts = root.join("fuzz/artifacts").join(&target);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);

    // Panics are caught and reported here, not printed by the default hook.
    let last_panic = std::sync::Arc::new(std::sync::Mutex::new(String::new()));
    {
        let last = last_panic.clone();
        std::panic::set_hook(Box::new(move |info| {
            if let Ok(mut s) = last.lock() {
                *s = info.to_string();
            }
        }));
    }

    let start = Instant::now();
    let (mut iters, mut found, mut kept) = (0u64, 0u64, 0usize);
    let mut seen = std::collections::HashSet::new();
    // The seeds themselves first (the corpus and earlier findings are regressions).
    let mut replay: Vec<Vec<u8>> = pool.clone();
    replay.reverse();
    while start.elapsed() < Duration::from_secs(seconds) {
        let input = match replay.pop() {
            Some(seed) => seed,
            None => {
                let base = &pool[rng.random_range(0..pool.len())];
                let other = &pool[rng.random_range(0..pool.len())];
                mutate(base, other, &mut rng)
            }
        };
        iters += 1;
        let t = Instant::now();
        let res = std::panic::catch_unwind(|| run(format, &input));
        let took = t.elapsed();
        let problem = match res {
            Err(_) => Some(format!(
                "panic: {}",
                last_panic.lock().map(|s| s.clone()).unwrap_or_default()
            )),
            Ok(_) if took > SLOW => Some(format!("slow: {took:?}")),
            Ok(read_ok) => {
                if read_ok && pool.len() < MAX_POOL {
                    pool.push(input.clone());
                    kept += 1;
                }
                None
            }
        };
        if let Some(p) = problem {
            let key: String = p.chars().take(200).collect();
            let name = format!("crash-{:016x}", hash(&input));
            let ext = format.map(|f| f.name()).unwrap_or("bin");
            let _ = std::fs::create_dir_all(&artifacts);
            let file = artifacts.join(format!("{name}.{ext}"));
            let _ = std::fs::write(&file, &input);
            if seen.insert(key.clone()) {
                found += 1;
                println!("FOUND {}: {key}", file.display());
            }
        }
        if iters % 20_000 == 0 {
            eprintln!(
                "{target}: {iters} inputs, {found} distinct findings, {} in pool, {:.0} s",
                pool.len(),
                start.elapsed().as_secs_f64()
            );
        }
    }
    println!(
        "{target}: {iters} inputs in {:.0} s, {found} distinct findings, {kept} inputs kept",
        start.elapsed().as_secs_f64()
    );
    if found > 0 {
        std::process::exit(1);
    }
}

/// Runs the target's check; true when the input was a readable mesh (kept as a seed).
fn run(format: Option<Format>, input: &[u8]) -> bool {
    match format {
        Some(f) => {
            common::check_read(f, input);
            holefill::io::read_bytes(
                Path::new("fuzz-input"),
                input,
                f,
                &holefill::io::ReadLimits::default(),
            )
            .is_ok()
        }
        None => {
            common::check_repair(input);
            false
        }
    }
}

fn seeds(root: &Path, target: &str, format: Option<Format>) -> Vec<Vec<u8>> {
    let mut dirs: Vec<PathBuf> = vec![
        root.join("tests/data"),
        root.join("tests/data/malformed"),
        root.join("fuzz/corpus").join(target),
    ];
    dirs.dedup();
    let mut out = Vec::new();
    for d in dirs {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        let mut files: Vec<PathBuf> = rd.filter_map(|e| e.ok()).map(|e| e.path()).collect();
        files.sort();
        for p in files {
            let matches = match format {
                Some(f) => Format::from_path(&p) == Some(f),
                None => p.is_file(),
            };
            if matches && p.is_file() {
                if let Ok(b) = std::fs::read(&p) {
                    if b.len() <= MAX_INPUT {
                        out.push(b);
                    }
                }
            }
        }
    }
    out
}

fn mutate(base: &[u8], other: &[u8], rng: &mut ChaCha8Rng) -> Vec<u8> {
    let mut v = base.to_vec();
    let rounds = 1 + rng.random_range(0..4);
    for _ in 0..rounds {
        let len = v.len();
        let pos = if len == 0 {
            0
        } else {
            rng.random_range(0..=len)
        };
        match rng.random_range(0..10) {
            // flip a bit
            0 if len > 0 => {
                let i = rng.random_range(0..len);
                v[i] ^= 1 << rng.random_range(0..8);
            }
            // set a random byte
            1 if len > 0 => {
                let i = rng.random_range(0..len);
                v[i] = rng.random();
            }
            // insert a token
            2 | 3 => {
                let t = TOKENS[rng.random_range(0..TOKENS.len())];
                v.splice(pos..pos, t.iter().copied());
            }
            // replace a run of digits with a token
            4 => {
                if let Some(s) = (pos..len).find(|&i| v[i].is_ascii_digit()) {
                    let e = (s..len).find(|&i| !v[i].is_ascii_digit()).unwrap_or(len);
                    let t = TOKENS[rng.random_range(0..TOKENS.len())];
                    v.splice(s..e, t.iter().copied());
                }
            }
            // delete a range
            5 if len > 0 => {
                let n = rng.random_range(1..=len.min(64));
                let s = rng.random_range(0..=len - n);
                v.drain(s..s + n);
            }
            // duplicate a range
            6 if len > 0 => {
                let n = rng.random_range(1..=len.min(256));
                let s = rng.random_range(0..=len - n);
                let chunk: Vec<u8> = v[s..s + n].to_vec();
                v.splice(pos..pos, chunk);
            }
            // splice in a piece of another input
            7 if !other.is_empty() => {
                let n = rng.random_range(1..=other.len().min(512));
                let s = rng.random_range(0..=other.len() - n);
                v.splice(pos..pos, other[s..s + n].iter().copied());
            }
            // truncate
            8 if len > 0 => v.truncate(rng.random_range(0..len)),
            // overwrite 4 bytes with an interesting little-endian word
            _ if len >= 4 => {
                let words: [u32; 8] = [
                    0,
                    1,
                    u32::MAX,
                    1 << 31,
                    0x7fc0_0000,
                    0x7f80_0000,
                    rng.random(),
                    (len as u32).saturating_sub(84) / 50,
                ];
                let w = words[rng.random_range(0..words.len())].to_le_bytes();
                let i = rng.random_range(0..=len - 4);
                v[i..i + 4].copy_from_slice(&w);
            }
            _ => {}
        }
    }
    v.truncate(MAX_INPUT);
    v
}

fn hash(b: &[u8]) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    b.hash(&mut h);
    h.finish()
}
