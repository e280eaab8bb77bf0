// OpenSubdiv (Far) for mipray: topology refinement, the adaptive patch table with Gregory-basis
// end caps, control points refined level by level, and limit evaluation. See include/osd.h.
//
// Error handling: OpenSubdiv reports problems through Far::Error / Far::Warning. Without a
// callback a FAR_FATAL_ERROR calls exit(), which would kill a Python host, so callbacks are
// installed once and record messages per thread; a call that saw an error throws
// std::runtime_error carrying them, and cxx hands that to Rust as an Err.

#include "mipray-bridge/include/osd.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <mutex>
#include <stdexcept>
#include <string>
#include <vector>

#include <opensubdiv/far/error.h>
#include <opensubdiv/far/patchMap.h>
#include <opensubdiv/far/patchTable.h>
#include <opensubdiv/far/patchTableFactory.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/ptexIndices.h>
#include <opensubdiv/far/stencilTable.h>
#include <opensubdiv/far/topologyDescriptor.h>
#include <opensubdiv/far/topologyRefinerFactory.h>

#include "mipray-bridge/src/ffi.rs.h"

namespace Far = OpenSubdiv::Far;
namespace Sdc = OpenSubdiv::Sdc;

namespace mipray_bridge {
namespace {

// ---------------------------------------------------------------------------------------------
// OpenSubdiv's error and warning callbacks.

// Per thread, so that meshes built concurrently on several threads keep their messages apart
// (OpenSubdiv calls the callback on the thread that hit the problem).
thread_local std::string t_errors;
thread_local std::string t_warnings;

void on_far_error(Far::ErrorType type, const char* message) {
  const char* label = "error";
  switch (type) {
    case Far::FAR_FATAL_ERROR: label = "fatal error"; break;
    case Far::FAR_INTERNAL_CODING_ERROR: label = "internal coding error"; break;
    case Far::FAR_CODING_ERROR: label = "coding error"; break;
    case Far::FAR_RUNTIME_ERROR: label = "runtime error"; break;
    default: break;
  }
  if (!t_errors.empty()) t_errors += "; ";
  t_errors += label;
  t_errors += ": ";
  t_errors += message ? message : "(no message)";
}

void on_far_warning(const char* message) {
  if (!t_warnings.empty()) t_warnings += "\n";
  t_warnings += message ? message : "(no message)";
}

std::once_flag g_callbacks_installed;

// Clears this thread's messages, installs the callbacks (once per process), and turns recorded
// errors into exceptions at the points where a result is used.
class FarCapture {
 public:
  FarCapture() {
    std::call_once(g_callbacks_installed, [] {
      Far::SetErrorCallback(on_far_error);
      Far::SetWarningCallback(on_far_warning);
    });
    t_errors.clear();
    t_warnings.clear();
  }
  // Throws if OpenSubdiv reported an error since construction.
  void check(const char* stage) const {
    if (!t_errors.empty()) {
      std::string msg = std::string(stage) + ": " + t_errors;
      if (!t_warnings.empty()) msg += " (warnings: " + one_line(t_warnings) + ")";
      throw std::runtime_error(msg);
    }
  }
  // Throws with the errors and warnings recorded so far (for a null result).
  [[noreturn]] void fail(const char* stage) const {
    std::string msg = stage;
    if (!t_errors.empty()) msg += ": " + t_errors;
    if (!t_warnings.empty()) msg += ": " + one_line(t_warnings);
    if (t_errors.empty() && t_warnings.empty()) msg += ": OpenSubdiv gave no reason";
    throw std::runtime_error(msg);
  }
  std::string warnings() const { return t_warnings; }

 private:
  static std::string one_line(std::string s) {
    std::replace(s.begin(), s.end(), '\n', ';');
    return s;
  }
};

// ---------------------------------------------------------------------------------------------
// Refiner construction.

using RefinerPtr = std::unique_ptr<Far::TopologyRefiner>;

void check_desc(const OsdMeshDesc& d, std::size_t point_floats) {
  // The Rust side validates the topology; these checks only keep OpenSubdiv from reading out of
  // bounds if it did not.
  if (d.num_vertices < 0 || point_floats != std::size_t(d.num_vertices) * 3)
    throw std::runtime_error("point array does not hold num_vertices × 3 floats");
  if (d.crease_pairs.size() != d.crease_weights.size() * 2)
    throw std::runtime_error("crease pairs and weights disagree");
  if (d.corner_indices.size() != d.corner_weights.size())
    throw std::runtime_error("corner indices and weights disagree");
  std::size_t total = 0;
  for (int32_t n : d.face_vertex_counts) {
    if (n < 3) throw std::runtime_error("a face has fewer than 3 vertices");
    total += std::size_t(n);
  }
  if (total != d.face_vertex_indices.size())
    throw std::runtime_error("face vertex counts and indices disagree");
  auto in_range = [](const rust::Vec<int32_t>& v, int32_t bound, const char* what) {
    for (int32_t i : v)
      if (i < 0 || i >= bound) throw std::runtime_error(std::string(what) + " out of range");
  };
  in_range(d.face_vertex_indices, d.num_vertices, "face vertex index");
  in_range(d.crease_pairs, d.num_vertices, "crease vertex index");
  in_range(d.corner_indices, d.num_vertices, "corner vertex index");
  in_range(d.hole_indices, int32_t(d.face_vertex_counts.size()), "hole face index");
  if (d.isolation_level < 1 || d.isolation_level > 10)
    throw std::runtime_error("isolation level must be in 1..=10");
  // Face-varying channels: one index per face-vertex per channel, 2 floats per value.
  const std::size_t nfv = d.face_vertex_indices.size();
  if (d.fvar_indices.size() != d.fvar_value_counts.size() * nfv)
    throw std::runtime_error("face-varying indices do not hold one per face-vertex per channel");
  std::size_t fvar_total = 0;
  for (std::size_t c = 0; c < d.fvar_value_counts.size(); ++c) {
    const int32_t count = d.fvar_value_counts[c];
    if (count < 1) throw std::runtime_error("a face-varying channel has no values");
    for (std::size_t k = c * nfv; k < (c + 1) * nfv; ++k)
      if (d.fvar_indices[k] < 0 || d.fvar_indices[k] >= count)
        throw std::runtime_error("face-varying index out of range");
    fvar_total += std::size_t(count);
  }
  if (d.fvar_values.size() != 2 * fvar_total)
    throw std::runtime_error("face-varying values do not hold 2 floats per value");
  if (d.num_vertices > 0 && d.vertex_primvars.size() % (2 * std::size_t(d.num_vertices)) != 0)
    throw std::runtime_error("vertex primvars do not hold 2 floats per point per channel");
}

Sdc::SchemeType scheme_of(const OsdMeshDesc& d) {
  switch (d.scheme) {
    case 0: return Sdc::SCHEME_CATMARK;
    case 1: return Sdc::SCHEME_LOOP;
    case 2: return Sdc::SCHEME_BILINEAR;
    default: throw std::runtime_error("unknown scheme code");
  }
}

Sdc::Options sdc_options_of(const OsdMeshDesc& d) {
  Sdc::Options o;
  switch (d.boundary) {
    case 0: o.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_NONE); break;
    case 1: o.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_ONLY); break;
    case 2: o.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER); break;
    default: throw std::runtime_error("unknown boundary interpolation code");
  }
  switch (d.fvar) {
    case 0: o.SetFVarLinearInterpolation(Sdc::Options::FVAR_LINEAR_NONE); break;
    case 1: o.SetFVarLinearInterpolation(Sdc::Options::FVAR_LINEAR_CORNERS_ONLY); break;
    case 2: o.SetFVarLinearInterpolation(Sdc::Options::FVAR_LINEAR_CORNERS_PLUS1); break;
    case 3: o.SetFVarLinearInterpolation(Sdc::Options::FVAR_LINEAR_CORNERS_PLUS2); break;
    case 4: o.SetFVarLinearInterpolation(Sdc::Options::FVAR_LINEAR_BOUNDARIES); break;
    case 5: o.SetFVarLinearInterpolation(Sdc::Options::FVAR_LINEAR_ALL); break;
    default: throw std::runtime_error("unknown face-varying interpolation code");
  }
  switch (d.triangle_subdivision) {
    case 0: o.SetTriangleSubdivision(Sdc::Options::TRI_SUB_CATMARK); break;
    case 1: o.SetTriangleSubdivision(Sdc::Options::TRI_SUB_SMOOTH); break;
    default: throw std::runtime_error("unknown triangle subdivision code");
  }
  // USD has no creasing-method attribute: OpenSubdiv's default, uniform.
  o.SetCreasingMethod(Sdc::Options::CREASE_UNIFORM);
  return o;
}

RefinerPtr create_refiner(const OsdMeshDesc& d, const FarCapture& capture) {
  Far::TopologyDescriptor td;
  td.numVertices = d.num_vertices;
  td.numFaces = int(d.face_vertex_counts.size());
  td.numVertsPerFace = d.face_vertex_counts.data();
  td.vertIndicesPerFace = d.face_vertex_indices.data();
  td.numCreases = int(d.crease_weights.size());
  td.creaseVertexIndexPairs = d.crease_pairs.data();
  td.creaseWeights = d.crease_weights.data();
  td.numCorners = int(d.corner_indices.size());
  td.cornerVertexIndices = d.corner_indices.data();
  td.cornerWeights = d.corner_weights.data();
  td.numHoles = int(d.hole_indices.size());
  td.holeIndices = d.hole_indices.data();
  // Face-varying topology: the indices say which faces share a value across an edge (a seam
  // where they do not). Must outlive Create, which copies it.
  std::vector<Far::TopologyDescriptor::FVarChannel> fvar(d.fvar_value_counts.size());
  for (std::size_t c = 0; c < fvar.size(); ++c) {
    fvar[c].numValues = d.fvar_value_counts[c];
    fvar[c].valueIndices = d.fvar_indices.data() + c * d.face_vertex_indices.size();
  }
  td.numFVarChannels = int(fvar.size());
  td.fvarChannels = fvar.empty() ? nullptr : fvar.data();
  // Winding stays as given: the core flips normals of left-handed meshes itself, so telling
  // OpenSubdiv as well would flip them twice.
  td.isLeftHanded = false;

  using Factory = Far::TopologyRefinerFactory<Far::TopologyDescriptor>;
  Factory::Options fo(scheme_of(d), sdc_options_of(d));
  RefinerPtr refiner(Factory::Create(td, fo));
  if (!refiner) capture.fail("OpenSubdiv refused the topology");
  capture.check("OpenSubdiv topology");
  return refiner;
}

// The highest valence the mesh's refinement meets: a vertex's edge count, or a Catmull-Clark
// n-gon's side count (its first refinement puts a vertex of valence n at its centre).
int max_valence(const Far::TopologyRefiner& refiner) {
  const Far::TopologyLevel& l = refiner.GetLevel(0);
  int most = 0;
  for (int v = 0; v < l.GetNumVertices(); ++v) most = std::max(most, l.GetVertexEdges(v).size());
  if (refiner.GetSchemeType() == Sdc::SCHEME_CATMARK)
    for (int f = 0; f < l.GetNumFaces(); ++f) most = std::max(most, l.GetFaceVertices(f).size());
  return most;
}

// Above this valence a mesh's end caps are bilinear, not Gregory. Each of the n Gregory patches
// around a vertex of valence n has 20 local points whose stencils span its whole 1-ring, so the
// stencils cost O(n²) (a 4096-gon took 2.3 GB, a 16384-gon over 24 GB). Held to this valence the
// end caps cost at most ~20·kMaxGregoryValence weights per unit of total valence: linear in the
// mesh. Bilinear end caps are the refined polygon at the isolation level: the regular patches
// (everything but the few around extraordinary vertices) stay the exact limit.
constexpr int kMaxGregoryValence = 256;

