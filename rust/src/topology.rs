//! Mesh topology as USD's `UsdGeom.Mesh` states it: what the patch source (OpenSubdiv in the bridge,
//! or [`crate::bilinear::BilinearSurface`] for polygonal meshes) needs to build a limit surface.
//!
//! Plain data, no behaviour beyond validation, so the core, the bridge and the Python bindings
//! agree on one description.

use crate::error::MeshError;

/// Subdivision scheme (`subdivisionScheme`). `None` means a polygonal mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum Scheme {
    #[default]
    CatmullClark,
    Loop,
    Bilinear,
    /// `subdivisionScheme = "none"`: render the control polygons as they are.
    None,
}

/// `interpolateBoundary`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum BoundaryInterpolation {
    None,
    EdgeOnly,
    #[default]
    EdgeAndCorner,
}

/// `faceVaryingLinearInterpolation`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum FaceVaryingInterpolation {
    None,
    CornersOnly,
    #[default]
    CornersPlus1,
    CornersPlus2,
    Boundaries,
    All,
}

/// `triangleSubdivisionRule`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Default)]
pub enum TriangleSubdivision {
    #[default]
    CatmullClark,
    Smooth,
}

/// Parses a USD token into one of these enums; the error lists the valid tokens.
fn from_token<T: Copy>(attribute: &str, token: &str, table: &[(&str, T)]) -> Result<T, MeshError> {
    table.iter().find(|(t, _)| *t == token).map(|(_, v)| *v).ok_or_else(|| {
        let valid: Vec<&str> = table.iter().map(|(t, _)| *t).collect();
        MeshError::Invalid(format!("{attribute} '{token}' is not one of {}", valid.join(", ")))
    })
}

impl Scheme {
    /// From USD's `subdivisionScheme` token.
    ///
    /// # Errors
    /// An unknown token; the message lists the valid ones.
    pub fn from_usd(token: &str) -> Result<Self, MeshError> {
        use Scheme::*;
        from_token("subdivisionScheme", token, &[("catmullClark", CatmullClark), ("loop", Loop), ("bilinear", Bilinear), ("none", None)])
    }
}

impl BoundaryInterpolation {
    /// From USD's `interpolateBoundary` token.
    ///
    /// # Errors
    /// An unknown token; the message lists the valid ones.
    pub fn from_usd(token: &str) -> Result<Self, MeshError> {
        use BoundaryInterpolation::*;
        from_token("interpolateBoundary", token, &[("none", None), ("edgeOnly", EdgeOnly), ("edgeAndCorner", EdgeAndCorner)])
    }
}

impl FaceVaryingInterpolation {
    /// From USD's `faceVaryingLinearInterpolation` token.
    ///
    /// # Errors
    /// An unknown token; the message lists the valid ones.
    pub fn from_usd(token: &str) -> Result<Self, MeshError> {
        use FaceVaryingInterpolation::*;
        from_token(
            "faceVaryingLinearInterpolation",
            token,
            &[
                ("none", None),
                ("cornersOnly", CornersOnly),
                ("cornersPlus1", CornersPlus1),
                ("cornersPlus2", CornersPlus2),
                ("boundaries", Boundaries),
                ("all", All),
            ],
        )
    }
}

impl TriangleSubdivision {
    /// From USD's `triangleSubdivisionRule` token.
    ///
    /// # Errors
    /// An unknown token; the message lists the valid ones.
    pub fn from_usd(token: &str) -> Result<Self, MeshError> {
        use TriangleSubdivision::*;
        from_token("triangleSubdivisionRule", token, &[("catmullClark", CatmullClark), ("smooth", Smooth)])
    }
}

