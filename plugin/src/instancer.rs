//! The instancer (Hydra's `HdInstancer`): places prototypes — meshes, or other instancers — at
//! many transforms, so a prototype's geometry exists once however often it is placed.
//!
//! USD has two kinds of instancing and both arrive here: a `UsdGeom.PointInstancer` (prototypes,
//! protoIndices and per-instance transforms) and native instancing (one instancer per prototype,
//! one instance per instanceable prim). The scene delegate registers each prototype's meshes with
//! [`crate::mesh::MeshData::prototype`] set and transforms relative to the prototype's root; an
//! instancer then says which prototype goes where. Prototypes may themselves be instancers
//! (nested PointInstancers, instances inside prototypes), up to [`MAX_NESTING`] levels.
//!
//! The render pass flattens instancers into the core's two-level scene: one core mesh per
//! prototype mesh, one core instance per placement with transform
//! `instance transform × prototype mesh transform`. The core's top-level BVH holds the
//! placements; the mesh's subpatches, its bottom-level BVH and its geometry cache entries are
//! shared by every placement (the paper's §5 cache is keyed by mesh, not by instance).

use std::collections::BTreeMap;
use std::sync::Arc;

use glam::Mat4;
use mipray::motion::{MotionKey, MotionTransform};

use crate::error::DelegateError;

/// The deepest chain of instancers placing instancers that a render follows; deeper chains (in
/// practice: cycles) are reported and cut.
pub const MAX_NESTING: usize = 8;

/// What the scene delegate knows about an instancer.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct InstancerData {
    /// Prim paths of the prototypes: meshes or instancers held by the delegate.
    pub prototypes: Vec<String>,
    /// Per instance, an index into `prototypes`.
    pub proto_indices: Vec<u32>,
    /// Per instance, prototype-root-to-world (or, for a prototype instancer, to its parent
    /// prototype's root); column-vector convention.
    pub transforms: Vec<Mat4>,
    /// A prototype of other instancers: it places nothing by itself.
    pub prototype: bool,
}

impl InstancerData {
    /// Checks the arrays against each other; `proto_indices` as the scene delegate gives them.
    ///
    /// # Errors
    /// Sizes that disagree, an index out of range, a transform that is not finite, or an empty
    /// prototype path; the message names `path`.
    pub fn new(
        path: &str,
        prototypes: Vec<String>,
        proto_indices: &[i32],
        transforms: Vec<Mat4>,
        prototype: bool,
    ) -> Result<Self, DelegateError> {
        if proto_indices.len() != transforms.len() {
            return Err(DelegateError::prim(
                path,
                format!("protoIndices has {} entries but there are {} transforms", proto_indices.len(), transforms.len()),
            ));
        }
        if let Some(i) = prototypes.iter().position(String::is_empty) {
            return Err(DelegateError::prim(path, format!("prototypes[{i}] is an empty path")));
        }
        let n = prototypes.len();
        let mut indices = Vec::with_capacity(proto_indices.len());
        for (i, &p) in proto_indices.iter().enumerate() {
            if p < 0 || p as usize >= n {
                return Err(DelegateError::prim(path, format!("protoIndices[{i}] = {p} is out of range for {n} prototypes")));
            }
            indices.push(p as u32);
        }
        if let Some(i) = transforms.iter().position(|m| !m.is_finite()) {
            return Err(DelegateError::prim(path, format!("the transform of instance {i} is not finite")));
        }
        Ok(InstancerData { prototypes, proto_indices: indices, transforms, prototype })
    }

    /// Number of instances.
    pub fn len(&self) -> usize {
        self.proto_indices.len()
    }

    /// True when the instancer places nothing.
    pub fn is_empty(&self) -> bool {
        self.proto_indices.is_empty()
    }
}

/// An instancer prim in the delegate.
#[derive(Clone, Debug)]
pub struct InstancerPrim {
    pub path: String,
    pub data: InstancerData,
    /// Per instance, its transform over the camera's shutter when it moves within it (`None`:
    /// it stays at `data.transforms[i]`); empty when no instance moves. Set by
    /// [`crate::render_delegate::Delegate::set_instancer_motion`], cleared when `data` is set.
    pub motion: Vec<Option<Arc<MotionTransform>>>,
    /// Times the instancer was set: tests count these.
    pub updates: u64,
}

impl InstancerPrim {
    /// Instance `i`'s pose: its motion when it moves, else its transform.
    fn pose(&self, i: usize) -> Pose {
        match self.motion.get(i) {
            Some(Some(m)) => Pose::Moving(m.clone()),
            _ => Pose::Fixed(self.data.transforms[i]),
        }
    }
}