bool bilinear_end_caps(const Far::TopologyRefiner& refiner) {
  return max_valence(refiner) > kMaxGregoryValence;
}

Far::PatchTableFactory::Options patch_options_of(const OsdMeshDesc& d, bool bilinear_caps = false) {
  Far::PatchTableFactory::Options po(d.isolation_level);
  po.SetEndCapType(bilinear_caps ? Far::PatchTableFactory::Options::ENDCAP_BILINEAR_BASIS
                                 : Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS);
  po.useInfSharpPatch = true;
  // A regular face along a straight semi-sharp crease is one patch, not ⌈sharpness⌉ levels of
  // isolation (17 patches a face on sharpness-3 creased cubes, 3 with it; docs/memory-usd.md);
  // Impl::crease_basis evaluates it. Catmull-Clark only (OpenSubdiv's test reads four corners).
  po.useSingleCreasePatch = d.scheme == 0;
  // Vertex data and face-varying channels are evaluated; varying primvars are interpolated over
  // the base faces in the core, so no varying tables.
  po.generateVaryingTables = false;
  po.generateVaryingLocalPoints = false;
  if (!d.fvar_value_counts.empty()) {
    // Smooth face-varying patches (not the legacy all-linear ones), so faceVaryingLinear-
    // Interpolation decides; this also makes adaptive refinement isolate face-varying features.
    po.generateFVarTables = true;
    po.generateFVarLegacyLinearPatches = false;
    po.numFVarChannels = -1;  // every channel
  }
  return po;
}

// `single_crease` false isolates every semi-sharp crease fully, as the references want it
// (osd_limit_reference_eval and osd_limit_reference_fvar_eval, as OpenSubdiv's limit stencils do).
void refine_adaptive(Far::TopologyRefiner& refiner, const OsdMeshDesc& d,
                     const FarCapture& capture, bool single_crease = true) {
  Far::TopologyRefiner::AdaptiveOptions ao = patch_options_of(d).GetRefineAdaptiveOptions();
  ao.useSingleCreasePatch = single_crease && ao.useSingleCreasePatch;
  ao.SetSecondaryLevel(std::min(d.secondary_level, d.isolation_level));
  refiner.RefineAdaptive(ao);
  capture.check("OpenSubdiv adaptive refinement");
}

// A grid's weights along s, four a column, and their derivatives: on the stack for every grid
// the tessellation makes (at most 17 vertices a side), on the heap beyond. As two vectors they
// were two allocations and frees in every grid built (and two more for a displaced grid's st).
class ColumnWeights {
 public:
  explicit ColumnWeights(std::size_t n) {
    if (n > kStackColumns) {
      heap_w_.resize(4 * n);
      heap_dw_.resize(4 * n);
      w = heap_w_.data();
      dw = heap_dw_.data();
    }
  }
  ColumnWeights(const ColumnWeights&) = delete;
  ColumnWeights& operator=(const ColumnWeights&) = delete;

 private:
  static constexpr std::size_t kStackColumns = 17;
  double stack_w_[4 * kStackColumns], stack_dw_[4 * kStackColumns];
  std::vector<double> heap_w_, heap_dw_;

 public:
  double* w = stack_w_;
  double* dw = stack_dw_;
};

// N floats of a primvar with double accumulators, as Far::PrimvarRefiner and
// PatchTable::ComputeLocalPointValues want them: masks around high-valence vertices have many
// small weights.
template <int N>
struct ValueD {
  double v[N];
  void Clear(void* = nullptr) {
    for (double& x : v) x = 0.0;
  }
  void AddWithWeight(const ValueD& src, float weight) {
    for (int i = 0; i < N; ++i) v[i] += double(weight) * src.v[i];
  }
};

// The values of every vertex of `refiner` (the mesh's own, then each refined level's) and then,
// when `table` is given, its end caps' local points: the index space of the patch table's
// control vertex indices. `base` holds N floats per mesh vertex; the result N floats per point.
//
// Level by level with Far::PrimvarRefiner, each new vertex from its parents' masks, then the
// local points from their stencils over those vertices. OpenSubdiv's StencilTableFactory would
// factorize every refined and local point down to the mesh's points instead; it merges weights
// by linear search, so a point near a vertex of valence n costs O(n²) and the mesh O(n³) (a
// minute at valence 360). This costs the masks' sizes: linear in the mesh.
template <int N>
std::vector<float> refine_values(const Far::TopologyRefiner& refiner, const Far::PatchTable* table,
                                 const float* base) {
  const std::size_t total = std::size_t(refiner.GetNumVerticesTotal());
  const std::size_t local = table ? std::size_t(std::max(table->GetNumLocalPoints(), 0)) : 0;
  const std::size_t nbase = std::size_t(refiner.GetLevel(0).GetNumVertices());
  std::vector<ValueD<N>> buf(total + local);
  for (std::size_t i = 0; i < nbase; ++i)
    for (int c = 0; c < N; ++c) buf[i].v[c] = base[N * i + std::size_t(c)];
  Far::PrimvarRefiner primvar(refiner);
  ValueD<N>* src = buf.data();
  for (int level = 1; level <= refiner.GetMaxLevel(); ++level) {
    ValueD<N>* dst = src + refiner.GetLevel(level - 1).GetNumVertices();
    primvar.Interpolate(level, src, dst);
    src = dst;
  }
  if (local > 0) table->ComputeLocalPointValues(buf.data(), buf.data() + total);
  std::vector<float> out(N * buf.size());
  for (std::size_t i = 0; i < buf.size(); ++i)
    for (int c = 0; c < N; ++c) out[N * i + std::size_t(c)] = float(buf[i].v[c]);
  // The mesh's own values exactly as given (the double round trip keeps them, but say so).
  std::copy(base, base + N * nbase, out.begin());
  return out;
}

// Frees the end-cap (local point) stencils a patch table holds once its local points are
// computed: they are most of a mesh's memory outside the cache (docs/memory.md) and only make
// local points from refined ones, which update_points does with a patch table of its own.
// Far::PatchTable hands them out const and StencilTable::Clear keeps the capacity, so the
// vectors are swapped out through pointers to the protected members, named from a subclass.
struct StencilRelease : Far::StencilTable {
  static void release(const Far::StencilTable* table) {
    if (!table) return;
    auto& t = const_cast<Far::StencilTable&>(*table);
    std::vector<int>().swap(t.*(&StencilRelease::_sizes));
    std::vector<Far::Index>().swap(t.*(&StencilRelease::_offsets));
    std::vector<Far::Index>().swap(t.*(&StencilRelease::_indices));
    std::vector<float>().swap(t.*(&StencilRelease::_weights));
  }
};

void release_local_stencils(const Far::PatchTable& table) {
  StencilRelease::release(table.GetLocalPointStencilTable());
  StencilRelease::release(table.GetLocalPointVaryingStencilTable());
  for (int c = 0; c < table.GetNumFVarChannels(); ++c)
    StencilRelease::release(table.GetLocalPointFaceVaryingStencilTable(c));
}

// A 2-float value as Far::PrimvarRefiner and StencilTable::UpdateValues want it.
struct Value2 {
  float v[2];
  void Clear(void* = nullptr) { v[0] = v[1] = 0.0f; }
  void AddWithWeight(const Value2& src, float weight) {
    v[0] += weight * src.v[0];
    v[1] += weight * src.v[1];
  }
};

bool is_triangle_type(Far::PatchDescriptor::Type t) {
  return t == Far::PatchDescriptor::LOOP || t == Far::PatchDescriptor::GREGORY_TRIANGLE ||
         t == Far::PatchDescriptor::TRIANGLES;
}

uint8_t kind_code(Far::PatchDescriptor::Type t) {
  switch (t) {
    case Far::PatchDescriptor::QUADS: return 0;
    case Far::PatchDescriptor::REGULAR: return 1;
    case Far::PatchDescriptor::GREGORY_BASIS: return 2;
    case Far::PatchDescriptor::LOOP: return 3;
    case Far::PatchDescriptor::GREGORY_TRIANGLE: return 4;
    default: return 5;
  }
}

constexpr int kMaxPatchPoints = 20;  // Gregory basis; every other type has fewer.

}  // namespace

// ---------------------------------------------------------------------------------------------
// OsdMesh

struct OsdMesh::Impl {
  std::unique_ptr<Far::PatchTable> patch_table;
  // Made on the first find_patch (only limit_at and the compare tool ask): rays never need it,
  // and it copies every patch's handle (12 bytes) plus a quadtree node per split.
  mutable std::once_flag patch_map_once;
  mutable std::unique_ptr<Far::PatchMap> patch_map;
  int num_base_points = 0;
  // Mesh points, then refined points of every level, then local (end-cap) points: the index
  // space of the patch table's control vertex indices. 3 floats each.
  std::vector<float> control_points;
  // Per patch array (a handful): its first patch, control points per patch and type. A patch's
  // handle and type are found from these rather than kept per patch (16 bytes a patch).
  struct Array {
    std::size_t first;
    int cvs;
    Far::PatchDescriptor::Type type;
  };
  std::vector<Array> arrays;
  std::size_t num_patches = 0;
  std::vector<int32_t> ptex_to_base;
  std::string warnings;
  // What was made cheaper than the exact limit surface to bound the work (empty: nothing).
  std::string simplified;
  // Face-varying channels: the values of every refinement level, then the end caps' local
  // values — the index space of GetPatchFVarValues. 2 floats each.
  std::vector<std::vector<float>> fvar_values;
  // Vertex primvars: one value per control point (the index space of GetPatchVertices).
  std::vector<std::vector<float>> vertex_primvars;

  // The control points from the mesh's points, through `refiner` and `table` (the ones the kept
  // patch table came from, or made again from the same descriptor: the same vertices and local
  // points in the same order). Nothing of the refinement is kept between calls.
  void set_points(const Far::TopologyRefiner& refiner, const Far::PatchTable& table,
                  const float* points) {
    std::vector<float> all = refine_values<3>(refiner, &table, points);
    if (all.size() != control_points.size())
      throw std::runtime_error("refined point count changed (" + std::to_string(all.size() / 3) +
                               ", was " + std::to_string(control_points.size() / 3) + ")");
    control_points = std::move(all);
  }

  const Array& array_of(std::size_t patch) const {
    std::size_t a = arrays.size() - 1;
    while (a > 0 && arrays[a].first > patch) --a;
    return arrays[a];
  }
  // The handle PatchMap would give: array, absolute patch index, first CV in the array.
  Far::PatchTable::PatchHandle handle(std::size_t patch) const {
    const std::size_t a = std::size_t(&array_of(patch) - arrays.data());
    Far::PatchTable::PatchHandle h;
    h.arrayIndex = int(a);
    h.patchIndex = int(patch);
    h.vertIndex = int(patch - arrays[a].first) * arrays[a].cvs;
    return h;
  }
  Far::PatchDescriptor::Type type(std::size_t patch) const { return array_of(patch).type; }

  // The sharpness of a single-crease patch (a regular patch whose one edge is a semi-sharp
  // crease, OpenSubdiv's useSingleCreasePatch), 0 for any other patch.
  // OpenSubdiv fills the sharpness of every patch but sets it only for regular ones (an
  // irregular patch carries over the value of the patch before it), so the type decides first.
  float crease_sharpness(std::size_t patch) const {
    const std::vector<Far::Index>& index = patch_table->GetSharpnessIndexTable();
    const std::vector<float>& values = patch_table->GetSharpnessValues();
    if (patch >= index.size() || index[patch] < 0 || std::size_t(index[patch]) >= values.size() ||
        type(patch) != Far::PatchDescriptor::REGULAR ||
        patch_table->GetPatchVertices(handle(patch)).size() != 16)
      return 0.0f;
    return values[std::size_t(index[patch])];
  }

