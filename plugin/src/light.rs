//! Light Sprims (UsdLux): distant, sphere, rect, disk, cylinder and dome lights; and emissive
//! meshes (`MeshLightAPI`, `GeometryLight`), which are mesh Rprims whose surface becomes a light
//! ([`mesh_light`]).

use glam::{Mat4, Vec3A};
use mipray::light::{Light, LightShape};

/// The inputs every UsdLux light has (for a distant light, all of them).
#[derive(Clone, Debug, PartialEq)]
pub struct DistantLightData {
    /// Light-to-world (column-vector convention); the light travels along its local −Z.
    pub transform: Mat4,
    pub intensity: f32,
    pub exposure: f32,
    pub color: [f32; 3],
    pub angle_deg: f32,
    pub normalize: bool,
    pub shadow_enable: bool,
}

/// The shape of a non-distant light, in the light's own space (UsdLux: sizes in the light's
/// units, emission along −Z for rect and disk lights).
#[derive(Clone, Debug, PartialEq)]
pub enum AreaKind {
    Sphere {
        radius: f32,
    },
    /// With the resolved path of its `texture:file`, if any.
    Rect {
        width: f32,
        height: f32,
        texture: Option<String>,
    },
    Disk {
        radius: f32,
    },
    /// A tube along the light's X axis, without end caps.
    Cylinder {
        radius: f32,
        length: f32,
    },
    /// An environment: constant radiance, or a latlong texture (resolved file path). `portals`:
    /// the PortalLight prims its `portals` relationship names (`None`: not authored, and every
    /// portal of the scene guides it).
    Dome {
        texture: Option<String>,
        portals: Option<Vec<String>>,
    },
    /// A UsdLux.PortalLight: a `width` × `height` rect in the light's XY plane passing a dome's
    /// light along its −Z. Not a light itself: it guides the domes' sampling
    /// ([`scene_lights`], [`mipray::light::Portal`]).
    Portal {
        width: f32,
        height: f32,
    },
}

/// UsdLux `ShapingAPI` inputs (sphere, rect and disk lights; see [`mipray::light::Shaping`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ShapingData {
    pub cone_angle_deg: f32,
    pub cone_softness: f32,
    pub focus: f32,
    pub focus_tint: [f32; 3],
    /// `shaping:ies:*`, when a file is authored.
    pub ies: Option<IesData>,
}

/// A light's IES profile: the file as read when the light was set (or why it could not be),
/// `ies:angleScale` and `ies:normalize`.
#[derive(Clone, Debug, PartialEq)]
pub struct IesData {
    pub file: String,
    pub profile: Result<mipray::light::IesProfile, String>,
    pub angle_scale: f32,
    pub normalize: bool,
    /// Render space's down (unit; the stage's up axis negated): a tilt table is read at the
    /// angle between the light's aim and it.
    pub down: [f32; 3],
    /// `mipray:iesProfileSampling`: directions drawn by the profile
    /// ([`mipray::light::Light::profile_sampling`]).
    pub profile_sampling: bool,
}

impl IesData {
    /// Reads and parses `file` (an error is kept, to be warned about when the light is used);
    /// a `TILT=<name>` file is read beside it.
    pub fn read(file: &str, angle_scale: f32, normalize: bool, down: [f32; 3]) -> IesData {
        let dir = std::path::Path::new(file).parent().map(std::path::Path::to_path_buf).unwrap_or_default();
        let tilt_file = |name: &str| -> Result<String, String> {
            std::fs::read(dir.join(name)).map(|b| String::from_utf8_lossy(&b).into_owned()).map_err(|e| e.to_string())
        };
        let profile = std::fs::read(file)
            .map_err(|e| e.to_string())
            .and_then(|bytes| mipray::light::IesProfile::parse_with(&String::from_utf8_lossy(&bytes), &tilt_file));
        IesData { file: file.to_string(), profile, angle_scale, normalize, down, profile_sampling: false }
    }
}

