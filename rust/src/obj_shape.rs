//! OpenSubdiv's regression shapes: OBJ files with `t` tags (creases, corners, holes, boundary
//! rules), read into a [`MeshTopology`] so that the bridge's patches can be compared with
//! OpenSubdiv's own results over the corpus OpenSubdiv itself regresses against.
//!
//! The reading follows OpenSubdiv's `regression/common/shape_utils.cpp` (`Shape::parseObj`) and
//! `far_utils.h` (`GetSdcOptions`, `assignComponentTags`), so a shape means here what it means to
//! OpenSubdiv:
//! - the scheme comes from the name's prefix (`catmark_`, `loop_`, `bilinear_`), as the
//!   regression drivers register them; failing that, from the `# ... scheme: X` header line;
//! - `t interpolateboundary 1/0/0 N`: 0 none, **1 edge-and-corner, 2 edge-only** (RenderMan's
//!   numbering, which `GetSdcOptions` follows); with no tag, edge-only (`GetSdcOptions`' default);
//! - `t facevaryinginterpolateboundary 1/0/0 N`: 0 none … 5 all, in `Sdc::Options` order; with no
//!   tag, all (`Sdc::Options`' default);
//! - `t smoothtriangles 0/0/1 catmark|smooth`, `t creasemethod 0/0/1 normal|chaikin`;
//! - `t crease 2/1/0 A B S`, `t corner 1/1/0 V S`, `t hole N/0/0 F…`;
//! - hierarchical edits (`vertexedit`, `edgeedit`, `faceedit`, or `hedit` in the name) are
//!   recorded in [`ObjShape::has_hierarchical_edits`]: OpenSubdiv 3 dropped them, and so does
//!   mipray, so callers refuse such shapes as "not supported".
//!
//! Left-handed shapes: OpenSubdiv's drivers flag `catmark_lefthanded` by name; here a name
//! containing `lefthanded` sets [`MeshTopology::left_handed`] (USD's `orientation`).

use crate::error::MeshError;
use crate::topology::{BoundaryInterpolation, FaceVaryingInterpolation, MeshTopology, Scheme, TriangleSubdivision};

/// How crease sharpness decays under subdivision (`Sdc::Options::CreasingMethod`).
///
/// USD's `UsdGeom.Mesh` has no such attribute, so [`MeshTopology`] cannot carry it: a shape that
/// asks for Chaikin creasing is evaluated with uniform creasing unless the caller refuses it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum CreaseMethod {
    /// `creasemethod normal`: sharpness decreases by 1 per level (OpenSubdiv's default).
    #[default]
    Uniform,
    /// `creasemethod chaikin`: sharpness along a crease chain is averaged (Chaikin's rule).
    Chaikin,
}

/// One regression shape, ready for a patch source.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ObjShape {
    /// The shape's name (the file stem, e.g. `catmark_cube_creases0`).
    pub name: String,
    /// The scheme the shape is meant for (also in `topology.scheme`).
    pub scheme: Scheme,
    /// Faces, creases, corners, holes and boundary rules, in USD's terms.
    pub topology: MeshTopology,
    /// Vertex positions (`v`), in the file's units (OpenSubdiv's shapes say centimeters).
    pub points: Vec<[f32; 3]>,
    /// Texture coordinates (`vt`), (u, v).
    pub uvs: Vec<[f32; 2]>,
    /// Per face-vertex index into `uvs`, parallel to `topology.face_vertex_indices`; empty when
    /// the faces carry no `vt` indices (or only some of them do).
    pub uv_indices: Vec<i32>,
    /// `creasemethod`: not representable in [`MeshTopology`] (see [`CreaseMethod`]).
    pub crease_method: CreaseMethod,
    /// The shape uses hierarchical edits, which mipray does not implement: refuse it.
    pub has_hierarchical_edits: bool,
    /// Tags that were read but have no effect here (e.g. `facevaryingpropagatecorners`), as
    /// `name` strings, so a caller can say what was ignored.
    pub ignored_tags: Vec<String>,
}

impl ObjShape {
    /// The refusal a caller should return for a shape with hierarchical edits, or `Ok`.
    ///
    /// # Errors
    /// [`MeshError::Unsupported`] naming the shape when it has hierarchical edits.
    pub fn check_supported(&self) -> Result<(), MeshError> {
        if self.has_hierarchical_edits {
            return Err(MeshError::Unsupported(format!("{}: hierarchical edits (OpenSubdiv 2 `hedit` tags) are not supported", self.name)));
        }
        Ok(())
    }
}

