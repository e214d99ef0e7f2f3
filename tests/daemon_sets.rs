//! Multi-file sets through the real daemon: an OBJ with its MTL and image, a PLY with
//! its texture, taken, repaired, published and archived together; a set with a missing
//! image fails with the reason; hostile references are never followed.

mod common;
mod daemon_support;

use daemon_support::*;
use serde_json::Value;
use std::fs;
use std::path::Path;
use std::time::Duration;

/// Any bytes, not UTF-8, standing in for a JPEG.
fn jpg_bytes(seed: u8) -> Vec<u8> {
    let mut v = vec![0xff, 0xd8, 0xff, 0xe0];
    v.extend((0..3000u32).map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed)));
    v.extend([0xff, 0xd9]);
    v
}

/// The test mesh with a material library and a material.
fn textured_obj(mtl: &str) -> String {
    let (obj, _) = mesh();
    format!("# a textured scan\nmtllib {mtl}\nusemtl skin\n{obj}")
}

fn mtl_text(image: &str) -> String {
    format!("newmtl skin\nKa 1 1 1\nKd 1 1 1\nmap_Kd -s 1 1 1 {image}\n")
}

fn drop_bytes(dir: &Path, name: &str, bytes: &[u8]) {
    let tmp = dir.join(format!(".{name}.part"));
    fs::write(&tmp, bytes).unwrap();
    fs::rename(&tmp, dir.join(name)).unwrap();
}

/// The `mtllib` argument of an OBJ text.
fn mtllib_of(obj: &str) -> Option<String> {
    obj.lines()
        .find_map(|l| l.strip_prefix("mtllib "))
        .map(|s| s.trim().to_string())
}