  // A regular B-spline patch's limit surface factors into uniform cubic B-spline weights along
  // s times those along t (OpenSubdiv's EvalBasisBSpline builds its 16 weights as exactly that
  // product, and adjusts them on boundary and infinitely sharp edges one axis at a time). A grid
  // can therefore contract its 4×4 control points along t once per row and along s once per
  // vertex: 12 multiply-adds a vertex instead of OpenSubdiv's basis set-up and 48. Evaluated in
  // double like `eval`, so the two agree to the float rounding of the result (the bridge's
  // osd_shapes test holds every grid to `evaluate` within 1e-6 of the shape's size).
  bool is_regular(std::size_t patch) const {
    return type(patch) == Far::PatchDescriptor::REGULAR &&
           patch_table->GetPatchVertices(handle(patch)).size() == 16 &&
           crease_sharpness(patch) == 0.0f;
  }

  // The uniform cubic B-spline's weights and their derivatives at t, with the end conditions of
  // a boundary (or infinitely sharp) edge at the low and/or high end of the axis.
  static void bspline(double t, bool lo, bool hi, double w[4], double dw[4]) {
    const double t2 = t * t, t3 = t * t2;
    w[0] = (1.0 - 3.0 * (t - t2) - t3) / 6.0;
    w[1] = (4.0 - 6.0 * t2 + 3.0 * t3) / 6.0;
    w[2] = (1.0 + 3.0 * (t + t2 - t3)) / 6.0;
    w[3] = t3 / 6.0;
    dw[0] = -0.5 * t2 + t - 0.5;
    dw[1] = 1.5 * t2 - 2.0 * t;
    dw[2] = -1.5 * t2 + t + 0.5;
    dw[3] = 0.5 * t2;
    for (double* x : {w, dw}) {
      if (lo) {
        x[2] -= x[0];
        x[1] += 2.0 * x[0];
        x[0] = 0.0;
      }
      if (hi) {
        x[1] -= x[3];
        x[2] += 2.0 * x[3];
        x[3] = 0.0;
      }
    }
  }

  // The regular patch's boundary mask as end conditions: (s low, s high, t low, t high).
  void regular_ends(std::size_t patch, bool ends[4]) const {
    const int b = patch_table->GetPatchParam(handle(patch)).GetBoundary();
    ends[0] = b & 8;  // u = 0
    ends[1] = b & 2;  // u = 1
    ends[2] = b & 1;  // v = 0
    ends[3] = b & 4;  // v = 1
  }

  // Row j's control points contracted along t: r[a] = Σ_b w[b]·cv[4b + a] (and dr with dw).
  void contract_rows(std::size_t patch, const double tw[4], const double dtw[4], double r[4][3],
                     double dr[4][3]) const {
    Far::ConstIndexArray cvs = patch_table->GetPatchVertices(handle(patch));
    for (int a = 0; a < 4; ++a)
      for (int c = 0; c < 3; ++c) r[a][c] = dr[a][c] = 0.0;
    for (int b = 0; b < 4; ++b) {
      for (int a = 0; a < 4; ++a) {
        const float* cv = control_points.data() + 3 * std::size_t(cvs[4 * b + a]);
        for (int c = 0; c < 3; ++c) {
          r[a][c] += tw[b] * cv[c];
          dr[a][c] += dtw[b] * cv[c];
        }
      }
    }
  }

  // Positions of a regular patch at `count` points (u, v interleaved in `uv`): the patch's end
  // conditions and control points read once, and the points taken in runs along an axis (the
  // seam probes of a grid run along its edges): a run of one v contracts the control rows
  // along t once and each point only along s, a run of one u the columns along s once and each
  // point only along t; a point alone contracts rows (as a 1×1 grid would). Position only: no
  // derivative weights or rows.
  void eval_regular_points(std::size_t patch, const float* uv, std::size_t count, float* p) const {
    bool ends[4];
    regular_ends(patch, ends);
    Far::ConstIndexArray cvs = patch_table->GetPatchVertices(handle(patch));
    auto cv = [&](int b, int a) { return control_points.data() + 3 * std::size_t(cvs[4 * b + a]); };
    auto bits = [](float x) {
      std::uint32_t b;
      std::memcpy(&b, &x, sizeof b);
      return b;
    };
    double w_fixed[4], w_run[4], dw[4], line[4][3];
    for (std::size_t k = 0; k < count;) {
      const float u = uv[2 * k], v = uv[2 * k + 1];
      // The run: the points after k sharing its v (or, failing that, its u), bit for bit.
      std::size_t end = k + 1;
      while (end < count && bits(uv[2 * end + 1]) == bits(v)) ++end;
      const bool along_s = end > k + 1 || k + 1 == count || bits(uv[2 * (k + 1)]) != bits(u);
      if (!along_s)
        while (end < count && bits(uv[2 * end]) == bits(u)) ++end;
      // line[i] = Σ_j w_fixed[j] · cv(fixed axis j, i): rows along t for a run of one v,
      // columns along s for a run of one u.
      bspline(double(along_s ? v : u), ends[along_s ? 2 : 0], ends[along_s ? 3 : 1], w_fixed, dw);
      for (int i = 0; i < 4; ++i)
        for (int c = 0; c < 3; ++c) line[i][c] = 0.0;
      for (int j = 0; j < 4; ++j)
        for (int i = 0; i < 4; ++i) {
          const float* x = along_s ? cv(j, i) : cv(i, j);
          for (int c = 0; c < 3; ++c) line[i][c] += w_fixed[j] * x[c];
        }
      for (; k < end; ++k) {
        const float t = along_s ? uv[2 * k] : uv[2 * k + 1];
        bspline(double(t), ends[along_s ? 0 : 2], ends[along_s ? 1 : 3], w_run, dw);
        for (int c = 0; c < 3; ++c)
          p[3 * k + c] = float(w_run[0] * line[0][c] + w_run[1] * line[1][c] +
                               w_run[2] * line[2][c] + w_run[3] * line[3][c]);
      }
    }
  }

  // A regular patch's grid (see is_regular); du, dv may be null.
  void eval_regular_grid(std::size_t patch, float u0, float v0, float u1, float v1, std::size_t n,
                         float* p, float* du, float* dv) const {
    bool ends[4];
    regular_ends(patch, ends);
    eval_tensor_grid(
        patch, u0, v0, u1, v1, n, p, du, dv,
        [&](double u, double w[4], double dw[4]) { bspline(u, ends[0], ends[1], w, dw); },
        [&](double v, double w[4], double dw[4]) { bspline(v, ends[2], ends[3], w, dw); });
  }

  // A 2-float vertex primvar's grid on a regular patch (see is_regular): value, d/du, d/dv
  // (patch-local) interleaved, 6 floats a vertex. The rows along t contracted once per grid
  // row, as eval_regular_grid does for the points: a displaced grid's st at each vertex cost
  // an OpenSubdiv basis evaluation and a 16-point sum. False when a control point has no value.
  bool eval_regular_primvar_grid(std::size_t channel, std::size_t patch, float u0, float v0,
                                 float u1, float v1, std::size_t n, float* out) const {
    const std::vector<float>& values = vertex_primvars[channel];
    Far::ConstIndexArray cvs = patch_table->GetPatchVertices(handle(patch));
    for (int k = 0; k < cvs.size(); ++k)
      if (cvs[k] < 0 || 2 * std::size_t(cvs[k]) + 1 >= values.size()) return false;
    bool ends[4];
    regular_ends(patch, ends);
    const float d = float((n < 2 ? 2 : n) - 1);
    ColumnWeights columns(n);
    double *sw = columns.w, *dsw = columns.dw;
    for (std::size_t i = 0; i < n; ++i) {
      const float u = u0 + (u1 - u0) * (float(i) / d);
      bspline(double(u), ends[0], ends[1], &sw[4 * i], &dsw[4 * i]);
    }
    for (std::size_t j = 0; j < n; ++j) {
      const float v = v0 + (v1 - v0) * (float(j) / d);
      double tw[4], dtw[4], r[4][2] = {}, dr[4][2] = {};
      bspline(double(v), ends[2], ends[3], tw, dtw);
      for (int b = 0; b < 4; ++b)
        for (int a = 0; a < 4; ++a) {
          const float* x = values.data() + 2 * std::size_t(cvs[4 * b + a]);
          for (int c = 0; c < 2; ++c) {
            r[a][c] += tw[b] * x[c];
            dr[a][c] += dtw[b] * x[c];
          }
        }
      for (std::size_t i = 0; i < n; ++i) {
        const double* w = &sw[4 * i];
        const double* dw = &dsw[4 * i];
        float* o = out + 6 * (j * n + i);
        for (int c = 0; c < 2; ++c) {
          o[c] = float(w[0] * r[0][c] + w[1] * r[1][c] + w[2] * r[2][c] + w[3] * r[3][c]);
          o[2 + c] = float(dw[0] * r[0][c] + dw[1] * r[1][c] + dw[2] * r[2][c] + dw[3] * r[3][c]);
          o[4 + c] = float(w[0] * dr[0][c] + w[1] * dr[1][c] + w[2] * dr[2][c] + w[3] * dr[3][c]);
        }
      }
    }
    return true;
  }

  // A single-crease patch's grid (crease_sharpness > 0): its basis is a tensor product too (a
  // B-spline along the crease, the pieces' cubic across it), so rows are contracted once as on
  // a regular patch instead of evaluating all 16 weights and their second derivatives at every
  // vertex. du, dv may be null.
  void eval_crease_grid(std::size_t patch, double sharpness, float u0, float v0, float u1, float v1,
                        std::size_t n, float* p, float* du, float* dv) const {
    bool across_t, low;
    crease_edge(patch, across_t, low);
    CreasePiece pieces[3];
    const int np = crease_pieces(sharpness, pieces);
    auto along = [](double a, double w[4], double dw[4]) { bspline(a, false, false, w, dw); };
    auto across = [&](double x, double w[4], double dw[4]) {
      double c[3][4];
      crease_across(pieces, np, low, x, c);
      for (int j = 0; j < 4; ++j) {
        w[j] = c[0][j];
        dw[j] = c[1][j];
      }
    };
    if (across_t)
      eval_tensor_grid(patch, u0, v0, u1, v1, n, p, du, dv, along, across);
    else
      eval_tensor_grid(patch, u0, v0, u1, v1, n, p, du, dv, across, along);
  }

  // Positions of a single-crease patch at `count` points (u, v interleaved in `uv`): its
  // pieces and crease edge found once, each point's weights as a product of the cubic across
  // the crease and the B-spline along it (no derivatives: the seam and chord-error probes ask
  // for positions only).
  void eval_crease_points(std::size_t patch, double sharpness, const float* uv, std::size_t count,
                          float* p) const {
    bool across_t, low;
    crease_edge(patch, across_t, low);
    CreasePiece pieces[3];
    const int np = crease_pieces(sharpness, pieces);
    Far::ConstIndexArray cvs = patch_table->GetPatchVertices(handle(patch));
    for (std::size_t k = 0; k < count; ++k) {
      const double s = uv[2 * k], t = uv[2 * k + 1];
      double across[3][4], along[4], dalong[4];
      crease_across(pieces, np, low, across_t ? t : s, across);
      bspline(across_t ? s : t, false, false, along, dalong);
      const double* su = across_t ? along : across[0];
      const double* sv = across_t ? across[0] : along;
      double acc[3] = {0.0, 0.0, 0.0};
      for (int b = 0; b < 4; ++b)
        for (int i = 0; i < 4; ++i) {
          const double w = su[i] * sv[b];
          const float* c = control_points.data() + 3 * std::size_t(cvs[4 * b + i]);
          for (int a = 0; a < 3; ++a) acc[a] += w * c[a];
        }
      for (int a = 0; a < 3; ++a) p[3 * k + std::size_t(a)] = float(acc[a]);
    }
  }

