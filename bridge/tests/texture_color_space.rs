//! UsdUVTexture `sourceColorSpace` through [`OiioTextureSystem::handle_encoded`]: lookups of an
//! sRGB-encoded file return linear values, decoded before filtering, alpha as stored; `auto`
//! follows Hydra's rule (8-bit with 3 or 4 channels is sRGB, anything else raw); the linear copy
//! is made once per file version and shared.
//!
//! Truth is the sRGB curve itself ([`srgb_to_linear`], IEC 61966-2-1) applied to the 8-bit values
//! written; tolerances are half-float precision (about 1e-3 relative) of the linear copy.

// Tests may unwrap: a panic is the failure report.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use mipray::image_io::{ChannelFormat, ImageBuf, ImageIo};
use mipray::texture::{srgb_to_linear, FilterMode, Lookup, SourceColorSpace, TextureHandle, TextureSampler};
use mipray_bridge::{OiioImageIo, OiioTextureOptions, OiioTextureSystem};

fn scratch_dir(test: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("mipray-colorspace-{test}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A `res`² image of `channels` 8-bit channels (names R, G, B, A from the first), each texel's
/// code value given by `code(x, row from the top, channel)`.
fn write_u8(path: &Path, res: usize, channels: usize, code: impl Fn(usize, usize, usize) -> u8) {
    let mut pixels = Vec::with_capacity(res * res * channels);
    for row in 0..res {
        for x in 0..res {
            for c in 0..channels {
                pixels.push(f32::from(code(x, row, c)) / 255.0);
            }
        }
    }
    let names = ["R", "G", "B", "A"][..channels].iter().map(|s| s.to_string()).collect();
    let image = ImageBuf { width: res, height: res, channels: names, pixels, metadata: vec![] };
    OiioImageIo.write(path, &image, &vec![ChannelFormat::U8; channels], &[]).unwrap();
}

fn system(cache: &Path) -> OiioTextureSystem {
    OiioTextureSystem::new(OiioTextureOptions { filter: FilterMode::Differentials, ..OiioTextureOptions::DEFAULT })
        .unwrap()
        .with_linear_cache_dir(cache)
}

/// A point lookup of `n` channels from `first` at `st`.
fn at(ts: &OiioTextureSystem, h: TextureHandle, st: [f32; 2], first: u32, n: usize) -> Vec<f32> {
    let mut out = vec![0.0; n];
    let lookup = Lookup { first_channel: first, ..Lookup::DEFAULT };
    assert!(ts.sample(h, st, [0.0; 2], [0.0; 2], &lookup, &mut out));
    out
}

fn copies(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    v.sort();
    v
}

#[test]
fn srgb_files_read_as_linear_values_with_alpha_as_stored() {
    let dir = scratch_dir("rgba");
    let cache = dir.join("cache");
    let png = dir.join("grey.png");
    // Left half: colour code 128 (encoded 0.502), opaque. Right half: white, alpha code 128
    // (OpenImageIO premultiplies what it reads, so colour is only checked where opaque).
    write_u8(&png, 32, 4, |x, _, c| match (x < 16, c < 3) {
        (true, true) => 128,
        (true, false) | (false, true) => 255,
        (false, false) => 128,
    });
    let ts = system(&cache);
    let p = png.to_str().unwrap();
    let raw = ts.handle_encoded(p, SourceColorSpace::Raw).unwrap();
    let auto = ts.handle_encoded(p, SourceColorSpace::Auto).unwrap();
    let srgb = ts.handle_encoded(p, SourceColorSpace::Srgb).unwrap();
    assert_eq!(auto, srgb, "auto on an 8-bit RGBA file is sRGB, the same copy");
    assert_ne!(raw, srgb);
    let encoded = 128.0 / 255.0;
    let linear = srgb_to_linear(encoded);
    for v in at(&ts, raw, [0.25, 0.5], 0, 3) {
        assert!((v - encoded).abs() < 1e-4, "raw {v} vs {encoded}");
    }
    for v in at(&ts, srgb, [0.25, 0.5], 0, 3) {
        assert!((v - linear).abs() < 1e-3 * linear + 1e-5, "sRGB {v} vs {linear}");
    }
    let alpha = at(&ts, srgb, [0.75, 0.5], 3, 1)[0];
    assert!((alpha - encoded).abs() < 1e-3, "alpha is not decoded: {alpha} vs {encoded}");
    // The stats say which file was decoded from which.
    let stats = ts.stats();
    let files = stats["files"].as_array().unwrap();
    let decoded: Vec<_> = files.iter().filter(|f| f["source_color_space"] == "sRGB").collect();
    assert_eq!(decoded.len(), 1, "{files:?}");
    assert_eq!(decoded[0]["decoded_from"], p);
    assert!(decoded[0]["path"].as_str().unwrap().starts_with(cache.to_str().unwrap()));
}

#[test]
fn wide_lookups_average_linear_values_not_encoded_ones() {
    // A black/white checker of 8-bit sRGB codes 0 and 255 (linear 0 and 1). Averaged over the
    // whole texture it is 0.5 in linear light; averaging the codes and decoding would give
    // srgb_to_linear(0.5) = 0.214, the darkening a decode-after-filter sampler makes on every
    // minified (wide, incoherent) lookup.
    let dir = scratch_dir("checker");
    let png = dir.join("checker.png");
    write_u8(&png, 256, 3, |x, row, _| if (x / 16 + row / 16) % 2 == 0 { 0 } else { 255 });
    let ts = system(&dir.join("cache"));
    let h = ts.handle_encoded(png.to_str().unwrap(), SourceColorSpace::Auto).unwrap();
    let mut out = [0.0f32; 3];
    assert!(ts.sample(h, [0.5, 0.5], [1.0, 0.0], [0.0, 1.0], &Lookup::DEFAULT, &mut out));
    for v in out {
        assert!((v - 0.5).abs() < 0.02, "wide lookup {v}, linear mean 0.5 (decode-after-filter: 0.214)");
    }
}

#[test]
fn auto_is_raw_for_one_channel_and_float_files() {
    let dir = scratch_dir("auto");
    let cache = dir.join("cache");
    let grey = dir.join("rough.png");
    write_u8(&grey, 16, 1, |_, _, _| 128);
    let ts = system(&cache);
    let h = ts.handle_encoded(grey.to_str().unwrap(), SourceColorSpace::Auto).unwrap();
    let v = at(&ts, h, [0.5, 0.5], 0, 1)[0];
    assert!((v - 128.0 / 255.0).abs() < 1e-4, "one 8-bit channel is raw under auto: {v}");
    let exr = dir.join("colour.exr");
    let image =
        ImageBuf { width: 8, height: 8, channels: vec!["R".into(), "G".into(), "B".into()], pixels: vec![0.5; 192], metadata: vec![] };
    OiioImageIo.write(&exr, &image, &[ChannelFormat::Half; 3], &[]).unwrap();
    let h = ts.handle_encoded(exr.to_str().unwrap(), SourceColorSpace::Auto).unwrap();
    assert!((at(&ts, h, [0.5, 0.5], 0, 3)[0] - 0.5).abs() < 1e-4, "float RGB is raw under auto");
    assert!(!cache.exists() || copies(&cache).is_empty(), "nothing was decoded: {:?}", copies(&cache));
    // An explicit sRGB still decodes a one-channel file.
    let h = ts.handle_encoded(grey.to_str().unwrap(), SourceColorSpace::Srgb).unwrap();
    let v = at(&ts, h, [0.5, 0.5], 0, 1)[0];
    assert!((v - srgb_to_linear(128.0 / 255.0)).abs() < 1e-3, "{v}");
}

#[test]
fn the_linear_copy_is_made_once_per_file_version() {
    let dir = scratch_dir("reuse");
    let cache = dir.join("cache");
    let png = dir.join("tile.png");
    write_u8(&png, 16, 3, |_, _, _| 64);
    let p = png.to_str().unwrap();
    let first = system(&cache);
    let h = first.handle_encoded(p, SourceColorSpace::Srgb).unwrap();
    assert!((at(&first, h, [0.5, 0.5], 0, 1)[0] - srgb_to_linear(64.0 / 255.0)).abs() < 1e-3);
    let made = copies(&cache);
    assert_eq!(made.len(), 1, "{made:?}");
    let stamp = std::fs::metadata(&made[0]).unwrap().modified().unwrap();
    // A second render (system) finds the copy rather than writing it again.
    let second = system(&cache);
    second.handle_encoded(p, SourceColorSpace::Srgb).unwrap();
    assert_eq!(copies(&cache), made);
    assert_eq!(std::fs::metadata(&made[0]).unwrap().modified().unwrap(), stamp);
    // An edited source (new size) is a new version: a new copy with the new values.
    write_u8(&png, 32, 3, |_, _, _| 200);
    let third = system(&cache);
    let h = third.handle_encoded(p, SourceColorSpace::Srgb).unwrap();
    assert!((at(&third, h, [0.5, 0.5], 0, 1)[0] - srgb_to_linear(200.0 / 255.0)).abs() < 2e-3);
    assert_eq!(copies(&cache).len(), 2);
}

#[test]
fn unreadable_srgb_files_are_refused_naming_the_path() {
    let dir = scratch_dir("errors");
    let ts = system(&dir.join("cache"));
    for space in [SourceColorSpace::Auto, SourceColorSpace::Srgb] {
        let missing = dir.join("missing.png");
        let err = ts.handle_encoded(missing.to_str().unwrap(), space).unwrap_err();
        assert!(err.to_string().contains("missing.png"), "{space:?}: {err}");
        let junk = dir.join("junk.png");
        std::fs::write(&junk, "not an image").unwrap();
        let err = ts.handle_encoded(junk.to_str().unwrap(), space).unwrap_err();
        assert!(err.to_string().contains("junk.png"), "{space:?}: {err}");
    }
    // Nothing half-written is left behind.
    let cache = dir.join("cache");
    assert!(!cache.exists() || copies(&cache).is_empty(), "{:?}", copies(&cache));
}

#[test]
fn an_unwritable_cache_falls_back_to_the_temporary_directory() {
    let dir = scratch_dir("unwritable");
    let png = dir.join("fallback.png");
    write_u8(&png, 16, 3, |_, _, _| 96);
    // A plain file where the cache directory should be: it cannot be created.
    let blocked = dir.join("not-a-dir");
    std::fs::write(&blocked, "file").unwrap();
    let ts = system(&blocked.join("cache"));
    let h = ts.handle_encoded(png.to_str().unwrap(), SourceColorSpace::Srgb).unwrap();
    assert!((at(&ts, h, [0.5, 0.5], 0, 1)[0] - srgb_to_linear(96.0 / 255.0)).abs() < 1e-3);
    let stats = ts.stats();
    let path = stats["files"][0]["path"].as_str().unwrap().to_string();
    assert!(path.starts_with(std::env::temp_dir().join("mipray-textures").to_str().unwrap()), "{path}");
}

#[test]
fn threads_opening_one_srgb_file_share_one_copy_and_handle() {
    let dir = scratch_dir("threads");
    let cache = dir.join("cache");
    let png = dir.join("shared.png");
    write_u8(&png, 64, 3, |x, _, _| (x * 4) as u8);
    let ts = system(&cache);
    let p = png.to_str().unwrap();
    let handles: Vec<TextureHandle> = std::thread::scope(|scope| {
        let workers: Vec<_> = (0..4).map(|_| scope.spawn(|| ts.handle_encoded(p, SourceColorSpace::Auto).unwrap())).collect();
        workers.into_iter().map(|w| w.join().unwrap()).collect()
    });
    assert!(handles.iter().all(|&h| h == handles[0]), "{handles:?}");
    assert_eq!(copies(&cache).len(), 1, "{:?}", copies(&cache));
}

#[test]
fn a_file_asked_for_again_is_not_read_again() {
    // Every mesh binding a texture asks for it at every render: the second request answers from
    // the first, without reading the file's header (auto) or looking for its copy (sRGB). The
    // source is removed after the first request, so any second read would fail.
    let dir = scratch_dir("again");
    let png = dir.join("once.png");
    write_u8(&png, 16, 3, |_, _, _| 160);
    let ts = system(&dir.join("cache"));
    let p = png.to_str().unwrap();
    let first = [SourceColorSpace::Auto, SourceColorSpace::Srgb, SourceColorSpace::Raw].map(|s| ts.handle_encoded(p, s).unwrap());
    std::fs::remove_file(&png).unwrap();
    let again = [SourceColorSpace::Auto, SourceColorSpace::Srgb, SourceColorSpace::Raw].map(|s| ts.handle_encoded(p, s).unwrap());
    assert_eq!(first, again);
    assert_eq!(first[0], first[1], "auto on 8-bit RGB is the sRGB copy");
    assert!(ts.decoded_from_srgb(first[0]) && !ts.decoded_from_srgb(first[2]));
}

#[test]
fn a_same_size_replacement_with_its_time_restored_gets_a_new_copy() {
    // The cache was keyed by path, size and modification time: this replacement was served the
    // old copy (issue 16).
    let dir = scratch_dir("replaced");
    let cache = dir.join("cache");
    let png = dir.join("swap.png");
    write_u8(&png, 16, 3, |_, _, _| 40);
    let stamp = std::fs::metadata(&png).unwrap().modified().unwrap();
    let p = png.to_str().unwrap();
    let first = system(&cache);
    let h = first.handle_encoded(p, SourceColorSpace::Srgb).unwrap();
    assert!((at(&first, h, [0.5, 0.5], 0, 1)[0] - srgb_to_linear(40.0 / 255.0)).abs() < 1e-3);
    let size = std::fs::metadata(&png).unwrap().len();
    write_u8(&png, 16, 3, |_, _, _| 220);
    assert_eq!(std::fs::metadata(&png).unwrap().len(), size, "the test needs a same-size file");
    std::fs::File::options().write(true).open(&png).unwrap().set_modified(stamp).unwrap();
    let second = system(&cache);
    let h = second.handle_encoded(p, SourceColorSpace::Srgb).unwrap();
    let v = at(&second, h, [0.5, 0.5], 0, 1)[0];
    assert!((v - srgb_to_linear(220.0 / 255.0)).abs() < 2e-3, "stale copy served: {v}");
}

#[test]
fn a_damaged_copy_is_made_again() {
    let dir = scratch_dir("damaged");
    let cache = dir.join("cache");
    let png = dir.join("dmg.png");
    write_u8(&png, 32, 3, |x, _, _| (x * 8) as u8);
    let p = png.to_str().unwrap();
    system(&cache).handle_encoded(p, SourceColorSpace::Srgb).unwrap();
    let made = copies(&cache);
    assert_eq!(made.len(), 1, "{made:?}");
    for damage in ["truncated", "edited"] {
        let mut bytes = std::fs::read(&made[0]).unwrap();
        if damage == "truncated" {
            bytes.truncate(bytes.len() / 2);
        } else {
            let n = bytes.len();
            bytes[n - 10] ^= 0x55;
        }
        std::fs::write(&made[0], &bytes).unwrap();
        let ts = system(&cache);
        let h = ts.handle_encoded(p, SourceColorSpace::Srgb).unwrap();
        let v = at(&ts, h, [0.3, 0.5], 0, 1)[0];
        let x = (0.3f32 * 32.0) as u32;
        assert!((v - srgb_to_linear((x * 8) as f32 / 255.0)).abs() < 2e-2, "{damage}: {v}");
        assert_eq!(copies(&cache).len(), 1, "{damage}: {:?}", copies(&cache));
        let rebuilt = std::fs::read(&copies(&cache)[0]).unwrap();
        assert_ne!(rebuilt, bytes, "{damage}: the damaged copy was served");
    }
}

#[test]
fn the_copy_is_half_float_and_the_cache_private() {
    use std::os::unix::fs::PermissionsExt;
    // Noise does not compress, so the file's size tells half (2 bytes) from float (4).
    let dir = scratch_dir("half");
    let cache = dir.join("cache");
    let png = dir.join("noise.png");
    let res = 128;
    write_u8(&png, res, 3, |x, row, c| ((x * 7919 + row * 104_729 + c * 31) % 251) as u8);
    system(&cache).handle_encoded(png.to_str().unwrap(), SourceColorSpace::Srgb).unwrap();
    let made = copies(&cache);
    let bytes = std::fs::metadata(&made[0]).unwrap().len() as f64;
    let float_bytes = (res * res * 3 * 4) as f64 * 4.0 / 3.0;
    assert!(bytes < 0.7 * float_bytes, "{bytes} bytes: not half float ({float_bytes} as float)");
    assert_eq!(std::fs::metadata(&cache).unwrap().permissions().mode() & 0o777, 0o700);
}