/// The scheme OpenSubdiv's regression drivers give a shape, from its name's prefix.
pub fn scheme_from_name(name: &str) -> Option<Scheme> {
    let stem = name.rsplit(['/', '\\']).next().unwrap_or(name);
    if stem.starts_with("catmark_") {
        Some(Scheme::CatmullClark)
    } else if stem.starts_with("loop_") {
        Some(Scheme::Loop)
    } else if stem.starts_with("bilinear_") {
        Some(Scheme::Bilinear)
    } else {
        None
    }
}

/// One `t` tag, split as OpenSubdiv's `Shape::tag::parseTag` splits it.
struct Tag<'a> {
    name: &'a str,
    ints: Vec<i64>,
    floats: Vec<f32>,
    strings: Vec<&'a str>,
}

fn parse_tag<'a>(rest: &'a str, err: &dyn Fn(String) -> MeshError) -> Result<Tag<'a>, MeshError> {
    let mut it = rest.split_whitespace();
    let name = it.next().ok_or_else(|| err("tag without a name".into()))?;
    let counts = it.next().ok_or_else(|| err(format!("tag '{name}' has no int/float/string counts")))?;
    let parsed: Vec<usize> = counts
        .split('/')
        .map(|c| c.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|_| err(format!("tag '{name}': bad counts '{counts}'")))?;
    let [ni, nf, ns] = parsed[..] else {
        return Err(err(format!("tag '{name}': counts '{counts}' are not N/N/N")));
    };
    let mut next = |what: &str| it.next().ok_or_else(|| err(format!("tag '{name}': missing {what} argument")));
    let mut ints = Vec::with_capacity(ni);
    for _ in 0..ni {
        let s = next("int")?;
        ints.push(s.parse().map_err(|_| err(format!("tag '{name}': '{s}' is not an integer")))?);
    }
    let mut floats = Vec::with_capacity(nf);
    for _ in 0..nf {
        let s = next("float")?;
        floats.push(s.parse().map_err(|_| err(format!("tag '{name}': '{s}' is not a number")))?);
    }
    let mut strings = Vec::with_capacity(ns);
    for _ in 0..ns {
        strings.push(next("string")?);
    }
    Ok(Tag { name, ints, floats, strings })
}

fn parse_floats<const N: usize>(rest: &str, err: &dyn Fn(String) -> MeshError) -> Result<[f32; N], MeshError> {
    let mut out = [0.0f32; N];
    let mut it = rest.split_whitespace();
    for o in out.iter_mut() {
        let s = it.next().ok_or_else(|| err(format!("expected {N} numbers")))?;
        *o = s.parse().map_err(|_| err(format!("'{s}' is not a number")))?;
    }
    Ok(out)
}

/// Resolves a 1-based (or negative, relative) OBJ index against `count` items read so far.
fn obj_index(s: &str, count: usize, err: &dyn Fn(String) -> MeshError) -> Result<i32, MeshError> {
    let i: i64 = s.parse().map_err(|_| err(format!("'{s}' is not an index")))?;
    let resolved = match i {
        0 => return Err(err("index 0 (OBJ indices start at 1)".into())),
        i if i > 0 => i - 1,
        i => count as i64 + i,
    };
    i32::try_from(resolved).map_err(|_| err(format!("index {i} is out of range")))
}

