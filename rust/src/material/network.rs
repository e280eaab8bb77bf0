//! A small network of MaterialX standard-library nodes feeding one material input, evaluated per
//! shading point: texture lookups (each at its own affine transform of the surface's `st`, so
//! `place2d` and `tiledimage` tiling move and scale the footprint too), constants, `st` itself,
//! and pointwise operators, as a flat op list run on a fixed-size stack of four-lane values.
//!
//! The scene delegate folds what it can (constants; one lookup under `texel · scale + bias`, the
//! [`super::TexturedColor`] fast path) and lowers the rest to this list (`docs/materials.md`).
//! Each operator is the MaterialX 1.39 standard library's, as its GLSL implementation
//! (`libraries/stdlib/genglsl/stdlib_genglsl_impl.mtlx`) writes it: `add` is `in1 + in2`,
//! `power` `pow(in1, in2)`, `mix` `mix(bg, fg, mix)`, `modulo` GLSL's `mod`, and so on.
//!
//! Values are four lanes whatever their MaterialX type; a float is kept splatted into all four
//! (texture lookups of one channel and float constants are), so `color3 · float` is a lane-wise
//! product. Lanes past a value's type are ignored by whoever reads it.
//!
//! Filtering: a lookup is filtered over the ray's footprint at its own texcoord (the footprint
//! carried through the lookup's affine map) and the filtered texel then goes through the
//! operators, as RenderMan's pattern networks and Storm's generated GLSL do; a non-linear
//! operator of a filtered texel is not the filtered operator (`pow` of a minified texture is
//! not the mean of `pow`), which is what every renderer that filters textures accepts.

use std::sync::Arc;

use glam::{Vec3A, Vec4};

use super::noise;
use crate::texture::{Lookup, TextureHandle, TextureSampler};

/// The deepest stack a network may need (checked by [`InputNetwork::new`]).
pub const MAX_STACK: usize = 16;

/// An affine map of `st`: `s' = m[0]·s + m[1]·t + m[2]`, `t' = m[3]·s + m[4]·t + m[5]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StTransform(pub [f32; 6]);

impl StTransform {
    pub const IDENTITY: StTransform = StTransform([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]);

    /// The transformed point.
    pub fn point(&self, st: [f32; 2]) -> [f32; 2] {
        let m = &self.0;
        [m[0] * st[0] + m[1] * st[1] + m[2], m[3] * st[0] + m[4] * st[1] + m[5]]
    }

    /// Whether the map has no linear part: the point is the same wherever the surface is, and
    /// whether it has an `st` at all (a MaterialX `geompropvalue`'s `default` as a texcoord).
    pub fn is_constant(&self) -> bool {
        let m = &self.0;
        m[0] == 0.0 && m[1] == 0.0 && m[3] == 0.0 && m[4] == 0.0
    }

    /// A transformed derivative (the linear part alone): how a footprint or a tangent maps.
    pub fn vector(&self, d: [f32; 2]) -> [f32; 2] {
        let m = &self.0;
        [m[0] * d[0] + m[1] * d[1], m[3] * d[0] + m[4] * d[1]]
    }
}

/// One texture lookup of a network (MaterialX `image` / `tiledimage`).
#[derive(Clone)]
pub struct NetworkLookup {
    pub sampler: Arc<dyn TextureSampler>,
    pub texture: TextureHandle,
    /// The file, for messages.
    pub path: String,
    pub lookup: Lookup,
    /// Channels read from `lookup.first_channel`, 1–4 (the node's output type); one channel is
    /// splatted into all four lanes.
    pub channels: u8,
    /// MaterialX `default`: the value where the lookup fails or the surface has no `st`.
    pub fallback: Vec4,
    /// The lookup's texcoord as a map of the surface's `st`.
    pub st_transform: StTransform,
}

impl std::fmt::Debug for NetworkLookup {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NetworkLookup")
            .field("path", &self.path)
            .field("channels", &self.channels)
            .field("st_transform", &self.st_transform)
            .finish_non_exhaustive()
    }
}

impl PartialEq for NetworkLookup {
    fn eq(&self, o: &Self) -> bool {
        Arc::ptr_eq(&self.sampler, &o.sampler)
            && self.texture == o.texture
            && self.lookup == o.lookup
            && self.channels == o.channels
            && self.fallback == o.fallback
            && self.st_transform == o.st_transform
    }
}

impl NetworkLookup {
    /// The filtered value at `st` with footprint `dst_dx`, `dst_dy` (of the surface's `st`, not
    /// yet transformed); the fallback where the lookup fails or there is no `st` (a constant
    /// texcoord needs none: the finest level at its point).
    fn eval(&self, st: Option<[[f32; 2]; 3]>) -> Vec4 {
        let t = &self.st_transform;
        let Some([st, dx, dy]) = st.or(t.is_constant().then_some([[0.0; 2]; 3])) else { return self.fallback };
        let mut out = [0.0f32; 4];
        let n = (self.channels as usize).clamp(1, 4);
        if !self.sampler.sample(self.texture, t.point(st), t.vector(dx), t.vector(dy), &self.lookup, &mut out[..n]) {
            return self.fallback;
        }
        if n == 1 {
            Vec4::splat(out[0])
        } else {
            Vec4::from(out)
        }
    }
}

/// A primvar of the surface a network reads (MaterialX `geompropvalue` of a primvar varying
/// over a mesh): `components` (1–4) floats from the surface's 2-float primvar channels
/// `channels` (the first two from `channels[0]`, the rest from `channels[1]`), set by whoever
/// knows the mesh; `None` (the mesh lacks it) reads `fallback`.
#[derive(Clone, Debug, PartialEq)]
pub struct NetworkPrimvar {
    /// The primvar's name, for whoever sets `channels`.
    pub name: String,
    pub components: u8,
    pub channels: Option<[usize; 2]>,
    /// MaterialX `default`.
    pub fallback: Vec4,
}

