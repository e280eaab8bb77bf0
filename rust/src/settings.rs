//! The render settings, stated once: one table row per setting (key, type, range or choices,
//! default, help, scope) from which everything else is made — the parsed [`RenderSettings`],
//! their parsing and validation, the core's [`RenderOptions`] and its
//! [`RenderOptions::validate`], the delegate's descriptors, and through `_mipray.settings()` the
//! Python side (`mipray.SETTINGS`, `mipray-record`'s flags and `--list-settings`, the sweep's
//! knobs). Adding a setting is one row of the `settings_table!` invocation below (plus the code
//! that reads it).
//!
//! One set of rules for every form a value arrives in: a JSON number, a JSON string holding a
//! number or token (the command line's `--setting key=value` and flags), a bool. Nothing is
//! clamped: a value out of range is refused with one line naming the setting, the value and the
//! range ([`SettingError`]).

use serde_json::Value;
use thiserror::Error;

use crate::geometry_cache::{CacheConfig, CacheMode};
use crate::options::{IntegratorKind, RenderOptions};
use crate::texture::FilterMode;

/// What values a setting takes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SettingType {
    /// A whole number in `min..=max`; a float form such as `2.0` is accepted, `2.5` is not.
    Int { min: u64, max: u64 },
    /// A number between `min` and `max`, each end excluded when its `_open` flag is set. `inf`
    /// (spelt so, as text) is a value only when `max` is infinite and not open.
    Float { min: f64, min_open: bool, max: f64, max_open: bool },
    /// On or off: `0`/`1`, `true`/`false`.
    Bool,
    /// One of these tokens.
    Choice(&'static [&'static str]),
    /// A window of the image in NDC, USD's `dataWindowNDC`: `xmin,ymin,xmax,ymax`, (0, 0) the
    /// bottom-left corner and (1, 1) the top-right one, each within [0, 1], min < max. Text
    /// (`0,0.5,0.5,1`) or four JSON numbers.
    Window,
}

/// Which part of the renderer reads a setting.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scope {
    /// The core's [`RenderOptions`] (sampling, integrators, tessellation rates).
    Render,
    /// The geometry cache's mode and budgets ([`CacheConfig`]).
    GeometryCache,
    /// The delegate's texture system.
    Textures,
    /// The delegate's scene build (meshes' defaults).
    Scene,
}

impl Scope {
    /// The scope's name in listings: `render`, `geometryCache`, `textures`, `scene`.
    pub const fn name(self) -> &'static str {
        match self {
            Scope::Render => "render",
            Scope::GeometryCache => "geometryCache",
            Scope::Textures => "textures",
            Scope::Scene => "scene",
        }
    }
}

/// One row of the settings table.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setting {
    /// The key in render settings, `--setting key=value` and stats (`samples`, `tessFactor`, ...).
    pub key: &'static str,
    pub ty: SettingType,
    /// What it does, one line.
    pub help: &'static str,
    pub scope: Scope,
}