/// Parses one OpenSubdiv regression shape.
///
/// `name` is the shape's name (the file stem); it chooses the scheme (see the module header) and
/// prefixes every error message.
///
/// # Errors
/// [`MeshError::Invalid`] naming the shape and the line for malformed lines, unknown schemes and
/// topology that [`MeshTopology::validate`] refuses. Hierarchical edits are *not* an error here:
/// see [`ObjShape::check_supported`].
pub fn parse_obj_shape(name: &str, text: &str) -> Result<ObjShape, MeshError> {
    let mut shape = ObjShape { name: name.to_string(), ..Default::default() };
    let mut header_scheme = None;
    let mut topo = MeshTopology {
        // OpenSubdiv's GetSdcOptions defaults, not USD's: these are OpenSubdiv's shapes.
        boundary: BoundaryInterpolation::EdgeOnly,
        face_varying: FaceVaryingInterpolation::All,
        triangle_subdivision: TriangleSubdivision::CatmullClark,
        ..Default::default()
    };
    let mut uv_indices = Vec::new();
    let mut all_faces_have_uvs = true;
    let mut smooth_triangles = None;

    for (lineno, raw) in text.lines().enumerate() {
        let err = |m: String| MeshError::Invalid(format!("{name}: line {}: {m}", lineno + 1));
        let line = raw.trim();
        if let Some(comment) = line.strip_prefix('#') {
            if let Some(s) = comment.split("scheme:").nth(1) {
                header_scheme = match s.trim() {
                    "catmark" => Some(Scheme::CatmullClark),
                    "loop" => Some(Scheme::Loop),
                    "bilinear" => Some(Scheme::Bilinear),
                    _ => header_scheme,
                };
            }
            continue;
        }
        let (key, rest) = line.split_once(char::is_whitespace).unwrap_or((line, ""));
        match key {
            "v" => shape.points.push(parse_floats::<3>(rest, &err)?),
            "vt" => shape.uvs.push(parse_floats::<2>(rest, &err)?),
            "f" => {
                let mut n = 0;
                for item in rest.split_whitespace() {
                    let mut parts = item.split('/');
                    let v = parts.next().unwrap_or("");
                    topo.face_vertex_indices.push(obj_index(v, shape.points.len(), &err)?);
                    match parts.next() {
                        Some(t) if !t.is_empty() => uv_indices.push(obj_index(t, shape.uvs.len(), &err)?),
                        _ => all_faces_have_uvs = false,
                    }
                    n += 1;
                }
                topo.face_vertex_counts.push(n);
            }
            "t" => {
                let tag = parse_tag(rest, &err)?;
                apply_tag(&tag, &mut topo, &mut shape, &mut smooth_triangles, &err)?;
            }
            // Normals, groups, materials, smoothing groups: nothing a limit surface needs.
            _ => {}
        }
    }

    shape.scheme = scheme_from_name(name)
        .or(header_scheme)
        .ok_or_else(|| MeshError::Invalid(format!("{name}: no scheme (name prefix catmark_/loop_/bilinear_ or header)")))?;
    topo.scheme = shape.scheme;
    if let Some(rule) = smooth_triangles {
        // GetSdcOptions applies `smoothtriangles` to Catmark meshes only.
        if shape.scheme == Scheme::CatmullClark {
            topo.triangle_subdivision = rule;
        } else {
            shape.ignored_tags.push("smoothtriangles".into());
        }
    }
    topo.left_handed = name.contains("lefthanded");
    if name.contains("hedit") {
        shape.has_hierarchical_edits = true;
    }
    if all_faces_have_uvs && uv_indices.len() == topo.face_vertex_indices.len() && !uv_indices.is_empty() {
        if let Some((i, &bad)) = uv_indices.iter().enumerate().find(|(_, &t)| t < 0 || t as usize >= shape.uvs.len()) {
            return Err(MeshError::Invalid(format!("{name}: uv index [{i}] = {bad} is out of range [0, {})", shape.uvs.len())));
        }
        shape.uv_indices = uv_indices;
    }
    topo.validate(shape.points.len()).map_err(|e| MeshError::Invalid(format!("{name}: {e}")))?;
    shape.topology = topo;
    Ok(shape)
}

