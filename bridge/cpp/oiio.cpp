// OpenImageIO for mipray: AOV images out (EXR, PNG, TIFF, … by extension) with per-channel
// storage formats and metadata, and images back in as f32. See include/oiio.h.

#include "mipray-bridge/include/oiio.h"

#include <algorithm>
#include <cstring>
#include <stdexcept>
#include <string>
#include <vector>

#include <OpenImageIO/imageio.h>
#include <OpenImageIO/typedesc.h>

#include "mipray-bridge/src/ffi.rs.h"

namespace mipray_bridge {
namespace {

std::string to_std(rust::Str s) { return std::string(s.data(), s.size()); }

// `path` is not repeated in the message: the Rust side's ImageError puts it in front.
[[noreturn]] void fail(const std::string& /*path*/, const std::string& what, std::string detail) {
  while (!detail.empty() && (detail.back() == '\n' || detail.back() == ' ')) detail.pop_back();
  std::replace(detail.begin(), detail.end(), '\n', ' ');
  throw std::runtime_error(detail.empty() ? what : what + ": " + detail);
}

OIIO::TypeDesc type_of(uint8_t code) {
  switch (code) {
    case 0: return OIIO::TypeDesc::HALF;
    case 1: return OIIO::TypeDesc::FLOAT;
    case 2: return OIIO::TypeDesc::UINT8;
    default: throw std::runtime_error("unknown channel format code");
  }
}

// Orders storage types by how much they hold: uint8 < half < float.
int width_rank(uint8_t code) { return code == 1 ? 2 : (code == 0 ? 1 : 0); }

// Formats whose writers, as mipray uses them, store 8 bits per channel (PNG could hold 16, but
// its AOVs are display images: 8 bits, as for JPEG).
bool eight_bit_only(const std::string& format_name) {
  static const char* const names[] = {"png", "jpeg", "gif", "bmp", "webp", "ico"};
  return std::any_of(std::begin(names), std::end(names),
                     [&](const char* n) { return format_name == n; });
}

}  // namespace

rust::String oiio_version() {
  const int v = OIIO::openimageio_version();  // e.g. 20407 for 2.4.7
  return rust::String(std::to_string(v / 10000) + "." + std::to_string((v / 100) % 100) + "." +
                      std::to_string(v % 100));
}

void oiio_write(rust::Str path_in, uint32_t width, uint32_t height,
                const rust::Vec<rust::String>& channel_names, rust::Slice<const uint8_t> formats,
                rust::Slice<const float> pixels, const rust::Vec<OiioAttr>& attrs,
                rust::Str software) {
  const std::string path = to_std(path_in);
  try {
    const std::size_t nch = channel_names.size();
    if (nch == 0 || formats.size() != nch)
      fail(path, "cannot write", "one storage format per channel is needed");
    if (width == 0 || height == 0 ||
        pixels.size() != std::size_t(width) * std::size_t(height) * nch)
      fail(path, "cannot write", "pixel count does not match width × height × channels");

    auto out = OIIO::ImageOutput::create(path);
    if (!out) fail(path, "no image writer for this file name", OIIO::geterror());

    OIIO::ImageSpec spec(int(width), int(height), int(nch), OIIO::TypeDesc::FLOAT);
    spec.channelnames.clear();
    for (const auto& n : channel_names) spec.channelnames.push_back(std::string(n));
    spec.alpha_channel = -1;
    spec.z_channel = -1;
    for (std::size_t c = 0; c < nch; ++c) {
      if (spec.channelnames[c] == "A") spec.alpha_channel = int(c);
      if (spec.channelnames[c] == "Z") spec.z_channel = int(c);
    }

    // Storage: per channel where the format can hold it (EXR); otherwise the widest requested,
    // narrowed to 8 bits for formats that are 8-bit here.
    uint8_t widest = formats[0];
    for (uint8_t f : formats)
      if (width_rank(f) > width_rank(widest)) widest = f;
    const bool mixed = std::any_of(formats.begin(), formats.end(),
                                   [&](uint8_t f) { return f != formats[0]; });
    if (mixed && out->supports("channelformats")) {
      spec.set_format(type_of(widest));
      spec.channelformats.clear();
      for (uint8_t f : formats) spec.channelformats.push_back(type_of(f));
    } else if (eight_bit_only(out->format_name())) {
      spec.set_format(OIIO::TypeDesc::UINT8);
    } else {
      spec.set_format(type_of(widest));
    }

    for (const auto& a : attrs) {
      const std::string name(a.name);
      switch (a.kind) {
        case 0: spec.attribute(name, std::string(a.s)); break;
        case 1: spec.attribute(name, int(a.i)); break;
        case 2: spec.attribute(name, float(a.f)); break;
        case 3:
          if (a.m.size() != 16) fail(path, "cannot write", "matrix attribute " + name + " needs 16 values");
          spec.attribute(name, OIIO::TypeMatrix44, a.m.data());
          break;
        default: fail(path, "cannot write", "unknown attribute kind for " + name);
      }
    }
    spec.attribute("Software", to_std(software));

    if (!out->open(path, spec)) fail(path, "cannot open for writing", out->geterror());
    if (!out->write_image(OIIO::TypeDesc::FLOAT, pixels.data())) {
      std::string err = out->geterror();
      out->close();
      fail(path, "cannot write pixels", err);
    }
    if (!out->close()) fail(path, "cannot finish writing", out->geterror());
  } catch (const std::runtime_error&) {
    throw;
  } catch (const std::exception& e) {
    fail(path, "OpenImageIO failed", e.what());
  } catch (...) {
    fail(path, "OpenImageIO failed", "unknown C++ exception");
  }
}

struct OiioReader::Impl {
  std::string path;
  std::unique_ptr<OIIO::ImageInput> in;
  OIIO::ImageSpec spec;
};

OiioReader::OiioReader() : impl(new Impl) {}
OiioReader::~OiioReader() = default;

uint32_t OiioReader::width() const { return uint32_t(std::max(impl->spec.width, 0)); }
uint32_t OiioReader::height() const { return uint32_t(std::max(impl->spec.height, 0)); }

rust::Vec<rust::String> OiioReader::channel_names() const {
  rust::Vec<rust::String> out;
  for (const auto& n : impl->spec.channelnames) out.push_back(rust::String(n));
  return out;
}

rust::Vec<OiioAttrText> OiioReader::metadata() const {
  rust::Vec<OiioAttrText> out;
  for (const auto& p : impl->spec.extra_attribs) {
    OiioAttrText t;
    t.name = rust::String(p.name().string());
    // Strings as they are; numbers and matrices as OpenImageIO formats them (comma separated).
    t.value = rust::String(p.type() == OIIO::TypeDesc::STRING ? std::string(p.get_ustring().string())
                                                              : p.get_string(1024));
    out.push_back(std::move(t));
  }
  return out;
}

void OiioReader::read_pixels(rust::Slice<float> out) {
  const Impl& m = *impl;
  try {
    const std::size_t n =
        std::size_t(m.spec.width) * std::size_t(m.spec.height) * std::size_t(m.spec.nchannels);
    if (out.size() != n) fail(m.path, "cannot read", "output buffer has the wrong size");
    if (!m.in->read_image(0, 0, 0, m.spec.nchannels, OIIO::TypeDesc::FLOAT, out.data()))
      fail(m.path, "cannot read pixels", m.in->geterror());
  } catch (const std::runtime_error&) {
    throw;
  } catch (const std::exception& e) {
    fail(m.path, "OpenImageIO failed", e.what());
  } catch (...) {
    fail(m.path, "OpenImageIO failed", "unknown C++ exception");
  }
}

std::unique_ptr<OiioReader> oiio_open(rust::Str path_in) {
  const std::string path = to_std(path_in);
  try {
    auto r = std::make_unique<OiioReader>();
    r->impl->path = path;
    r->impl->in = OIIO::ImageInput::open(path);
    if (!r->impl->in) fail(path, "cannot open for reading", OIIO::geterror());
    r->impl->spec = r->impl->in->spec();
    if (r->impl->spec.depth > 1) fail(path, "cannot read", "volume images are not supported");
    return r;
  } catch (const std::runtime_error&) {
    throw;
  } catch (const std::exception& e) {
    fail(path, "OpenImageIO failed", e.what());
  } catch (...) {
    fail(path, "OpenImageIO failed", "unknown C++ exception");
  }
}

}  // namespace mipray_bridge