/// A setting's value once checked against its row.
#[derive(Clone, Debug, PartialEq)]
pub enum SettingValue {
    Int(u64),
    Float(f64),
    Bool(bool),
    Choice(&'static str),
    /// A [`SettingType::Window`]: xmin, ymin, xmax, ymax in NDC.
    Window([f64; 4]),
    /// An optional setting left unset (e.g. a per-tier cache budget).
    Unset,
}

/// A setting that cannot be taken; the message is one line.
#[derive(Clone, Debug, Error, PartialEq)]
pub enum SettingError {
    #[error("unknown render setting '{key}'; valid settings: {valid}")]
    Unknown { key: String, valid: String },
    #[error("render setting {key}={value}: {why}; {key} takes {range}")]
    Value { key: &'static str, value: String, why: &'static str, range: String },
    #[error("render setting {key}={value}: not one of {choices}")]
    Choice { key: &'static str, value: String, choices: String },
    /// Two settings that do not go together.
    #[error("render setting {0}")]
    Conflict(&'static str),
}

/// Why `integrator = ao` without ambient-occlusion rays is refused (checked wherever both are
/// known: [`RenderSettings::from_pairs`], [`RenderOptions::validate`], the integrator choice).
pub const AO_NEEDS_SAMPLES: &str = "integrator=ao needs aoSamples > 0 (ambient-occlusion rays per shading point)";

impl SettingType {
    /// The values it takes, for messages and listings: `integer, 1 ≤ x ≤ 1e+06`,
    /// `number, 0 < x ≤ 10`, `0 or 1`, `one of multires, single`.
    pub fn describe(&self) -> String {
        match *self {
            SettingType::Int { min, max: u64::MAX } => format!("integer, x ≥ {min}"),
            SettingType::Int { min, max } => format!("integer, {} ≤ x ≤ {}", short(min as f64), short(max as f64)),
            SettingType::Float { min, min_open, max, max_open } => {
                let low = if min_open { "<" } else { "≤" };
                if max == f64::INFINITY && max_open {
                    format!("number, {} {low} x", short(min))
                } else {
                    format!("number, {} {low} x {} {}", short(min), if max_open { "<" } else { "≤" }, short(max))
                }
            }
            SettingType::Bool => "0 or 1".into(),
            SettingType::Choice(names) => format!("one of {}", names.join(", ")),
            SettingType::Window => "xmin,ymin,xmax,ymax, NDC (y up), 0 ≤ min < max ≤ 1".into(),
        }
    }

    /// `value` as this type, checked; the reason when it is not one (`not an integer`, `out of
    /// range`, ...).
    fn parse(&self, value: &Value) -> Result<SettingValue, &'static str> {
        match *self {
            SettingType::Int { max, .. } => {
                // Exact integers first: a u64 seed beyond 2^53 must not go through f64.
                let exact = match value {
                    Value::Number(n) => n.as_u64(),
                    Value::String(s) => s.trim().parse::<u64>().ok(),
                    _ => None,
                };
                let x = match exact {
                    Some(x) => x,
                    None => {
                        let f = number(value)?;
                        if !f.is_finite() {
                            return Err("not a finite number");
                        }
                        if f.fract() != 0.0 {
                            return Err("not an integer");
                        }
                        if f < 0.0 || f > max as f64 {
                            return Err("out of range");
                        }
                        f as u64
                    }
                };
                self.check(&SettingValue::Int(x))?;
                Ok(SettingValue::Int(x))
            }
            SettingType::Float { .. } => {
                let x = number(value)?;
                self.check(&SettingValue::Float(x))?;
                Ok(SettingValue::Float(x))
            }
            SettingType::Bool => {
                let on = match value {
                    Value::Bool(b) => Some(*b),
                    Value::String(s) if s.trim() == "true" => Some(true),
                    Value::String(s) if s.trim() == "false" => Some(false),
                    _ => match number(value) {
                        Ok(0.0) => Some(false),
                        Ok(1.0) => Some(true),
                        Ok(_) => return Err("out of range"),
                        Err(_) => None,
                    },
                };
                on.map(SettingValue::Bool).ok_or("not 0 or 1")
            }
            SettingType::Choice(names) => match value {
                Value::String(s) => names.iter().find(|n| **n == s.trim()).map(|n| SettingValue::Choice(n)).ok_or("not one of the choices"),
                _ => Err("not one of the choices"),
            },
            SettingType::Window => {
                let corners: Vec<f64> = match value {
                    Value::String(s) => {
                        s.split(',').map(|c| c.trim().parse::<f64>().map_err(|_| "not four numbers")).collect::<Result<_, _>>()?
                    }
                    Value::Array(items) => items.iter().map(number).collect::<Result<_, _>>().map_err(|_| "not four numbers")?,
                    _ => return Err("not four numbers"),
                };
                let window: [f64; 4] = corners.try_into().map_err(|_| "not four numbers")?;
                self.check(&SettingValue::Window(window))?;
                Ok(SettingValue::Window(window))
            }
        }
    }

    /// Whether a value of this type is within range.
    fn check(&self, value: &SettingValue) -> Result<(), &'static str> {
        match (*self, value) {
            (_, SettingValue::Unset) => Ok(()),
            (SettingType::Int { min, max }, SettingValue::Int(x)) => (min..=max).contains(x).then_some(()).ok_or("out of range"),
            (SettingType::Float { min, min_open, max, max_open }, SettingValue::Float(x)) => {
                let x = *x;
                if x.is_nan() || (x.is_infinite() && !(x == f64::INFINITY && max == f64::INFINITY && !max_open)) {
                    return Err("not a finite number");
                }
                let low = if min_open { x > min } else { x >= min };
                let high = if max_open { x < max } else { x <= max };
                (low && high).then_some(()).ok_or("out of range")
            }
            (SettingType::Bool, SettingValue::Bool(_)) => Ok(()),
            (SettingType::Choice(names), SettingValue::Choice(c)) => names.contains(c).then_some(()).ok_or("not one of the choices"),
            (SettingType::Window, SettingValue::Window([x0, y0, x1, y1])) => {
                if ![x0, y0, x1, y1].iter().all(|c| c.is_finite()) {
                    return Err("not a finite number");
                }
                let inside = [x0, y0, x1, y1].iter().all(|c| (0.0..=1.0).contains(*c));
                (inside && x0 < x1 && y0 < y1).then_some(()).ok_or("out of range")
            }
            _ => Err("of the wrong type"),
        }
    }
}

/// `x` as C's `%g` writes it (six significant digits; exponent form from 10^6): `1e+06`, `65536`,
/// `0.5`, `inf` — the form Python's sweep tables have always shown ranges in.
fn short(x: f64) -> String {
    if !x.is_finite() || x == 0.0 {
        return if x == 0.0 { "0".into() } else { x.to_string() };
    }
    let exponent = x.abs().log10().floor() as i32;
    if (-4..6).contains(&exponent) {
        let fixed = format!("{:.*}", (5 - exponent).max(0) as usize, x);
        if fixed.contains('.') {
            fixed.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            fixed
        }
    } else {
        let mantissa = format!("{:.5}", x / 10f64.powi(exponent));
        let mantissa = mantissa.trim_end_matches('0').trim_end_matches('.');
        format!("{mantissa}e{}{:02}", if exponent < 0 { '-' } else { '+' }, exponent.abs())
    }
}

/// A JSON number, or text that reads as one (`inf` included), as f64.
fn number(value: &Value) -> Result<f64, &'static str> {
    match value {
        Value::Number(n) => n.as_f64().ok_or("not a finite number"),
        Value::String(s) => s.trim().parse::<f64>().map_err(|_| "not a finite number"),
        _ => Err("not a finite number"),
    }
}

