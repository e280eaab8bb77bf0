//! OpenImageIO round trips: EXR with half and float channels and metadata, PNG (8 bits), TIFF,
//! and failures that must name the path.
//!
//! Tolerances: half channels 2⁻¹¹ relative (half's precision), float channels exact, 8-bit
//! channels half a step (1/510).

// Tests may unwrap: a panic is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo, MetaValue};
use mipray_bridge::{oiio_version, OiioImageIo};

fn scratch_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mipray-bridge-{test}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn test_image(channels: &[&str], width: usize, height: usize) -> ImageBuf {
    let nch = channels.len();
    let mut pixels = Vec::with_capacity(width * height * nch);
    for y in 0..height {
        for x in 0..width {
            for (c, name) in channels.iter().enumerate() {
                // Values in [0, 1) that half cannot hold exactly, plus a large depth-like value.
                let v = 0.1 + (x as f32 * 0.071 + y as f32 * 0.113 + c as f32 * 0.029) % 0.85;
                pixels.push(if *name == "Z" { 1234.567 + v } else { v });
            }
        }
    }
    ImageBuf { width, height, channels: channels.iter().map(|s| s.to_string()).collect(), pixels, metadata: vec![] }
}

/// The value of channel `name` at pixel index `i` of `img`.
fn value(img: &ImageBuf, name: &str, i: usize) -> f32 {
    let c = img.channels.iter().position(|n| n == name).unwrap_or_else(|| panic!("no channel {name} in {:?}", img.channels));
    img.pixels[i * img.channels.len() + c]
}

/// Metadata by name, ignoring case: OpenImageIO stores well-known names in the file format's
/// spelling (`worldtocamera` becomes EXR's `worldToCamera`).
fn meta<'a>(img: &'a ImageBuf, name: &str) -> &'a str {
    img.metadata
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case(name))
        .map(|(_, v)| v.as_str())
        .unwrap_or_else(|| panic!("no metadata {name} in {:?}", img.metadata))
}

#[test]
fn version_is_2_4_or_later() {
    let v = oiio_version();
    let mut parts = v.split('.').map(|p| p.parse::<u32>().unwrap());
    let (major, minor) = (parts.next().unwrap(), parts.next().unwrap());
    println!("OpenImageIO {v}");
    assert!((major, minor) >= (2, 4), "{v}");
}

