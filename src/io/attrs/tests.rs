use super::*;

#[test]
fn values_keep_their_bits_and_convert_new_ones() {
    let mut a = Values::new(ScalarType::U8, 0);
    a.push_f64(254.6);
    a.push_f64(-3.0);
    a.push_f64(f64::NAN);
    a.push_f64(1e9);
    assert_eq!(a, Values::U8(vec![255, 0, 0, 255]));
    let src = Values::F32(vec![f32::from_bits(0x7fc0_0001), 0.1]);
    let mut b = Values::new(ScalarType::F32, 0);
    assert!(b.push_from(&src, 0) && b.push_from(&src, 1));
    assert!(!b.push_from(&src, 2));
    let Values::F32(v) = &b else { panic!() };
    assert_eq!(v[0].to_bits(), 0x7fc0_0001);
    let mut bytes = Vec::new();
    b.write_bytes(1, true, &mut bytes);
    assert_eq!(bytes, 0.1f32.to_be_bytes());
}

#[test]
fn meanings_from_names() {
    let p = |name: &str, ty| Property {
        name: name.into(),
        data: PropData::Scalar(Values::new(ty, 0)),
    };
    assert_eq!(p("ny", ScalarType::F32).meaning(), Meaning::Normal(1));
    assert_eq!(p("red", ScalarType::U8).meaning(), Meaning::Color);
    assert_eq!(p("quality", ScalarType::F32).meaning(), Meaning::Smooth);
    assert_eq!(p("label", ScalarType::I32).meaning(), Meaning::Label);
}

#[test]
fn mtl_images_skip_the_options() {
    let m = "newmtl a\nKd 1 1 1\nmap_Kd -s 1 1 1 tex.jpg\nbump n.png # c\nmap_Kd tex.jpg\n";
    assert_eq!(mtl_images(m), vec!["tex.jpg", "n.png"]);
    let m = "\
        newmtl b\n\
        map_Ka -o 0.5 -s 2 2 -t 0 0 0 -clamp on amb.png\n\
        map_Ks -mm 0 1 -imfchan r spec.tga\n\
        map_Bump -bm 0.3 normal map.png\n\
        MAP_D -blendu off -blendv on alpha.png\n\
        disp -texres 512 d.exr\n\
        norm ./n2.png\n\
        refl -type sphere sky.hdr\n\
        map_aat on\n\
        map_Pr -s 1 rough.png\n\
        map_Kd\n\
        map_Kd -s 1 1 1\n\
        Ns 10\n\
        # map_Kd commented.png\n";
    assert_eq!(
        mtl_images(m),
        vec![
            "amb.png",
            "spec.tga",
            "normal map.png",
            "alpha.png",
            "d.exr",
            "./n2.png",
            "sky.hdr",
            "rough.png"
        ]
    );
    // CRLF line ends, tabs, and a name that looks like a number
    assert_eq!(
        mtl_images("map_Kd\t-s 1 1\t 1.jpg\r\nmap_Kd 2\r\n"),
        vec!["1.jpg", "2"]
    );
    // hostile names are returned as written: the caller decides what to follow
    assert_eq!(
        mtl_images("map_Kd ../../etc/passwd\nmap_Kd /etc/shadow\n"),
        vec!["../../etc/passwd", "/etc/shadow"]
    );
}