/// A value as the user wrote it, for messages: text without quotes, numbers as JSON.
fn shown(value: &Value) -> String {
    match value {
        Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

impl Setting {
    /// `value` checked against this row.
    ///
    /// # Errors
    /// [`SettingError::Value`] naming the key, the value and the range.
    pub fn parse(&self, value: &Value) -> Result<SettingValue, SettingError> {
        self.ty.parse(value).map_err(|why| self.refuse(shown(value), why))
    }

    /// A value already of this row's type, checked against its range.
    fn check(&self, value: &SettingValue) -> Result<(), SettingError> {
        self.ty.check(value).map_err(|why| self.refuse(value.to_text(), why))
    }

    fn refuse(&self, value: String, why: &'static str) -> SettingError {
        match self.ty {
            // The choices are the reason and the range at once.
            SettingType::Choice(names) => SettingError::Choice { key: self.key, value, choices: names.join(", ") },
            ty => SettingError::Value { key: self.key, value, why, range: ty.describe() },
        }
    }

    /// The default, as text: `""` for a setting unset unless given.
    pub fn default_text(&self) -> String {
        RenderSettings::default().value(self.key).map(|v| v.to_text()).unwrap_or_default()
    }
}

impl SettingValue {
    /// The value as the table and `--list-settings` show it: `4`, `0.2`, `inf`, `multires`,
    /// `0`/`1` for bools, `""` when unset.
    pub fn to_text(&self) -> String {
        match self {
            SettingValue::Int(x) => x.to_string(),
            SettingValue::Float(x) => x.to_string(),
            SettingValue::Bool(b) => u8::from(*b).to_string(),
            SettingValue::Choice(c) => (*c).to_string(),
            SettingValue::Window(w) => w.map(|c| c.to_string()).join(","),
            SettingValue::Unset => String::new(),
        }
    }
}

/// A Rust type a setting is held in, and how it converts from and to a checked value.
pub trait SettingField: Sized {
    /// `None` when the value is not of this field's type (a table row that disagrees with its
    /// field; `every_default_round_trips` keeps that from happening).
    fn from_value(value: &SettingValue) -> Option<Self>;
    fn to_value(&self) -> SettingValue;
}

macro_rules! int_field {
    ($($t:ty),*) => {$(
        impl SettingField for $t {
            fn from_value(value: &SettingValue) -> Option<Self> {
                match value {
                    SettingValue::Int(x) => <$t>::try_from(*x).ok(),
                    _ => None,
                }
            }
            fn to_value(&self) -> SettingValue {
                SettingValue::Int(*self as u64)
            }
        }
    )*};
}
int_field!(u32, u64, usize);

/// Fields held as the value itself.
macro_rules! plain_field {
    ($($t:ty => $variant:ident),*) => {$(
        impl SettingField for $t {
            fn from_value(value: &SettingValue) -> Option<Self> {
                match value {
                    SettingValue::$variant(x) => Some(*x),
                    _ => None,
                }
            }
            fn to_value(&self) -> SettingValue {
                SettingValue::$variant(*self)
            }
        }
    )*};
}
plain_field!(f64 => Float, bool => Bool);

impl SettingField for f32 {
    fn from_value(value: &SettingValue) -> Option<Self> {
        f64::from_value(value).map(|x| x as f32)
    }
    /// Through the shortest decimal that reads back as this f32, so `0.2_f32` shows as `0.2`.
    fn to_value(&self) -> SettingValue {
        SettingValue::Float(self.to_string().parse().unwrap_or(f64::from(*self)))
    }
}

impl SettingField for [f64; 4] {
    fn from_value(value: &SettingValue) -> Option<Self> {
        match value {
            SettingValue::Window(w) => Some(*w),
            _ => None,
        }
    }
    fn to_value(&self) -> SettingValue {
        SettingValue::Window(*self)
    }
}

impl SettingField for Option<f64> {
    fn from_value(value: &SettingValue) -> Option<Self> {
        match value {
            SettingValue::Unset => Some(None),
            v => f64::from_value(v).map(Some),
        }
    }
    fn to_value(&self) -> SettingValue {
        self.map_or(SettingValue::Unset, SettingValue::Float)
    }
}

/// The enums a choice setting is held in: one list of names, in variant order.
pub trait Named: Copy + 'static {
    /// Every variant, in the order of [`Named::NAMES`].
    const ALL: &'static [Self];
    const NAMES: &'static [&'static str];
}