/// Per-instance motion from keys at shared shutter `times` (fractions, 0 = open, 1 = close):
/// `transforms[k * n + i]` is instance `i`'s transform at `times[k]`, `n` the instance count.
/// An instance whose keys are all equal does not move (`None`), so it is placed exactly as
/// without motion; all `None` comes back empty.
///
/// # Errors
/// A size that is not `times.len() × n`, or a time or transform that is not finite; the
/// message names `path`.
pub fn instance_motion(
    path: &str,
    n: usize,
    times: &[f32],
    transforms: &[Mat4],
) -> Result<Vec<Option<Arc<MotionTransform>>>, DelegateError> {
    if times.is_empty() && transforms.is_empty() {
        return Ok(Vec::new());
    }
    if transforms.len() != times.len() * n {
        return Err(DelegateError::prim(path, format!("{} motion transforms for {} times × {n} instances", transforms.len(), times.len())));
    }
    if let Some(t) = times.iter().find(|t| !t.is_finite()) {
        return Err(DelegateError::prim(path, format!("motion time {t} is not finite")));
    }
    if let Some(j) = transforms.iter().position(|m| !m.is_finite()) {
        return Err(DelegateError::prim(
            path,
            format!("the motion transform of instance {} at shutter time {} is not finite", j % n, times[j / n]),
        ));
    }
    let motion: Vec<_> = (0..n)
        .map(|i| {
            let keys = times.iter().enumerate().map(|(k, &time)| MotionKey { time, render_from_object: transforms[k * n + i] });
            MotionTransform::new(keys.collect()).map(Arc::new)
        })
        .collect();
    Ok(if motion.iter().all(Option::is_none) { Vec::new() } else { motion })
}

/// Where one placement puts its prototype during the shutter.
#[derive(Clone, Debug, PartialEq)]
pub enum Pose {
    /// One transform the whole shutter.
    Fixed(Mat4),
    /// A transform that changes within the shutter.
    Moving(Arc<MotionTransform>),
}

impl Pose {
    /// `self × child` (column vectors: `child` first). When either moves the product is keyed
    /// at the union of their key times, each factor interpolated there; between those times the
    /// renderer interpolates the product, which matches the product of the interpolations
    /// exactly for translations and closely for rotations.
    pub fn then(&self, child: &Pose) -> Pose {
        match (self, child) {
            (Pose::Fixed(a), Pose::Fixed(b)) => Pose::Fixed(*a * *b),
            (Pose::Fixed(a), Pose::Moving(m)) => Pose::keyed(m.keys().iter().map(|k| (k.time, *a * k.render_from_object))),
            (Pose::Moving(m), Pose::Fixed(b)) => Pose::keyed(m.keys().iter().map(|k| (k.time, k.render_from_object * *b))),
            (Pose::Moving(a), Pose::Moving(b)) => {
                let mut times: Vec<f32> = a.keys().iter().chain(b.keys()).map(|k| k.time).collect();
                times.sort_by(f32::total_cmp);
                times.dedup();
                Pose::keyed(times.into_iter().map(|t| (t, a.at(t) * b.at(t))))
            }
        }
    }

    /// The pose through `keys`, fixed at the first when they do not move.
    fn keyed(keys: impl Iterator<Item = (f32, Mat4)>) -> Pose {
        let keys: Vec<MotionKey> = keys.map(|(time, render_from_object)| MotionKey { time, render_from_object }).collect();
        let first = keys[0].render_from_object;
        MotionTransform::new(keys).map_or(Pose::Fixed(first), |m| Pose::Moving(Arc::new(m)))
    }
}

/// What a prototype path names, resolved once per instancer rather than once per instance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PrototypeKind {
    Mesh,
    Instancer,
    Missing,
}

/// Checks that every prototype of every instancer exists and that no chain of instancers is
/// deeper than [`MAX_NESTING`]; `is_mesh` says whether the delegate holds a mesh at a path.
/// Instancers with problems still place their valid prototypes.
pub fn check_references(instancers: &BTreeMap<String, InstancerPrim>, is_mesh: &dyn Fn(&str) -> bool) -> Vec<DelegateError> {
    let mut errors = Vec::new();
    for inst in instancers.values() {
        for proto in &inst.data.prototypes {
            if !is_mesh(proto) && !instancers.contains_key(proto) {
                errors.push(DelegateError::prim(
                    &inst.path,
                    format!("prototype {proto} is neither a mesh nor an instancer; its instances are left out"),
                ));
            }
        }
        if nesting_depth(instancers, &inst.path, 0) > MAX_NESTING {
            errors.push(DelegateError::prim(
                &inst.path,
                format!("instancers nest more than {MAX_NESTING} deep (a cycle?); deeper levels are left out"),
            ));
        }
    }
    errors
}