fn apply_tag(
    tag: &Tag<'_>,
    topo: &mut MeshTopology,
    shape: &mut ObjShape,
    smooth_triangles: &mut Option<TriangleSubdivision>,
    err: &dyn Fn(String) -> MeshError,
) -> Result<(), MeshError> {
    let to_i32 = |v: i64| i32::try_from(v).map_err(|_| err(format!("tag '{}': {v} is out of range", tag.name)));
    // OpenSubdiv clamps negative sharpness to 0; one float applies to all, else one per element.
    let sharpness = |k: usize| -> Result<f32, MeshError> {
        let s = match tag.floats.len() {
            0 => return Err(err(format!("tag '{}' has no sharpness", tag.name))),
            1 => tag.floats[0],
            _ => *tag.floats.get(k).ok_or_else(|| err(format!("tag '{}': no sharpness for element {k}", tag.name)))?,
        };
        Ok(s.max(0.0))
    };
    let single_int = || -> Result<i64, MeshError> {
        match tag.ints[..] {
            [v] => Ok(v),
            _ => Err(err(format!("tag '{}' expects one integer", tag.name))),
        }
    };
    match tag.name {
        "crease" => {
            if tag.ints.len() < 2 || tag.ints.len() % 2 != 0 {
                return Err(err("tag 'crease' expects vertex pairs".into()));
            }
            for (k, pair) in tag.ints.chunks_exact(2).enumerate() {
                topo.crease_indices.extend([to_i32(pair[0])?, to_i32(pair[1])?]);
                topo.crease_lengths.push(2);
                topo.crease_sharpnesses.push(sharpness(k)?);
            }
        }
        "corner" => {
            for (k, &v) in tag.ints.iter().enumerate() {
                topo.corner_indices.push(to_i32(v)?);
                topo.corner_sharpnesses.push(sharpness(k)?);
            }
        }
        "hole" => {
            for &f in &tag.ints {
                topo.hole_indices.push(to_i32(f)?);
            }
        }
        "interpolateboundary" => {
            topo.boundary = match single_int()? {
                0 => BoundaryInterpolation::None,
                1 => BoundaryInterpolation::EdgeAndCorner,
                2 => BoundaryInterpolation::EdgeOnly,
                v => return Err(err(format!("unknown interpolateboundary {v}"))),
            }
        }
        "facevaryinginterpolateboundary" => {
            topo.face_varying = match single_int()? {
                0 => FaceVaryingInterpolation::None,
                1 => FaceVaryingInterpolation::CornersOnly,
                2 => FaceVaryingInterpolation::CornersPlus1,
                3 => FaceVaryingInterpolation::CornersPlus2,
                4 => FaceVaryingInterpolation::Boundaries,
                5 => FaceVaryingInterpolation::All,
                v => return Err(err(format!("unknown facevaryinginterpolateboundary {v}"))),
            }
        }
        "smoothtriangles" => {
            *smooth_triangles = Some(match tag.strings.first().copied() {
                Some("catmark") => TriangleSubdivision::CatmullClark,
                Some("smooth") => TriangleSubdivision::Smooth,
                other => return Err(err(format!("smoothtriangles expects catmark or smooth, got {other:?}"))),
            })
        }
        "creasemethod" => {
            shape.crease_method = match tag.strings.first().copied() {
                Some("normal") => CreaseMethod::Uniform,
                Some("chaikin") => CreaseMethod::Chaikin,
                other => return Err(err(format!("creasemethod expects normal or chaikin, got {other:?}"))),
            }
        }
        "vertexedit" | "edgeedit" | "faceedit" => shape.has_hierarchical_edits = true,
        other => shape.ignored_tags.push(other.to_string()),
    }
    Ok(())
}

/// OpenSubdiv's regression-shape corpus: `MIPRAY_OSD_SHAPES` when set, else as this workplace
/// lays it out, `shared/osd-shapes` beside the checkout (every crate of the workspace sits one
/// level below its root). A worktree elsewhere (`/work/wt/NAME`) has no such neighbour and its
/// corpus tests skip unless the variable names the folder.
pub fn corpus_dir() -> std::path::PathBuf {
    match std::env::var_os("MIPRAY_OSD_SHAPES") {
        Some(dir) => std::path::PathBuf::from(dir),
        None => std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../shared/osd-shapes"),
    }
}

/// The `.obj` files in `dir`, sorted; when `MIPRAY_SHAPES` is set (comma-separated stems), only
/// those shapes. `None` when the folder cannot be read (the corpus is absent): table-driven
/// tests then say so and skip.
pub fn corpus_paths(dir: &std::path::Path) -> Option<Vec<std::path::PathBuf>> {
    let only = std::env::var("MIPRAY_SHAPES").ok();
    let mut paths: Vec<std::path::PathBuf> = std::fs::read_dir(dir)
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "obj"))
        .filter(|p| {
            let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
            only.as_deref().is_none_or(|o| o.split(',').any(|x| x == stem))
        })
        .collect();
    paths.sort();
    Some(paths)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a panic is the test's failure report
mod tests {
    use super::*;