fn member_names(log: &Value) -> Vec<String> {
    let mut v: Vec<String> = log["daemon"]["set"]["members"]
        .as_array()
        .map(|a| {
            a.iter()
                .filter_map(|m| m["name"].as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// Checks one set published whole under `out` (the outbox or a folder of it).
fn assert_whole(out: &Path, stem: &str, mtl: &str, jpg: &[u8]) {
    let obj = fs::read_to_string(out.join(format!("{stem}.obj"))).unwrap();
    let lib = mtllib_of(&obj).expect("the repaired OBJ keeps its mtllib");
    assert_eq!(lib, format!("{stem}.mtl"));
    assert!(obj.contains("usemtl skin"), "the material is carried");
    assert_eq!(
        fs::read_to_string(out.join(&lib)).unwrap(),
        mtl,
        "the MTL the OBJ names is beside it, unchanged"
    );
    assert_eq!(
        fs::read(out.join(format!("{stem}.jpg"))).unwrap(),
        jpg,
        "the image, byte for byte"
    );
    let log = Folders::log(out, &format!("{stem}.obj"));
    assert_eq!(log["status"], "repaired", "{log}");
    assert_eq!(
        member_names(&log),
        vec![format!("{stem}.jpg"), format!("{stem}.mtl")]
    );
}

#[test]
fn a_set_dropped_file_by_file_in_any_order_comes_out_whole() {
    let f = Folders::new();
    let d = Daemon::ready(&f, &["--set-wait-secs", "60"], &[]);
    // (stem, order of the drops: o = OBJ, m = MTL, j = JPG)
    let orders = [("a", "omj"), ("b", "jmo"), ("c", "mjo"), ("e", "ojm")];
    let mut inputs = Vec::new();
    for (k, (stem, order)) in orders.iter().enumerate() {
        let obj = textured_obj(&format!("{stem}.mtl"));
        let mtl = mtl_text(&format!("{stem}.jpg"));
        let jpg = jpg_bytes(k as u8);
        for c in order.chars() {
            match c {
                'o' => drop_renamed(&f.inbox, &format!("{stem}.obj"), &obj),
                'm' => drop_renamed(&f.inbox, &format!("{stem}.mtl"), &mtl),
                _ => drop_bytes(&f.inbox, &format!("{stem}.jpg"), &jpg),
            }
            // longer than the settle time: a mesh dropped first is taken alone
            std::thread::sleep(Duration::from_millis(700));
        }
        inputs.push((stem, obj, mtl, jpg));
    }
    assert!(
        wait_until(Duration::from_secs(60), || orders.iter().all(|(s, _)| f
            .outbox
            .join(format!("{s}.obj.repair.json"))
            .exists())),
        "not all sets published: outbox {:?}\n{}",
        Folders::files(&f.outbox),
        d.log()
    );
    assert!(
        d.log().contains("a.obj: its set waits for"),
        "the OBJ dropped first waited for its files: {}",
        d.log()
    );
    for (stem, obj, mtl, jpg) in &inputs {
        assert_whole(&f.outbox, stem, mtl, jpg);
        // archived together, the originals unchanged
        assert_eq!(
            fs::read_to_string(f.archive.join(format!("{stem}.obj"))).unwrap(),
            *obj
        );
        assert_eq!(
            fs::read_to_string(f.archive.join(format!("{stem}.mtl"))).unwrap(),
            *mtl
        );
        assert_eq!(
            fs::read(f.archive.join(format!("{stem}.jpg"))).unwrap(),
            *jpg
        );
        let log = Folders::log(&f.outbox, &format!("{stem}.obj"));
        let members = log["daemon"]["set"]["members"].as_array().unwrap();
        for m in members {
            let archived = m["original"].as_str().unwrap();
            assert!(Path::new(archived).is_file(), "{archived}");
            assert!(Path::new(m["output"].as_str().unwrap()).is_file());
        }
    }
    assert!(
        Folders::files(&f.inbox).is_empty(),
        "{:?}",
        Folders::files(&f.inbox)
    );
    assert!(Folders::files(&f.failed).is_empty());
    assert!(f.processing().is_empty(), "{:?}", f.processing());

    // the same names again: the outbox's are taken, so the set goes into a folder of
    // its own, with every name kept (the OBJ's reference still finds its MTL)
    let (_, obj, mtl, jpg) = &inputs[0];
    drop_bytes(&f.inbox, "a.jpg", jpg);
    drop_renamed(&f.inbox, "a.mtl", mtl);
    drop_renamed(&f.inbox, "a.obj", obj);
    let sub = || {
        fs::read_dir(&f.outbox)
            .unwrap()
            .flatten()
            .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
            .map(|e| e.path())
            .find(|p| p.join("a.obj.repair.json").exists())
    };
    assert!(
        wait_until(Duration::from_secs(30), || sub().is_some()),
        "second set not published: {}",
        d.log()
    );
    let sub = sub().unwrap();
    assert!(
        sub.file_name().unwrap().to_string_lossy().starts_with("a."),
        "{}",
        sub.display()
    );
    assert_whole(&sub, "a", mtl, jpg);
    assert_eq!(
        fs::read_to_string(f.outbox.join("a.mtl")).unwrap(),
        *mtl,
        "the first set's files are untouched"
    );
    // archived together too, none overwritten
    assert!(wait_until(Duration::from_secs(10), || Folders::files(
        &f.inbox
    )
    .is_empty()));
    let archived: Vec<_> = fs::read_dir(&f.archive)
        .unwrap()
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .map(|e| Folders::files(&e.path()))
        .collect();
    assert_eq!(
        archived,
        vec![vec!["a.jpg".to_string(), "a.mtl".into(), "a.obj".into()]]
    );
}

#[test]
fn a_set_with_a_missing_image_fails_with_the_reason() {
    let f = Folders::new();
    let d = Daemon::ready(&f, &["--set-wait-secs", "2"], &[]);
    let obj = textured_obj("m.mtl");
    let mtl = mtl_text("m.jpg");
    drop_renamed(&f.inbox, "m.mtl", &mtl);
    drop_renamed(&f.inbox, "m.obj", &obj);
    // an OBJ whose material library never comes
    drop_renamed(&f.inbox, "n.obj", &textured_obj("n.mtl"));
    assert!(
        wait_until(Duration::from_secs(30), || f
            .failed
            .join("m.obj.repair.json")
            .exists()
            && f.failed.join("n.obj.repair.json").exists()),
        "failed: {:?}\n{}",
        Folders::files(&f.failed),
        d.log()
    );
    let log = Folders::log(&f.failed, "m.obj");
    assert_eq!(log["status"], "failed");
    assert_eq!(log["stage"], "set");
    let err = log["error"].as_str().unwrap();
    assert!(err.contains("missing texture m.jpg"), "{err}");
    assert_eq!(member_names(&log), vec!["m.mtl"]);
    // the set's present files went to failed with it, unchanged
    assert_eq!(fs::read_to_string(f.failed.join("m.obj")).unwrap(), obj);
    assert_eq!(fs::read_to_string(f.failed.join("m.mtl")).unwrap(), mtl);
    let log = Folders::log(&f.failed, "n.obj");
    let err = log["error"].as_str().unwrap();
    assert!(err.contains("missing material library n.mtl"), "{err}");
    assert!(Folders::models(&f).is_empty());
    assert!(Folders::files(&f.inbox).is_empty());
}

#[test]
fn references_outside_the_inbox_are_never_followed() {
    let f = Folders::new();
    let secret = f.root().join("secret.jpg");
    fs::write(&secret, b"secret").unwrap();
    let etc = f.root().join("etc");
    fs::create_dir(&etc).unwrap();
    fs::write(etc.join("abs.jpg"), b"absolute").unwrap();
    fs::write(etc.join("lib.mtl"), mtl_text("secret.jpg")).unwrap();
    let d = Daemon::ready(&f, &["--set-wait-secs", "30"], &[]);
    // the OBJ names its own MTL and two outside it; the MTL names images outside
    let obj = format!(
        "mtllib h.mtl\nmtllib ../etc/lib.mtl\nmtllib {}\n{}",
        etc.join("lib.mtl").display(),
        mesh().0
    );
    let mtl = format!(
        "newmtl a\nmap_Kd ../secret.jpg\nmap_Ka {}\nmap_Ks link.jpg\nbump sub/x.png\nnorm h.png\n",
        etc.join("abs.jpg").display()
    );
    std::os::unix::fs::symlink(&secret, f.inbox.join("link.jpg")).unwrap();
    drop_bytes(&f.inbox, "h.png", b"png bytes");
    drop_renamed(&f.inbox, "h.mtl", &mtl);
    drop_renamed(&f.inbox, "h.obj", &obj);
    assert!(
        wait_until(Duration::from_secs(30), || f
            .outbox
            .join("h.obj.repair.json")
            .exists()),
        "{}",
        d.log()
    );
    let log = Folders::log(&f.outbox, "h.obj");
    assert_eq!(log["status"], "repaired");
    assert_eq!(member_names(&log), vec!["h.mtl", "h.png"]);
    let refused = log["daemon"]["set"]["not_followed"].as_array().unwrap();
    let why = |r: &str| {
        refused
            .iter()
            .find(|x| x["reference"].as_str().is_some_and(|s| s.contains(r)))
            .and_then(|x| x["why"].as_str())
            .unwrap_or_else(|| panic!("{r} not listed as not followed: {refused:?}"))
            .to_string()
    };
    assert!(why("../etc/lib.mtl").contains(".."));
    assert!(why(&format!("{}", etc.join("lib.mtl").display())).contains("absolute"));
    assert!(why("../secret.jpg").contains(".."));
    assert!(why("abs.jpg").contains("absolute"));
    assert!(why("sub/x.png").contains("subfolder"));
    assert!(why("link.jpg").contains("not a regular file"));
    // nothing of outside the inbox was read into the outputs, moved or changed
    assert_eq!(
        Folders::files(&f.outbox)
            .into_iter()
            .filter(|n| !n.ends_with(".repair.png"))
            .collect::<Vec<_>>(),
        vec!["h.mtl", "h.obj", "h.obj.repair.json", "h.png"]
    );
    assert_eq!(fs::read(&secret).unwrap(), b"secret");
    assert_eq!(fs::read(etc.join("abs.jpg")).unwrap(), b"absolute");
    assert!(etc.join("lib.mtl").is_file());
    assert!(
        fs::symlink_metadata(f.inbox.join("link.jpg")).is_ok_and(|m| m.file_type().is_symlink()),
        "the symlink is left where it is"
    );
}

#[test]
fn lone_members_are_left_alone_and_a_ply_takes_its_texture() {
    let f = Folders::new();
    let d = Daemon::ready(&f, &["--set-wait-secs", "30"], &[]);
    drop_bytes(&f.inbox, "alone.jpg", &jpg_bytes(9));
    drop_renamed(&f.inbox, "alone.mtl", &mtl_text("alone.jpg"));
    // a PLY naming its texture
    let (obj, _) = mesh();
    let vs: Vec<&str> = obj.lines().filter(|l| l.starts_with("v ")).collect();
    let fs_: Vec<&str> = obj.lines().filter(|l| l.starts_with("f ")).collect();
    let mut ply = format!(
        "ply\nformat ascii 1.0\ncomment TextureFile p.png\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nelement face {}\nproperty list uchar int vertex_indices\nend_header\n",
        vs.len(),
        fs_.len()
    );
    for v in &vs {
        ply.push_str(&v[2..]);
        ply.push('\n');
    }
    for l in &fs_ {
        let ix: Vec<usize> = l[2..]
            .split_whitespace()
            .map(|w| w.split('/').next().unwrap().parse::<usize>().unwrap() - 1)
            .collect();
        ply.push_str(&format!(
            "{} {}\n",
            ix.len(),
            ix.iter()
                .map(|i| i.to_string())
                .collect::<Vec<_>>()
                .join(" ")
        ));
    }
    drop_renamed(&f.inbox, "p.ply", &ply);
    std::thread::sleep(Duration::from_millis(800));
    drop_bytes(&f.inbox, "p.png", b"\x89PNG texture");
    assert!(
        wait_until(Duration::from_secs(30), || f
            .outbox
            .join("p.ply.repair.json")
            .exists()),
        "{}",
        d.log()
    );
    assert_eq!(
        fs::read(f.outbox.join("p.png")).unwrap(),
        b"\x89PNG texture"
    );
    assert!(fs::read_to_string(f.outbox.join("p.ply"))
        .unwrap()
        .contains("comment TextureFile p.png"));
    assert_eq!(
        member_names(&Folders::log(&f.outbox, "p.ply")),
        vec!["p.png"]
    );
    assert!(f.archive.join("p.png").is_file());
    // the lone MTL and image: not meshes, never failed, still waiting in the inbox
    std::thread::sleep(Duration::from_secs(2));
    assert_eq!(Folders::files(&f.inbox), vec!["alone.jpg", "alone.mtl"]);
    assert!(Folders::files(&f.failed).is_empty());
    assert!(!d.log().contains("alone.jpg:"), "{}", d.log());
}

#[test]
fn a_kill_while_a_set_is_published_leaves_one_copy_of_each_file() {
    for point in [
        "committing",
        "model-published",
        "members-published",
        "archived",
    ] {
        let f = Folders::new();
        let obj = textured_obj("k.mtl");
        let mtl = mtl_text("k.jpg");
        let jpg = jpg_bytes(3);
        let mut d = Daemon::ready(
            &f,
            &["--set-wait-secs", "30"],
            &[("HOLEFILL_TEST_DIE_AT", &format!("{point}:k.obj"))],
        );
        drop_bytes(&f.inbox, "k.jpg", &jpg);
        drop_renamed(&f.inbox, "k.mtl", &mtl);
        drop_renamed(&f.inbox, "k.obj", &obj);
        assert!(
            d.wait_exit(Duration::from_secs(30)).is_some(),
            "{point}: did not die: {}",
            d.log()
        );
        let d2 = Daemon::ready(&f, &["--set-wait-secs", "30"], &[]);
        assert!(
            wait_until(Duration::from_secs(30), || f
                .outbox
                .join("k.obj.repair.json")
                .exists()),
            "{point}: {}\n{}",
            d.log(),
            d2.log()
        );
        assert_whole(&f.outbox, "k", &mtl, &jpg);
        assert_eq!(
            Folders::files(&f.outbox)
                .into_iter()
                .filter(|n| !n.ends_with(".png"))
                .collect::<Vec<_>>(),
            vec!["k.jpg", "k.mtl", "k.obj", "k.obj.repair.json"],
            "{point}"
        );
        assert_eq!(
            Folders::files(&f.archive),
            vec!["k.jpg", "k.mtl", "k.obj"],
            "{point}"
        );
        assert!(Folders::files(&f.inbox).is_empty(), "{point}");
        assert!(Folders::files(&f.failed).is_empty(), "{point}");
        assert!(wait_until(Duration::from_secs(10), || f
            .processing()
            .is_empty()));
    }
}

#[test]
fn a_mesh_waiting_for_its_set_goes_back_to_the_inbox_on_sigterm() {
    let f = Folders::new();
    let mut d = Daemon::ready(&f, &["--set-wait-secs", "60"], &[]);
    let obj = textured_obj("w.mtl");
    drop_renamed(&f.inbox, "w.obj", &obj);
    assert!(d.wait_log("w.obj: its set waits for", 1), "{}", d.log());
    assert!(
        Folders::files(&f.inbox).is_empty(),
        "claimed while it waits"
    );
    d.signal("TERM");
    let st = d.wait_exit(Duration::from_secs(20)).expect("stops");
    assert!(st.success(), "{st:?}\n{}", d.log());
    assert_eq!(Folders::files(&f.inbox), vec!["w.obj"]);
    assert_eq!(fs::read_to_string(f.inbox.join("w.obj")).unwrap(), obj);
    assert!(f.processing().is_empty());
    // the next daemon takes it again and completes the set once it is there
    let d2 = Daemon::ready(&f, &["--set-wait-secs", "60"], &[]);
    let jpg = jpg_bytes(5);
    drop_bytes(&f.inbox, "w.jpg", &jpg);
    drop_renamed(&f.inbox, "w.mtl", &mtl_text("w.jpg"));
    assert!(
        wait_until(Duration::from_secs(30), || f
            .outbox
            .join("w.obj.repair.json")
            .exists()),
        "{}",
        d2.log()
    );
    assert_whole(&f.outbox, "w", &mtl_text("w.jpg"), &jpg);
}

/// The test mesh as a `.gltf` whose buffer is the external file `bin` and which names
/// the images `images` (and one `data:` image, no file): the document and the
/// buffer's bytes.
fn gltf_set(bin: &str, images: &[&str]) -> (String, Vec<u8>) {
    use base64::Engine as _;
    let dir = tempfile::tempdir().unwrap();
    fs::write(dir.path().join("m.obj"), mesh().0).unwrap();
    let raw = holefill::io::read(&dir.path().join("m.obj"), None).unwrap();
    holefill::io::write(&dir.path().join("m.gltf"), &raw, None).unwrap();
    let mut doc: Value =
        serde_json::from_slice(&fs::read(dir.path().join("m.gltf")).unwrap()).unwrap();
    let uri = doc["buffers"][0]["uri"].as_str().unwrap().to_string();
    let (_, b64) = uri.split_once(";base64,").unwrap();
    let bytes = base64::engine::general_purpose::STANDARD
        .decode(b64)
        .unwrap();
    doc["buffers"][0]["uri"] = Value::from(bin);
    let mut imgs: Vec<Value> = images
        .iter()
        .map(|u| serde_json::json!({ "uri": u }))
        .collect();
    imgs.push(serde_json::json!({"uri": "data:image/png;base64,iVBORw0KGgo="}));
    doc["images"] = Value::from(imgs);
    (serde_json::to_string_pretty(&doc).unwrap(), bytes)
}

/// Any bytes standing in for a PNG.
fn png_bytes(seed: u8) -> Vec<u8> {
    let mut v = b"\x89PNG\r\n\x1a\n".to_vec();
    v.extend((0..2000u32).map(|i| (i as u8).wrapping_mul(17).wrapping_add(seed)));
    v
}

#[test]
fn a_gltf_with_its_bin_and_png_dropped_in_any_order_comes_out_whole() {
    let f = Folders::new();
    let d = Daemon::ready(&f, &["--set-wait-secs", "60"], &[]);
    // (stem, order of the drops: g = .gltf, b = .bin, p = .png)
    let orders = [("ga", "gbp"), ("gb", "pbg"), ("gc", "bgp")];
    let mut inputs = Vec::new();
    for (k, (stem, order)) in orders.iter().enumerate() {
        let (gltf, bin) = gltf_set(&format!("{stem}.bin"), &[&format!("{stem}.png")]);
        let png = png_bytes(k as u8);
        for c in order.chars() {
            match c {
                'g' => drop_renamed(&f.inbox, &format!("{stem}.gltf"), &gltf),
                'b' => drop_bytes(&f.inbox, &format!("{stem}.bin"), &bin),
                _ => drop_bytes(&f.inbox, &format!("{stem}.png"), &png),
            }
            std::thread::sleep(Duration::from_millis(700));
        }
        inputs.push((stem, gltf, bin, png));
    }
    assert!(
        wait_until(Duration::from_secs(60), || orders.iter().all(|(s, _)| f
            .outbox
            .join(format!("{s}.gltf.repair.json"))
            .exists())),
        "not all sets published: outbox {:?}\n{}",
        Folders::files(&f.outbox),
        d.log()
    );
    assert!(
        d.log().contains("ga.gltf: its set waits for"),
        "{}",
        d.log()
    );
    for (stem, gltf, bin, png) in &inputs {
        let log = Folders::log(&f.outbox, &format!("{stem}.gltf"));
        assert_eq!(log["status"], "repaired", "{log}");
        assert_eq!(
            member_names(&log),
            vec![format!("{stem}.bin"), format!("{stem}.png")]
        );
        // the repaired document still names its buffer file, which is beside it
        // unchanged (the patch is in a data: URI), and reads with its holes closed
        let out = f.outbox.join(format!("{stem}.gltf"));
        let doc: Value = serde_json::from_slice(&fs::read(&out).unwrap()).unwrap();
        assert_eq!(doc["buffers"][0]["uri"], format!("{stem}.bin"));
        assert_eq!(
            fs::read(f.outbox.join(format!("{stem}.bin"))).unwrap(),
            *bin
        );
        assert_eq!(
            fs::read(f.outbox.join(format!("{stem}.png"))).unwrap(),
            *png
        );
        let repaired = holefill::io::read(&out, None).unwrap();
        assert!(repaired.faces.len() > mesh().1, "the holes were filled");
        // archived together, unchanged
        assert_eq!(
            fs::read_to_string(f.archive.join(format!("{stem}.gltf"))).unwrap(),
            *gltf
        );
        assert_eq!(
            fs::read(f.archive.join(format!("{stem}.bin"))).unwrap(),
            *bin
        );
        assert_eq!(
            fs::read(f.archive.join(format!("{stem}.png"))).unwrap(),
            *png
        );
    }
    assert!(
        Folders::files(&f.inbox).is_empty(),
        "{:?}",
        Folders::files(&f.inbox)
    );
}

#[test]
fn a_gltf_missing_its_bin_fails_and_hostile_uris_are_never_followed() {
    let f = Folders::new();
    let secret = f.root().join("secret.bin");
    fs::write(&secret, b"secret").unwrap();
    let d = Daemon::ready(&f, &["--set-wait-secs", "2"], &[]);
    // the buffer never comes; the image does
    let (gltf, _) = gltf_set("gm.bin", &["gm.png"]);
    drop_bytes(&f.inbox, "gm.png", &png_bytes(1));
    drop_renamed(&f.inbox, "gm.gltf", &gltf);
    // a buffer outside the inbox, images by absolute path and through a symlink
    std::os::unix::fs::symlink(&secret, f.inbox.join("link.png")).unwrap();
    let (hostile, _) = gltf_set(
        "../secret.bin",
        &[&secret.display().to_string(), "link.png"],
    );
    drop_renamed(&f.inbox, "gh.gltf", &hostile);
    assert!(
        wait_until(Duration::from_secs(30), || f
            .failed
            .join("gm.gltf.repair.json")
            .exists()
            && f.failed.join("gh.gltf.repair.json").exists()),
        "failed: {:?}\n{}",
        Folders::files(&f.failed),
        d.log()
    );
    let log = Folders::log(&f.failed, "gm.gltf");
    assert_eq!(log["stage"], "set", "{log}");
    let err = log["error"].as_str().unwrap();
    assert!(
        err.contains("missing buffer gm.bin (named by gm.gltf)"),
        "{err}"
    );
    assert_eq!(member_names(&log), vec!["gm.png"]);
    assert_eq!(fs::read_to_string(f.failed.join("gm.gltf")).unwrap(), gltf);
    assert_eq!(fs::read(f.failed.join("gm.png")).unwrap(), png_bytes(1));
    // nothing outside the inbox was read: the buffer's reference is listed as not
    // followed and the repair cannot read it
    let log = Folders::log(&f.failed, "gh.gltf");
    let refused = log["daemon"]["set"]["not_followed"].as_array().unwrap();
    let why = |r: &str| {
        refused
            .iter()
            .find(|x| x["reference"].as_str().is_some_and(|s| s.contains(r)))
            .and_then(|x| x["why"].as_str())
            .unwrap_or_else(|| panic!("{r} not listed as not followed: {refused:?}"))
            .to_string()
    };
    assert!(why("../secret.bin").contains(".."));
    assert!(why(&secret.display().to_string()).contains("absolute"));
    assert!(why("link.png").contains("not a regular file"));
    assert!(!refused.iter().any(|x| x["reference"]
        .as_str()
        .is_some_and(|s| s.starts_with("data:"))));
    let err = log["error"].as_str().unwrap();
    assert!(err.contains("secret.bin"), "{err}");
    assert_eq!(fs::read(&secret).unwrap(), b"secret");
    assert!(Folders::models(&f).is_empty());
}