impl<T: Named + PartialEq> SettingField for T {
    fn from_value(value: &SettingValue) -> Option<Self> {
        match value {
            SettingValue::Choice(c) => T::NAMES.iter().position(|n| n == c).map(|i| T::ALL[i]),
            _ => None,
        }
    }
    fn to_value(&self) -> SettingValue {
        let i = T::ALL.iter().position(|v| v == self).unwrap_or(0);
        SettingValue::Choice(T::NAMES[i])
    }
}

impl Named for IntegratorKind {
    const ALL: &'static [Self] = &IntegratorKind::ALL;
    const NAMES: &'static [&'static str] = IntegratorKind::NAMES;
}

/// The defaults of [`RenderSettings`], at 320×240 pixels, the colour AOV. Here rather than in
/// `options.rs`: the settings table makes options, not the other way round.
impl Default for RenderOptions {
    fn default() -> Self {
        RenderSettings::default().to_options(320, 240, &[crate::aov::Aov::Color])
    }
}

impl Named for CacheMode {
    const ALL: &'static [Self] = &CacheMode::ALL;
    const NAMES: &'static [&'static str] =
        &[CacheMode::ALL[0].name(), CacheMode::ALL[1].name(), CacheMode::ALL[2].name(), CacheMode::ALL[3].name()];
}

impl Named for FilterMode {
    const ALL: &'static [Self] = &[FilterMode::Differentials, FilterMode::Finest];
    const NAMES: &'static [&'static str] = &[FilterMode::Differentials.name(), FilterMode::Finest.name()];
}

const fn int(min: u64, max: u64) -> SettingType {
    SettingType::Int { min, max }
}

/// A number in `[min, max]`.
const fn closed(min: f64, max: f64) -> SettingType {
    SettingType::Float { min, min_open: false, max, max_open: false }
}

/// A number in `(min, max]`.
const fn above(min: f64, max: f64) -> SettingType {
    SettingType::Float { min, min_open: true, max, max_open: false }
}

/// A finite number greater than `min` (or at least `min` when `min_open` is false).
const fn finite_from(min: f64, min_open: bool) -> SettingType {
    SettingType::Float { min, min_open, max: f64::INFINITY, max_open: true }
}

const fn choice<T: Named>() -> SettingType {
    SettingType::Choice(T::NAMES)
}