impl NetworkPrimvar {
    /// The value as four lanes: one component splatted, else the components and zeros.
    /// `read(channel)`: the channel's two floats at the shading point.
    fn eval(&self, read: &dyn Fn(usize) -> Option<[f32; 2]>) -> Vec4 {
        let Some([c0, c1]) = self.channels else { return self.fallback };
        let Some(a) = read(c0) else { return self.fallback };
        let mut v = [a[0], a[1], 0.0, 0.0];
        if self.components > 2 {
            let Some(b) = read(c1) else { return self.fallback };
            v[2] = b[0];
            v[3] = b[1];
        }
        let n = (self.components as usize).clamp(1, 4);
        if n == 1 {
            return Vec4::splat(v[0]);
        }
        for x in &mut v[n..] {
            *x = 0.0;
        }
        Vec4::from(v)
    }
}

/// One step of an [`InputNetwork`]. Binary operators pop `in2` then `in1` and push
/// `op(in1, in2)`, lane by lane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Op {
    /// Pushes a constant.
    Const([f32; 4]),
    /// Pushes lookup `i` of [`InputNetwork::lookups`].
    Texture(u16),
    /// Pushes primvar `i` of [`InputNetwork::primvars`].
    Primvar(u16),
    /// Pushes the surface's `st` under a transform, as (s, t, 0, 0) (a `texcoord` feeding
    /// arithmetic, a `checkerboard`); (0, 0, 0, 0) without `st`, unless the transform is
    /// constant.
    Coord(StTransform),
    /// `in1 + in2`.
    Add,
    /// `in1 − in2` (also `invert`: `amount − in`).
    Subtract,
    /// `in1 · in2`.
    Multiply,
    /// `in1 / in2`.
    Divide,
    /// GLSL `mod(in1, in2)` = `in1 − in2 · floor(in1 / in2)`.
    Modulo,
    /// `pow(in1, in2)`.
    Power,
    Min,
    Max,
    /// Pops `mix`, `fg`, `bg`: `bg · (1 − mix) + fg · mix` (GLSL `mix(bg, fg, mix)`).
    Mix,
    /// Pops `high`, `low`, `in`: `min(max(in, low), high)` (GLSL `clamp`).
    Clamp,
    /// Pops `in2`, `in1`, `value2`, `value1`: `value1 > value2 ? in1 : in2`, lane by lane
    /// (`ifgreater`; its values are floats, so splatted, and every lane agrees).
    IfGreater,
    /// `value1 >= value2 ? in1 : in2` (`ifgreatereq`).
    IfGreaterEq,
    /// `value1 == value2 ? in1 : in2` (`ifequal`).
    IfEqual,
    Abs,
    Floor,
    Ceil,
    /// Lane-wise `sin`, `cos`, `tan` (radians), `asin`, `acos` (NaN outside [−1, 1]), `exp`,
    /// `ln` (natural; NaN below 0, −∞ at 0) and GLSL `sign` (−1, 0 or 1), as the stdlib's
    /// genglsl `mx_sin(in)` … `log(in)`, `sign(in)`.
    Unary(Unary),
    /// `atan(in1, in2)` (GLSL's two-argument `atan`, `atan2`): the angle of (in2, in1), in
    /// radians in [−π, π]; MaterialX `atan2` pushes `iny` then `inx`.
    Atan2,
    /// The dot product of the first `n` lanes of `in1` and `in2` (`dotproduct_vectorN`),
    /// splatted.
    DotProduct(u8),
    /// The first `n` lanes scaled to unit length (`normalize_vectorN`); the other lanes 0.
    Normalize(u8),
    /// The length of the first `n` lanes (`magnitude_vectorN`), splatted.
    Magnitude(u8),
    /// `out[i] = in[lanes[i]]` (`extract`, splatting a float).
    Swizzle([u8; 4]),
    /// Pops `b`, `a`: `a`'s first `n` lanes, then `b`'s first `4 − n` (`combineN`, `convert`).
    Combine(u8),
    /// Pushes the shading point's position (`position`) in a space, as (x, y, z, 0).
    Position(Space),
    /// Pushes the surface's unit outward normal (`normal`) in a space, as (x, y, z, 0).
    Normal(Space),
    /// Pops a position (x, y, z): the stdlib's Perlin noise there (`mx_perlin_noise_float`,
    /// [`super::noise::perlin3`]), splatted; `noise3d`'s amplitude and pivot are ops around it.
    Noise3d,
    /// Pops a texcoord (x, y): [`super::noise::perlin2`], splatted (`noise2d`).
    Noise2d,
    /// Pops a position: `mx_fractal3d_noise_float` of it with these octaves, lacunarity and
    /// diminish (uniform in practice, so arguments), splatted (`fractal3d` before its amplitude).
    Fractal3d(Fractal),
    /// Pops a texcoord: `mx_fractal2d_noise_float` (`fractal2d` before its amplitude).
    Fractal2d(Fractal),
}

/// The space [`Op::Position`] and [`Op::Normal`] read in (MaterialX `space`; `model` is
/// `object`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Space {
    /// The gprim's own space, before its (instance's) transform.
    Object,
    /// Render (world) space.
    World,
}

/// A fractal noise's octaves, lacunarity and diminish.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fractal {
    pub octaves: u32,
    pub lacunarity: f32,
    pub diminish: f32,
}