  // A grid of a patch whose 16 weights are a tensor product: `s_weights(u, w, dw)` along s (the
  // control points' fastest index), `t_weights(v, w, dw)` along t, derivatives with respect to
  // the patch's local (s, t). du, dv may be null.
  template <class S, class T>
  void eval_tensor_grid(std::size_t patch, float u0, float v0, float u1, float v1, std::size_t n,
                        float* p, float* du, float* dv, S s_weights, T t_weights) const {
    // The same (u, v) as the general path (and UvRect::grid_uv) computes, in f32.
    const float d = float((n < 2 ? 2 : n) - 1);
    ColumnWeights columns(n);
    double *sw = columns.w, *dsw = columns.dw;
    for (std::size_t i = 0; i < n; ++i) {
      const float u = u0 + (u1 - u0) * (float(i) / d);
      s_weights(double(u), &sw[4 * i], &dsw[4 * i]);
    }
    for (std::size_t j = 0; j < n; ++j) {
      const float v = v0 + (v1 - v0) * (float(j) / d);
      double tw[4], dtw[4], r[4][3], dr[4][3];
      t_weights(double(v), tw, dtw);
      contract_rows(patch, tw, dtw, r, dr);
      for (std::size_t i = 0; i < n; ++i) {
        const double* w = &sw[4 * i];
        const double* dw = &dsw[4 * i];
        const std::size_t k = 3 * (j * n + i);
        for (int c = 0; c < 3; ++c) {
          p[k + c] = float(w[0] * r[0][c] + w[1] * r[1][c] + w[2] * r[2][c] + w[3] * r[3][c]);
          if (du) {
            du[k + c] = float(dw[0] * r[0][c] + dw[1] * r[1][c] + dw[2] * r[2][c] + dw[3] * r[3][c]);
            dv[k + c] = float(w[0] * dr[0][c] + w[1] * dr[1][c] + w[2] * dr[2][c] + w[3] * dr[3][c]);
          }
        }
      }
    }
  }

  // Pads bounds rounded to floats from doubles by a few ulps of their largest coordinate `mx`,
  // for the rounding of the conversion and of evaluation in floats.
  static void pad_bounds(double mx, float lo[3], float hi[3]) {
    const float pad = float(8.0 * std::numeric_limits<float>::epsilon() * mx);
    for (int c = 0; c < 3; ++c) {
      lo[c] -= pad;
      hi[c] += pad;
    }
  }

  // Bounds of a regular patch from its Bézier control points: the B-spline control points
  // (with a boundary edge's phantom row or column, 2·P1 − P2, as its end weights imply) turned
  // into Bézier form along s and t, whose convex hull holds the patch. The B-spline hull reaches
  // a whole span beyond the patch on every side; this one hugs it, so rays test fewer subpatches
  // and the tracer sizes rates by the patch rather than by its neighbourhood. Padded by a few
  // ulps of the coordinates for the rounding of the conversion and of evaluation in floats.
  void regular_bezier_bounds(std::size_t patch, float lo[3], float hi[3]) const {
    double b[4][4][3];
    regular_bezier_net(patch, b);
    double mx = 0.0;
    for (int c = 0; c < 3; ++c) {
      double l = std::numeric_limits<double>::infinity(), h = -l;
      for (int r = 0; r < 4; ++r)
        for (int a = 0; a < 4; ++a) {
          l = std::min(l, b[r][a][c]);
          h = std::max(h, b[r][a][c]);
        }
      lo[c] = float(l);
      hi[c] = float(h);
      mx = std::max({mx, std::fabs(l), std::fabs(h)});
    }
    pad_bounds(mx, lo, hi);
  }

  // A regular patch's Bézier control net, b[t row][s column][xyz] (see regular_bezier_bounds).
  void regular_bezier_net(std::size_t patch, double b[4][4][3]) const {
    Far::ConstIndexArray cvs = patch_table->GetPatchVertices(handle(patch));
    bool ends[4];
    regular_ends(patch, ends);
    double q[4][4][3];  // [t row][s column][xyz]
    for (int r = 0; r < 4; ++r)
      for (int a = 0; a < 4; ++a)
        for (int c = 0; c < 3; ++c)
          q[r][a][c] = control_points[3 * std::size_t(cvs[4 * r + a]) + std::size_t(c)];
    for (int c = 0; c < 3; ++c) {
      for (int r = 0; r < 4; ++r) {
        if (ends[0]) q[r][0][c] = 2.0 * q[r][1][c] - q[r][2][c];
        if (ends[1]) q[r][3][c] = 2.0 * q[r][2][c] - q[r][1][c];
      }
      for (int a = 0; a < 4; ++a) {
        if (ends[2]) q[0][a][c] = 2.0 * q[1][a][c] - q[2][a][c];
        if (ends[3]) q[3][a][c] = 2.0 * q[2][a][c] - q[1][a][c];
      }
    }
    auto to_bezier = [](double p0, double p1, double p2, double p3, double out[4]) {
      out[0] = (p0 + 4.0 * p1 + p2) / 6.0;
      out[1] = (2.0 * p1 + p2) / 3.0;
      out[2] = (p1 + 2.0 * p2) / 3.0;
      out[3] = (p1 + 4.0 * p2 + p3) / 6.0;
    };
    for (int c = 0; c < 3; ++c) {
      double rows[4][4];  // Bézier along s, per B-spline row
      for (int r = 0; r < 4; ++r) to_bezier(q[r][0][c], q[r][1][c], q[r][2][c], q[r][3][c], rows[r]);
      for (int a = 0; a < 4; ++a) {
        double col[4];
        to_bezier(rows[0][a], rows[1][a], rows[2][a], rows[3][a], col);
        for (int r = 0; r < 4; ++r) b[r][a][c] = col[r];
      }
    }
  }

