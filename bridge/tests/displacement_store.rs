//! The displacement texture store ([`mipray::displacement_texture`]) against OpenImageIO:
//!
//! - the levels it keeps are the levels OpenImageIO's lookups filter (each compared texel for
//!   texel with the ImageCache's own read of that level, [`TextureSampler::texels`]), in the
//!   file's format, for `maketx` files of four formats and for untiled files through automip;
//! - a linear ramp displaces exactly linearly and a constant exactly constantly (analytic), and
//!   OpenImageIO's own filter agrees on both;
//! - every wrap mode, the file's own included, reads where OpenImageIO's does;
//! - on a smooth texture at the footprints grids ask for, the two filters differ by a small
//!   fraction of the texture's range (they are different filters: trilinear against
//!   OpenImageIO's anisotropic bicubic; the figures for the throughput scene are in
//!   docs/throughput-callgrind.md).
//!
//! `maketx` and `oiiotool` come with Debian's openimageio-tools (`scripts/setup.sh`); a test that
//! needs one and does not find it fails, saying so.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::PathBuf;
use std::sync::Arc;

use mipray::displacement::TextureDisplacement;
use mipray::displacement_texture::DisplacementTextures;
use mipray::image_io::ChannelFormat;
use mipray::patch::UvRect;
use mipray::texture::{LevelTexels, Lookup, SourceColorSpace, TextureSampler, Wrap};
use mipray_bridge::{OiioTextureOptions, OiioTextureSystem};

mod common;

use common::{maketx, require, write};

/// The core's tests' quad (a file of theirs: no crate depends on the other's tests).
#[path = "../../rust/tests/common/st_quad.rs"]
mod st_quad;

use st_quad::st_quad as quad;

fn scratch_dir(test: &str) -> PathBuf {
    common::scratch_dir("dispstore", test)
}

fn system() -> Arc<OiioTextureSystem> {
    Arc::new(OiioTextureSystem::new(OiioTextureOptions::DEFAULT).unwrap())
}

fn store(ts: &Arc<OiioTextureSystem>) -> Arc<DisplacementTextures> {
    Arc::new(DisplacementTextures::new(ts.clone()))
}

/// A level's texels as OpenImageIO converts them to float.
fn values(t: &LevelTexels) -> Vec<f32> {
    match t {
        LevelTexels::U8(v) => v.iter().map(|&x| f32::from(x) * (1.0 / 255.0)).collect(),
        LevelTexels::U16(v) => v.iter().map(|&x| f32::from(x) * (1.0 / 65535.0)).collect(),
        LevelTexels::Half(v) => v.iter().map(|&x| mipray::displacement_texture::half_to_f32(x)).collect(),
        LevelTexels::F32(v) => v.clone(),
    }
}

#[test]
fn kept_levels_are_the_levels_openimageio_filters() {
    require("maketx");
    let dir = scratch_dir("levels");
    let wave = |x: usize, y: usize| 0.5 + 0.4 * ((x as f32 * 0.21).sin() * (y as f32 * 0.13).cos());
    let exr = write(&dir, "wave.exr", 64, ChannelFormat::Float, wave);
    let png = write(&dir, "wave.png", 64, ChannelFormat::U8, wave);
    let cases = [
        (maketx(&exr, &dir.join("f.tx"), &[]), "float", 7),
        (maketx(&exr, &dir.join("h.exr"), &["-d", "half"]), "half", 7),
        (maketx(&exr, &dir.join("b.tx"), &["-d", "uint8"]), "uint8", 7),
        (maketx(&exr, &dir.join("s.tx"), &["-d", "uint16"]), "uint16", 7),
        // No levels in the file: automip's, as the lookups read them.
        (exr.clone(), "float", 7),
        (png.clone(), "uint8", 7),
    ];
    let ts = system();
    for (path, format, count) in cases {
        let h = ts.handle(path.to_str().unwrap()).unwrap();
        let levels = ts.channel_levels(h, 0).expect("levels offered").expect("levels read");
        assert_eq!(levels.levels.len(), count, "{path:?}");
        for (l, level) in levels.levels.iter().enumerate() {
            assert_eq!(level.texels.format_name(), format, "{path:?} level {l}");
            assert_eq!((level.width, level.height), (64 >> l, 64 >> l), "{path:?} level {l}");
            let theirs = ts.texels(h, level.width, 1).unwrap();
            assert_eq!((theirs.width, theirs.height), (level.width, level.height));
            assert_eq!(values(&level.texels), theirs.data, "{path:?} level {l}: the ImageCache's own texels");
        }
        // UsdUVTexture's g and b of a one-channel file are its channel; its alpha is a constant
        // the lookups answer.
        assert_eq!(ts.channel_levels(h, 2).unwrap().unwrap().levels[0], levels.levels[0]);
        assert!(ts.channel_levels(h, 3).is_none());
    }
    // What the store keeps is counted in bytes at the file's own size.
    let s = store(&ts);
    let d = TextureDisplacement::in_store(&s, dir.join("b.tx").to_str().unwrap(), SourceColorSpace::Raw, 0).unwrap();
    assert!(d.pyramid().is_some());
    let bytes: usize = (0..7).map(|l| (64usize >> l).pow(2)).sum();
    assert_eq!(s.bytes(), bytes);
    let stats = mipray::displacement_texture::stats([&s]);
    assert_eq!(stats["bytes"], bytes);
    assert_eq!(stats["files"][0]["format"], "uint8");
    assert_eq!(stats["files"][0]["levels"], 7);
}

