//! Writing AOVs to an image file, once: the file type's rules (which AOVs an 8-bit file holds,
//! each AOV's pixel type from [`crate::aov::AOV_TABLE`]), the sRGB transfer curve for 8-bit
//! files, values a pixel type cannot hold clamped and counted, and the atomic replace (a
//! temporary file beside the target, renamed over it). The film of a render, the delegate's
//! render buffers and Python's arrays all go through [`write_layers`]; the pixels are read where
//! they are (borrowed), interleaved once for the [`ImageIo`] that writes them.
//!
//! Floating-point files (EXR, TIFF, ...) keep every AOV linear: EXR with the table's per-AOV
//! pixel type, the other float types as 32-bit float. 8-bit files (PNG, JPEG, ...) hold the
//! `color` AOV only, sRGB-encoded unless colour correction is disabled, as usdrecord's
//! `--colorCorrectionMode sRGB` does. The `Software` attribute is the [`ImageIo`]'s to set.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use crate::aov::Aov;
use crate::error::ImageError;
use crate::image_io::{ChannelFormat, ImageBuf, ImageIo, MetaValue};

/// File extensions (lower case, no dot) whose images hold 8 bits per channel.
pub const EIGHT_BIT_EXTENSIONS: [&str; 8] = ["png", "jpg", "jpeg", "bmp", "gif", "tga", "ppm", "webp"];
/// 8-bit types with an alpha channel: they hold the colour as RGB and the alpha AOV as A (RGBA,
/// as usdrecord writes them; the colour is premultiplied).
const ALPHA_EXTENSIONS: [&str; 3] = ["png", "tga", "webp"];
/// Extensions of floating-point types without per-channel pixel types: every AOV 32-bit float.
const FLOAT_EXTENSIONS: [&str; 4] = ["tif", "tiff", "hdr", "pfm"];

/// The largest finite half float: anything larger becomes Inf when stored as half.
pub const HALF_MAX: f32 = 65504.0;

/// usdrecord's `--colorCorrectionMode`, for 8-bit files.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ColorCorrection {
    /// The sRGB transfer curve (IEC 61966-2-1) on the colour AOV.
    #[default]
    Srgb,
    /// The linear values, quantized as they are.
    Disabled,
}

impl ColorCorrection {
    /// The mode names, in variant order.
    pub const NAMES: [&'static str; 2] = ["sRGB", "disabled"];

    /// Parses [`ColorCorrection::NAMES`].
    ///
    /// # Errors
    /// A message naming the mode and the valid ones.
    pub fn from_name(name: &str) -> Result<Self, String> {
        match name {
            "sRGB" => Ok(ColorCorrection::Srgb),
            "disabled" => Ok(ColorCorrection::Disabled),
            _ => Err(format!("unknown color correction mode '{name}'; use {}", Self::NAMES.join(" or "))),
        }
    }
}

/// The sRGB transfer curve (IEC 61966-2-1) of a linear value, clamped to [0, 1] (NaN is 0).
pub fn srgb_encode(linear: f32) -> f32 {
    let x = if linear.is_nan() { 0.0 } else { linear.clamp(0.0, 1.0) };
    if x <= 0.003_130_8 {
        x * 12.92
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    }
}

/// Whether `path`'s extension names an 8-bit image type.
pub fn is_eight_bit(path: &Path) -> bool {
    extension(path).is_some_and(|e| EIGHT_BIT_EXTENSIONS.contains(&e.as_str()))
}

/// The AOVs an 8-bit file at `path` holds, in channel order: the colour, and the alpha where
/// the type has an alpha channel; none for other types.
pub fn eight_bit_aovs(path: &Path) -> Vec<&'static str> {
    match extension(path) {
        Some(e) if ALPHA_EXTENSIONS.contains(&e.as_str()) => vec![Aov::Color.name(), Aov::Alpha.name()],
        Some(e) if EIGHT_BIT_EXTENSIONS.contains(&e.as_str()) => vec![Aov::Color.name()],
        _ => Vec::new(),
    }
}