  // A cone holding the direction of dP/ds × dP/dt over a regular patch, up to sign: axis into
  // out[0..3], the sine of its half-angle into out[3]. dP/ds is a non-negative combination of
  // the Bézier net's differences along s, so it lies in their cone (axis a, half-angle α); so
  // for t (b, β). For unit u within α of a and v within β of b, |u×v − a×b| ≤ |u−a| + |v−b| ≤
  // 2 sin(α/2) + 2 sin(β/2) =: δ, so the angle γ between u×v and a×b has
  // sin γ ≤ δ / (|a×b| − δ). False when a cone is not narrower than a half-space, a difference
  // vanishes, or δ is not below |a×b| (then no cone is claimed).
  bool regular_normal_cone(std::size_t patch, double out[4]) const {
    double b[4][4][3];
    regular_bezier_net(patch, b);
    // The 12 differences' cone: axis the sum of their directions, half-angle to the farthest.
    auto cone = [](const double (*d)[3], double axis[3], double& sin_half) -> bool {
      double len[12], mx = 0.0;
      for (int k = 0; k < 12; ++k) {
        len[k] = std::sqrt(d[k][0] * d[k][0] + d[k][1] * d[k][1] + d[k][2] * d[k][2]);
        mx = std::max(mx, len[k]);
      }
      if (!(mx > 0.0) || !std::isfinite(mx)) return false;
      double sum[3] = {0, 0, 0};
      for (int k = 0; k < 12; ++k) {
        if (!(len[k] > 1e-9 * mx)) return false;
        for (int c = 0; c < 3; ++c) sum[c] += d[k][c] / len[k];
      }
      const double ls = std::sqrt(sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]);
      if (!(ls > 0.0)) return false;
      for (int c = 0; c < 3; ++c) axis[c] = sum[c] / ls;
      double min_cos = 1.0;
      for (int k = 0; k < 12; ++k)
        min_cos = std::min(min_cos, (d[k][0] * axis[0] + d[k][1] * axis[1] + d[k][2] * axis[2]) / len[k]);
      if (!(min_cos > 0.0)) return false;
      // sin(α/2) = sqrt((1 − cos α) / 2)
      sin_half = std::sqrt(std::max(0.0, (1.0 - min_cos) * 0.5));
      return true;
    };
    double du[12][3], dv[12][3];
    int k = 0;
    for (int r = 0; r < 4; ++r)
      for (int a = 0; a < 3; ++a, ++k)
        for (int c = 0; c < 3; ++c) du[k][c] = b[r][a + 1][c] - b[r][a][c];
    k = 0;
    for (int r = 0; r < 3; ++r)
      for (int a = 0; a < 4; ++a, ++k)
        for (int c = 0; c < 3; ++c) dv[k][c] = b[r + 1][a][c] - b[r][a][c];
    double a[3], bb[3], sa = 0.0, sb = 0.0;
    if (!cone(du, a, sa) || !cone(dv, bb, sb)) return false;
    const double n[3] = {a[1] * bb[2] - a[2] * bb[1], a[2] * bb[0] - a[0] * bb[2], a[0] * bb[1] - a[1] * bb[0]};
    const double ln = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
    const double delta = 2.0 * sa + 2.0 * sb;
    if (!(ln - delta > 1e-12)) return false;
    const double sin_g = delta / (ln - delta);
    if (!(sin_g < 1.0)) return false;
    for (int c = 0; c < 3; ++c) out[c] = n[c] / ln;
    out[3] = sin_g;
    return true;
  }

  // A single-crease patch (crease_sharpness > 0): a regular patch one of whose edges is a
  // semi-sharp crease running straight through its 4×4 control points (OpenSubdiv's
  // useSingleCreasePatch, which stops isolating such faces). There Catmull-Clark's rules are the
  // tensor product of the uniform cubic B-spline's along the crease and, across it, the curve's
  // rules with the crease row held in place (interpolated) for as many levels as the sharpness
  // lasts, so the limit is the B-spline along the crease times a piecewise cubic across it. With
  // the crease at x = 1 and S = ⌊S⌋ + r its sharpness: on [0, 1 − 2^−⌊S⌋] the infinitely sharp
  // (boundary) cubic, which the first ⌊S⌋ levels share with it; on [1 − 2^−⌈S⌉, 1] the smooth
  // patch of level ⌈S⌉, whose rows are linear in r; between them the level-⌈S⌉ patch away from
  // the crease, a blend of the two. OpenSubdiv's GPU patches (glslPatchCommon.glsl,
  // OsdComputeMs) hold these cubics as Bézier points over the whole [0, 1]; Far's CPU
  // EvaluateBasis ignores the sharpness, so the bridge evaluates them itself. The pieces match
  // a level-by-level refinement to rounding (a crease sharper than the isolation level allows
  // is clamped by OpenSubdiv to that level, as full isolation would treat it).
  struct CreasePiece {
    double from, to;   // the piece's span of x
    double m[4][4];    // [Bézier point][B-spline control point, crease at index 2]
  };

  // The pieces of `sharpness` (> 0), in order of x; empty spans are left out.
  static int crease_pieces(double sharpness, CreasePiece out[3]) {
    // OsdComputeMs: the smooth level-S patch next to the crease after S sharp levels.
    auto ms = [](double sh, double m[4][4]) {
      const double s = std::exp2(sh), s2 = s * s, s3 = s2 * s, d = 6.0 * s;
      const double r[4][4] = {{s, s + 1 + 3 * s2 - s3, 7 * s - 2 - 6 * s2 + 2 * s3, (1 - s) * (s - 1) * (s - 1)},
                              {0, (1 + s) * (1 + s), 6 * s - 2 - 2 * s2, (s - 1) * (s - 1)},
                              {0, 1 + s, 6 * s - 2, 1 - s},
                              {0, 1, 6 * s - 2, 1}};
      for (int i = 0; i < 4; ++i)
        for (int k = 0; k < 4; ++k) m[i][k] = r[i][k] / d;
    };
    static const double mi[4][4] = {{1.0 / 6, 4.0 / 6, 1.0 / 6, 0},
                                    {0, 4.0 / 6, 2.0 / 6, 0},
                                    {0, 2.0 / 6, 4.0 / 6, 0},
                                    {0, 0, 1, 0}};
    const double sf = std::floor(sharpness), sc = std::ceil(sharpness), sr = sharpness - sf;
    double mf[4][4], mc[4][4];
    ms(sf, mf);
    ms(sc, mc);
    const double s0 = 1.0 - std::exp2(-sf), s1 = 1.0 - std::exp2(-sc);
    int n = 0;
    if (s0 > 0.0) {
      out[n] = CreasePiece{0.0, s0, {}};
      std::memcpy(out[n].m, mi, sizeof mi);
      ++n;
    }
    if (s1 > s0) {
      out[n] = CreasePiece{s0, s1, {}};
      for (int i = 0; i < 4; ++i)
        for (int k = 0; k < 4; ++k) out[n].m[i][k] = (1.0 - sr) * mf[i][k] + sr * mi[i][k];
      ++n;
    }
    out[n] = CreasePiece{s1, 1.0, {}};
    for (int i = 0; i < 4; ++i)
      for (int k = 0; k < 4; ++k) out[n].m[i][k] = (1.0 - sr) * mf[i][k] + sr * mc[i][k];
    return n + 1;
  }

  // The crease's edge: whether it crosses t (lies on t = 0 or 1) and whether it is on the low
  // edge (u = 0 or v = 0). OpenSubdiv marks it in the param's boundary bits.
  void crease_edge(std::size_t patch, bool& across_t, bool& low) const {
    const int b = patch_table->GetPatchParam(handle(patch)).GetBoundary();
    across_t = (b & 5) != 0;  // 1: v = 0, 4: v = 1
    low = (b & 9) != 0;       // 1: v = 0, 8: u = 0
  }

  // The cubic across a single-crease patch's crease at the patch's parameter `param` across
  // it: its 4 weights (out[0]) and their first and second derivatives with respect to `param`
  // (out[1], out[2]), for the control points in the patch's own order across the crease.
  static void crease_across(const CreasePiece pieces[3], int n, bool low, double param, double out[3][4]) {
    const double x = low ? 1.0 - param : param;
    int k = 0;
    while (k + 1 < n && x > pieces[k].to) ++k;
    const double y = 1.0 - x;
    const double bern[3][4] = {{y * y * y, 3 * x * y * y, 3 * x * x * y, x * x * x},
                               {-3 * y * y, 3 * y * y - 6 * x * y, 6 * x * y - 3 * x * x, 3 * x * x},
                               {6 * y, 18 * x - 12, 6 - 18 * x, 6 * x}};
    double c[3][4] = {};  // across the crease: weight, d/dx, d²/dx², crease at index 2
    for (int d = 0; d < 3; ++d)
      for (int i = 0; i < 4; ++i)
        for (int j = 0; j < 4; ++j) c[d][j] += bern[d][i] * pieces[k].m[i][j];
    for (int j = 0; j < 4; ++j)
      for (int d = 0; d < 3; ++d) out[d][j] = low ? (d == 1 ? -c[d][3 - j] : c[d][3 - j]) : c[d][j];
  }

  // The 16 weights of a single-crease patch at local (s, t), and their derivatives with
  // respect to s and t (all six sets; the caller ignores what it did not ask for).
  void crease_basis(std::size_t patch, double sharpness, double s, double t, double w[16],
                    double wu[16], double wv[16], double wuu[16], double wuv[16],
                    double wvv[16]) const {
    bool across_t, low;
    crease_edge(patch, across_t, low);
    CreasePiece pieces[3];
    const int n = crease_pieces(sharpness, pieces);
    double across[3][4];
    crease_across(pieces, n, low, across_t ? t : s, across);
    double along[3][4];
    const double a = across_t ? s : t;
    bspline(a, false, false, along[0], along[1]);
    along[2][0] = 1.0 - a;
    along[2][1] = 3.0 * a - 2.0;
    along[2][2] = 1.0 - 3.0 * a;
    along[2][3] = a;
    const double(*su)[4] = across_t ? along : across;  // along s: weights, d, d²
    const double(*sv)[4] = across_t ? across : along;  // along t
    for (int b = 0; b < 4; ++b)
      for (int i = 0; i < 4; ++i) {
        const int q = 4 * b + i;
        w[q] = su[0][i] * sv[0][b];
        wu[q] = su[1][i] * sv[0][b];
        wv[q] = su[0][i] * sv[1][b];
        wuu[q] = su[2][i] * sv[0][b];
        wuv[q] = su[1][i] * sv[1][b];
        wvv[q] = su[0][i] * sv[2][b];
      }
  }

  // Bounds of a single-crease patch: each piece's cubic across the crease cut to its span (the
  // blossoms at its ends) and turned into Bézier form along the crease; the union of the
  // pieces' Bézier hulls, padded as regular_bezier_bounds pads.
  void crease_bounds(std::size_t patch, double sharpness, float lo[3], float hi[3]) const {
    bool across_t, low;
    crease_edge(patch, across_t, low);
    Far::ConstIndexArray cvs = patch_table->GetPatchVertices(handle(patch));
    // g[k][i]: the control point k across the crease (crease at k = 2) and i along it.
    double g[4][4][3];
    for (int k = 0; k < 4; ++k)
      for (int i = 0; i < 4; ++i) {
        const int j = low ? 3 - k : k;
        const int q = across_t ? 4 * j + i : 4 * i + j;
        for (int c = 0; c < 3; ++c) g[k][i][c] = control_points[3 * std::size_t(cvs[q]) + std::size_t(c)];
      }
    CreasePiece pieces[3];
    const int n = crease_pieces(sharpness, pieces);
    auto to_bezier = [](const double p[4], double out[4]) {
      out[0] = (p[0] + 4.0 * p[1] + p[2]) / 6.0;
      out[1] = (2.0 * p[1] + p[2]) / 3.0;
      out[2] = (p[1] + 2.0 * p[2]) / 3.0;
      out[3] = (p[1] + 4.0 * p[2] + p[3]) / 6.0;
    };
    double mx = 0.0;
    for (int c = 0; c < 3; ++c) {
      double l = std::numeric_limits<double>::infinity(), h = -l;
      for (int p = 0; p < n; ++p) {
        const CreasePiece& piece = pieces[p];
        double sub[4][4];  // [Bézier point across, over the piece's span][control point along]
        for (int i = 0; i < 4; ++i) {
          double bz[4];  // Bézier points across the crease over the whole [0, 1]
          for (int r = 0; r < 4; ++r) {
            bz[r] = 0.0;
            for (int k = 0; k < 4; ++k) bz[r] += piece.m[r][k] * g[k][i][c];
          }
          // Over [a, b] the cubic's Bézier points are its blossoms f(a,a,a), f(a,a,b), f(a,b,b),
          // f(b,b,b): de Casteljau with a different parameter at each level.
          auto blossom = [&bz](double x1, double x2, double x3) {
            double q[4] = {bz[0], bz[1], bz[2], bz[3]};
            const double xs[3] = {x1, x2, x3};
            for (int level = 0; level < 3; ++level)
              for (int m = 0; m < 3 - level; ++m) q[m] = (1.0 - xs[level]) * q[m] + xs[level] * q[m + 1];
            return q[0];
          };
          const double a = piece.from, b = piece.to;
          sub[0][i] = blossom(a, a, a);
          sub[1][i] = blossom(a, a, b);
          sub[2][i] = blossom(a, b, b);
          sub[3][i] = blossom(b, b, b);
        }
        for (int r = 0; r < 4; ++r) {
          double bez[4];
          to_bezier(sub[r], bez);
          for (double x : bez) {
            l = std::min(l, x);
            h = std::max(h, x);
          }
        }
      }
      lo[c] = float(l);
      hi[c] = float(h);
      mx = std::max({mx, std::fabs(l), std::fabs(h)});
    }
    pad_bounds(mx, lo, hi);
  }

  // Evaluates at the patch's local (s, t). Derivative outputs may be null (then not computed);
  // second derivatives are computed only when all three are given.
  void eval(std::size_t patch, float s, float t, float* p, float* du, float* dv, float* duu,
            float* duv, float* dvv) const noexcept {
    const Far::PatchTable::PatchHandle h = handle(patch);
    const Far::PatchParam param = patch_table->GetPatchParam(h);
    const bool tri = is_triangle_type(type(patch));
    const bool rotated = tri && param.IsTriangleRotated();
    // EvaluateBasis takes (u, v) in the ptex face's parameterization and normalizes them with
    // the PatchParam; map the local (s, t) out the same way so it lands back on (s, t). Double
    // keeps the round trip from eating low bits at deep levels.
    double w[kMaxPatchPoints], wu[kMaxPatchPoints], wv[kMaxPatchPoints];
    double wuu[kMaxPatchPoints], wuv[kMaxPatchPoints], wvv[kMaxPatchPoints];
    const bool d1 = du && dv;
    const bool d2 = d1 && duu && duv && dvv;
    // OpenSubdiv scales the normalized basis derivatives by 2^depth (negated for rotated
    // triangles) and the second derivatives by sign × (sign × 2^depth)² (Far's
    // internal::EvaluatePatchBasis). Dividing by exactly those factors gives derivatives with
    // respect to the patch's local (s, t), which is what mipray's LimitSurface promises.
    double s1 = 1.0, s2 = 1.0;
    const float sharpness = crease_sharpness(patch);
    if (sharpness > 0.0f) {
      crease_basis(patch, double(sharpness), double(s), double(t), w, wu, wv, wuu, wuv, wvv);
    } else {
      double fu = s, fv = t;
      if (tri)
        param.UnnormalizeTriangle(fu, fv);
      else
        param.Unnormalize(fu, fv);
      patch_table->EvaluateBasis(h, fu, fv, w, d1 ? wu : nullptr, d1 ? wv : nullptr,
                                 d2 ? wuu : nullptr, d2 ? wuv : nullptr, d2 ? wvv : nullptr);
      const double sign = rotated ? -1.0 : 1.0;
      s1 = sign * double(1 << param.GetDepth());
      s2 = sign * s1 * s1;
    }

    Far::ConstIndexArray cvs = patch_table->GetPatchVertices(h);
    // One pass per set of weights asked for (each accumulator sums in control point order, as
    // one interleaved loop would), so a position-only call does none of the derivatives' work.
    double acc[6][3] = {};
    const double* weights[6] = {w, wu, wv, wuu, wuv, wvv};
    const int sets = d2 ? 6 : d1 ? 3 : 1;
    for (int set = 0; set < sets; ++set) {
      const double* ws = weights[set];
      for (int k = 0; k < cvs.size(); ++k) {
        const float* c = control_points.data() + 3 * std::size_t(cvs[k]);
        for (int a = 0; a < 3; ++a) acc[set][a] += ws[k] * c[a];
      }
    }
    for (int a = 0; a < 3; ++a) {
      p[a] = float(acc[0][a]);
      if (d1) {
        du[a] = float(acc[1][a] / s1);
        dv[a] = float(acc[2][a] / s1);
      }
      if (d2) {
        duu[a] = float(acc[3][a] / s2);
        duv[a] = float(acc[4][a] / s2);
        dvv[a] = float(acc[5][a] / s2);
      }
    }
  }
};