/// The most octaves a fractal noise sums: past about 24 the lattice is finer than an f32
/// resolves and each octave is 0 again, so more is only time.
pub const MAX_OCTAVES: u16 = 32;

/// Where a network is evaluated, for [`Op::Position`] and [`Op::Normal`]: the shading point and
/// the surface's unit outward normal, in object space and in render (world) space.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct NetworkGeometry {
    pub p_object: Vec3A,
    pub p_world: Vec3A,
    pub n_object: Vec3A,
    pub n_world: Vec3A,
}

/// The one-argument functions of [`Op::Unary`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unary {
    Sin,
    Cos,
    Tan,
    Asin,
    Acos,
    Exp,
    Ln,
    Sign,
}

impl Unary {
    fn apply(self, x: f32) -> f32 {
        match self {
            Unary::Sin => x.sin(),
            Unary::Cos => x.cos(),
            Unary::Tan => x.tan(),
            Unary::Asin => x.asin(),
            Unary::Acos => x.acos(),
            Unary::Exp => x.exp(),
            Unary::Ln => x.ln(),
            // GLSL sign: 0 at 0 (f32::signum would give ±1).
            Unary::Sign => {
                if x > 0.0 {
                    1.0
                } else if x < 0.0 {
                    -1.0
                } else {
                    0.0
                }
            }
        }
    }
}

impl Op {
    /// The op named `name` (the scene delegate's spelling: the MaterialX node's name, or
    /// `const`, `texture`, `coord`, `swizzle`, `combine`) with its arguments: `position` and
    /// `normal` take their space (0 object, 1 world), `fractal3d` and `fractal2d` their
    /// octaves (0–[`MAX_OCTAVES`]), lacunarity and diminish.
    ///
    /// # Errors
    /// A one-line reason: an unknown name, or arguments of the wrong count or range.
    pub fn parse(name: &str, args: &[f32]) -> Result<Op, String> {
        let want = match name {
            "const" | "swizzle" => 4,
            "coord" => 6,
            "fractal3d" | "fractal2d" => 3,
            "texture" | "position" | "normal" | "primvar" | "dotproduct" | "normalize" | "magnitude" | "combine" => 1,
            _ => 0,
        };
        if args.len() != want {
            return Err(format!("op '{name}' takes {want} argument(s), got {}", args.len()));
        }
        if !args.iter().all(|x| x.is_finite()) {
            return Err(format!("op '{name}' has a non-finite argument {args:?}"));
        }
        let whole = |v: f32, lo: u16, hi: u16| {
            if v.fract() == 0.0 && v >= lo as f32 && v <= hi as f32 {
                Ok(v as u16)
            } else {
                Err(format!("op '{name}' argument {v} is not a whole number in {lo}–{hi}"))
            }
        };
        let lane = |v: f32, lo: u8, hi: u8| whole(v, lo as u16, hi as u16).map(|i| i as u8);
        Ok(match name {
            "const" => Op::Const([args[0], args[1], args[2], args[3]]),
            "texture" => Op::Texture(whole(args[0], 0, u16::MAX)?),
            "primvar" => Op::Primvar(whole(args[0], 0, u16::MAX)?),
            "coord" => Op::Coord(StTransform([args[0], args[1], args[2], args[3], args[4], args[5]])),
            "add" => Op::Add,
            "subtract" => Op::Subtract,
            "multiply" => Op::Multiply,
            "divide" => Op::Divide,
            "modulo" => Op::Modulo,
            "power" => Op::Power,
            "min" => Op::Min,
            "max" => Op::Max,
            "mix" => Op::Mix,
            "clamp" => Op::Clamp,
            "ifgreater" => Op::IfGreater,
            "ifgreatereq" => Op::IfGreaterEq,
            "ifequal" => Op::IfEqual,
            "absval" => Op::Abs,
            "floor" => Op::Floor,
            "ceil" => Op::Ceil,
            "sin" => Op::Unary(Unary::Sin),
            "cos" => Op::Unary(Unary::Cos),
            "tan" => Op::Unary(Unary::Tan),
            "asin" => Op::Unary(Unary::Asin),
            "acos" => Op::Unary(Unary::Acos),
            "exp" => Op::Unary(Unary::Exp),
            "ln" => Op::Unary(Unary::Ln),
            "sign" => Op::Unary(Unary::Sign),
            "atan2" => Op::Atan2,
            "dotproduct" => Op::DotProduct(lane(args[0], 1, 4)?),
            "normalize" => Op::Normalize(lane(args[0], 1, 4)?),
            "magnitude" => Op::Magnitude(lane(args[0], 1, 4)?),
            "swizzle" => Op::Swizzle([lane(args[0], 0, 3)?, lane(args[1], 0, 3)?, lane(args[2], 0, 3)?, lane(args[3], 0, 3)?]),
            "combine" => Op::Combine(lane(args[0], 1, 3)?),
            "position" | "normal" => {
                let space = if whole(args[0], 0, 1)? == 0 { Space::Object } else { Space::World };
                if name == "position" {
                    Op::Position(space)
                } else {
                    Op::Normal(space)
                }
            }
            "noise3d" => Op::Noise3d,
            "noise2d" => Op::Noise2d,
            "fractal3d" | "fractal2d" => {
                let f = Fractal { octaves: whole(args[0], 0, MAX_OCTAVES)? as u32, lacunarity: args[1], diminish: args[2] };
                if name == "fractal3d" {
                    Op::Fractal3d(f)
                } else {
                    Op::Fractal2d(f)
                }
            }
            _ => return Err(format!("'{name}' is not a network op mipray evaluates")),
        })
    }