    const CREASED_SQUARE: &str = "\
# OpenSubdiv regression shape 'catmark_test', scheme: catmark
v 0 0 0
v 1 0 0
v 2 0 0
v 0 1 0
v 1 1 0
v 2 1 0
vt 0 0
vt 1 0
vt 0.5 1
f 1/1 2/2 5/3 4/1
f 2/2 3/1 6/2 5/3
t crease 2/1/0 1 4 3.5
t corner 1/1/0 0 10
t interpolateboundary 1/0/0 1
";

    #[test]
    fn parses_crease_corner_and_boundary() {
        let s = parse_obj_shape("catmark_test", CREASED_SQUARE).unwrap();
        assert_eq!(s.scheme, Scheme::CatmullClark);
        assert_eq!(s.points.len(), 6);
        assert_eq!(s.points[2], [2.0, 0.0, 0.0]);
        assert_eq!(s.topology.face_vertex_counts, vec![4, 4]);
        assert_eq!(s.topology.face_vertex_indices, vec![0, 1, 4, 3, 1, 2, 5, 4]);
        assert_eq!(s.topology.crease_edges(), vec![(1, 4, 3.5)]);
        assert_eq!(s.topology.corner_indices, vec![0]);
        assert_eq!(s.topology.corner_sharpnesses, vec![10.0]);
        assert_eq!(s.topology.boundary, BoundaryInterpolation::EdgeAndCorner);
        assert_eq!(s.uv_indices, vec![0, 1, 2, 0, 1, 0, 1, 2]);
        assert!(!s.has_hierarchical_edits);
        assert!(s.check_supported().is_ok());
    }

    #[test]
    fn scheme_comes_from_the_name_then_the_header() {
        assert_eq!(parse_obj_shape("loop_x", "v 0 0 0\n").unwrap().scheme, Scheme::Loop);
        assert_eq!(parse_obj_shape("x", "# s, scheme: bilinear\nv 0 0 0\n").unwrap().scheme, Scheme::Bilinear);
        assert!(parse_obj_shape("x", "v 0 0 0\n").is_err());
    }

    #[test]
    fn defaults_follow_opensubdiv_not_usd() {
        let s = parse_obj_shape("catmark_q", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n").unwrap();
        assert_eq!(s.topology.boundary, BoundaryInterpolation::EdgeOnly);
        assert_eq!(s.topology.face_varying, FaceVaryingInterpolation::All);
        assert!(s.uv_indices.is_empty());
    }

    #[test]
    fn bad_lines_name_the_shape_and_line() {
        let e = parse_obj_shape("catmark_bad", "v 0 0 0\nv 1 0\n").unwrap_err().to_string();
        assert!(e.contains("catmark_bad: line 2"), "{e}");
        let e = parse_obj_shape("catmark_bad", "v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n").unwrap_err().to_string();
        assert!(e.contains("catmark_bad") && e.contains("faceVertexIndices"), "{e}");
        let e = parse_obj_shape("catmark_bad", "v 0 0 0\nf 0 1 1\n").unwrap_err().to_string();
        assert!(e.contains("index 0"), "{e}");
    }

    #[test]
    fn hierarchical_edits_are_flagged() {
        let text = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n\
                    t vertexedit 4/6/1 1 0 1 0 0 0 1 0 0 1 add\n";
        let s = parse_obj_shape("catmark_q", text).unwrap();
        assert!(s.has_hierarchical_edits);
        let e = s.check_supported().unwrap_err().to_string();
        assert!(e.contains("not supported") && e.contains("catmark_q"), "{e}");
    }

    #[test]
    fn every_regression_shape_parses() {
        let dir = corpus_dir();
        let Some(paths) = corpus_paths(&dir) else {
            println!("note: {} is absent; skipping the shape corpus", dir.display());
            return;
        };
        assert!(!paths.is_empty(), "no .obj files in {}", dir.display());
        let mut hedits = 0;
        for p in &paths {
            let name = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
            let text = std::fs::read_to_string(p).unwrap();
            let s = parse_obj_shape(name, &text).unwrap_or_else(|e| panic!("{e}"));
            assert!(!s.points.is_empty() && s.topology.face_count() > 0, "{name} is empty");
            assert_eq!(s.has_hierarchical_edits, name.contains("hedit"), "{name}");
            hedits += usize::from(s.has_hierarchical_edits);
        }
        println!("{} shapes parsed, {hedits} with hierarchical edits", paths.len());
    }
}