// Primvar channel `channel` (face-varying, or vertex when `vertex`) at the patch's local (s, t):
// value, d/ds, d/dt (2 floats each) into out[0..6]. False if an index falls outside the values.
static bool eval_primvar(const OsdMesh::Impl& m, bool vertex, std::size_t channel, std::size_t patch,
                  float s, float t, float* out) noexcept {
  const std::vector<float>& values =
      vertex ? m.vertex_primvars[channel] : m.fvar_values[channel];
  const Far::PatchTable::PatchHandle h = m.handle(patch);
  const Far::PatchParam param = m.patch_table->GetPatchParam(h);
  const bool tri = is_triangle_type(m.type(patch));
  // As in eval: out to the ptex face through the vertex patch's parameterization (the
  // face-varying patch covers the same part of the face), and derivatives back by its factor.
  double fu = s, fv = t;
  if (tri)
    param.UnnormalizeTriangle(fu, fv);
  else
    param.Unnormalize(fu, fv);
  double w[kMaxPatchPoints], wu[kMaxPatchPoints], wv[kMaxPatchPoints];
  double wuu[kMaxPatchPoints], wuv[kMaxPatchPoints], wvv[kMaxPatchPoints];
  Far::ConstIndexArray cvs;
  const float sharpness = vertex ? m.crease_sharpness(patch) : 0.0f;
  if (sharpness > 0.0f) {
    // Vertex primvars follow the points' patches; the basis is already in local (s, t).
    m.crease_basis(patch, double(sharpness), double(s), double(t), w, wu, wv, wuu, wuv, wvv);
    cvs = m.patch_table->GetPatchVertices(h);
  } else if (vertex) {
    m.patch_table->EvaluateBasis(h, fu, fv, w, wu, wv);
    cvs = m.patch_table->GetPatchVertices(h);
  } else {
    m.patch_table->EvaluateBasisFaceVarying(h, fu, fv, w, wu, wv, nullptr, nullptr, nullptr,
                                            int(channel));
    cvs = m.patch_table->GetPatchFVarValues(h, int(channel));
  }
  if (cvs.size() > kMaxPatchPoints) return false;
  const double sign = (tri && param.IsTriangleRotated()) ? -1.0 : 1.0;
  const double s1 = sharpness > 0.0f ? 1.0 : sign * double(1 << param.GetDepth());
  double acc[3][2] = {};
  for (int k = 0; k < cvs.size(); ++k) {
    const std::size_t i = 2 * std::size_t(cvs[k]);
    if (cvs[k] < 0 || i + 1 >= values.size()) return false;
    for (int a = 0; a < 2; ++a) {
      acc[0][a] += w[k] * values[i + a];
      acc[1][a] += wu[k] * values[i + a];
      acc[2][a] += wv[k] * values[i + a];
    }
  }
  for (int a = 0; a < 2; ++a) {
    out[a] = float(acc[0][a]);
    out[2 + a] = float(acc[1][a] / s1);
    out[4 + a] = float(acc[2][a] / s1);
  }
  return true;
}

OsdMesh::OsdMesh() : impl(new Impl) {}
OsdMesh::~OsdMesh() = default;

rust::String OsdMesh::warnings() const { return rust::String(impl->warnings); }
rust::String OsdMesh::simplified() const { return rust::String(impl->simplified); }

std::size_t OsdMesh::ptex_face_count() const {
  return std::size_t(impl->patch_table->GetNumPtexFaces());
}

rust::Vec<OsdPatchInfo> OsdMesh::patch_infos() const {
  rust::Vec<OsdPatchInfo> out;
  out.reserve(impl->num_patches);
  for (std::size_t i = 0; i < impl->num_patches; ++i) {
    const Far::PatchParam param = impl->patch_table->GetPatchParam(impl->handle(i));
    const Far::PatchDescriptor::Type type = impl->type(i);
    const bool tri = is_triangle_type(type);
    const float frac = param.GetParamFraction();
    OsdPatchInfo info{};
    info.ptex_face = param.GetFaceId();
    info.base_face =
        (info.ptex_face >= 0 && std::size_t(info.ptex_face) < impl->ptex_to_base.size())
            ? impl->ptex_to_base[std::size_t(info.ptex_face)]
            : -1;
    if (tri && param.IsTriangleRotated()) {
      // A rotated triangle runs from its corner ((2^depth − U)·frac, (2^depth − V)·frac) in the
      // negative directions (PatchParam::UnnormalizeTriangle): a negative size says so, and
      // keeps u0 + u·size the exact map from local to face (u, v).
      const int depth_factor = 1 << param.GetDepth();
      info.u0 = float(depth_factor - param.GetU()) * frac;
      info.v0 = float(depth_factor - param.GetV()) * frac;
      info.size = -frac;
    } else {
      info.u0 = float(param.GetU()) * frac;
      info.v0 = float(param.GetV()) * frac;
      info.size = frac;
    }
    info.depth = uint8_t(param.GetDepth());
    // A single-crease patch's param marks its crease edge in the boundary bits; it is interior.
    info.boundary = impl->crease_sharpness(i) > 0.0f ? 0 : uint8_t(param.GetBoundary());
    info.transition = uint8_t(param.GetTransition());
    info.kind = kind_code(type);
    out.push_back(info);
  }
  return out;
}

bool OsdMesh::patch_bound(std::size_t patch, rust::Slice<float> out) const noexcept {
  if (patch >= impl->num_patches || out.size() < 6) return false;
  float lo[3] = {std::numeric_limits<float>::infinity(), std::numeric_limits<float>::infinity(),
                 std::numeric_limits<float>::infinity()};
  float hi[3] = {-lo[0], -lo[1], -lo[2]};
  const float sharpness = impl->crease_sharpness(patch);
  if (impl->is_regular(patch)) {
    impl->regular_bezier_bounds(patch, lo, hi);
  } else if (sharpness > 0.0f) {
    impl->crease_bounds(patch, double(sharpness), lo, hi);
  } else {
    Far::ConstIndexArray cvs = impl->patch_table->GetPatchVertices(impl->handle(patch));
    for (int k = 0; k < cvs.size(); ++k) {
      const float* c = impl->control_points.data() + 3 * std::size_t(cvs[k]);
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], c[a]);
        hi[a] = std::max(hi[a], c[a]);
      }
    }
  }
  for (int a = 0; a < 3; ++a) {
    out[std::size_t(a)] = lo[a];
    out[std::size_t(a) + 3] = hi[a];
  }
  return true;
}

bool OsdMesh::patch_normal_cone(std::size_t patch, rust::Slice<float> out) const noexcept {
  if (patch >= impl->num_patches || out.size() < 4 || !impl->is_regular(patch)) return false;
  double c[4];
  if (!impl->regular_normal_cone(patch, c)) return false;
  for (int k = 0; k < 4; ++k) out[std::size_t(k)] = float(c[k]);
  return true;
}

uint8_t OsdMesh::edge_knots(std::size_t patch, rust::Slice<float> out) const noexcept {
  if (patch >= impl->num_patches || out.size() < 2) return 0;
  const float sharpness = impl->crease_sharpness(patch);
  if (!(sharpness > 0.0f)) return 0;
  bool across_t, low;
  impl->crease_edge(patch, across_t, low);
  OsdMesh::Impl::CreasePiece pieces[3];
  const int n = OsdMesh::Impl::crease_pieces(double(sharpness), pieces);
  out[0] = out[1] = std::numeric_limits<float>::quiet_NaN();
  // The pieces' inner ends, from the crease at x = 1 back to the patch's own parameter.
  for (int k = 0; k + 1 < n && k < 2; ++k) {
    const double x = pieces[k].to;
    out[std::size_t(k)] = float(low ? 1.0 - x : x);
  }
  return across_t ? 2 : 1;
}

rust::Vec<uint64_t> OsdMesh::memory_parts() const {
  auto bytes = [](const auto& v) { return uint64_t(v.capacity() * sizeof(v[0])); };
  const Far::PatchTable& t = *impl->patch_table;
  uint64_t stencils = 0;
  if (const Far::StencilTable* st = t.GetLocalPointStencilTable())
    stencils = bytes(st->GetSizes()) + bytes(st->GetOffsets()) + bytes(st->GetControlIndices()) +
               bytes(st->GetWeights());
  uint64_t primvars = 0;
  for (const auto& v : impl->fvar_values) primvars += bytes(v);
  for (const auto& v : impl->vertex_primvars) primvars += bytes(v);
  rust::Vec<uint64_t> out;
  out.push_back(bytes(impl->control_points));
  out.push_back(bytes(t.GetPatchControlVerticesTable()));
  // With single-crease patches, each patch's sharpness index (and the few distinct values).
  out.push_back(bytes(t.GetPatchParamTable()) + bytes(t.GetSharpnessIndexTable()) +
                bytes(t.GetSharpnessValues()));
  out.push_back(stencils);
  out.push_back(bytes(impl->arrays) + bytes(impl->ptex_to_base));
  out.push_back(primvars);
  return out;
}

bool OsdMesh::base_points(rust::Slice<float> out) const noexcept {
  if (out.size() != 3 * std::size_t(impl->num_base_points)) return false;
  std::copy(impl->control_points.begin(), impl->control_points.begin() + std::ptrdiff_t(out.size()),
            out.data());
  return true;
}

void OsdMesh::update_points(const OsdMeshDesc& desc, rust::Slice<const float> points) {
  if (points.size() != 3 * std::size_t(impl->num_base_points))
    throw std::runtime_error("update_points: the point count differs from the mesh's");
  check_desc(desc, points.size());
  // The refinement is not kept (it is most of a mesh's memory): refined again, it numbers the
  // vertices as the first time.
  FarCapture capture;
  RefinerPtr refiner = create_refiner(desc, capture);
  refine_adaptive(*refiner, desc, capture);
  // A patch table of its own for the end caps' stencils (the kept one's are released).
  std::unique_ptr<Far::PatchTable> table(
      Far::PatchTableFactory::Create(*refiner, patch_options_of(desc, bilinear_end_caps(*refiner))));
  if (!table) capture.fail("OpenSubdiv could not build the patch table");
  capture.check("OpenSubdiv patch table");
  impl->set_points(*refiner, *table, points.data());
}

bool OsdMesh::evaluate(std::size_t patch, float u, float v, rust::Slice<float> out) const noexcept {
  if (patch >= impl->num_patches || out.size() < 18) return false;
  float* o = out.data();
  impl->eval(patch, u, v, o, o + 3, o + 6, o + 9, o + 12, o + 15);
  return true;
}