/// Makes, from one row per setting: the [`RenderSettings`] struct and its `Default`, the
/// [`SETTINGS`] table, reading and writing a field by key, and the copy into (and the check of)
/// the [`RenderOptions`] fields a row names after `=>`.
macro_rules! settings_table {
    ($(
        $key:literal: $field:ident: $t:ty = $default:expr, $ty:expr, $scope:ident $(=> $option:ident)?, $help:literal;
    )*) => {
        /// Every render setting, parsed and checked; defaults are what a user gets without
        /// asking. One field per row of [`SETTINGS`], named as the key in snake case.
        #[derive(Clone, Debug, PartialEq)]
        pub struct RenderSettings {
            $(#[doc = $help] pub $field: $t,)*
        }

        impl Default for RenderSettings {
            fn default() -> Self {
                RenderSettings { $($field: $default,)* }
            }
        }

        /// Every setting, in the order listings show them.
        pub const SETTINGS: &[Setting] = &[$(Setting { key: $key, ty: $ty, help: $help, scope: Scope::$scope },)*];

        impl RenderSettings {
            /// The value of setting `key`, or `None` for an unknown key.
            pub fn value(&self, key: &str) -> Option<SettingValue> {
                match key {
                    $($key => Some(self.$field.to_value()),)*
                    _ => None,
                }
            }

            /// Stores a value checked against `key`'s row.
            fn store(&mut self, key: &str, value: &SettingValue) -> Option<()> {
                match key {
                    $($key => self.$field = <$t as SettingField>::from_value(value)?,)*
                    _ => return None,
                }
                Some(())
            }

            /// The core's options for a render of `width`×`height` pixels with `aovs`: every
            /// field of [`RenderOptions`] but these, the geometry cache's and the AOVs is a
            /// setting's (the compiler holds the table to that).
            pub fn to_options(&self, width: usize, height: usize, aovs: &[crate::aov::Aov]) -> RenderOptions {
                RenderOptions {
                    width,
                    height,
                    cache: self.cache_config(),
                    aovs: aovs.to_vec(),
                    $($($option: self.$field.clone(),)?)*
                }
            }
        }

        /// Checks the [`RenderOptions`] fields that come from settings against their rows.
        fn check_options(options: &RenderOptions) -> Result<(), SettingError> {
            $($(setting($key)?.check(&options.$option.to_value())?;)?)*
            Ok(())
        }
    };
}

settings_table! {
    "samples": samples: u32 = 1, int(1, 1_000_000), Render => samples,
        "camera samples per pixel (stratified; sample 0 is the pixel centre)";
    "seed": seed: u64 = 0, int(0, u64::MAX), Render => seed,
        "random seed; the image depends on it alone, whatever the thread count";
    "threads": threads: usize = 0, int(0, 1024), Render => threads,
        "render threads (0: all cores)";
    "tessFactor": tess_factor: f32 = 1.0, above(0.0, 1000.0), Render => tess_factor,
        "tessellated quad size relative to the ray beam width; larger is coarser";
    "tessFactorIncoherent": tess_factor_incoherent: f32 = 1.0, above(0.0, 1000.0), Render => tess_factor_incoherent,
        "extra tessFactor for incoherent rays (ambient occlusion, diffuse, glossy): the paper's claim is that coarsening them costs little";
    "geometryCacheMb": geometry_cache_mb: f64 = 30.0, closed(0.0, 1e6), GeometryCache,
        "geometry cache budget in MB (10^6 bytes), split evenly over the three tiers in multires mode";
    "geometryCacheCoarseMb": geometry_cache_coarse_mb: Option<f64> = None, closed(0.0, 1e6), GeometryCache,
        "multires only: the coarse (2×2) tier's budget in MB, overriding its third of geometryCacheMb";
    "geometryCacheMediumMb": geometry_cache_medium_mb: Option<f64> = None, closed(0.0, 1e6), GeometryCache,
        "multires only: the medium (5×5) tier's budget in MB";
    "geometryCacheFineMb": geometry_cache_fine_mb: Option<f64> = None, closed(0.0, 1e6), GeometryCache,
        "multires only: the fine (17×17) tier's budget in MB";
    "geometryMemoryMb": geometry_memory_mb: f64 = f64::INFINITY, above(0.0, f64::INFINITY), Render => geometry_memory_mb,
        "the render's whole geometry memory in MB (10^6 bytes): the geometry cache's budget, the meshes' patch tables, subpatch records and BVHs; meshes built on first use that no ray has entered lately are dropped and built again when reached, the image unchanged (inf: no bound)";
    "textureFilter": texture_filter: FilterMode = FilterMode::Differentials, choice::<FilterMode>(), Textures,
        "texture MIP level choice: differentials (filter widths from the ray differentials) or finest (the paper's 6.3.3 experiment)";
    "textureCacheMb": texture_cache_mb: f32 = 10.0, above(0.0, 1e6), Textures,
        "OpenImageIO texture cache budget in MB";
    "cacheMode": cache_mode: CacheMode = CacheMode::Multires, choice::<CacheMode>(), GeometryCache,
        "geometry cache: multires (three tiers, the paper's), single (17x17 only), unbounded (never evicts), none (retessellate every test)";
    "displacementBound": displacement_bound: f32 = 0.0, finite_from(0.0, false), Scene,
        "displacement bound (object units) for meshes that state none";
    "aoSamples": ao_samples: u32 = 0, int(0, 65_536), Render => ao_samples,
        "ambient-occlusion rays per shading point (0: off)";
    "aoDistance": ao_distance: f32 = f32::INFINITY, above(0.0, f64::INFINITY), Render => ao_distance,
        "ambient-occlusion ray length, scene units";
    "aoIntensity": ao_intensity: f32 = 1.0, finite_from(0.0, false), Render => ao_intensity,
        "radiance of the white sky ambient occlusion lights with";
    "shadowSamples": shadow_samples: u32 = 4, int(1, 4096), Render => shadow_samples,
        "light samples per shading point, shared among the lights by importance (plus as many BSDF samples)";
    "glossySamples": glossy_samples: u32 = 4, int(1, 65_536), Render => glossy_samples,
        "glossy rays per shading point at a camera ray's first non-mirror hit (1 further along)";
    "maxDepth": max_depth: u32 = 4, int(0, 64), Render => max_depth,
        "longest chain of specular bounces (and path length for path tracing)";
    "integrator": integrator: IntegratorKind = IntegratorKind::Auto, choice::<IntegratorKind>(), Render => integrator,
        "auto (what the scene calls for: direct light, specular, glossy, and ambient occlusion when aoSamples is set), direct, ao, colorBleeding (one diffuse bounce) or path (path tracing with Russian roulette)";
    "indirectSamples": indirect_samples: u32 = 16, int(0, 65_536), Render => indirect_samples,
        "hemisphere rays per shading point for one-bounce indirect diffuse (color bleeding)";
    "irradianceCache": irradiance_cache: bool = false, SettingType::Bool, Render => irradiance_cache,
        "interpolate ambient occlusion and irradiance with gradients (the paper's 5.1)";
    "irradianceCacheError": irradiance_cache_error: f32 = 0.2, above(0.0, 10.0), Render => irradiance_cache_error,
        "the irradiance cache's error bound (Ward's a); smaller is more accurate";
    "russianRouletteDepth": russian_roulette_depth: u32 = 3, int(0, 64), Render => russian_roulette_depth,
        "path tracing: bounces before Russian roulette may end a path (maxDepth or more: never)";
    "progressive": progressive: bool = false, SettingType::Bool, Render => progressive,
        "render in passes of 1, 2, 4, ... samples per pixel, reporting each; the final image is the same";
    "seams": seams: bool = true, SettingType::Bool, Render => seams,
        "seam boxes closing cracks between tessellation rates (docs/cracks.md); 0 only to measure them: rays then slip through cracks";
    "displacementRateFloor": displacement_rate_floor: bool = false, SettingType::Bool, Render => displacement_rate_floor,
        "displaced meshes are never read coarser than their finest detail (the fBm's finest octave; a texture's finest MIP level): closed displaced shells then let no light through at any rate, at a cost in time where that detail is fine (docs/cracks.md, rules 4 and 5)";
    "domeLightCameraVisibility": dome_light_camera_visibility: bool = true, SettingType::Bool, Render => dome_light_camera_visibility,
        "camera rays see a dome light as the background (0: it lights the scene and shows in reflections only)";
    "crop": crop: [f64; 4] = [0.0, 0.0, 1.0, 1.0], SettingType::Window, Render => crop,
        "render only the pixels whose centres lie in this window of the frame (USD's dataWindowNDC), bit-identical to the same pixels of the whole frame";
}

/// The row of setting `key`.
///
/// # Errors
/// [`SettingError::Unknown`] listing the valid keys.
pub fn setting(key: &str) -> Result<&'static Setting, SettingError> {
    SETTINGS
        .iter()
        .find(|s| s.key == key)
        .ok_or_else(|| SettingError::Unknown { key: key.to_string(), valid: SETTINGS.iter().map(|s| s.key).collect::<Vec<_>>().join(", ") })
}