/// Lights and files already warned about: a bad IES file or a light texture that cannot be
/// read is named once, not at every render (each render converts the lights again).
static WARNED: std::sync::Mutex<std::collections::BTreeSet<(String, String)>> = std::sync::Mutex::new(std::collections::BTreeSet::new());

/// Light and shadow linking, resolved by the scene delegate: the mesh prims (paths) a light's
/// `collection:lightLink` leaves out, and those its `collection:shadowLink` leaves out.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LinkData {
    pub unlit: Vec<String>,
    pub no_shadow: Vec<String>,
}

/// A light prim.
#[derive(Clone, Debug, PartialEq)]
pub struct LightPrim {
    pub path: String,
    pub data: DistantLightData,
    /// `None`: a distant light.
    pub area: Option<AreaKind>,
    pub shaping: Option<ShapingData>,
    pub links: LinkData,
}

impl LightPrim {
    /// The core's light. Non-finite inputs are the scene delegate's to refuse; here they are
    /// zeroed so nothing non-finite can reach the film.
    pub fn to_light(&self) -> Light {
        self.to_light_with(None)
    }

    /// As [`LightPrim::to_light`], with the texture system a dome texture is read through
    /// (without one, or when the file cannot be read, the dome is its constant colour).
    pub fn to_light_with(&self, textures: Option<&std::sync::Arc<dyn mipray::texture::TextureSampler>>) -> Light {
        let d = &self.data;
        let f = |x: f32| if x.is_finite() { x } else { 0.0 };
        let color = Vec3A::from(d.color.map(f));
        let m = &d.transform;
        let mut l = match &self.area {
            None => Light::usd_distant(&self.path, m, f(d.intensity), f(d.exposure), color, f(d.angle_deg), d.normalize),
            Some(kind) => {
                let center = m.transform_point3a(Vec3A::ZERO);
                let normal = m.transform_vector3a(Vec3A::NEG_Z).normalize_or(Vec3A::NEG_Z);
                let shape = match kind.clone() {
                    AreaKind::Sphere { radius } => {
                        // A sphere stays a sphere under the light's mean scale.
                        let s = (m.transform_vector3a(Vec3A::X).length()
                            + m.transform_vector3a(Vec3A::Y).length()
                            + m.transform_vector3a(Vec3A::Z).length())
                            / 3.0;
                        LightShape::Sphere { center, radius: f(radius) * s }
                    }
                    AreaKind::Rect { width, height, .. } => LightShape::Rect {
                        center,
                        u: m.transform_vector3a(Vec3A::X * (f(width) * 0.5)),
                        v: m.transform_vector3a(Vec3A::Y * (f(height) * 0.5)),
                        normal,
                    },
                    AreaKind::Disk { radius } => LightShape::Disk {
                        center,
                        u: m.transform_vector3a(Vec3A::X * f(radius)),
                        v: m.transform_vector3a(Vec3A::Y * f(radius)),
                        normal,
                    },
                    AreaKind::Cylinder { radius, length } => {
                        // The tube stays round under the mean of the light's Y and Z scales.
                        let axis = m.transform_vector3a(Vec3A::X * (f(length) * 0.5));
                        let s = (m.transform_vector3a(Vec3A::Y).length() + m.transform_vector3a(Vec3A::Z).length()) / 2.0;
                        let (e1, e2) = axis.normalize_or(Vec3A::X).any_orthonormal_pair();
                        LightShape::Cylinder { center, axis, radius: f(radius) * s, e1, e2 }
                    }
                    // Not a light: a dark rect for callers that ask anyway ([`scene_lights`]
                    // leaves portals out of the scene's lights).
                    AreaKind::Portal { .. } => LightShape::Rect { center, u: Vec3A::ZERO, v: Vec3A::ZERO, normal },
                    AreaKind::Dome { texture, .. } => {
                        let env = texture.as_ref().zip(textures).and_then(|(file, sampler)| {
                            match sampler.handle_encoded(file, mipray::texture::SourceColorSpace::Auto) {
                                // The light's rotation only: directions, and densities over them, must
                                // not be distorted by a scale.
                                Ok(handle) => Some(mipray::light::EnvTexture::new(
                                    sampler.clone(),
                                    handle,
                                    glam::Mat3A::from_quat(m.to_scale_rotation_translation().1),
                                )),
                                Err(e) => {
                                    let mut warned = WARNED.lock().unwrap_or_else(|p| p.into_inner());
                                    if warned.insert((self.path.clone(), file.clone())) {
                                        log::warn!(
                                            "{}: cannot read dome texture {file}: {}; lighting with its colour",
                                            self.path,
                                            e.message
                                        );
                                    }
                                    None
                                }
                            }
                        });
                        LightShape::Dome(env)
                    }
                };
                let color = if matches!(kind, AreaKind::Portal { .. }) { Vec3A::ZERO } else { color };
                Light::usd_area(&self.path, shape, f(d.intensity), f(d.exposure), color, d.normalize)
            }
        };
        l.casts_shadows = d.shadow_enable;
        if let (Some(AreaKind::Rect { texture: Some(file), .. }), Some(sampler)) = (&self.area, textures) {
            match sampler.handle_encoded(file, mipray::texture::SourceColorSpace::Auto) {
                Ok(texture) => l.texture = Some(mipray::light::RectTexture { sampler: sampler.clone(), texture }),
                Err(e) => {
                    let mut warned = WARNED.lock().unwrap_or_else(|p| p.into_inner());
                    if warned.insert((self.path.clone(), file.clone())) {
                        log::warn!("{}: cannot read rect light texture {file}: {}; lighting with its colour", self.path, e.message);
                    }
                }
            }
        }
        if let (Some(sh), Some(AreaKind::Sphere { .. } | AreaKind::Rect { .. } | AreaKind::Disk { .. } | AreaKind::Cylinder { .. })) =
            (&self.shaping, &self.area)
        {
            let axis = m.transform_vector3a(Vec3A::NEG_Z);
            l.shaping = mipray::light::Shaping::new(axis, sh.cone_angle_deg, sh.cone_softness, sh.focus, Vec3A::from(sh.focus_tint.map(f)));
            match sh.ies.as_ref().map(|ies| (ies, &ies.profile)) {
                Some((ies, Ok(profile))) => {
                    if profile.kind != mipray::light::Photometry::C && ies.angle_scale != 0.0 {
                        let mut warned = WARNED.lock().unwrap_or_else(|p| p.into_inner());
                        if warned.insert((self.path.clone(), format!("{} angleScale", ies.file))) {
                            log::warn!(
                                "{}: ies:angleScale applies to type C profiles only; {} is type {:?}, rendered unscaled",
                                self.path,
                                ies.file,
                                profile.kind
                            );
                        }
                    }
                    let down = Vec3A::from(ies.down).normalize_or(Vec3A::NEG_Y);
                    let aim = axis.normalize_or(Vec3A::NEG_Z);
                    let x = m.transform_vector3a(Vec3A::X).normalize_or(Vec3A::X);
                    // LM-63's lamp-to-luminaire geometry says which tilt the table is read at.
                    let tilt = profile.tilt.as_ref().map_or(0.0, |t| t.tilt_angle(aim, x, down));
                    let shaping = mipray::light::IesShaping {
                        profile: profile.clone(),
                        file: ies.file.clone(),
                        // UsdLux: the scale must stay above −1 (1 + s divides θ).
                        angle_scale: if ies.angle_scale.is_finite() { ies.angle_scale.max(-0.99) } else { 0.0 },
                        normalize: ies.normalize,
                        x,
                        y: m.transform_vector3a(Vec3A::Y).normalize_or(Vec3A::Y),
                        tilt,
                    };
                    l.shaping = Some(mipray::light::Shaping::with_ies(l.shaping.take(), axis, shaping));
                    l.profile_sampling = ies.profile_sampling;
                }
                Some((ies, Err(e))) => {
                    let mut warned = WARNED.lock().unwrap_or_else(|p| p.into_inner());
                    if warned.insert((self.path.clone(), ies.file.clone())) {
                        log::warn!("{}: cannot read IES profile {}: {e}; the light renders without it", self.path, ies.file);
                    }
                }
                None => {}
            }
        }
        l
    }