    /// (values popped, values pushed).
    const fn arity(self) -> (usize, usize) {
        match self {
            Op::Const(_) | Op::Texture(_) | Op::Primvar(_) | Op::Coord(_) | Op::Position(_) | Op::Normal(_) => (0, 1),
            Op::Mix | Op::Clamp => (3, 1),
            Op::IfGreater | Op::IfGreaterEq | Op::IfEqual => (4, 1),
            Op::Abs | Op::Floor | Op::Ceil | Op::Unary(_) | Op::Normalize(_) | Op::Magnitude(_) | Op::Swizzle(_) => (1, 1),
            Op::Noise3d | Op::Noise2d | Op::Fractal3d(_) | Op::Fractal2d(_) => (1, 1),
            _ => (2, 1),
        }
    }
}

/// A network feeding one input: [`Op`]s over [`NetworkLookup`]s, all reading the surface's `st`
/// channel `st_channel`. Checked when made, so evaluation never fails.
#[derive(Clone, Debug, PartialEq)]
pub struct InputNetwork {
    ops: Vec<Op>,
    pub lookups: Vec<NetworkLookup>,
    /// The primvars [`Op::Primvar`] reads.
    pub primvars: Vec<NetworkPrimvar>,
    /// The surface's 2-float primvar channel holding `st` (set by whoever knows the mesh).
    pub st_channel: usize,
}

impl InputNetwork {
    /// A network of `ops` over `lookups`.
    ///
    /// # Errors
    /// [`InputNetwork::check`]'s reason.
    pub fn new(ops: Vec<Op>, lookups: Vec<NetworkLookup>) -> Result<Self, String> {
        Self::with_primvars(ops, lookups, Vec::new())
    }

    /// A network of `ops` over `lookups` and `primvars`.
    ///
    /// # Errors
    /// [`InputNetwork::check`]'s reason, or a primvar [`Op::Primvar`] names that is not there.
    pub fn with_primvars(ops: Vec<Op>, lookups: Vec<NetworkLookup>, primvars: Vec<NetworkPrimvar>) -> Result<Self, String> {
        Self::check(&ops, lookups.len())?;
        Self::check_primvars(&ops, primvars.len())?;
        Ok(InputNetwork { ops, lookups, primvars, st_channel: 0 })
    }

    /// Checks that every [`Op::Primvar`] of `ops` names one of `primvars` primvars.
    ///
    /// # Errors
    /// A one-line reason naming the op.
    pub fn check_primvars(ops: &[Op], primvars: usize) -> Result<(), String> {
        for (k, op) in ops.iter().enumerate() {
            if let Op::Primvar(i) = op {
                if *i as usize >= primvars {
                    return Err(format!("op {k} reads primvar {i} of {primvars}"));
                }
            }
        }
        Ok(())
    }

    /// Checks an op list over `lookups` lookups.
    ///
    /// # Errors
    /// A one-line reason when the list pops more than it pushed, needs more than [`MAX_STACK`]
    /// values, names a lookup that is not there, or leaves other than one value.
    pub fn check(ops: &[Op], lookups: usize) -> Result<(), String> {
        let mut depth = 0usize;
        for (k, op) in ops.iter().enumerate() {
            if let Op::Texture(i) = op {
                if *i as usize >= lookups {
                    return Err(format!("op {k} reads lookup {i} of {lookups}"));
                }
            }
            let (pop, push) = op.arity();
            if depth < pop {
                return Err(format!("op {k} ({op:?}) needs {pop} value(s) and has {depth}"));
            }
            depth = depth - pop + push;
            if depth > MAX_STACK {
                return Err(format!("the network needs more than {MAX_STACK} values at once"));
            }
        }
        if depth != 1 {
            return Err(format!("the network leaves {depth} values, not one"));
        }
        Ok(())
    }

    /// The ops, in order.
    pub fn ops(&self) -> &[Op] {
        &self.ops
    }

    /// The value at a shading point: `st` = (st, d(st)/dx, d(st)/dy) of channel
    /// [`InputNetwork::st_channel`], `None` where the surface has none (lookups then give their
    /// fallbacks, [`Op::Coord`] zero). Unclamped and possibly non-finite (`divide` by 0,
    /// `power` of a negative base): the caller clamps into the input's range.
    pub fn eval(&self, st: Option<[[f32; 2]; 3]>) -> Vec4 {
        self.eval_with(st, &|_| None)
    }

    /// [`InputNetwork::eval`] where the surface's primvar channels are `read(channel)` (the
    /// channel's two floats at the shading point; `None`: no such channel), for
    /// [`Op::Primvar`].
    pub fn eval_with(&self, st: Option<[[f32; 2]; 3]>, read: &dyn Fn(usize) -> Option<[f32; 2]>) -> Vec4 {
        self.eval_at(st, read, &NetworkGeometry::default())
    }