bool OsdMesh::evaluate_grid(std::size_t patch, float u0, float v0, float u1, float v1,
                            std::size_t n, rust::Slice<float> p, rust::Slice<float> du,
                            rust::Slice<float> dv) const noexcept {
  const bool derivs = !du.empty();
  if (patch >= impl->num_patches || n == 0 || p.size() != 3 * n * n) return false;
  if (derivs && (du.size() != p.size() || dv.size() != p.size())) return false;
  if (impl->is_regular(patch)) {
    try {
      impl->eval_regular_grid(patch, u0, v0, u1, v1, n, p.data(), derivs ? du.data() : nullptr,
                              derivs ? dv.data() : nullptr);
      return true;
    } catch (...) {
      return false;  // std::bad_alloc of the weight rows: nothing may cross into Rust
    }
  }
  if (const float sharpness = impl->crease_sharpness(patch); sharpness > 0.0f) {
    try {
      impl->eval_crease_grid(patch, double(sharpness), u0, v0, u1, v1, n, p.data(),
                             derivs ? du.data() : nullptr, derivs ? dv.data() : nullptr);
      return true;
    } catch (...) {
      return false;
    }
  }
  // The same (u, v) as UvRect::grid_uv computes in Rust, in the same f32 arithmetic, so a grid
  // vertex equals the single evaluation at that vertex.
  const float d = float((n < 2 ? 2 : n) - 1);
  for (std::size_t j = 0; j < n; ++j) {
    const float v = v0 + (v1 - v0) * (float(j) / d);
    for (std::size_t i = 0; i < n; ++i) {
      const float u = u0 + (u1 - u0) * (float(i) / d);
      const std::size_t k = 3 * (j * n + i);
      impl->eval(patch, u, v, p.data() + k, derivs ? du.data() + k : nullptr,
                 derivs ? dv.data() + k : nullptr, nullptr, nullptr, nullptr);
    }
  }
  return true;
}

bool OsdMesh::evaluate_points(std::size_t patch, rust::Slice<const float> uv,
                              rust::Slice<float> p) const noexcept {
  if (patch >= impl->num_patches || uv.size() % 2 != 0 || p.size() != uv.size() / 2 * 3)
    return false;
  if (impl->is_regular(patch)) {
    impl->eval_regular_points(patch, uv.data(), uv.size() / 2, p.data());
    return true;
  }
  if (const float sharpness = impl->crease_sharpness(patch); sharpness > 0.0f) {
    impl->eval_crease_points(patch, double(sharpness), uv.data(), uv.size() / 2, p.data());
    return true;
  }
  for (std::size_t k = 0; 2 * k < uv.size(); ++k)
    impl->eval(patch, uv[2 * k], uv[2 * k + 1], p.data() + 3 * k, nullptr, nullptr, nullptr,
               nullptr, nullptr);
  return true;
}

int64_t OsdMesh::find_patch(int32_t ptex_face, float u, float v,
                            rust::Slice<float> local_uv) const noexcept {
  if (local_uv.size() < 2 || ptex_face < 0 || ptex_face >= impl->patch_table->GetNumPtexFaces())
    return -1;
  try {
    std::call_once(impl->patch_map_once,
                   [&] { impl->patch_map = std::make_unique<Far::PatchMap>(*impl->patch_table); });
  } catch (...) {
    return -1;  // std::bad_alloc: nothing may cross into Rust (call_once tries again next time)
  }
  const Far::PatchMap::Handle* h = impl->patch_map->FindPatch(ptex_face, double(u), double(v));
  if (!h) return -1;
  const std::size_t patch = std::size_t(h->patchIndex);
  if (patch >= impl->num_patches) return -1;
  const Far::PatchParam param = impl->patch_table->GetPatchParam(*h);
  double s = u, t = v;
  if (is_triangle_type(impl->type(patch)))
    param.NormalizeTriangle(s, t);
  else
    param.Normalize(s, t);
  local_uv[0] = float(s);
  local_uv[1] = float(t);
  return int64_t(patch);
}

std::size_t OsdMesh::fvar_channel_count() const noexcept { return impl->fvar_values.size(); }

std::size_t OsdMesh::vertex_primvar_count() const noexcept { return impl->vertex_primvars.size(); }

bool OsdMesh::evaluate_primvar(bool vertex, std::size_t channel, std::size_t patch, float u,
                               float v, rust::Slice<float> out) const noexcept {
  const std::size_t channels = vertex ? impl->vertex_primvars.size() : impl->fvar_values.size();
  if (channel >= channels || patch >= impl->num_patches || out.size() < 6) return false;
  return eval_primvar(*impl, vertex, channel, patch, u, v, out.data());
}

bool OsdMesh::evaluate_primvar_grid(bool vertex, std::size_t channel, std::size_t patch,
                                    float u0, float v0, float u1, float v1, std::size_t n,
                                    rust::Slice<float> out) const noexcept {
  const std::size_t channels = vertex ? impl->vertex_primvars.size() : impl->fvar_values.size();
  if (channel >= channels || patch >= impl->num_patches || n == 0 || out.size() != 6 * n * n)
    return false;
  if (vertex && impl->is_regular(patch)) {
    try {
      return impl->eval_regular_primvar_grid(channel, patch, u0, v0, u1, v1, n, out.data());
    } catch (...) {
      return false;  // std::bad_alloc of the weight rows: nothing may cross into Rust
    }
  }
  // The same (u, v) as UvRect::grid_uv computes in Rust (see evaluate_grid).
  const float d = float((n < 2 ? 2 : n) - 1);
  for (std::size_t j = 0; j < n; ++j) {
    const float v = v0 + (v1 - v0) * (float(j) / d);
    for (std::size_t i = 0; i < n; ++i) {
      const float u = u0 + (u1 - u0) * (float(i) / d);
      if (!eval_primvar(*impl, vertex, channel, patch, u, v, out.data() + 6 * (j * n + i)))
        return false;
    }
  }
  return true;
}

namespace {

// Refines face-varying channel `c` through every level of the (adaptively refined) refiner and
// computes the end caps' local values: the values GetPatchFVarValues indexes.
std::vector<float> refine_fvar_channel(const Far::TopologyRefiner& refiner,
                                       const Far::PatchTable& table, const OsdMeshDesc& d,
                                       std::size_t c, std::size_t first_value) {
  const int total = refiner.GetNumFVarValuesTotal(int(c));
  const int local = table.GetNumLocalPointsFaceVarying(int(c));
  const int base = refiner.GetLevel(0).GetNumFVarValues(int(c));
  if (base != d.fvar_value_counts[c])
    throw std::runtime_error("OpenSubdiv kept " + std::to_string(base) + " of " +
                             std::to_string(d.fvar_value_counts[c]) +
                             " face-varying values of channel " + std::to_string(c));
  std::vector<Value2> buf(std::size_t(total) + std::size_t(std::max(local, 0)));
  for (int i = 0; i < base; ++i) {
    buf[std::size_t(i)].v[0] = d.fvar_values[2 * (first_value + std::size_t(i))];
    buf[std::size_t(i)].v[1] = d.fvar_values[2 * (first_value + std::size_t(i)) + 1];
  }
  Far::PrimvarRefiner primvar(refiner);
  Value2* src = buf.data();
  for (int level = 1; level <= refiner.GetMaxLevel(); ++level) {
    Value2* dst = src + refiner.GetLevel(level - 1).GetNumFVarValues(int(c));
    primvar.InterpolateFaceVarying(level, src, dst, int(c));
    src = dst;
  }
  if (local > 0) table.ComputeLocalPointValuesFaceVarying(buf.data(), buf.data() + total, int(c));
  std::vector<float> out(2 * buf.size());
  for (std::size_t i = 0; i < buf.size(); ++i) {
    out[2 * i] = buf[i].v[0];
    out[2 * i + 1] = buf[i].v[1];
  }
  return out;
}

}  // namespace

std::unique_ptr<OsdMesh> osd_mesh_new(const OsdMeshDesc& desc, rust::Slice<const float> points) {
  try {
    check_desc(desc, points.size());
    FarCapture capture;
    RefinerPtr refiner = create_refiner(desc, capture);
    refine_adaptive(*refiner, desc, capture);

    auto mesh = std::make_unique<OsdMesh>();
    OsdMesh::Impl& m = *mesh->impl;
    const int valence = max_valence(*refiner);
    const bool bilinear = valence > kMaxGregoryValence;
    m.patch_table.reset(Far::PatchTableFactory::Create(*refiner, patch_options_of(desc, bilinear)));
    if (bilinear)
      m.simplified = "a vertex of valence " + std::to_string(valence) +
                     " (an n-gon counts its sides) is above " +
                     std::to_string(kMaxGregoryValence) +
                     ": bilinear end caps for this mesh (near its extraordinary vertices the "
                     "surface is the polygon refined to level " +
                     std::to_string(int(desc.isolation_level)) + ", not the limit)";
    if (!m.patch_table) capture.fail("OpenSubdiv could not build the patch table");
    capture.check("OpenSubdiv patch table");

    // Every refined vertex (all levels: adaptive patches index into all of them), then the end
    // caps' local points.
    m.num_base_points = desc.num_vertices;
    const std::size_t total = std::size_t(refiner->GetNumVerticesTotal()) +
                              std::size_t(std::max(m.patch_table->GetNumLocalPoints(), 0));
    m.control_points.assign(3 * total, 0.0f);
    m.set_points(*refiner, *m.patch_table, points.data());
    capture.check("OpenSubdiv refined points");

    // Vertex primvars go through the same refinement as the points.
    const std::size_t nv = std::size_t(desc.num_vertices);
    for (std::size_t ofs = 0; nv > 0 && ofs < desc.vertex_primvars.size(); ofs += 2 * nv)
      m.vertex_primvars.push_back(
          refine_values<2>(*refiner, m.patch_table.get(), desc.vertex_primvars.data() + ofs));
    if (!desc.fvar_value_counts.empty()) {
      if (m.patch_table->GetNumFVarChannels() != int(desc.fvar_value_counts.size()))
        throw std::runtime_error("OpenSubdiv built " +
                                 std::to_string(m.patch_table->GetNumFVarChannels()) +
                                 " face-varying patch channels for " +
                                 std::to_string(desc.fvar_value_counts.size()));
      std::size_t first_value = 0;
      for (std::size_t c = 0; c < desc.fvar_value_counts.size(); ++c) {
        m.fvar_values.push_back(
            refine_fvar_channel(*refiner, *m.patch_table, desc, c, first_value));
        first_value += std::size_t(desc.fvar_value_counts[c]);
      }
      capture.check("OpenSubdiv face-varying refinement");
    }

    for (int a = 0; a < m.patch_table->GetNumPatchArrays(); ++a) {
      const Far::PatchDescriptor pd = m.patch_table->GetPatchArrayDescriptor(a);
      if (pd.GetNumControlVertices() > kMaxPatchPoints)
        throw std::runtime_error("patch type with more control points than supported");
      m.arrays.push_back({m.num_patches, pd.GetNumControlVertices(), pd.GetType()});
      m.num_patches += std::size_t(m.patch_table->GetNumPatches(a));
    }
    if (m.arrays.empty()) m.arrays.push_back({0, 0, Far::PatchDescriptor::NON_PATCH});
    // Every local point and value is computed: their stencils are not needed again.
    release_local_stencils(*m.patch_table);

    // Ptex face -> base face: a base face owns its ptex ids from GetFaceId(f) up to the next's.
    Far::PtexIndices ptex(*refiner);
    const int nfaces = refiner->GetLevel(0).GetNumFaces();
    m.ptex_to_base.assign(std::size_t(ptex.GetNumFaces()), -1);
    for (int f = 0; f < nfaces; ++f) {
      const int first = ptex.GetFaceId(f);
      const int last = (f + 1 < nfaces) ? ptex.GetFaceId(f + 1) : ptex.GetNumFaces();
      for (int k = first; k < last; ++k) m.ptex_to_base[std::size_t(k)] = f;
    }
    m.warnings = capture.warnings();
    return mesh;
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception while building OpenSubdiv tables");
  }
}

// A point of the reference's own refinement, in double: masks around high-valence vertices have
// many small weights.
struct RefPoint {
  double x[3];
  void Clear(void* = nullptr) { x[0] = x[1] = x[2] = 0.0; }
  void AddWithWeight(const RefPoint& src, float weight) {
    for (int i = 0; i < 3; ++i) x[i] += double(weight) * src.x[i];
  }
};

