// OpenImageIO side of mipray's bridge: write AOV images with per-channel storage formats and
// metadata, read images back as f32.
//
// Functions that can fail throw std::runtime_error with the path and OpenImageIO's geterror();
// the cxx shim turns that into a Rust `Err`. OpenImageIO's own exceptions are caught and rethrown
// the same way, so nothing else crosses into Rust.
#pragma once

#include <cstdint>
#include <memory>

#include "rust/cxx.h"

namespace mipray_bridge {

struct OiioAttr;
struct OiioAttrText;

rust::String oiio_version();

void oiio_write(rust::Str path, uint32_t width, uint32_t height,
                const rust::Vec<rust::String>& channel_names, rust::Slice<const uint8_t> formats,
                rust::Slice<const float> pixels, const rust::Vec<OiioAttr>& attrs,
                rust::Str software);

// An image opened for reading; opaque to Rust.
class OiioReader {
 public:
  OiioReader();
  ~OiioReader();
  OiioReader(const OiioReader&) = delete;
  OiioReader& operator=(const OiioReader&) = delete;

  uint32_t width() const;
  uint32_t height() const;
  rust::Vec<rust::String> channel_names() const;
  rust::Vec<OiioAttrText> metadata() const;
  void read_pixels(rust::Slice<float> out);

  struct Impl;
  std::unique_ptr<Impl> impl;
};

std::unique_ptr<OiioReader> oiio_open(rust::Str path);

}  // namespace mipray_bridge