    /// [`InputNetwork::eval_with`] at `geom`, for [`Op::Position`] and [`Op::Normal`].
    pub fn eval_at(&self, st: Option<[[f32; 2]; 3]>, read: &dyn Fn(usize) -> Option<[f32; 2]>, geom: &NetworkGeometry) -> Vec4 {
        let mut stack = [Vec4::ZERO; MAX_STACK];
        let mut n = 0usize;
        for op in &self.ops {
            let v = match *op {
                Op::Const(c) => Vec4::from(c),
                Op::Texture(i) => self.lookups[i as usize].eval(st),
                Op::Primvar(i) => self.primvars[i as usize].eval(read),
                Op::Coord(t) => match st.map(|s| s[0]).or(t.is_constant().then_some([0.0; 2])) {
                    Some(s) => {
                        let p = t.point(s);
                        Vec4::new(p[0], p[1], 0.0, 0.0)
                    }
                    None => Vec4::ZERO,
                },
                Op::Position(space) => match space {
                    Space::Object => geom.p_object.extend(0.0),
                    Space::World => geom.p_world.extend(0.0),
                },
                Op::Normal(space) => match space {
                    Space::Object => geom.n_object.extend(0.0),
                    Space::World => geom.n_world.extend(0.0),
                },
                Op::Noise3d | Op::Noise2d | Op::Fractal3d(_) | Op::Fractal2d(_) => {
                    n -= 1;
                    let a = stack[n];
                    Vec4::splat(match *op {
                        Op::Noise3d => noise::perlin3([a.x, a.y, a.z]),
                        Op::Noise2d => noise::perlin2([a.x, a.y]),
                        Op::Fractal3d(f) => noise::fractal3([a.x, a.y, a.z], f.octaves, f.lacunarity, f.diminish),
                        Op::Fractal2d(f) => noise::fractal2([a.x, a.y], f.octaves, f.lacunarity, f.diminish),
                        _ => unreachable!("noise ops only"),
                    })
                }
                Op::Mix | Op::Clamp => {
                    let (a, b, c) = (stack[n - 3], stack[n - 2], stack[n - 1]);
                    n -= 3;
                    if matches!(op, Op::Mix) {
                        a * (Vec4::ONE - c) + b * c
                    } else {
                        a.max(b).min(c)
                    }
                }
                Op::IfGreater | Op::IfGreaterEq | Op::IfEqual => {
                    let (v1, v2, a, b) = (stack[n - 4], stack[n - 3], stack[n - 2], stack[n - 1]);
                    n -= 4;
                    let take_a = match op {
                        Op::IfGreater => v1.cmpgt(v2),
                        Op::IfGreaterEq => v1.cmpge(v2),
                        _ => v1.cmpeq(v2),
                    };
                    Vec4::select(take_a, a, b)
                }
                Op::Abs | Op::Floor | Op::Ceil | Op::Unary(_) | Op::Normalize(_) | Op::Magnitude(_) | Op::Swizzle(_) => {
                    n -= 1;
                    let a = stack[n];
                    match *op {
                        Op::Abs => a.abs(),
                        Op::Unary(f) => Vec4::from(a.to_array().map(|x| f.apply(x))),
                        Op::Floor => a.floor(),
                        Op::Ceil => a.ceil(),
                        Op::Normalize(k) => {
                            let m = lanes(a, k);
                            let len = m.length();
                            if len > 0.0 {
                                m / len
                            } else {
                                Vec4::ZERO
                            }
                        }
                        Op::Magnitude(k) => Vec4::splat(lanes(a, k).length()),
                        Op::Swizzle(s) => {
                            let a = a.to_array();
                            Vec4::new(a[s[0] as usize], a[s[1] as usize], a[s[2] as usize], a[s[3] as usize])
                        }
                        _ => unreachable!("unary ops only"),
                    }
                }
                _ => {
                    let (a, b) = (stack[n - 2], stack[n - 1]);
                    n -= 2;
                    match *op {
                        Op::Add => a + b,
                        Op::Subtract => a - b,
                        Op::Multiply => a * b,
                        Op::Divide => a / b,
                        Op::Modulo => a - b * (a / b).floor(),
                        Op::Power => Vec4::new(a.x.powf(b.x), a.y.powf(b.y), a.z.powf(b.z), a.w.powf(b.w)),
                        Op::Atan2 => Vec4::new(a.x.atan2(b.x), a.y.atan2(b.y), a.z.atan2(b.z), a.w.atan2(b.w)),
                        Op::Min => a.min(b),
                        Op::Max => a.max(b),
                        Op::DotProduct(k) => Vec4::splat(lanes(a, k).dot(lanes(b, k))),
                        Op::Combine(k) => {
                            let (a, b) = (a.to_array(), b.to_array());
                            let mut out = [0.0; 4];
                            let k = k as usize;
                            out[..k].copy_from_slice(&a[..k]);
                            out[k..].copy_from_slice(&b[..4 - k]);
                            Vec4::from(out)
                        }
                        _ => unreachable!("binary ops only"),
                    }
                }
            };
            stack[n] = v;
            n += 1;
        }
        stack[0]
    }
}