OsdLimitSamples osd_limit_reference_eval(const OsdMeshDesc& desc, rust::Slice<const float> points,
                                         rust::Slice<const int32_t> ptex_faces,
                                         rust::Slice<const float> u, rust::Slice<const float> v) {
  try {
    check_desc(desc, points.size());
    if (ptex_faces.size() != u.size() || u.size() != v.size())
      throw std::runtime_error("location arrays differ in length");
    FarCapture capture;
    RefinerPtr refiner = create_refiner(desc, capture);
    refine_adaptive(*refiner, desc, capture, false);

    // The patch table Far::LimitStencilTableFactory builds for itself when given none (its
    // options in OpenSubdiv 3.5): Gregory end caps at every valence, no single-crease patches,
    // infinitely sharp patches as the refiner isolated them. Not patch_options_of: the reference
    // shares nothing with OsdMesh but the refiner's construction.
    Far::PatchTableFactory::Options po;
    po.SetEndCapType(Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS);
    po.useInfSharpPatch = refiner->GetAdaptiveOptions().useInfSharpPatch;
    po.generateVaryingTables = false;
    std::unique_ptr<const Far::PatchTable> table(Far::PatchTableFactory::Create(*refiner, po));
    if (!table) capture.fail("OpenSubdiv could not build the reference patch table");
    capture.check("OpenSubdiv reference patch table");

    // The patches' control points as OpenSubdiv's far tutorials make them: every level refined
    // from the one before (Far::PrimvarRefiner), then the end caps' local points from their
    // stencils over the refined points. The factory's limit stencils factorize every point down
    // to the mesh's own instead, merging weights by linear search: O(n^2) per point near a
    // vertex of valence n, 2 min 43 s and 4.9 GB at valence 360 (docs/subdivision-compare.md).
    const std::size_t refined = std::size_t(refiner->GetNumVerticesTotal());
    const std::size_t local = std::size_t(std::max(table->GetNumLocalPoints(), 0));
    const std::size_t nbase = std::size_t(desc.num_vertices);
    std::vector<RefPoint> cv(refined + local);
    for (std::size_t i = 0; i < nbase; ++i)
      for (int a = 0; a < 3; ++a) cv[i].x[a] = points[3 * i + std::size_t(a)];
    Far::PrimvarRefiner primvar(*refiner);
    RefPoint* src = cv.data();
    for (int level = 1; level <= refiner->GetMaxLevel(); ++level) {
      RefPoint* dst = src + refiner->GetLevel(level - 1).GetNumVertices();
      primvar.Interpolate(level, src, dst);
      src = dst;
    }
    if (local > 0) table->ComputeLocalPointValues(cv.data(), cv.data() + refined);
    capture.check("OpenSubdiv reference refinement");

    // Each location's patch by OpenSubdiv's PatchMap and its basis by PatchTable::EvaluateBasis
    // at the ptex face's (u, v): derivatives are per unit of the ptex face's parameters, as the
    // limit stencils' are.
    const Far::PatchMap map(*table);
    const std::size_t n = ptex_faces.size();
    OsdLimitSamples out;
    out.p.reserve(3 * n);
    out.dpdu.reserve(3 * n);
    out.dpdv.reserve(3 * n);
    double w[20], wu[20], wv[20];
    for (std::size_t s = 0; s < n; ++s) {
      const Far::PatchTable::PatchHandle* h = map.FindPatch(ptex_faces[s], u[s], v[s]);
      if (!h)
        throw std::runtime_error("no reference patch at ptex face " + std::to_string(ptex_faces[s]) +
                                 " (" + std::to_string(u[s]) + ", " + std::to_string(v[s]) +
                                 "): a location fell in a hole or outside its face");
      const Far::ConstIndexArray cvs = table->GetPatchVertices(*h);
      if (cvs.size() > 20) throw std::runtime_error("reference patch with more than 20 points");
      table->EvaluateBasis(*h, double(u[s]), double(v[s]), w, wu, wv);
      double acc[3][3] = {};
      for (int k = 0; k < cvs.size(); ++k) {
        const double* c = cv[std::size_t(cvs[k])].x;
        for (int a = 0; a < 3; ++a) {
          acc[0][a] += w[k] * c[a];
          acc[1][a] += wu[k] * c[a];
          acc[2][a] += wv[k] * c[a];
        }
      }
      for (int a = 0; a < 3; ++a) {
        out.p.push_back(float(acc[0][a]));
        out.dpdu.push_back(float(acc[1][a]));
        out.dpdv.push_back(float(acc[2][a]));
      }
    }
    return out;
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception in the reference limit evaluation");
  }
}

OsdLimitSamples osd_limit_reference_fvar_eval(const OsdMeshDesc& desc, std::size_t channel,
                                            rust::Slice<const int32_t> ptex_faces,
                                            rust::Slice<const float> u,
                                            rust::Slice<const float> v) {
  try {
    check_desc(desc, std::size_t(desc.num_vertices) * 3);
    if (channel >= desc.fvar_value_counts.size())
      throw std::runtime_error("no face-varying channel " + std::to_string(channel));
    if (ptex_faces.size() != u.size() || u.size() != v.size())
      throw std::runtime_error("location arrays differ in length");
    FarCapture capture;
    RefinerPtr refiner = create_refiner(desc, capture);
    refine_adaptive(*refiner, desc, capture, false);

    // The patch table Far::LimitStencilTableFactory builds for a face-varying channel when given
    // none (its options in OpenSubdiv 3.5): Gregory end caps, this channel only, smooth
    // face-varying patches where the refiner considered the channels. Evaluated as the vertex
    // reference is (osd_limit_reference_eval): values refined level by level, the end caps'
    // local values from their stencils over those, PatchMap and EvaluateBasisFaceVarying; the
    // factory's stencils would factorize every value down to the mesh's, O(n^2) a value near a
    // vertex of valence n.
    const int fvar_channel = int(channel);
    Far::PatchTableFactory::Options po;
    po.includeBaseLevelIndices = true;
    po.generateVaryingTables = false;
    po.generateFVarTables = true;
    po.includeFVarBaseLevelIndices = true;
    po.numFVarChannels = 1;
    po.fvarChannelIndices = &fvar_channel;
    po.generateFVarLegacyLinearPatches = !refiner->GetAdaptiveOptions().considerFVarChannels;
    po.SetEndCapType(Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS);
    po.useInfSharpPatch = refiner->GetAdaptiveOptions().useInfSharpPatch;
    std::unique_ptr<const Far::PatchTable> table(Far::PatchTableFactory::Create(*refiner, po));
    if (!table) capture.fail("OpenSubdiv could not build the face-varying reference patch table");
    capture.check("OpenSubdiv face-varying reference patch table");

    std::size_t first = 0;
    for (std::size_t c = 0; c < channel; ++c) first += std::size_t(desc.fvar_value_counts[c]);
    const int base = refiner->GetLevel(0).GetNumFVarValues(fvar_channel);
    if (base != desc.fvar_value_counts[channel])
      throw std::runtime_error("OpenSubdiv kept " + std::to_string(base) + " of " +
                               std::to_string(desc.fvar_value_counts[channel]) +
                               " face-varying values");
    const std::size_t refined = std::size_t(refiner->GetNumFVarValuesTotal(fvar_channel));
    const std::size_t local = std::size_t(std::max(table->GetNumLocalPointsFaceVarying(0), 0));
    std::vector<RefPoint> values(refined + local);
    for (int i = 0; i < base; ++i)
      for (int a = 0; a < 2; ++a)
        values[std::size_t(i)].x[a] = desc.fvar_values[2 * (first + std::size_t(i)) + std::size_t(a)];
    Far::PrimvarRefiner primvar(*refiner);
    RefPoint* src = values.data();
    for (int level = 1; level <= refiner->GetMaxLevel(); ++level) {
      RefPoint* dst = src + refiner->GetLevel(level - 1).GetNumFVarValues(fvar_channel);
      primvar.InterpolateFaceVarying(level, src, dst, fvar_channel);
      src = dst;
    }
    if (local > 0)
      table->ComputeLocalPointValuesFaceVarying(values.data(), values.data() + refined, 0);
    capture.check("OpenSubdiv face-varying reference refinement");

    const Far::PatchMap map(*table);
    const std::size_t n = ptex_faces.size();
    OsdLimitSamples out;
    out.p.reserve(3 * n);
    out.dpdu.reserve(3 * n);
    out.dpdv.reserve(3 * n);
    double w[20], wu[20], wv[20];
    for (std::size_t s = 0; s < n; ++s) {
      const Far::PatchTable::PatchHandle* h = map.FindPatch(ptex_faces[s], u[s], v[s]);
      if (!h)
        throw std::runtime_error("no face-varying reference patch at ptex face " +
                                 std::to_string(ptex_faces[s]) + ": a location fell in a hole or "
                                 "outside its face");
      const Far::ConstIndexArray cvs = table->GetPatchFVarValues(*h, 0);
      if (cvs.size() > 20) throw std::runtime_error("face-varying patch with more than 20 values");
      table->EvaluateBasisFaceVarying(*h, double(u[s]), double(v[s]), w, wu, wv, nullptr, nullptr,
                                      nullptr, 0);
      double acc[3][2] = {};
      for (int k = 0; k < cvs.size(); ++k) {
        if (cvs[k] < 0 || std::size_t(cvs[k]) >= values.size())
          throw std::runtime_error("face-varying reference index out of range");
        const double* c = values[std::size_t(cvs[k])].x;
        for (int a = 0; a < 2; ++a) {
          acc[0][a] += w[k] * c[a];
          acc[1][a] += wu[k] * c[a];
          acc[2][a] += wv[k] * c[a];
        }
      }
      // 3 floats per sample, as OsdLimitSamples holds them; the third is 0.
      for (int a = 0; a < 3; ++a) {
        out.p.push_back(a < 2 ? float(acc[0][a]) : 0.0f);
        out.dpdu.push_back(a < 2 ? float(acc[1][a]) : 0.0f);
        out.dpdv.push_back(a < 2 ? float(acc[2][a]) : 0.0f);
      }
    }
    return out;
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception in the face-varying reference evaluation");
  }
}

OsdUniform osd_uniform_refine(const OsdMeshDesc& desc, rust::Slice<const float> points,
                              int32_t level) {
  try {
    check_desc(desc, points.size());
    if (level < 0 || level > 10) throw std::runtime_error("uniform level must be in 0..=10");
    FarCapture capture;
    RefinerPtr refiner = create_refiner(desc, capture);
    Far::TopologyRefiner::UniformOptions uo(level);
    uo.fullTopologyInLastLevel = true;
    refiner->RefineUniform(uo);
    capture.check("OpenSubdiv uniform refinement");

    // The last level's points, refined level by level (see refine_values).
    OsdUniform out;
    const Far::TopologyLevel& last = refiner->GetLevel(level);
    const std::size_t nv = std::size_t(last.GetNumVertices());
    std::vector<float> all = refine_values<3>(*refiner, nullptr, points.data());
    if (all.size() < 3 * nv) capture.fail("OpenSubdiv could not refine the points uniformly");
    out.points.reserve(3 * nv);
    for (std::size_t i = all.size() - 3 * nv; i < all.size(); ++i) out.points.push_back(all[i]);
    for (int f = 0; f < last.GetNumFaces(); ++f) {
      // Holes stay holes in the refined mesh: leave their children out.
      if (last.IsFaceHole(f)) continue;
      Far::ConstIndexArray fv = last.GetFaceVertices(f);
      out.face_vertex_counts.push_back(fv.size());
      for (int k = 0; k < fv.size(); ++k) out.face_vertex_indices.push_back(fv[k]);
    }
    return out;
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception in uniform refinement");
  }
}

}  // namespace mipray_bridge