/// `value` checked as setting `key`'s.
///
/// # Errors
/// An unknown key, or a value it does not take.
pub fn parse(key: &str, value: &Value) -> Result<SettingValue, SettingError> {
    setting(key)?.parse(value)
}

impl RenderSettings {
    /// Applies `key = value` pairs over the defaults, each checked against its row, then the
    /// rules between settings.
    ///
    /// # Errors
    /// The first unknown key (the message lists the valid ones) or value out of range.
    pub fn from_pairs<'a, I: IntoIterator<Item = (&'a str, &'a Value)>>(pairs: I) -> Result<Self, SettingError> {
        let mut s = RenderSettings::default();
        for (key, value) in pairs {
            let row = setting(key)?;
            let parsed = row.parse(value)?;
            s.store(row.key, &parsed).ok_or_else(|| row.refuse(shown(value), "of the wrong type"))?;
        }
        check_together(s.integrator, s.ao_samples)?;
        Ok(s)
    }

    /// The geometry cache these settings ask for; bytes are 10^6 per MB.
    pub fn cache_config(&self) -> CacheConfig {
        let bytes = (self.geometry_cache_mb * 1e6) as usize;
        match self.cache_mode {
            CacheMode::Multires => {
                let mut c = CacheConfig::multires(bytes);
                let tiers = [self.geometry_cache_coarse_mb, self.geometry_cache_medium_mb, self.geometry_cache_fine_mb];
                for (budget, mb) in c.budget_bytes.iter_mut().zip(tiers) {
                    if let Some(mb) = mb {
                        *budget = (mb * 1e6) as usize;
                    }
                }
                c
            }
            CacheMode::Single => CacheConfig::single(bytes),
            CacheMode::Unbounded => CacheConfig::unbounded(),
            CacheMode::None => CacheConfig::none(),
        }
    }
}