#[test]
fn a_ramp_displaces_exactly_linearly_and_a_constant_exactly_constantly() {
    require("maketx");
    let dir = scratch_dir("ramp");
    let res = 256;
    // Texel x holds its centre's s: the ramp value = s, at every box-filtered level too.
    let ramp = maketx(&write(&dir, "ramp.exr", res, ChannelFormat::Float, |x, _| (x as f32 + 0.5) / res as f32), &dir.join("ramp.tx"), &[]);
    let constant = maketx(&write(&dir, "c.exr", res, ChannelFormat::Float, |_, _| 0.375), &dir.join("c.tx"), &[]);
    let ts = system();
    let s = store(&ts);
    let surface = quad();
    let clamp = Lookup { wrap_s: Wrap::Clamp, wrap_t: Wrap::Clamp, ..Lookup::DEFAULT };
    let mut d = TextureDisplacement::in_store(&s, ramp.to_str().unwrap(), SourceColorSpace::Raw, 0).unwrap();
    (d.lookup, d.scale, d.bias) = (clamp, 0.2, -0.1);
    let mut c = TextureDisplacement::in_store(&s, constant.to_str().unwrap(), SourceColorSpace::Raw, 0).unwrap();
    (c.lookup, c.scale, c.bias) = (clamp, 0.2, -0.1);
    let mut out = Vec::new();
    let (mut worst, mut worst_oiio) = (0.0f32, 0.0f32);
    // Grids of 2 to 17 vertices a side over patches a 2^k-th of the quad, with steps of 0.75
    // to 32 texels, so levels 0 to 5 are read, and between levels. (Coarser levels are too few
    // texels for [0.1, 0.9] to lie between their first and last texel centres, inside the
    // clamped border.)
    for k in 0..5u32 {
        let size = 0.8 / (1 << k) as f32;
        for n in [2usize, 3, 5, 9, 17] {
            if size / (n - 1) as f32 * res as f32 > 32.0 {
                continue;
            }
            let rect = UvRect { u0: 0.1, v0: 0.1 + 0.03 * k as f32, u1: 0.1 + size, v1: 0.1 + 0.03 * k as f32 + size };
            d.grid_offsets(&surface, 0, rect, n, &mut out);
            for (i, &o) in out.iter().enumerate() {
                let (u, v) = rect.grid_uv(i % n, i / n, n);
                worst = worst.max((o - (u * 0.2 - 0.1)).abs());
                let steps = (n - 1) as f32;
                let (du, dv) = ((rect.u1 - rect.u0) / steps, (rect.v1 - rect.v0) / steps);
                worst_oiio = worst_oiio.max((d.offset_st_sampled([u, v], [du, 0.0], [0.0, dv]) - (u * 0.2 - 0.1)).abs());
            }
            c.grid_offsets(&surface, 0, rect, n, &mut out);
            assert!(out.iter().all(|&o| o == 0.375 * 0.2 - 0.1), "constant: {out:?}");
        }
    }
    println!("ramp: store {worst:.2e}, OpenImageIO {worst_oiio:.2e} object units from the exact line (scale 0.2)");
    // A few float roundings of values up to 0.2.
    assert!(worst < 2e-7, "store: {worst}");
    assert!(worst_oiio < 2e-6, "OpenImageIO: {worst_oiio}");
    assert_eq!(d.failed_lookups() + c.failed_lookups(), 0);
}