    /// As [`LightPrim::to_light_with`], with the links resolved to core meshes: `mesh_index`
    /// gives a mesh prim's index in the scene (`None`: not in it).
    pub fn to_scene_light(
        &self,
        textures: Option<&std::sync::Arc<dyn mipray::texture::TextureSampler>>,
        mesh_index: &dyn Fn(&str) -> Option<usize>,
    ) -> Light {
        let mut l = self.to_light_with(textures);
        let resolve =
            |paths: &[String]| mipray::light::MeshFilter::excluding(paths.iter().filter_map(|p| mesh_index(p)).map(|i| i as u32).collect());
        l.illuminates = resolve(&self.links.unlit);
        l.shadowed_by = resolve(&self.links.no_shadow);
        l
    }
}

impl LightPrim {
    /// A PortalLight's portal in render space; `None` for every other light (and a degenerate
    /// portal).
    pub fn portal(&self) -> Option<mipray::light::Portal> {
        let Some(AreaKind::Portal { width, height }) = self.area else { return None };
        let m = &self.data.transform;
        let u = m.transform_vector3a(Vec3A::X * (width * 0.5));
        let v = m.transform_vector3a(Vec3A::Y * (height * 0.5));
        // The plane's normal (a sheared transform's −Z need not be perpendicular to it), on
        // the side of the light's −Z.
        let mut normal = u.cross(v).normalize_or_zero();
        if !(normal.dot(m.transform_vector3a(Vec3A::NEG_Z)) > 0.0) {
            normal = -normal;
        }
        let center = m.transform_point3a(Vec3A::ZERO);
        (normal != Vec3A::ZERO && (center + u + v).is_finite()).then(|| mipray::light::Portal {
            name: self.path.clone(),
            center,
            u,
            v,
            normal,
        })
    }
}