/// How many instancers deep the chain below `path` goes (1 for an instancer of meshes only),
/// stopping just past [`MAX_NESTING`].
fn nesting_depth(instancers: &BTreeMap<String, InstancerPrim>, path: &str, depth: usize) -> usize {
    let Some(inst) = instancers.get(path) else { return depth };
    if depth > MAX_NESTING {
        return depth;
    }
    inst.data
        .prototypes
        .iter()
        .filter(|p| instancers.contains_key(p.as_str()))
        .map(|p| nesting_depth(instancers, p, depth + 1))
        .max()
        .unwrap_or(depth + 1)
        .max(depth + 1)
}

/// Calls `place(mesh_path, pose)` for every mesh placement `inst` makes, nested instancers
/// followed, each pose composed with `parent` (`parent × instance pose`; an instance that moves
/// over the shutter makes every placement below it move). Prototype meshes' own transforms are
/// the caller's to apply.
pub fn expand(
    instancers: &BTreeMap<String, InstancerPrim>,
    inst: &InstancerPrim,
    parent: &Pose,
    is_mesh: &dyn Fn(&str) -> bool,
    place: &mut dyn FnMut(&str, Pose),
) {
    expand_at(instancers, inst, parent, 1, is_mesh, place);
}

fn expand_at(
    instancers: &BTreeMap<String, InstancerPrim>,
    inst: &InstancerPrim,
    parent: &Pose,
    depth: usize,
    is_mesh: &dyn Fn(&str) -> bool,
    place: &mut dyn FnMut(&str, Pose),
) {
    if depth > MAX_NESTING {
        return; // reported by check_references
    }
    let kinds: Vec<(PrototypeKind, Option<&InstancerPrim>)> = inst
        .data
        .prototypes
        .iter()
        .map(|p| match instancers.get(p) {
            Some(child) => (PrototypeKind::Instancer, Some(child)),
            None if is_mesh(p) => (PrototypeKind::Mesh, None),
            None => (PrototypeKind::Missing, None),
        })
        .collect();
    for (i, &pi) in inst.data.proto_indices.iter().enumerate() {
        let pi = pi as usize;
        let world = parent.then(&inst.pose(i));
        match kinds[pi] {
            (PrototypeKind::Mesh, _) => place(&inst.data.prototypes[pi], world),
            (PrototypeKind::Instancer, Some(child)) => expand_at(instancers, child, &world, depth + 1, is_mesh, place),
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    fn prim(path: &str, prototypes: &[&str], indices: &[i32], xs: &[f32], prototype: bool) -> (String, InstancerPrim) {
        let transforms = xs.iter().map(|x| Mat4::from_translation(Vec3::new(*x, 0.0, 0.0))).collect();
        let data =
            InstancerData::new(path, prototypes.iter().map(|s| s.to_string()).collect(), indices, transforms, prototype).expect("valid");
        (path.to_string(), InstancerPrim { path: path.to_string(), data, motion: Vec::new(), updates: 1 })
    }

    #[test]
    fn bad_arrays_name_the_prim() {
        let one = vec![Mat4::IDENTITY];
        let e = InstancerData::new("/pi", vec!["/m".into()], &[1], one.clone(), false).expect_err("invalid").to_string();
        assert_eq!(e, "/pi: protoIndices[0] = 1 is out of range for 1 prototypes");
        let e = InstancerData::new("/pi", vec!["/m".into()], &[-1], one.clone(), false).expect_err("invalid").to_string();
        assert!(e.contains("protoIndices[0] = -1"), "{e}");
        let e = InstancerData::new("/pi", vec!["/m".into()], &[0, 0], one, false).expect_err("invalid").to_string();
        assert!(e.contains("2 entries but there are 1 transforms"), "{e}");
        let nan = vec![Mat4::from_translation(Vec3::new(f32::NAN, 0.0, 0.0))];
        let e = InstancerData::new("/pi", vec!["/m".into()], &[0], nan, false).expect_err("invalid").to_string();
        assert!(e.contains("instance 0 is not finite"), "{e}");
    }

    #[test]
    fn nested_instancers_compose_transforms() {
        let map: BTreeMap<String, InstancerPrim> = [
            prim("/outer", &["/inner", "/m"], &[0, 0, 1], &[10.0, 20.0, 30.0], false),
            prim("/inner", &["/m"], &[0, 0], &[1.0, 2.0], true),
        ]
        .into_iter()
        .collect();
        let is_mesh = |p: &str| p == "/m";
        let mut xs = Vec::new();
        expand(&map, &map["/outer"], &Pose::Fixed(Mat4::IDENTITY), &is_mesh, &mut |p, t| {
            assert_eq!(p, "/m");
            let Pose::Fixed(t) = t else { panic!("nothing moves") };
            xs.push(t.w_axis.x);
        });
        assert_eq!(xs, vec![11.0, 12.0, 21.0, 22.0, 30.0]);
        assert!(check_references(&map, &is_mesh).is_empty());
    }

    #[test]
    fn missing_prototypes_and_cycles_are_reported_not_followed() {
        let map: BTreeMap<String, InstancerPrim> =
            [prim("/a", &["/b", "/gone"], &[0, 1], &[1.0, 2.0], false), prim("/b", &["/a"], &[0], &[1.0], true)].into_iter().collect();
        let is_mesh = |_: &str| false;
        let errors: Vec<String> = check_references(&map, &is_mesh).iter().map(ToString::to_string).collect();
        assert!(errors.iter().any(|e| e.starts_with("/a: prototype /gone")), "{errors:?}");
        assert!(errors.iter().any(|e| e.contains("nest more than")), "{errors:?}");
        let mut n = 0;
        expand(&map, &map["/a"], &Pose::Fixed(Mat4::IDENTITY), &is_mesh, &mut |_, _| n += 1);
        assert_eq!(n, 0);
    }

    fn slide(x0: f32, x1: f32) -> Vec<Mat4> {
        vec![Mat4::from_translation(Vec3::new(x0, 0.0, 0.0)), Mat4::from_translation(Vec3::new(x1, 0.0, 0.0))]
    }

    #[test]
    fn instance_motion_keeps_still_instances_fixed_and_checks_sizes() {
        let still = Mat4::from_translation(Vec3::new(5.0, 0.0, 0.0));
        // Time-major: [t0: i0, i1], [t1: i0, i1].
        let a = slide(0.0, 2.0);
        let m = instance_motion("/pi", 2, &[0.0, 1.0], &[a[0], still, a[1], still]).expect("valid");
        assert!(m[0].is_some() && m[1].is_none());
        assert!(instance_motion("/pi", 2, &[0.0, 1.0], &[still; 4]).expect("valid").is_empty());
        assert!(instance_motion("/pi", 2, &[], &[]).expect("valid").is_empty());
        let e = instance_motion("/pi", 2, &[0.0, 1.0], &[still; 3]).expect_err("sizes").to_string();
        assert_eq!(e, "/pi: 3 motion transforms for 2 times × 2 instances");
        let nan = Mat4::from_translation(Vec3::new(f32::NAN, 0.0, 0.0));
        let e = instance_motion("/pi", 2, &[0.0, 1.0], &[still, still, still, nan]).expect_err("nan").to_string();
        assert!(e.starts_with("/pi: the motion transform of instance 1 at shutter time 1"), "{e}");
    }

    /// A moving instancer placing a moving nested instancer: the placement at any time is the
    /// product of both poses there (translations add exactly), and a still instance of a
    /// still instancer stays `Fixed` with the very matrix the static path makes.
    #[test]
    fn nested_motion_composes_over_the_shutter() {
        let mut map: BTreeMap<String, InstancerPrim> =
            [prim("/outer", &["/inner", "/m"], &[0, 1], &[10.0, 30.0], false), prim("/inner", &["/m"], &[0], &[1.0], true)]
                .into_iter()
                .collect();
        let (o, i) = (slide(10.0, 12.0), slide(1.0, 0.0));
        let outer = map.get_mut("/outer").expect("outer");
        let thirty = outer.data.transforms[1];
        outer.motion = instance_motion("/outer", 2, &[0.0, 1.0], &[o[0], thirty, o[1], thirty]).expect("valid");
        let inner = map.get_mut("/inner").expect("inner");
        inner.motion = instance_motion("/inner", 1, &[0.0, 0.5], &i).expect("valid");
        let is_mesh = |p: &str| p == "/m";
        let mut poses = Vec::new();
        expand(&map, &map["/outer"], &Pose::Fixed(Mat4::IDENTITY), &is_mesh, &mut |_, pose| poses.push(pose));
        assert_eq!(poses[1], Pose::Fixed(Mat4::IDENTITY * thirty));
        let Pose::Moving(m) = &poses[0] else { panic!("the nested placement moves") };
        for k in 0..=20 {
            let t = k as f32 / 20.0;
            // outer: 10 → 12 over [0, 1]; inner: 1 → 0 over [0, 0.5], then held.
            let want = 10.0 + 2.0 * t + (1.0 - (t / 0.5).min(1.0));
            assert!((m.at(t).w_axis.x - want).abs() < 1e-5, "t {t}: {} vs {want}", m.at(t).w_axis.x);
        }
    }
}