#[test]
fn every_wrap_mode_reads_where_openimageio_reads() {
    require("maketx");
    let dir = scratch_dir("wrap");
    // 8×8 blocks of 8 texels, each its own value, rows from the top.
    let blocks = |x: usize, y: usize| ((y / 8) * 8 + x / 8) as f32 / 64.0;
    let exr = write(&dir, "blocks.exr", 64, ChannelFormat::Float, blocks);
    let files = [
        // No wrap mode named: OpenImageIO's default.
        exr.clone(),
        maketx(&exr, &dir.join("black.tx"), &["--wrap", "black"]),
        maketx(&exr, &dir.join("clamp.tx"), &["--wrap", "clamp"]),
        maketx(&exr, &dir.join("periodic.tx"), &["--wrap", "periodic"]),
        maketx(&exr, &dir.join("mirror.tx"), &["--swrap", "mirror", "--twrap", "periodic"]),
    ];
    let ts = system();
    let s = store(&ts);
    let modes = [Wrap::FromFile, Wrap::Black, Wrap::Clamp, Wrap::Periodic, Wrap::Mirror];
    let tiny = [0.01 / 64.0, 0.0];
    let mut checked = 0;
    for file in &files {
        for mode in modes {
            let mut d = TextureDisplacement::in_store(&s, file.to_str().unwrap(), SourceColorSpace::Raw, 0).unwrap();
            d.lookup = Lookup { wrap_s: mode, wrap_t: mode, ..Lookup::DEFAULT };
            // Block centres (4 texels from any block edge, where bicubic and bilinear both read
            // the block) shifted by whole and half periods, inside and outside [0, 1]².
            for k in 0..64 {
                let base = [((k % 8) as f32 + 0.5) / 8.0, ((k / 8) as f32 + 0.5) / 8.0];
                for shift in [[0.0, 0.0], [-1.0, 0.0], [1.0, 2.0], [-0.5, -3.0], [2.5, 1.0], [-7.0, 0.5]] {
                    let st = [base[0] + shift[0], base[1] + shift[1]];
                    let ours = d.offset_st(st, tiny, [0.0, tiny[0]]);
                    let theirs = d.offset_st_sampled(st, tiny, [0.0, tiny[0]]);
                    assert!((ours - theirs).abs() < 1e-5, "{file:?} {mode:?} at {st:?}: store {ours}, OpenImageIO {theirs}");
                    checked += 1;
                }
            }
        }
    }
    assert_eq!(checked, 5 * 5 * 64 * 6);
}

#[test]
fn on_a_smooth_texture_the_two_filters_differ_by_little() {
    require("maketx");
    let dir = scratch_dir("smooth");
    let res = 512;
    let f = |x: usize, y: usize| {
        let (s, t) = (x as f32 / res as f32 * std::f32::consts::TAU, y as f32 / res as f32 * std::f32::consts::TAU);
        0.5 + 0.25 * (3.0 * s).sin() * (2.0 * t).cos() + 0.15 * (11.0 * s + 7.0 * t).sin() + 0.1 * (29.0 * t - 5.0 * s).cos()
    };
    let tx = maketx(&write(&dir, "smooth.exr", res, ChannelFormat::Float, f), &dir.join("smooth.tx"), &["--wrap", "periodic"]);
    let ts = system();
    let d = TextureDisplacement::in_store(&store(&ts), tx.to_str().unwrap(), SourceColorSpace::Raw, 0).unwrap();
    let (mut worst, mut sum2, mut n) = (0.0f64, 0.0f64, 0usize);
    for k in 0..20_000 {
        let st = [(k as f32 * 0.618_034).fract() * 3.0 - 1.0, (k as f32 * 0.414_214).fract() * 3.0 - 1.0];
        // Grid steps of a quarter texel to 64 texels, a little anisotropic, rotated.
        let w = 2f32.powf(-2.0 + 8.0 * ((k * 7919) % 1000) as f32 / 1000.0) / res as f32;
        let a = k as f32 * 0.37;
        let (dx, dy) = ([w * a.cos(), w * a.sin()], [-0.7 * w * a.sin(), 0.7 * w * a.cos()]);
        let diff = f64::from(d.offset_st(st, dx, dy) - d.offset_st_sampled(st, dx, dy));
        worst = worst.max(diff.abs());
        sum2 += diff * diff;
        n += 1;
    }
    let rms = (sum2 / n as f64).sqrt();
    println!("smooth 512² texture, range ~1: store − OpenImageIO max {worst:.4}, RMS {rms:.4}");
    // Of a range of about 1: a flipped t or a level off by one would be several times these.
    assert!(rms < 0.03, "RMS {rms}");
    assert!(worst < 0.15, "max {worst}");
}
