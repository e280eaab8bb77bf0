// OpenImageIO TextureSystem side of mipray's bridge: filtered MIP-map lookups behind a private,
// bounded tile cache, for texture displacement and texture shading.
//
// One OiioTexSys owns one ImageCache and one TextureSystem built on it (neither is OpenImageIO's
// process-wide shared one), so two samplers never share tiles or statistics. Lookups are `const`
// and `noexcept` and may run on any number of threads at once: OpenImageIO's TextureSystem is
// thread safe, its per-thread state is fetched once per thread and cached, and the handle table
// is read lock-free. Functions that can fail throw std::runtime_error, which the cxx shim turns
// into a Rust `Err`; nothing else escapes.
#pragma once

#include <cstdint>
#include <memory>

#include "rust/cxx.h"

namespace mipray_bridge {

struct OiioTexOptions;
struct OiioLookup;
struct OiioStat;
struct OiioLevel;

// Opaque to Rust.
class OiioTexSys {
 public:
  OiioTexSys();
  ~OiioTexSys();
  OiioTexSys(const OiioTexSys&) = delete;
  OiioTexSys& operator=(const OiioTexSys&) = delete;

  // Opens the texture and returns its index in the handle table. Throws naming the reason when
  // the file cannot be read or the table is full.
  uint32_t open(rust::Str path) const;
  // One filtered lookup; false (with `out` unspecified) for a bad handle or a failed read.
  bool sample(const OiioLookup& lookup, rust::Slice<float> out) const noexcept;
  // Resolution of the finest level into out[0..2]; false if unknown.
  bool resolution(uint32_t handle, rust::Slice<int32_t> out) const noexcept;
  // Channels the file has; 0 if unknown.
  int32_t channels(uint32_t handle) const noexcept;
  // The whole first MIP level at most `max_width` texels wide (the coarsest there is if none
  // is), up to `channels` channels from channel 0, as floats, scanlines top first; its width,
  // height and channel count into dims[0..3]. Throws naming the reason.
  rust::Vec<float> texels(uint32_t handle, uint32_t max_width, uint32_t channels,
                          rust::Slice<int32_t> dims) const;
  // The MIP levels of a texture with file channel `channel` (the levels automip makes for a
  // file without any), finest first, each with the format it is read in (the file's own: uint8,
  // uint16, half; float for any other); the wrap modes the file names into wrap[0..2] (0 when
  // none). Throws naming the reason.
  rust::Vec<OiioLevel> level_shapes(uint32_t handle, int32_t channel,
                                    rust::Slice<uint8_t> wrap) const;
  // Channel `channel` of every level level_shapes gave, one after another into `out` (its exact
  // size), in `format`: read once through a private ImageCache set up as this one, so neither
  // this system's tiles nor its statistics change. Throws naming the reason.
  void read_levels(uint32_t handle, int32_t channel, uint8_t format,
                   rust::Slice<uint8_t> out) const;
  // The ImageCache's statistics, under mipray's names (see texture.cpp).
  rust::Vec<OiioStat> cache_stats() const;
  // One file's statistics (tiles and bytes read, re-reads, I/O time).
  rust::Vec<OiioStat> file_stats(uint32_t handle) const;
  // OpenImageIO's own statistics report, for logs.
  rust::String report(int32_t level) const;
  // The calling thread's pending OpenImageIO error message (and clears it); empty if none.
  rust::String take_error() const;

  struct Impl;
  std::unique_ptr<Impl> impl;
};

std::unique_ptr<OiioTexSys> oiio_texsys_new(const OiioTexOptions& options);

// Whether UsdUVTexture's sourceColorSpace `auto` reads the file as sRGB: Hydra's Storm rule
// (8-bit integer channels, 3 or 4 of them), so images match usdview. Throws naming the reason
// when the header cannot be read.
bool oiio_auto_is_srgb(rust::Str path);
// Writes `dst`: `src` decoded from sRGB (colour channels; alpha as stored) into a linear,
// half-float, tiled OpenEXR MIP map, as `maketx --colorconvert sRGB linear -d half` would. Throws with
// OpenImageIO's reason. The caller writes to a temporary name and renames.
void oiio_make_linear_texture(rust::Str src, rust::Str dst);

}  // namespace mipray_bridge
