//! Light Sprims (UsdLux): distant, sphere, rect, disk, cylinder and dome lights.

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
    /// An environment: constant radiance, or a latlong texture (resolved file path).
    Dome {
        texture: Option<String>,
    },
}

/// UsdLux `ShapingAPI` inputs (sphere, rect and disk lights; see [`mipray::light::Shaping`]).
#[derive(Clone, Debug, PartialEq)]
pub struct ShapingData {
    pub cone_angle_deg: f32,
    pub cone_softness: f32,
    pub focus: f32,
    pub focus_tint: [f32; 3],
}

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
                    AreaKind::Dome { texture } => {
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
                                    log::warn!("{}: cannot read dome texture {file}: {}; lighting with its colour", self.path, e.message);
                                    None
                                }
                            }
                        });
                        LightShape::Dome(env)
                    }
                };
                Light::usd_area(&self.path, shape, f(d.intensity), f(d.exposure), color, d.normalize)
            }
        };
        l.casts_shadows = d.shadow_enable;
        if let (Some(AreaKind::Rect { texture: Some(file), .. }), Some(sampler)) = (&self.area, textures) {
            match sampler.handle_encoded(file, mipray::texture::SourceColorSpace::Auto) {
                Ok(texture) => l.texture = Some(mipray::light::RectTexture { sampler: sampler.clone(), texture }),
                Err(e) => log::warn!("{}: cannot read rect light texture {file}: {}; lighting with its colour", self.path, e.message),
            }
        }
        if let (Some(sh), Some(AreaKind::Sphere { .. } | AreaKind::Rect { .. } | AreaKind::Disk { .. } | AreaKind::Cylinder { .. })) =
            (&self.shaping, &self.area)
        {
            let axis = m.transform_vector3a(Vec3A::NEG_Z);
            l.shaping = mipray::light::Shaping::new(axis, sh.cone_angle_deg, sh.cone_softness, sh.focus, Vec3A::from(sh.focus_tint.map(f)));
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