/// The topology of one mesh, in USD's terms. Indices refer to the mesh's points.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshTopology {
    pub scheme: Scheme,
    /// Vertices per face (`faceVertexCounts`).
    pub face_vertex_counts: Vec<i32>,
    /// Point index per face-vertex (`faceVertexIndices`).
    pub face_vertex_indices: Vec<i32>,
    /// `creaseIndices`: runs of point indices; each run is one crease chain.
    pub crease_indices: Vec<i32>,
    /// `creaseLengths`: the length of each chain in `crease_indices`.
    pub crease_lengths: Vec<i32>,
    /// `creaseSharpnesses`: one per chain, or one per edge of all chains.
    pub crease_sharpnesses: Vec<f32>,
    pub corner_indices: Vec<i32>,
    pub corner_sharpnesses: Vec<f32>,
    /// `holeIndices`: faces that are holes.
    pub hole_indices: Vec<i32>,
    pub boundary: BoundaryInterpolation,
    pub face_varying: FaceVaryingInterpolation,
    pub triangle_subdivision: TriangleSubdivision,
    /// `orientation = "leftHanded"`: faces wind clockwise; the core flips geometric normals.
    pub left_handed: bool,
}

impl MeshTopology {
    /// Number of faces.
    pub fn face_count(&self) -> usize {
        self.face_vertex_counts.len()
    }

    /// Checks the counts and indices against `point_count`, and the crease, corner and hole
    /// arrays against each other, so that nothing downstream
    /// (OpenSubdiv included) sees a malformed mesh. The messages are the USD attributes' names
    /// and indices, as a user fixes them.
    ///
    /// # Errors
    /// The first problem found, as a [`MeshError::Invalid`] whose message names the offending
    /// array.
    pub fn validate(&self, point_count: usize) -> Result<(), MeshError> {
        let invalid = |m: String| Err(MeshError::Invalid(m));
        if let Some((f, n)) = self.face_vertex_counts.iter().enumerate().find(|(_, &n)| n < 3) {
            return invalid(format!("faceVertexCounts[{f}] = {n}; a face needs at least 3 vertices"));
        }
        let total: i64 = self.face_vertex_counts.iter().map(|&n| i64::from(n)).sum();
        if total != self.face_vertex_indices.len() as i64 {
            return invalid(format!(
                "faceVertexCounts add up to {total} but faceVertexIndices has {} entries",
                self.face_vertex_indices.len()
            ));
        }
        in_range("faceVertexIndices", &self.face_vertex_indices, point_count, "points")?;
        if let Some((c, l)) = self.crease_lengths.iter().enumerate().find(|(_, &l)| l < 2) {
            return invalid(format!("creaseLengths[{c}] = {l}; a crease needs at least 2 vertices"));
        }
        let chain_total: i64 = self.crease_lengths.iter().map(|&l| i64::from(l)).sum();
        if chain_total != self.crease_indices.len() as i64 {
            return invalid(format!("creaseLengths add up to {chain_total} but creaseIndices has {} entries", self.crease_indices.len()));
        }
        // USD allows one sharpness per crease or one per crease edge.
        let chains = self.crease_lengths.len() as i64;
        let edges = chain_total - chains;
        let ns = self.crease_sharpnesses.len() as i64;
        if ns != chains && ns != edges {
            return invalid(format!(
                "creaseSharpnesses has {ns} entries; expected {chains} (one per crease) or {edges} (one per crease edge)"
            ));
        }
        if let Some((i, s)) = self.crease_sharpnesses.iter().enumerate().find(|(_, s)| !s.is_finite()) {
            return invalid(format!("creaseSharpnesses[{i}] = {s}: a sharpness must be finite"));
        }
        in_range("creaseIndices", &self.crease_indices, point_count, "points")?;
        if self.corner_sharpnesses.len() != self.corner_indices.len() {
            return invalid(format!(
                "cornerIndices has {} entries but cornerSharpnesses has {}",
                self.corner_indices.len(),
                self.corner_sharpnesses.len()
            ));
        }
        in_range("cornerIndices", &self.corner_indices, point_count, "points")?;
        if let Some((i, s)) = self.corner_sharpnesses.iter().enumerate().find(|(_, s)| !s.is_finite()) {
            return invalid(format!("cornerSharpnesses[{i}] = {s}: a sharpness must be finite"));
        }
        in_range("holeIndices", &self.hole_indices, self.face_count(), "faces")
    }