/// The rules between settings, checked once all are known.
///
/// # Errors
/// [`SettingError::Conflict`]: `integrator = ao` without ambient-occlusion rays.
pub fn check_together(integrator: IntegratorKind, ao_samples: u32) -> Result<(), SettingError> {
    if integrator == IntegratorKind::Ao && ao_samples == 0 {
        return Err(SettingError::Conflict(AO_NEEDS_SAMPLES));
    }
    Ok(())
}

/// Checks the [`RenderOptions`] fields that come from settings against their rows, and the
/// rules between them (for options made in Rust, not parsed from settings).
///
/// # Errors
/// The first value out of range.
pub fn check(options: &RenderOptions) -> Result<(), SettingError> {
    check_options(options)?;
    check_together(options.integrator, options.ao_samples)
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn one(key: &str, value: Value) -> Result<RenderSettings, SettingError> {
        RenderSettings::from_pairs([(key, &value)])
    }

    #[test]
    fn every_row_has_a_field_and_its_default_reads_back() {
        let defaults = RenderSettings::default();
        for row in SETTINGS {
            let value = defaults.value(row.key).unwrap_or_else(|| panic!("{} has no field", row.key));
            let text = row.default_text();
            if value == SettingValue::Unset {
                assert_eq!(text, "", "{}", row.key);
                continue;
            }
            // The default is in range, and its text parses back to the same field value.
            assert_eq!(row.parse(&json!(text)), Ok(value.clone()), "{}", row.key);
            assert_eq!(one(row.key, json!(text)).unwrap(), defaults, "{}", row.key);
        }
        let keys: std::collections::HashSet<_> = SETTINGS.iter().map(|s| s.key).collect();
        assert_eq!(keys.len(), SETTINGS.len(), "keys are unique");
    }

    #[test]
    fn text_and_numbers_are_held_to_the_same_rules() {
        // What the command line's flags and `--setting key=value` send (text) and what Python
        // dicts send (numbers) are accepted and refused alike.
        for (key, ok, refused) in [
            ("geometryCacheMb", vec![json!(0), json!("0"), json!(30.5)], vec![json!(-1), json!("-0.5"), json!(2e6)]),
            ("maxDepth", vec![json!(64), json!("0")], vec![json!(65), json!("-1")]),
            ("aoSamples", vec![json!(0), json!("16")], vec![json!(-1), json!("65537"), json!(1.5)]),
            ("threads", vec![json!(0), json!("8")], vec![json!(-1), json!(4096)]),
            ("seed", vec![json!(0), json!("18446744073709551615")], vec![json!(-1), json!("0.5")]),
            ("samples", vec![json!(1), json!(2.0), json!("4")], vec![json!(0), json!(2.5), json!("2.5"), json!(true)]),
            ("tessFactor", vec![json!(0.25), json!("2"), json!(1000)], vec![json!(0), json!("inf"), json!("x"), json!(1001)]),
            ("aoDistance", vec![json!("inf"), json!(3)], vec![json!(0), json!("-inf")]),
            ("irradianceCache", vec![json!(1), json!(false), json!("0")], vec![json!(2), json!("yes")]),
            ("cacheMode", vec![json!("single")], vec![json!("lru"), json!(1)]),
        ] {
            for v in ok {
                assert!(one(key, v.clone()).is_ok(), "{key}={v} refused: {:?}", one(key, v.clone()));
            }
            for v in refused {
                let e = one(key, v.clone()).expect_err(&format!("{key}={v} accepted")).to_string();
                assert!(e.starts_with(&format!("render setting {key}=")) && !e.contains('\n'), "{e}");
            }
        }
        assert_eq!(one("seed", json!("18446744073709551615")).unwrap().seed, u64::MAX, "big seeds stay exact");
        assert_eq!(one("samples", json!("4")).unwrap().samples, 4);
        assert!(one("progressive", json!(true)).unwrap().progressive);
    }

    #[test]
    fn refusals_name_the_setting_the_value_and_the_range() {
        let e = one("samples", json!(2.5)).unwrap_err().to_string();
        assert_eq!(e, "render setting samples=2.5: not an integer; samples takes integer, 1 ≤ x ≤ 1e+06");
        let e = one("aoSamples", json!("-1")).unwrap_err().to_string();
        assert_eq!(e, "render setting aoSamples=-1: out of range; aoSamples takes integer, 0 ≤ x ≤ 65536");
        let e = one("irradianceCacheError", json!(0)).unwrap_err().to_string();
        assert_eq!(e, "render setting irradianceCacheError=0: out of range; irradianceCacheError takes number, 0 < x ≤ 10");
        let e = one("cacheMode", json!("lru")).unwrap_err().to_string();
        assert_eq!(e, "render setting cacheMode=lru: not one of multires, single, unbounded, none");
        let e = one("sample", json!(1)).unwrap_err().to_string();
        assert!(e.starts_with("unknown render setting 'sample'; valid settings: samples, seed,"), "{e}");
        assert!(one("integrator", json!("ao")).unwrap_err().to_string().contains("aoSamples > 0"));
    }

    #[test]
    fn ranges_print_as_percent_g() {
        let shown: Vec<String> = [1e6, 65_536.0, 0.2, 10.0, 0.0, 1e-5, 1234567.0, f64::INFINITY].into_iter().map(short).collect();
        assert_eq!(shown, ["1e+06", "65536", "0.2", "10", "0", "1e-05", "1.23457e+06", "inf"]);
    }

    #[test]
    fn options_made_in_rust_are_checked_against_the_same_rows() {
        assert!(RenderOptions::default().validate().is_ok());
        let bad = RenderOptions { shadow_samples: 0, ..Default::default() };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("shadowSamples=0: out of range") && e.contains("1 ≤ x ≤ 4096"), "{e}");
        let bad = RenderOptions { ao_distance: f32::NAN, ..Default::default() };
        assert!(bad.validate().unwrap_err().to_string().contains("aoDistance=NaN: not a finite number"));
        // Every option a setting feeds is copied from it.
        let s = RenderSettings::from_pairs([("samples", &json!(7)), ("seams", &json!(0)), ("aoSamples", &json!(3))]).unwrap();
        let o = s.to_options(2, 3, &[]);
        assert_eq!((o.samples, o.seams, o.ao_samples, o.width, o.height), (7, false, 3, 2, 3));
    }
}