/// Portal and dome pairs already warned about.
static PORTALS_WARNED: std::sync::Mutex<std::collections::BTreeSet<(String, String)>> =
    std::sync::Mutex::new(std::collections::BTreeSet::new());

fn warn_portal_once(a: &str, b: &str, message: std::fmt::Arguments<'_>) {
    let mut warned = PORTALS_WARNED.lock().unwrap_or_else(|p| p.into_inner());
    if warned.insert((a.to_string(), b.to_string())) {
        log::warn!("{message}");
    }
}

/// The scene's lights from its light prims ([`LightPrim::to_scene_light`]): PortalLights are
/// not lights but guide the domes: each dome gets the portals its `portals` relationship names,
/// or, when that is not authored, every portal of the scene. A portal no dome uses, and a
/// `portals` target that is no PortalLight of the scene, are named in one warning each.
pub fn scene_lights<'a>(
    prims: impl Iterator<Item = &'a LightPrim>,
    textures: Option<&std::sync::Arc<dyn mipray::texture::TextureSampler>>,
    mesh_index: &dyn Fn(&str) -> Option<usize>,
) -> Vec<Light> {
    let prims: Vec<&LightPrim> = prims.collect();
    let portals: std::collections::BTreeMap<&str, mipray::light::Portal> =
        prims.iter().filter_map(|l| l.portal().map(|p| (l.path.as_str(), p))).collect();
    let mut used = std::collections::BTreeSet::new();
    let mut out = Vec::new();
    for prim in prims.iter().filter(|l| !matches!(l.area, Some(AreaKind::Portal { .. }))) {
        let mut light = prim.to_scene_light(textures, mesh_index);
        if let Some(AreaKind::Dome { portals: named, .. }) = &prim.area {
            let chosen: Vec<mipray::light::Portal> = match named {
                None => portals.values().cloned().collect(),
                Some(paths) => paths
                    .iter()
                    .filter_map(|p| {
                        let found = portals.get(p.as_str()).cloned();
                        if found.is_none() {
                            warn_portal_once(
                                &prim.path,
                                p,
                                format_args!(
                                    "{}: portals target {p} is not a PortalLight of the scene; it does not guide the dome",
                                    prim.path
                                ),
                            );
                        }
                        found
                    })
                    .collect(),
            };
            used.extend(chosen.iter().map(|p| p.name.clone()));
            light.portals = chosen.into();
        }
        out.push(light);
    }
    for path in portals.keys().filter(|p| !used.contains(**p)) {
        warn_portal_once(
            path,
            "",
            format_args!("{path}: PortalLight guides no dome light (none on the stage names it or takes every portal)"),
        );
    }
    out
}