fn extension(path: &Path) -> Option<String> {
    path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase)
}

/// How AOVs go into one file: which, in channel order, each one's pixel type, and whether the
/// colour is sRGB-encoded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OutputPlan {
    pub aovs: Vec<String>,
    /// One per entry of `aovs`.
    pub formats: Vec<ChannelFormat>,
    pub encode_srgb: bool,
}

/// The plan for writing `aovs` (in channel order) to `path`. An 8-bit type keeps the colour AOV
/// only, and the alpha where it has an alpha channel ([`eight_bit_aovs`]; a warning names what
/// it leaves out).
///
/// # Errors
/// The path has no extension, or an 8-bit file is asked for without the colour AOV.
pub fn plan(path: &Path, aovs: &[&str], color_correction: ColorCorrection) -> Result<OutputPlan, ImageError> {
    let err = |message: String| ImageError { path: path.display().to_string(), message };
    let ext = extension(path).ok_or_else(|| err("no file extension to choose the image type (use .exr, .png, .tif...)".into()))?;
    if EIGHT_BIT_EXTENSIONS.contains(&ext.as_str()) {
        let color = Aov::Color.name();
        if !aovs.contains(&color) {
            return Err(err("an 8-bit image needs the color AOV".into()));
        }
        let held: Vec<&str> = eight_bit_aovs(path).into_iter().filter(|a| aovs.contains(a)).collect();
        let others: Vec<&str> = aovs.iter().copied().filter(|a| !held.contains(a)).collect();
        if !others.is_empty() {
            log::warn!("{} holds only the {} AOV; write an EXR to keep {}", path.display(), held.join(" and "), others.join(", "));
        }
        return Ok(OutputPlan {
            formats: vec![ChannelFormat::U8; held.len()],
            aovs: held.into_iter().map(String::from).collect(),
            encode_srgb: color_correction == ColorCorrection::Srgb,
        });
    }
    let float = FLOAT_EXTENSIONS.contains(&ext.as_str());
    let formats = aovs
        .iter()
        .map(|a| match Aov::from_name(a) {
            Some(aov) if !float => aov.info().format,
            _ => ChannelFormat::Float,
        })
        .collect();
    Ok(OutputPlan { aovs: aovs.iter().map(|a| a.to_string()).collect(), formats, encode_srgb: false })
}

/// One AOV's pixels as the writer reads them: `height × width × channels` f32, row 0 at the
/// top, borrowed from wherever they live (a film, a render buffer, a numpy array).
#[derive(Clone, Copy, Debug)]
pub struct Layer<'a> {
    pub name: &'a str,
    pub channels: usize,
    pub data: &'a [f32],
}

/// How [`write_layers`] writes, besides the plan's defaults.
#[derive(Clone, Debug, Default)]
pub struct WriteOptions {
    /// The AOVs to write, in channel order; empty: every layer given, in order.
    pub order: Vec<String>,
    /// Pixel types that replace the plan's, by AOV name.
    pub formats: Vec<(String, ChannelFormat)>,
    pub color_correction: ColorCorrection,
    /// Image attributes (EXR header attributes, TIFF tags, PNG text).
    pub metadata: Vec<(String, MetaValue)>,
    /// Write a hidden temporary file beside `path` (same directory, so one file system; same
    /// extension, so the same type) and rename it over `path`: a reader sees the old image or
    /// the new one, never half of one. The temporary file is removed when the write fails.
    pub atomic: bool,
}