/// The first `k` lanes of `v`, the rest 0.
fn lanes(v: Vec4, k: u8) -> Vec4 {
    let mut a = v.to_array();
    for x in &mut a[(k as usize).min(4)..] {
        *x = 0.0;
    }
    Vec4::from(a)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::texture::TextureError;
    use glam::Vec2;
    use std::sync::Mutex;

    /// Texture 0 is the ramp (s, t, s + t, 1) from channel `first_channel` on; texture 1 cannot be
    /// read. Remembers the last lookup's point and footprint.
    #[derive(Default)]
    struct Ramp {
        last: Mutex<Option<[[f32; 2]; 3]>>,
    }

    impl TextureSampler for Ramp {
        fn handle(&self, _path: &str) -> Result<TextureHandle, TextureError> {
            Ok(TextureHandle::new(0))
        }
        fn sample(&self, h: TextureHandle, st: [f32; 2], dx: [f32; 2], dy: [f32; 2], lookup: &Lookup, out: &mut [f32]) -> bool {
            if h.index() != 0 {
                return false;
            }
            *self.last.lock().unwrap() = Some([st, dx, dy]);
            let texel = [st[0], st[1], st[0] + st[1], 1.0];
            for (k, o) in out.iter_mut().enumerate() {
                *o = texel[(lookup.first_channel as usize + k).min(3)];
            }
            true
        }
        fn filter_mode(&self) -> crate::texture::FilterMode {
            crate::texture::FilterMode::Differentials
        }
        fn stats(&self) -> serde_json::Value {
            serde_json::Value::Null
        }
    }

    fn lookup(sampler: &Arc<Ramp>, texture: u32, channels: u8, st_transform: StTransform) -> NetworkLookup {
        NetworkLookup {
            sampler: sampler.clone(),
            texture: TextureHandle::new(texture),
            path: "ramp".into(),
            lookup: Lookup::DEFAULT,
            channels,
            fallback: Vec4::new(0.25, 0.5, 0.75, 1.0),
            st_transform,
        }
    }

    const AT: [[f32; 2]; 3] = [[0.2, 0.6], [0.01, 0.0], [0.0, 0.02]];

    fn eval(ops: Vec<Op>, lookups: Vec<NetworkLookup>) -> Vec4 {
        InputNetwork::new(ops, lookups).unwrap().eval(Some(AT))
    }

    #[test]
    fn two_lookups_combine_pointwise_as_the_stdlib_defines_each_op() {
        let ramp = Arc::new(Ramp::default());
        // A second lookup of the same ramp, its texcoord placed at 2·st + (0.1, 0).
        let placed = StTransform([2.0, 0.0, 0.1, 0.0, 2.0, 0.0]);
        let (s, t) = (0.2f32, 0.6f32);
        let a = Vec4::new(s, t, s + t, 1.0);
        let (s2, t2) = (2.0 * s + 0.1, 2.0 * t);
        let b = Vec4::new(s2, t2, s2 + t2, 1.0);
        let both = || vec![lookup(&ramp, 0, 4, StTransform::IDENTITY), lookup(&ramp, 0, 4, placed)];
        let two = |op: Op| eval(vec![Op::Texture(0), Op::Texture(1), op], both());
        assert_eq!(two(Op::Add), a + b);
        assert_eq!(two(Op::Subtract), a - b);
        assert_eq!(two(Op::Multiply), a * b);
        assert_eq!(two(Op::Divide), a / b);
        assert_eq!(two(Op::Min), a.min(b));
        assert_eq!(two(Op::Max), a.max(b));
        let pow = two(Op::Power);
        for k in 0..4 {
            assert_eq!(pow[k], a[k].powf(b[k]));
        }
        // GLSL mod: in1 − in2·floor(in1/in2), negative operands included.
        let m = eval(vec![Op::Const([-0.5, 2.5, 3.0, -3.0]), Op::Const([2.0, 2.0, -2.0, 2.0]), Op::Modulo], vec![]);
        assert_eq!(m, Vec4::new(1.5, 0.5, -1.0, 1.0));
        // mix(bg, fg, mask) with a textured mask: the first lookup's s, splatted (one channel).
        let mask = lookup(&ramp, 0, 1, StTransform::IDENTITY);
        let mixed = eval(vec![Op::Const([1.0, 0.0, 0.0, 0.0]), Op::Const([0.0, 0.0, 1.0, 0.0]), Op::Texture(0), Op::Mix], vec![mask]);
        assert_eq!(mixed, Vec4::new(1.0 - s, 0.0, s, 0.0));
        // ifgreater(mask, 0.5, a, b) with the textured mask s, splatted: b where s ≤ 0.5.
        let cond = |op: Op, v2: f32| {
            let ops = vec![Op::Texture(0), Op::Const([v2; 4]), Op::Const([1.0; 4]), Op::Const([2.0; 4]), op];
            eval(ops, vec![lookup(&ramp, 0, 1, StTransform::IDENTITY)])
        };
        assert_eq!(cond(Op::IfGreater, 0.1), Vec4::ONE);
        assert_eq!(cond(Op::IfGreater, s), Vec4::splat(2.0));
        assert_eq!(cond(Op::IfGreaterEq, s), Vec4::ONE);
        assert_eq!(cond(Op::IfEqual, s), Vec4::ONE);
        assert_eq!(cond(Op::IfEqual, 0.5), Vec4::splat(2.0));
        // clamp(in, low, high).
        let clamped = eval(vec![Op::Texture(0), Op::Const([0.3; 4]), Op::Const([0.7; 4]), Op::Clamp], both());
        assert_eq!(clamped, Vec4::new(0.3, 0.6, 0.7, 0.7));
    }

    #[test]
    fn channels_are_extracted_combined_normalized_and_dotted() {
        let ramp = Arc::new(Ramp::default());
        let one = || vec![lookup(&ramp, 0, 3, StTransform::IDENTITY)];
        let (s, t) = (0.2f32, 0.6f32);
        // extract index 1, splatted.
        assert_eq!(eval(vec![Op::Texture(0), Op::Swizzle([1; 4])], one()), Vec4::splat(t));
        // combine3(extract 2, extract 0, 0.5): two Combine steps.
        let ops = vec![
            Op::Texture(0),
            Op::Swizzle([2; 4]),
            Op::Texture(0),
            Op::Swizzle([0; 4]),
            Op::Combine(1),
            Op::Const([0.5; 4]),
            Op::Combine(2),
        ];
        assert_eq!(eval(ops, one()).truncate(), glam::Vec3::new(s + t, s, 0.5));
        let n = eval(vec![Op::Texture(0), Op::Normalize(3)], one());
        let v = glam::Vec3::new(s, t, s + t);
        assert!((n.truncate() - v / v.length()).abs().max_element() < 1e-7 && n.w == 0.0);
        assert_eq!(eval(vec![Op::Texture(0), Op::Magnitude(2)], one()), Vec4::splat(Vec2::new(s, t).length()));
        let d = eval(vec![Op::Texture(0), Op::Const([1.0, 2.0, 3.0, 100.0]), Op::DotProduct(3)], one());
        assert_eq!(d, Vec4::splat(s + 2.0 * t + 3.0 * (s + t)));
        assert_eq!(eval(vec![Op::Const([-1.5, 1.5, -0.0, 2.0]), Op::Abs], vec![]), Vec4::new(1.5, 1.5, 0.0, 2.0));
        assert_eq!(eval(vec![Op::Const([-1.5, 1.5, 0.0, 2.0]), Op::Floor], vec![]), Vec4::new(-2.0, 1.0, 0.0, 2.0));
        assert_eq!(eval(vec![Op::Const([-1.5, 1.5, 0.0, 2.0]), Op::Ceil], vec![]), Vec4::new(-1.0, 2.0, 0.0, 2.0));
    }

    #[test]
    fn math_functions_are_glsls_lane_by_lane() {
        let x = [0.5f32, -0.25, 0.0, 2.0];
        let unary = |name: &str| eval(vec![Op::Const(x), Op::parse(name, &[]).unwrap()], vec![]).to_array();
        assert_eq!(unary("sin"), x.map(f32::sin));
        assert_eq!(unary("cos"), x.map(f32::cos));
        assert_eq!(unary("tan"), x.map(f32::tan));
        assert_eq!(unary("exp"), x.map(f32::exp));
        // GLSL sign is 0 at 0; asin, acos and ln are NaN outside their domains (the caller
        // clamps NaN to 0 before the image).
        assert_eq!(unary("sign"), [1.0, -1.0, 0.0, 1.0]);
        let (asin, acos, ln) = (unary("asin"), unary("acos"), unary("ln"));
        assert_eq!(asin[..3], [0.5f32.asin(), (-0.25f32).asin(), 0.0]);
        assert_eq!(acos[..3], [0.5f32.acos(), (-0.25f32).acos(), std::f32::consts::FRAC_PI_2]);
        assert!(asin[3].is_nan() && acos[3].is_nan());
        assert_eq!(ln[0], 0.5f32.ln());
        assert!(ln[1].is_nan() && ln[2] == f32::NEG_INFINITY);
        // atan2(iny, inx): the angle of (inx, iny), every quadrant.
        let y = Op::Const([1.0, 1.0, -1.0, -1.0]);
        let at = eval(vec![y, Op::Const([1.0, -1.0, -1.0, 1.0]), Op::Atan2], vec![]);
        let q = std::f32::consts::FRAC_PI_4;
        assert_eq!(at.to_array(), [q, 3.0 * q, -3.0 * q, -q]);
    }

    #[test]
    fn a_lookups_transform_moves_its_point_and_scales_its_footprint() {
        let ramp = Arc::new(Ramp::default());
        // tiledimage uvtiling (2, 3), uvoffset (0.5, 0): st' = st·tiling − offset.
        let tiled = StTransform([2.0, 0.0, -0.5, 0.0, 3.0, 0.0]);
        let v = eval(vec![Op::Texture(0)], vec![lookup(&ramp, 0, 2, tiled)]);
        let want = [2.0 * 0.2 - 0.5, 3.0 * 0.6];
        assert_eq!([v.x, v.y], want);
        let last = ramp.last.lock().unwrap().unwrap();
        assert_eq!(last, [want, [0.02, 0.0], [0.0, 0.06]]);
        // Coord pushes the transformed st; without st it is zero and lookups give the fallback.
        let net = InputNetwork::new(vec![Op::Coord(tiled)], vec![]).unwrap();
        assert_eq!(net.eval(Some(AT)), Vec4::new(want[0], want[1], 0.0, 0.0));
        assert_eq!(net.eval(None), Vec4::ZERO);
        let net = InputNetwork::new(vec![Op::Texture(0)], vec![lookup(&ramp, 0, 3, tiled)]).unwrap();
        assert_eq!(net.eval(None), Vec4::new(0.25, 0.5, 0.75, 1.0));
        // A constant texcoord (a geompropvalue's default) is looked up, and pushed, without st.
        let fixed = StTransform([0.0, 0.0, 0.25, 0.0, 0.0, 0.75]);
        let net = InputNetwork::new(vec![Op::Texture(0)], vec![lookup(&ramp, 0, 3, fixed)]).unwrap();
        assert_eq!(net.eval(None), Vec4::new(0.25, 0.75, 1.0, 0.0));
        assert_eq!(*ramp.last.lock().unwrap(), Some([[0.25, 0.75], [0.0; 2], [0.0; 2]]));
        assert_eq!(InputNetwork::new(vec![Op::Coord(fixed)], vec![]).unwrap().eval(None), Vec4::new(0.25, 0.75, 0.0, 0.0));
        // An unreadable texture gives its fallback too.
        assert_eq!(eval(vec![Op::Texture(0)], vec![lookup(&ramp, 1, 3, tiled)]), Vec4::new(0.25, 0.5, 0.75, 1.0));
    }

    #[test]
    fn a_primvar_is_read_from_its_channels_into_its_lanes() {
        // Channel 3 holds (0.25, 0.5), channel 5 (0.75, 2.0); channel 9 is not there.
        let read = |c: usize| match c {
            3 => Some([0.25, 0.5]),
            5 => Some([0.75, 2.0]),
            _ => None,
        };
        let pv = |components: u8, channels: Option<[usize; 2]>| NetworkPrimvar {
            name: "p".into(),
            components,
            channels,
            fallback: Vec4::new(9.0, 8.0, 7.0, 6.0),
        };
        let value = |p: NetworkPrimvar| {
            InputNetwork::with_primvars(vec![Op::Primvar(0), Op::Const([2.0; 4]), Op::Multiply], vec![], vec![p])
                .unwrap()
                .eval_with(Some(AT), &read)
        };
        assert_eq!(value(pv(1, Some([3, 3]))), Vec4::splat(0.5));
        assert_eq!(value(pv(2, Some([3, 3]))), Vec4::new(0.5, 1.0, 0.0, 0.0));
        assert_eq!(value(pv(3, Some([3, 5]))), Vec4::new(0.5, 1.0, 1.5, 0.0));
        assert_eq!(value(pv(4, Some([3, 5]))), Vec4::new(0.5, 1.0, 1.5, 4.0));
        // Missing: the fallback (MaterialX default).
        assert_eq!(value(pv(3, None)), Vec4::new(18.0, 16.0, 14.0, 12.0));
        assert_eq!(value(pv(3, Some([9, 9]))), Vec4::new(18.0, 16.0, 14.0, 12.0));
        let err = InputNetwork::with_primvars(vec![Op::Primvar(1)], vec![], vec![pv(1, None)]).unwrap_err();
        assert_eq!(err, "op 0 reads primvar 1 of 1");
    }

    #[test]
    fn malformed_lists_are_refused_when_made() {
        let ramp = Arc::new(Ramp::default());
        let err = |ops: Vec<Op>| InputNetwork::new(ops, vec![lookup(&ramp, 0, 3, StTransform::IDENTITY)]).unwrap_err();
        assert_eq!(err(vec![Op::Texture(0), Op::Add]), "op 1 (Add) needs 2 value(s) and has 1");
        assert_eq!(err(vec![Op::Texture(1)]), "op 0 reads lookup 1 of 1");
        assert_eq!(err(vec![Op::Texture(0), Op::Texture(0)]), "the network leaves 2 values, not one");
        assert_eq!(err(vec![]), "the network leaves 0 values, not one");
        assert_eq!(err(vec![Op::Texture(0); MAX_STACK + 1]), format!("the network needs more than {MAX_STACK} values at once"));
        assert_eq!(Op::parse("power", &[]), Ok(Op::Power));
        assert_eq!(Op::parse("swizzle", &[3.0, 0.0, 0.0, 1.0]), Ok(Op::Swizzle([3, 0, 0, 1])));
        // (noise3d was the example here until it was evaluated.)
        assert_eq!(Op::parse("worleynoise3d", &[]).unwrap_err(), "'worleynoise3d' is not a network op mipray evaluates");
        assert_eq!(Op::parse("position", &[2.0]).unwrap_err(), "op 'position' argument 2 is not a whole number in 0–1");
        assert_eq!(Op::parse("fractal3d", &[33.0, 2.0, 0.5]).unwrap_err(), "op 'fractal3d' argument 33 is not a whole number in 0–32");
        assert_eq!(Op::parse("add", &[1.0]).unwrap_err(), "op 'add' takes 0 argument(s), got 1");
        assert_eq!(Op::parse("swizzle", &[4.0, 0.0, 0.0, 0.0]).unwrap_err(), "op 'swizzle' argument 4 is not a whole number in 0–3");
        assert!(Op::parse("const", &[f32::NAN, 0.0, 0.0, 0.0]).unwrap_err().contains("non-finite"));
    }

    #[test]
    fn position_and_normal_are_read_in_their_space_and_feed_the_noise() {
        let geom = NetworkGeometry {
            p_object: Vec3A::new(0.25, -1.5, 2.0),
            p_world: Vec3A::new(3.0, 4.0, 5.0),
            n_object: Vec3A::new(0.0, 0.0, 1.0),
            n_world: Vec3A::new(1.0, 0.0, 0.0),
        };
        let at = |ops: Vec<Op>| InputNetwork::new(ops, vec![]).unwrap().eval_at(None, &|_| None, &geom);
        let op = |name: &str, args: &[f32]| Op::parse(name, args).unwrap();
        assert_eq!(at(vec![op("position", &[0.0])]), Vec4::new(0.25, -1.5, 2.0, 0.0));
        assert_eq!(at(vec![op("position", &[1.0])]), Vec4::new(3.0, 4.0, 5.0, 0.0));
        assert_eq!(at(vec![op("normal", &[0.0])]), Vec4::new(0.0, 0.0, 1.0, 0.0));
        assert_eq!(at(vec![op("normal", &[1.0])]), Vec4::new(1.0, 0.0, 0.0, 0.0));
        let p = [0.25, -1.5, 2.0];
        assert_eq!(at(vec![op("position", &[0.0]), op("noise3d", &[])]), Vec4::splat(noise::perlin3(p)));
        assert_eq!(at(vec![op("position", &[0.0]), op("noise2d", &[])]), Vec4::splat(noise::perlin2([0.25, -1.5])));
        assert_eq!(at(vec![op("position", &[0.0]), op("fractal3d", &[3.0, 2.0, 0.5])]), Vec4::splat(noise::fractal3(p, 3, 2.0, 0.5)));
        assert_eq!(
            at(vec![op("position", &[0.0]), op("fractal2d", &[2.0, 3.0, 0.25])]),
            Vec4::splat(noise::fractal2([0.25, -1.5], 2, 3.0, 0.25))
        );
        // Without geometry (eval_with), both read zero: noise at the lattice origin is 0.
        let net = InputNetwork::new(vec![op("position", &[0.0]), op("noise3d", &[])], vec![]).unwrap();
        assert_eq!(net.eval_with(None, &|_| None), Vec4::ZERO);
    }
}