/// A mesh's light inputs (UsdLux `MeshLightAPI` on it, or a `GeometryLight` naming it): what
/// every light has but a transform and a shape, which are the mesh's.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshLightData {
    pub intensity: f32,
    pub exposure: f32,
    /// Linear RGB, the colour temperature folded in.
    pub color: [f32; 3],
    pub normalize: bool,
    pub shadow_enable: bool,
    pub links: LinkData,
    /// UsdLux `materialGlowTintsLight` with a bound material mipray reads: the material's
    /// `emissiveColor` multiplies `color` (the USD front end decides, `material_tint`) on the
    /// faces no GeomSubset in `tint_materials` binds.
    pub tint: bool,
    /// Under `materialGlowTintsLight`, the GeomSubsets' materials (among the mesh's face
    /// materials, by name) whose `emissiveColor` tints their own faces.
    pub tint_materials: Vec<String>,
}

/// What an emissive mesh's faces emit, as a factor of its light's colour (UsdLux
/// `materialGlowTintsLight`).
#[derive(Clone, Debug, PartialEq)]
pub enum MeshEmitters {
    /// Every face the same (1 without a tinting material).
    Uniform(Vec3A),
    /// Per control face (USD face order), an index into `emitters`; textures read the
    /// surface's 2-float primvar channel `st_channel` (`None`: the mesh has no `st`).
    PerFace { emitters: Vec<mipray::light::Emitter>, per_face: Vec<u32>, st_channel: Option<usize> },
}

/// Vertices per side of the grid each patch of an emissive subdivision surface (or gprim) is
/// tessellated at for lighting: 4×4 quads, 32 triangles a patch. A polygonal mesh's patches are
/// its faces, flat or bilinear, taken at their corners (2 triangles a quad).
pub const MESH_LIGHT_GRID: usize = 5;

/// The render-space triangles of `surface` placed by `transform` (object to render, column
/// vectors), oriented so their right-hand normals point out of the front face: USD's
/// right-handed winding, flipped for `left_handed` and for a transform that mirrors.
pub fn light_triangles(surface: &dyn mipray::patch::LimitSurface, transform: &Mat4, left_handed: bool, grid: usize) -> Vec<[Vec3A; 3]> {
    tessellate_light(surface, transform, left_handed, grid, None).0
}