    /// Crease edges as (point a, point b, sharpness), expanding chains and per-chain sharpness.
    pub fn crease_edges(&self) -> Vec<(i32, i32, f32)> {
        let per_chain = self.crease_sharpnesses.len() == self.crease_lengths.len();
        let mut out = Vec::new();
        let (mut start, mut edge) = (0usize, 0usize);
        for (c, &len) in self.crease_lengths.iter().enumerate() {
            let len = len.max(0) as usize;
            for k in 1..len {
                let s = if per_chain { self.crease_sharpnesses.get(c) } else { self.crease_sharpnesses.get(edge) };
                if let (Some(&a), Some(&b)) = (self.crease_indices.get(start + k - 1), self.crease_indices.get(start + k)) {
                    out.push((a, b, s.copied().unwrap_or(0.0)));
                }
                edge += 1;
            }
            start += len;
        }
        out
    }
}

/// `name[i]` out of `[0, limit)`, named as USD's attribute (`what`: points or faces).
fn in_range(name: &str, indices: &[i32], limit: usize, what: &str) -> Result<(), MeshError> {
    match indices.iter().enumerate().find(|(_, &v)| v < 0 || v as usize >= limit) {
        Some((i, v)) => Err(MeshError::Invalid(format!("{name}[{i}] = {v} is out of range for {limit} {what}"))),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad() -> MeshTopology {
        MeshTopology { face_vertex_counts: vec![4], face_vertex_indices: vec![0, 1, 2, 3], ..Default::default() }
    }

    #[test]
    fn usd_tokens_parse_and_unknown_ones_list_the_valid() {
        assert_eq!(Scheme::from_usd("loop"), Ok(Scheme::Loop));
        assert_eq!(BoundaryInterpolation::from_usd("edgeOnly"), Ok(BoundaryInterpolation::EdgeOnly));
        assert_eq!(FaceVaryingInterpolation::from_usd("cornersPlus2"), Ok(FaceVaryingInterpolation::CornersPlus2));
        assert_eq!(TriangleSubdivision::from_usd("smooth"), Ok(TriangleSubdivision::Smooth));
        let e = Scheme::from_usd("catmull-clark").unwrap_err().to_string();
        assert!(e.contains("subdivisionScheme 'catmull-clark'") && e.contains("catmullClark, loop, bilinear, none"), "{e}");
    }

    #[test]
    fn valid_quad_passes() {
        assert!(quad().validate(4).is_ok());
    }

    #[test]
    fn out_of_range_index_is_named() {
        let err = quad().validate(3).unwrap_err().to_string();
        assert!(err.contains("faceVertexIndices[3] = 3"), "{err}");
    }

    #[test]
    fn count_mismatch_is_refused() {
        let mut t = quad();
        t.face_vertex_counts = vec![5];
        assert!(t.validate(4).is_err());
        t.face_vertex_counts = vec![2];
        assert!(t.validate(4).is_err());
    }

    #[test]
    fn crease_chains_expand_per_chain_and_per_edge() {
        let mut t = quad();
        t.crease_indices = vec![0, 1, 2];
        t.crease_lengths = vec![3];
        t.crease_sharpnesses = vec![2.0];
        assert!(t.validate(4).is_ok());
        assert_eq!(t.crease_edges(), vec![(0, 1, 2.0), (1, 2, 2.0)]);
        t.crease_sharpnesses = vec![1.0, 3.0];
        assert_eq!(t.crease_edges(), vec![(0, 1, 1.0), (1, 2, 3.0)]);
        t.crease_sharpnesses = vec![1.0, 3.0, 4.0];
        assert!(t.validate(4).is_err());
    }
}