/// Writes `layers` (all `width × height`) into the image file `path` through `io`, making its
/// directory if needed: the AOVs of `options.order` (all by default) as [`plan`] says, with
/// `options`'s pixel types and metadata. Values a pixel type cannot hold are clamped with one
/// warning (see [`fit_to_formats`]): no file holds NaN or Inf.
///
/// # Errors
/// [`ImageError`] naming `path` (never the temporary file): as [`plan`], an AOV asked for that
/// no layer holds, layers of the wrong size, a directory that cannot be made, or what `io`
/// reports.
pub fn write_layers(
    io: &dyn ImageIo,
    path: &Path,
    width: usize,
    height: usize,
    layers: &[Layer<'_>],
    options: &WriteOptions,
) -> Result<(), ImageError> {
    let err = |message: String| ImageError { path: path.display().to_string(), message };
    let asked: Vec<&str> =
        if options.order.is_empty() { layers.iter().map(|l| l.name).collect() } else { options.order.iter().map(String::as_str).collect() };
    if let Some(missing) = asked.iter().find(|a| !layers.iter().any(|l| &l.name == *a)) {
        return Err(err(format!("no AOV named '{missing}' was rendered")));
    }
    let plan = plan(path, &asked, options.color_correction)?;
    let mut selected = Vec::with_capacity(plan.aovs.len());
    let mut channels = Vec::new();
    let mut chan_formats = Vec::new();
    for (name, planned) in plan.aovs.iter().zip(&plan.formats) {
        let Some(layer) = layers.iter().find(|l| l.name == name.as_str()) else { continue };
        if layer.data.len() != width * height * layer.channels {
            return Err(err(format!(
                "AOV {name} holds {} values, not {width}×{height}×{} (the image's size)",
                layer.data.len(),
                layer.channels
            )));
        }
        let format = options.formats.iter().find(|(n, _)| n == name).map_or(*planned, |(_, f)| *f);
        chan_formats.extend(std::iter::repeat_n(format, layer.channels));
        channels.extend(crate::film::file_channel_names(name, layer.channels));
        selected.push(*layer);
    }
    let mut pixels = Vec::with_capacity(width * height * channels.len());
    for p in 0..width * height {
        for l in &selected {
            let values = &l.data[p * l.channels..(p + 1) * l.channels];
            if plan.encode_srgb && l.name == Aov::Color.name() {
                pixels.extend(values.iter().map(|&v| srgb_encode(v)));
            } else {
                pixels.extend_from_slice(values);
            }
        }
    }
    let clamped = fit_to_formats(&mut pixels, &chan_formats);
    if clamped > 0 {
        log::warn!(
            "{}: {clamped} values the file cannot hold (NaN, infinite, or beyond half float's ±65504) clamped to its range",
            path.display()
        );
    }
    let image = ImageBuf { width, height, channels, pixels, metadata: Vec::new() };
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| err(format!("cannot create directory {}: {e}", dir.display())))?;
    }
    if !options.atomic {
        return io.write(path, &image, &chan_formats, &options.metadata);
    }
    let temporary = temporary_path(path);
    let written = io
        .write(&temporary, &image, &chan_formats, &options.metadata)
        .and_then(|()| std::fs::rename(&temporary, path).map_err(|e| err(format!("cannot replace it: {e}"))));
    if let Err(e) = written {
        // Whatever the writer left behind; it may have made nothing.
        let _ = std::fs::remove_file(&temporary);
        let message = e.message.replace(&temporary.display().to_string(), &path.display().to_string());
        return Err(err(message));
    }
    Ok(())
}

/// A hidden file beside `path` with its extension (the writer picks the type by it). The
/// process id and a counter keep two writers of one path (processes or threads) apart.
fn temporary_path(path: &Path) -> PathBuf {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let ext = path.extension().map(|e| format!(".{}", e.to_string_lossy())).unwrap_or_default();
    let n = NEXT.fetch_add(1, Ordering::Relaxed);
    path.with_file_name(format!(".{stem}.mipray-{}-{n}.tmp{ext}", std::process::id()))
}