/// The triangles of [`light_triangles`] with, per triangle, its control face and (when
/// `st_channel` is given and the surface has it) the 2-float primvar at its vertices.
#[allow(clippy::type_complexity)]
fn tessellate_light(
    surface: &dyn mipray::patch::LimitSurface,
    transform: &Mat4,
    left_handed: bool,
    grid: usize,
    st_channel: Option<usize>,
) -> (Vec<[Vec3A; 3]>, Vec<u32>, Vec<[[f32; 2]; 3]>) {
    let n = grid.max(2);
    let flip = left_handed != (transform.determinant() < 0.0);
    let mut out = Vec::with_capacity(surface.patch_count() * 2 * (n - 1) * (n - 1));
    let mut faces = Vec::with_capacity(out.capacity());
    let mut st = Vec::new();
    let mut g = mipray::patch::GridSamples::default();
    let rect = mipray::patch::UvRect::UNIT;
    for patch in 0..surface.patch_count() {
        surface.evaluate_grid(patch, rect, n, false, &mut g);
        let face = surface.patch_param(patch).base_face;
        let at = |i: usize, j: usize| transform.transform_point3a(Vec3A::from(g.p[j * n + i]));
        let st_at = |i: usize, j: usize| {
            let (u, v) = rect.grid_uv(i, j, n);
            st_channel.and_then(|c| surface.face_varying(c, patch, u, v)).map(|(x, ..)| x)
        };
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let (p00, p10, p11, p01) = (at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1));
                let corners = [st_at(i, j), st_at(i + 1, j), st_at(i + 1, j + 1), st_at(i, j + 1)];
                // u then v: dP/du × dP/dv is the patch's front normal.
                for (t, k) in [([p00, p10, p11], [0, 1, 2]), ([p00, p11, p01], [0, 2, 3])] {
                    let k = if flip { [k[0], k[2], k[1]] } else { k };
                    out.push(if flip { [t[0], t[2], t[1]] } else { t });
                    faces.push(face);
                    if let [Some(a), Some(b), Some(c)] = k.map(|x| corners[x]) {
                        st.push([a, b, c]);
                    }
                }
            }
        }
    }
    if st.len() != out.len() {
        st.clear();
    }
    (out, faces, st)
}

