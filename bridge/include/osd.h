// OpenSubdiv (Far) side of mipray's bridge: one mesh's adaptive patch table with Gregory-basis end
// caps, its control points refined from the mesh's points, and evaluation.
//
// Nothing here lets an exception or an OpenSubdiv error escape: functions that can fail throw
// std::runtime_error, which the cxx shim turns into a Rust `Err`; the rest never throw.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "rust/cxx.h"

namespace mipray_bridge {

struct OsdMeshDesc;
struct OsdPatchInfo;
struct OsdUniform;
struct OsdLimitSamples;

// Opaque to Rust. Holds only immutable tables plus the control points, so `const` methods are
// safe to call from many threads at once.
class OsdMesh {
 public:
  OsdMesh();
  ~OsdMesh();
  OsdMesh(const OsdMesh&) = delete;
  OsdMesh& operator=(const OsdMesh&) = delete;

  rust::String warnings() const;
  rust::String simplified() const;
  std::size_t ptex_face_count() const;
  rust::Vec<OsdPatchInfo> patch_infos() const;
  bool patch_bound(std::size_t patch, rust::Slice<float> out) const noexcept;
  bool patch_normal_cone(std::size_t patch, rust::Slice<float> out) const noexcept;
  uint8_t edge_knots(std::size_t patch, rust::Slice<float> out) const noexcept;
  rust::Vec<uint64_t> memory_parts() const;
  bool base_points(rust::Slice<float> out) const noexcept;
  void update_points(const OsdMeshDesc& desc, rust::Slice<const float> points);
  bool evaluate(std::size_t patch, float u, float v, rust::Slice<float> out) const noexcept;
  bool evaluate_grid(std::size_t patch, float u0, float v0, float u1, float v1, std::size_t n,
                     rust::Slice<float> p, rust::Slice<float> du,
                     rust::Slice<float> dv) const noexcept;
  bool evaluate_points(std::size_t patch, rust::Slice<const float> uv,
                       rust::Slice<float> p) const noexcept;
  int64_t find_patch(int32_t ptex_face, float u, float v, rust::Slice<float> local_uv) const noexcept;
  std::size_t fvar_channel_count() const noexcept;
  std::size_t vertex_primvar_count() const noexcept;
  bool evaluate_primvar(bool vertex, std::size_t channel, std::size_t patch, float u, float v,
                        rust::Slice<float> out) const noexcept;
  bool evaluate_primvar_grid(bool vertex, std::size_t channel, std::size_t patch, float u0,
                             float v0, float u1, float v1, std::size_t n,
                             rust::Slice<float> out) const noexcept;

  struct Impl;
  std::unique_ptr<Impl> impl;
};

std::unique_ptr<OsdMesh> osd_mesh_new(const OsdMeshDesc& desc, rust::Slice<const float> points);

OsdLimitSamples osd_limit_reference_eval(const OsdMeshDesc& desc, rust::Slice<const float> points,
                                         rust::Slice<const int32_t> ptex_faces,
                                         rust::Slice<const float> u, rust::Slice<const float> v);

OsdLimitSamples osd_limit_reference_fvar_eval(const OsdMeshDesc& desc, std::size_t channel,
                                            rust::Slice<const int32_t> ptex_faces,
                                            rust::Slice<const float> u,
                                            rust::Slice<const float> v);

OsdUniform osd_uniform_refine(const OsdMeshDesc& desc, rust::Slice<const float> points,
                              int32_t level);

}  // namespace mipray_bridge