#[test]
fn exr_keeps_half_and_float_channels_and_metadata() {
    let dir = scratch_dir("exr");
    let path = dir.join("beauty.exr");
    let img = test_image(&["R", "G", "B", "Z"], 7, 5);
    let formats = [ChannelFormat::Half, ChannelFormat::Half, ChannelFormat::Half, ChannelFormat::Float];
    let w2c: [f32; 16] = [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.5, -2.0, 3.25, 1.0];
    let metadata = vec![
        ("worldtocamera".to_string(), MetaValue::Matrix44(w2c)),
        ("mipray:scene".to_string(), MetaValue::Str("/tmp/scene.usda".into())),
        ("mipray:samples".to_string(), MetaValue::Int(64)),
        ("mipray:wall_s".to_string(), MetaValue::Float(1.5)),
    ];
    let io = OiioImageIo;
    io.write(&path, &img, &formats, &metadata).unwrap();
    let back = io.read(&path).unwrap();
    assert_eq!((back.width, back.height), (7, 5));
    let mut names = back.channels.clone();
    names.sort();
    assert_eq!(names, ["B", "G", "R", "Z"]);
    let (mut half_err, mut float_err, mut half_rounded) = (0.0f32, 0.0f32, 0usize);
    for i in 0..35 {
        for c in ["R", "G", "B"] {
            let (w, r) = (value(&img, c, i), value(&back, c, i));
            half_err = half_err.max((w - r).abs() / w.abs());
            half_rounded += usize::from(w != r);
        }
        float_err = float_err.max((value(&img, "Z", i) - value(&back, "Z", i)).abs());
    }
    println!("exr: half rel err {half_err:.1e} ({half_rounded} values rounded), float err {float_err:.1e}");
    assert!(half_err <= 2f32.powi(-11), "half channels off by {half_err}");
    // The color channels really were stored as half (values rounded), depth as float (exact).
    assert!(half_rounded > 0, "color channels were not stored as half");
    assert_eq!(float_err, 0.0, "depth was not stored as float");
    assert_eq!(meta(&back, "Software"), format!("mipray {}", env!("CARGO_PKG_VERSION")));
    assert_eq!(meta(&back, "mipray:scene"), "/tmp/scene.usda");
    assert_eq!(meta(&back, "mipray:samples"), "64");
    assert_eq!(meta(&back, "mipray:wall_s").parse::<f32>().unwrap(), 1.5);
    let m: Vec<f32> = meta(&back, "worldtocamera").split(',').map(|s| s.trim().parse().unwrap()).collect();
    assert_eq!(m, w2c, "worldtocamera round trip");
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn png_is_stored_as_8_bits() {
    let dir = scratch_dir("png");
    let path = dir.join("color.png");
    let img = test_image(&["R", "G", "B"], 6, 4);
    // Asked for float: PNG cannot hold it, so 8 bits.
    OiioImageIo.write(&path, &img, &[ChannelFormat::Float], &[]).unwrap();
    let back = OiioImageIo.read(&path).unwrap();
    assert_eq!(back.channels, ["R", "G", "B"]);
    let mut err = 0.0f32;
    for (w, r) in img.pixels.iter().zip(&back.pixels) {
        err = err.max((w - r).abs());
        assert!((r * 255.0 - (r * 255.0).round()).abs() < 1e-4, "{r} is not an 8-bit value");
    }
    println!("png: max err {err:.1e}");
    assert!(err <= 1.0 / 510.0 + 1e-6);
    assert_eq!(meta(&back, "Software"), format!("mipray {}", env!("CARGO_PKG_VERSION")));
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn tiff_keeps_float() {
    let dir = scratch_dir("tiff");
    let path = dir.join("aovs.tif");
    let img = test_image(&["R", "G", "B", "A"], 5, 3);
    OiioImageIo.write(&path, &img, &[ChannelFormat::Float; 4], &[("mipray:note".into(), MetaValue::Str("tiff".into()))]).unwrap();
    let back = OiioImageIo.read(&path).unwrap();
    assert_eq!(back.channels, ["R", "G", "B", "A"]);
    assert_eq!(back.pixels, img.pixels);
    std::fs::remove_dir_all(dir).ok();
}

#[test]
fn failures_name_the_path() {
    let img = test_image(&["R", "G", "B"], 2, 2);
    let io = OiioImageIo;
    let check = |path: &Path, err: mipray::error::ImageError| {
        let s = err.to_string();
        println!("{s}");
        assert!(s.contains(&path.display().to_string()), "path missing from: {s}");
    };
    let unwritable = Path::new("/nonexistent-mipray-dir/sub/out.exr");
    check(unwritable, io.write(unwritable, &img, &[ChannelFormat::Half], &[]).unwrap_err());
    let unknown = std::env::temp_dir().join("mipray-bridge-test.not-an-image-format");
    check(&unknown, io.write(&unknown, &img, &[ChannelFormat::Half], &[]).unwrap_err());
    let missing = Path::new("/nonexistent-mipray-dir/in.exr");
    check(missing, io.read(missing).unwrap_err());
    let short = ImageBuf { pixels: vec![0.0; 5], ..img.clone() };
    let p = std::env::temp_dir().join("mipray-bridge-short.exr");
    check(&p, io.write(&p, &short, &[ChannelFormat::Half], &[]).unwrap_err());
    check(&p, io.write(&p, &img, &[ChannelFormat::Half, ChannelFormat::Float], &[]).unwrap_err());
    let big = [("n".to_string(), MetaValue::Int(1 << 40))];
    check(&p, io.write(&p, &img, &[ChannelFormat::Half], &big).unwrap_err());
}