/// The core light an emissive mesh `name` makes: its surface's triangles ([`light_triangles`],
/// polygonal meshes at their corners, others at [`MESH_LIGHT_GRID`]) emitting
/// `emitters · color · intensity · 2^exposure` as radiance from their front (both sides when
/// `double_sided`), divided by their area with `normalize` (UsdLux; `emitters` are the bound
/// materials' emission under `materialGlowTintsLight`, per face, else 1). `transform` places
/// it (object to render); with `motion` it moves instead
/// ([`mipray::light::TriangleLight::moving`]: `transform` is then ignored and the emission
/// follows each ray's time). `None` when the surface has no area.
#[allow(clippy::too_many_arguments)]
pub fn mesh_light(
    name: &str,
    light: &MeshLightData,
    emitters: &MeshEmitters,
    surface: &dyn mipray::patch::LimitSurface,
    polygonal: bool,
    transform: &Mat4,
    motion: Option<&mipray::motion::MotionTransform>,
    left_handed: bool,
    double_sided: bool,
) -> Option<Light> {
    let grid = if polygonal { 2 } else { MESH_LIGHT_GRID };
    let f = |x: f32| if x.is_finite() { x } else { 0.0 };
    let place = if motion.is_some() { Mat4::IDENTITY } else { *transform };
    // A deforming mesh: its triangles at every sample (one topology, so the same triangles in
    // the same order), blended at each ray's time as its geometry is.
    let deformed = |tris0: Vec<[Vec3A; 3]>| -> Option<Vec<(f32, Vec<[Vec3A; 3]>)>> {
        let d = surface.deformation()?;
        let mut out: Vec<(f32, Vec<[Vec3A; 3]>)> = vec![(d.times()[0], tris0)];
        for (k, &t) in d.times().iter().enumerate().skip(1) {
            out.push((t, light_triangles(d.sample(k), &place, left_handed, grid)));
        }
        Some(out)
    };
    let (tris, tint) = match emitters {
        MeshEmitters::Uniform(tint) => {
            let first = surface.deformation().map_or(surface, |d| d.sample(0));
            let tris = light_triangles(first, &place, left_handed, grid);
            let tris = match (deformed(tris.clone()), motion) {
                (Some(samples), _) => mipray::light::TriangleLight::deforming(samples, double_sided, motion.cloned(), None)?,
                (None, Some(motion)) => mipray::light::TriangleLight::moving(tris, double_sided, motion.clone())?,
                (None, None) => mipray::light::TriangleLight::new(tris, double_sided)?,
            };
            (tris, Vec3A::from(tint.to_array().map(|x| f(x).max(0.0))))
        }
        MeshEmitters::PerFace { emitters, per_face, st_channel } => {
            let first = surface.deformation().map_or(surface, |d| d.sample(0));
            let (tris, faces, st) = tessellate_light(first, &place, left_handed, grid, *st_channel);
            let per_triangle = faces.iter().map(|&face| per_face.get(face as usize).copied().unwrap_or(u32::MAX)).collect();
            let emission = mipray::light::MeshEmission { emitters: emitters.clone(), per_triangle, st };
            let light = match deformed(tris.clone()) {
                Some(samples) => mipray::light::TriangleLight::deforming(samples, double_sided, motion.cloned(), Some(emission))?,
                None => mipray::light::TriangleLight::with_emission(tris, double_sided, motion.cloned(), emission)?,
            };
            (light, Vec3A::ONE)
        }
    };
    let color = Vec3A::from(light.color.map(f)) * tint;
    let mut l = Light::usd_area(name, LightShape::Mesh(tris), f(light.intensity), f(light.exposure), color, light.normalize);
    l.casts_shadows = light.shadow_enable;
    Some(l)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prim(path: &str, transform: Mat4, area: AreaKind) -> LightPrim {
        LightPrim {
            path: path.into(),
            data: DistantLightData {
                transform,
                intensity: 1.0,
                exposure: 0.0,
                color: [1.0; 3],
                angle_deg: 0.0,
                normalize: false,
                shadow_enable: true,
            },
            area: Some(area),
            shaping: None,
            links: LinkData::default(),
        }
    }

    #[test]
    fn portals_attach_to_the_domes_that_take_them_and_are_no_lights() {
        // A 2 × 1 window at height 3, scaled by 2 along X, rotated 90° about Z: its X axis
        // becomes +Y, its −Z stays down.
        let m = Mat4::from_translation(glam::Vec3::new(0.0, 0.0, 3.0))
            * Mat4::from_rotation_z(std::f32::consts::FRAC_PI_2)
            * Mat4::from_scale(glam::Vec3::new(2.0, 1.0, 1.0));
        let window = prim("/Window", m, AreaKind::Portal { width: 2.0, height: 1.0 });
        let all = prim("/Sky", Mat4::IDENTITY, AreaKind::Dome { texture: None, portals: None });
        let none = prim("/Other", Mat4::IDENTITY, AreaKind::Dome { texture: None, portals: Some(vec!["/Missing".into()]) });
        let lights = scene_lights([&window, &all, &none].into_iter(), None, &|_| None);
        let names: Vec<&str> = lights.iter().map(|l| l.name.as_str()).collect();
        assert_eq!(names, ["/Sky", "/Other"]);
        let p = &lights[0].portals[0];
        assert_eq!(p.name, "/Window");
        // 2 × 2 (scaled) by 1.
        assert!((p.area() - 4.0).abs() < 1e-4, "{}", p.area());
        assert!((p.normal - Vec3A::NEG_Z).length() < 1e-5 && (p.center - Vec3A::new(0.0, 0.0, 3.0)).length() < 1e-5);
        assert!((p.u - Vec3A::new(0.0, 2.0, 0.0)).length() < 1e-5, "{}", p.u);
        assert!(lights[1].portals.is_empty());
        // A mirroring transform keeps the light's −Z as the way light passes.
        let flipped = prim("/W2", Mat4::from_scale(glam::Vec3::new(-1.0, 1.0, 1.0)), AreaKind::Portal { width: 1.0, height: 1.0 });
        assert!((flipped.portal().unwrap().normal - Vec3A::NEG_Z).length() < 1e-6);
    }
}