/// Makes interleaved `pixels` (channel `c` of each pixel stored as `formats[c]`) representable:
/// NaN becomes 0, and values beyond a channel's finite range are clamped to it (±65504 for half,
/// ±`f32::MAX` for float; 8-bit channels are clamped to [0, 1] by the conversion itself). A
/// written image never holds Inf or NaN. Returns how many values changed.
pub fn fit_to_formats(pixels: &mut [f32], formats: &[ChannelFormat]) -> u64 {
    if formats.is_empty() {
        return 0;
    }
    let mut changed = 0;
    for (k, v) in pixels.iter_mut().enumerate() {
        let limit = match formats[k % formats.len()] {
            ChannelFormat::Half => HALF_MAX,
            ChannelFormat::Float | ChannelFormat::U8 => f32::MAX,
        };
        let fitted = if v.is_nan() { 0.0 } else { v.clamp(-limit, limit) };
        if fitted.to_bits() != v.to_bits() && !(fitted == 0.0 && *v == 0.0) {
            changed += 1;
        }
        *v = fitted;
    }
    changed
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    #[test]
    fn values_a_format_cannot_hold_are_clamped_and_counted() {
        use ChannelFormat::{Float, Half, U8};
        let mut px = vec![1e5, -1e5, 65504.0, f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 0.5, f32::NAN, -0.0];
        let changed = fit_to_formats(&mut px, &[Half, Half, Half, Float, Float, Float, U8, U8, Half]);
        assert_eq!(px, [65504.0, -65504.0, 65504.0, 0.0, f32::MAX, f32::MIN, 0.5, 0.0, -0.0]);
        assert_eq!(changed, 6);
    }

    #[test]
    fn srgb_curve_matches_the_standard_at_known_values() {
        // IEC 61966-2-1: the linear segment's end, mid grey, white; clamped outside [0, 1].
        let cases = [(0.0, 0.0), (0.003_130_8, 0.040_45), (0.18, 0.461_356_1), (0.5, 0.735_357), (1.0, 1.0), (4.0, 1.0), (-1.0, 0.0)];
        for (x, y) in cases {
            assert!((srgb_encode(x) - y).abs() < 2e-6, "srgb({x}) = {} not {y}", srgb_encode(x));
        }
        assert_eq!(srgb_encode(f32::NAN), 0.0);
    }

    #[test]
    fn plans_follow_the_file_type() {
        let three = ["color", "depth", "normal"];
        let exr = plan(Path::new("a.EXR"), &three, ColorCorrection::Srgb).unwrap();
        use ChannelFormat::{Float, Half, U8};
        assert_eq!((exr.formats, exr.encode_srgb), (vec![Half, Float, Half], false));
        assert_eq!(plan(Path::new("a.tif"), &three, ColorCorrection::Srgb).unwrap().formats, [Float; 3]);
        let png = plan(Path::new("d/a.png"), &three, ColorCorrection::Srgb).unwrap();
        assert_eq!((png.aovs, png.formats, png.encode_srgb), (vec!["color".to_string()], vec![U8], true));
        // RGBA where the type has alpha and the alpha was rendered; RGB in types without.
        let rgba = plan(Path::new("a.png"), &["alpha", "depth", "color"], ColorCorrection::Srgb).unwrap();
        assert_eq!((rgba.aovs, rgba.formats), (vec!["color".to_string(), "alpha".to_string()], vec![U8, U8]));
        let jpg = plan(Path::new("a.jpg"), &["color", "alpha"], ColorCorrection::Srgb).unwrap();
        assert_eq!(jpg.aovs, ["color"]);
        assert_eq!(eight_bit_aovs(Path::new("a.TGA")), ["color", "alpha"]);
        assert!(eight_bit_aovs(Path::new("a.exr")).is_empty());
        assert!(!plan(Path::new("a.jpg"), &["color"], ColorCorrection::Disabled).unwrap().encode_srgb);
        let e = plan(Path::new("image"), &["color"], ColorCorrection::Srgb).unwrap_err();
        assert!(e.to_string().starts_with("image: no file extension"), "{e}");
        assert!(plan(Path::new("a.png"), &["depth"], ColorCorrection::Srgb).unwrap_err().message.contains("needs the color AOV"));
        assert!(ColorCorrection::from_name("openColorIO").unwrap_err().contains("unknown color correction"));
    }

    /// Records what it is asked to write; with `fail`, writes half a file and fails, as a full
    /// disk would.
    struct Recorder {
        fail: bool,
        written: Mutex<Vec<(PathBuf, ImageBuf, Vec<ChannelFormat>)>>,
    }

    impl ImageIo for Recorder {
        fn write(&self, path: &Path, image: &ImageBuf, formats: &[ChannelFormat], _: &[(String, MetaValue)]) -> Result<(), ImageError> {
            if self.fail {
                std::fs::write(path, "half written").unwrap();
                return Err(ImageError { path: path.display().to_string(), message: format!("{}: disk full", path.display()) });
            }
            std::fs::write(path, "new image").unwrap();
            self.written.lock().unwrap().push((path.to_path_buf(), image.clone(), formats.to_vec()));
            Ok(())
        }

        fn read(&self, path: &Path) -> Result<ImageBuf, ImageError> {
            Err(ImageError { path: path.display().to_string(), message: "not read".into() })
        }
    }

    fn scratch(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("mipray-image-output-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn layers_are_interleaved_in_order_with_the_colour_encoded_for_8_bit() {
        let io = Recorder { fail: false, written: Mutex::new(Vec::new()) };
        let dir = scratch("order");
        let color = [0.18, 0.5, 2.0, 0.0, 1.0, f32::NAN];
        let depth = [3.0, f32::INFINITY];
        let layers = [Layer { name: "color", channels: 3, data: &color }, Layer { name: "depth", channels: 1, data: &depth }];
        let options = WriteOptions { order: vec!["depth".into(), "color".into()], ..Default::default() };
        write_layers(&io, &dir.join("a.exr"), 2, 1, &layers, &options).unwrap();
        write_layers(&io, &dir.join("sub/a.png"), 2, 1, &layers, &WriteOptions::default()).unwrap();
        let written = io.written.lock().unwrap();
        let (_, exr, formats) = &written[0];
        assert_eq!(exr.channels, ["Z", "R", "G", "B"]);
        assert_eq!(formats, &[ChannelFormat::Float, ChannelFormat::Half, ChannelFormat::Half, ChannelFormat::Half]);
        assert_eq!(exr.pixels, [3.0, 0.18, 0.5, 2.0, f32::MAX, 0.0, 1.0, 0.0]);
        let (path, png, _) = &written[1];
        assert!(path.ends_with("sub/a.png"), "the missing folder is made");
        let expected: Vec<f32> = color.iter().map(|&c| srgb_encode(c)).collect();
        assert_eq!(png.pixels, expected);
        let missing =
            write_layers(&io, &dir.join("b.exr"), 2, 1, &layers, &WriteOptions { order: vec!["normal".into()], ..Default::default() });
        assert!(missing.unwrap_err().message.contains("no AOV named 'normal'"));
        let short = [Layer { name: "color", channels: 3, data: &color[..3] }];
        assert!(write_layers(&io, &dir.join("c.exr"), 2, 1, &short, &WriteOptions::default()).is_err());
    }

    #[test]
    fn an_atomic_write_replaces_the_file_or_leaves_it_and_no_temporary_file() {
        let dir = scratch("atomic");
        let target = dir.join("img.exr");
        std::fs::write(&target, "the previous image").unwrap();
        let color = [0.5f32; 6];
        let layers = [Layer { name: "color", channels: 3, data: &color }];
        let atomic = WriteOptions { atomic: true, ..Default::default() };
        let failing = Recorder { fail: true, written: Mutex::new(Vec::new()) };
        let e = write_layers(&failing, &target, 2, 1, &layers, &atomic).unwrap_err();
        assert!(e.to_string().contains("img.exr: disk full") && !e.to_string().contains(".tmp"), "{e}");
        let names = || std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect::<Vec<_>>();
        assert_eq!(names(), ["img.exr"]);
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "the previous image");
        let working = Recorder { fail: false, written: Mutex::new(Vec::new()) };
        write_layers(&working, &target, 2, 1, &layers, &atomic).unwrap();
        assert_eq!(names(), ["img.exr"]);
        assert_eq!(std::fs::read_to_string(&target).unwrap(), "new image");
        assert!(working.written.lock().unwrap()[0].0.file_name().unwrap().to_string_lossy().starts_with(".img.mipray-"));
    }
}
