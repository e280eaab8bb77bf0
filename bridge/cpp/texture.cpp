// OpenImageIO TextureSystem for mipray: MIP-mapped, filtered lookups through a private tile cache.
// See include/texture.h.

#include "mipray-bridge/include/texture.h"

#include <algorithm>
#include <atomic>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <OpenImageIO/imagebuf.h>
#include <OpenImageIO/imagebufalgo.h>
#include <OpenImageIO/imagecache.h>
#include <OpenImageIO/imageio.h>
#include <OpenImageIO/texture.h>
#include <OpenImageIO/typedesc.h>
#include <OpenImageIO/ustring.h>

#include "mipray-bridge/src/ffi.rs.h"

namespace mipray_bridge {
namespace {

using OIIO::TextureOpt;
using OIIO::TextureSystem;

// Every OiioTexSys gets an id never reused, so a thread's cached Perthread pointer can never be
// taken for one of a later system allocated at the same address.
std::atomic<uint64_t> g_next_id{1};

// This thread's Perthread for the system it used last. The pointer is OpenImageIO's own
// (get_perthread_info(nullptr)), which it frees when the thread or the cache ends; caching it only
// spares the thread-specific-pointer lookup on every texture call.
struct PerthreadCache {
  uint64_t id = 0;
  TextureSystem::Perthread* info = nullptr;
};
thread_local PerthreadCache t_perthread;

std::string one_line(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  std::replace(s.begin(), s.end(), '\n', ' ');
  return s;
}

TextureOpt::Wrap wrap_of(uint8_t code) {
  switch (code) {
    case 1: return TextureOpt::WrapBlack;
    case 2: return TextureOpt::WrapClamp;
    case 3: return TextureOpt::WrapPeriodic;
    case 4: return TextureOpt::WrapMirror;
    default: return TextureOpt::WrapDefault;
  }
}

// ImageCache statistics (imagecache.h, "Read-only attributes") under mipray's stats names, with
// units where they could be mistaken. `type`: 0 int, 1 int64, 2 float.
struct StatName {
  const char* oiio;
  const char* mipray;
  int type;
};
constexpr StatName kCacheStats[] = {
    {"stat:bytes_read", "bytes_read", 1},
    {"stat:tiles_created", "tiles_read", 0},
    {"stat:tiles_current", "tiles_current", 0},
    {"stat:tiles_peak", "tiles_peak", 0},
    {"stat:cache_memory_used", "cache_memory_used_bytes", 1},
    {"stat:open_files_created", "open_files_created", 0},
    {"stat:open_files_current", "open_files_current", 0},
    {"stat:open_files_peak", "open_files_peak", 0},
    {"stat:find_tile_calls", "find_tile_calls", 0},
    {"stat:unique_files", "unique_files", 0},
    {"stat:image_size", "image_size_bytes", 1},
    {"stat:file_size", "file_size_bytes", 1},
    {"stat:fileio_time", "fileio_time_s", 2},
    {"stat:fileopen_time", "fileopen_time_s", 2},
    {"stat:file_locking_time", "file_locking_time_s", 2},
    {"stat:tile_locking_time", "tile_locking_time_s", 2},
    {"stat:find_file_time", "find_file_time_s", 2},
    {"stat:find_tile_time", "find_tile_time_s", 2},
};

// Per-file statistics (texture.h, get_texture_info).
constexpr StatName kFileStats[] = {
    {"stat:tilesread", "tiles_read", 1},
    {"stat:bytesread", "bytes_read", 1},
    {"stat:redundant_tiles", "redundant_tiles", 1},
    {"stat:redundant_bytesread", "redundant_bytes_read", 1},
    {"stat:timesopened", "times_opened", 0},
    {"stat:iotime", "io_time_s", 2},
};

// Reads one statistic as a double, trying the documented type first and then the others (the
// documentation and the implementation have disagreed on int vs int64 across releases).
template <class Get>
bool read_stat(int type, Get get, double& out) {
  const int order[3][3] = {{0, 1, 2}, {1, 0, 2}, {2, 1, 0}};
  for (int t : order[std::clamp(type, 0, 2)]) {
    if (t == 0) {
      int v = 0;
      if (get(OIIO::TypeInt, &v)) {
        out = double(v);
        return true;
      }
    } else if (t == 1) {
      int64_t v = 0;
      if (get(OIIO::TypeInt64, &v)) {
        out = double(v);
        return true;
      }
    } else {
      float v = 0;
      if (get(OIIO::TypeFloat, &v)) {
        out = double(v);
        return true;
      }
    }
  }
  return false;
}

}  // namespace

struct OiioTexSys::Impl {
  OIIO::ImageCache* cache = nullptr;
  TextureSystem* ts = nullptr;
  uint64_t id = 0;
  bool finest = false;
  // The cache's tiling and MIP emulation, for the private caches of channel_levels.
  int autotile = 64;
  bool automip = true;
  // Handle table: written under `open_mutex`, read lock-free. Slots never change once set.
  std::unique_ptr<std::atomic<TextureSystem::TextureHandle*>[]> table;
  uint32_t capacity = 0;
  std::atomic<uint32_t> count{0};
  std::mutex open_mutex;
  // Paths by handle (under `open_mutex`): whole-level reads go through the ImageCache by name.
  std::vector<std::string> paths;

  ~Impl() {
    if (ts) TextureSystem::destroy(ts);
    if (cache) OIIO::ImageCache::destroy(cache);
  }

  TextureSystem::Perthread* perthread() const noexcept {
    if (t_perthread.id != id) {
      t_perthread.info = ts->get_perthread_info(nullptr);
      t_perthread.id = id;
    }
    return t_perthread.info;
  }

  TextureSystem::TextureHandle* get(uint32_t handle) const noexcept {
    if (handle >= count.load(std::memory_order_acquire)) return nullptr;
    return table[handle].load(std::memory_order_acquire);
  }
};

OiioTexSys::OiioTexSys() : impl(new Impl) {}
OiioTexSys::~OiioTexSys() = default;

std::unique_ptr<OiioTexSys> oiio_texsys_new(const OiioTexOptions& o) {
  try {
    if (!(o.max_memory_mb > 0.0f)) throw std::runtime_error("max_memory_mb must be positive");
    if (o.max_textures == 0 || o.max_textures > (1u << 24))
      throw std::runtime_error("max_textures must be within 1..=16777216");
    auto sys = std::make_unique<OiioTexSys>();
    OiioTexSys::Impl& m = *sys->impl;
    m.id = g_next_id.fetch_add(1);
    m.finest = o.finest;
    // A private cache (shared = false), so this system's budget and statistics are its own.
    m.cache = OIIO::ImageCache::create(false);
    if (!m.cache) throw std::runtime_error("OpenImageIO could not create an ImageCache");
    m.cache->attribute("max_memory_MB", o.max_memory_mb);
    m.cache->attribute("max_open_files", std::max(o.max_open_files, 1));
    // Untiled, un-MIP-mapped images still work (tiles and levels emulated), just less well than
    // `maketx` output.
    m.autotile = std::max(o.autotile, 0);
    m.automip = o.automip;
    m.cache->attribute("autotile", m.autotile);
    m.cache->attribute("automip", m.automip ? 1 : 0);
    // Colour and alpha as the file stores them, never premultiplied on read (OpenImageIO's
    // default for PNG and others): UsdUVTexture's rgb and a are independent outputs, as Hydra's
    // image reader (hioOiio, oiio:UnassociatedAlpha) gives them.
    m.cache->attribute("unassociatedalpha", 1);
    m.ts = TextureSystem::create(false, m.cache);
    if (!m.ts) throw std::runtime_error("OpenImageIO could not create a TextureSystem");
    m.capacity = o.max_textures;
    m.table.reset(new std::atomic<TextureSystem::TextureHandle*>[m.capacity]);
    for (uint32_t i = 0; i < m.capacity; ++i) m.table[i].store(nullptr, std::memory_order_relaxed);
    return sys;
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception while creating the texture system");
  }
}

uint32_t OiioTexSys::open(rust::Str path_in) const {
  try {
    Impl& m = *impl;
    const std::string path(path_in.data(), path_in.size());
    std::lock_guard<std::mutex> lock(m.open_mutex);
    const uint32_t n = m.count.load(std::memory_order_relaxed);
    if (n >= m.capacity)
      throw std::runtime_error("too many textures (max_textures = " + std::to_string(m.capacity) +
                               ")");
    TextureSystem::Perthread* pt = m.perthread();
    TextureSystem::TextureHandle* h = m.ts->get_texture_handle(OIIO::ustring(path), pt);
    // Reading the resolution opens the file and its header: a missing or unreadable file fails
    // here, once, rather than on every lookup.
    int res[2] = {0, 0};
    if (!h || !m.ts->good(h) ||
        !m.ts->get_texture_info(h, pt, 0, OIIO::ustring("resolution"),
                                OIIO::TypeDesc(OIIO::TypeDesc::INT, 2), res)) {
      std::string err = one_line(m.ts->geterror());
      throw std::runtime_error(err.empty() ? "cannot be opened as a texture" : err);
    }
    m.table[n].store(h, std::memory_order_release);
    m.paths.push_back(path);
    m.count.store(n + 1, std::memory_order_release);
    return n;
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception while opening the texture");
  }
}

bool OiioTexSys::sample(const OiioLookup& l, rust::Slice<float> out) const noexcept {
  try {
    const Impl& m = *impl;
    TextureSystem::TextureHandle* h = m.get(l.handle);
    if (!h || out.empty() || out.size() > 64) return false;
    TextureOpt opt;
    opt.firstchannel = l.first_channel;
    opt.swrap = wrap_of(l.wrap_s);
    opt.twrap = wrap_of(l.wrap_t);
    opt.fill = l.fill;
    if (m.finest) {
      // The §6.3.3 experiment: the finest level only (the Rust side zeroes the derivatives).
      opt.mipmode = TextureOpt::MipModeNoMIP;
      opt.interpmode = TextureOpt::InterpBilinear;
    }
    // mipray's t runs up the image (USD); OpenImageIO's runs down from the first scanline.
    return m.ts->texture(h, m.perthread(), opt, l.s, 1.0f - l.t, l.dsdx, -l.dtdx, l.dsdy, -l.dtdy,
                         int(out.size()), out.data());
  } catch (...) {
    return false;
  }
}

bool OiioTexSys::resolution(uint32_t handle, rust::Slice<int32_t> out) const noexcept {
  try {
    const Impl& m = *impl;
    TextureSystem::TextureHandle* h = m.get(handle);
    if (!h || out.size() < 2) return false;
    int res[2] = {0, 0};
    if (!m.ts->get_texture_info(h, m.perthread(), 0, OIIO::ustring("resolution"),
                                OIIO::TypeDesc(OIIO::TypeDesc::INT, 2), res))
      return false;
    out[0] = res[0];
    out[1] = res[1];
    return true;
  } catch (...) {
    return false;
  }
}

int32_t OiioTexSys::channels(uint32_t handle) const noexcept {
  try {
    const Impl& m = *impl;
    TextureSystem::TextureHandle* h = m.get(handle);
    int n = 0;
    if (!h || !m.ts->get_texture_info(h, m.perthread(), 0, OIIO::ustring("channels"), OIIO::TypeDesc::INT, &n))
      return 0;
    return n;
  } catch (...) {
    return 0;
  }
}

rust::Vec<float> OiioTexSys::texels(uint32_t handle, uint32_t max_width, uint32_t channels,
                                   rust::Slice<int32_t> dims) const {
  try {
    Impl& m = *impl;
    if (dims.size() < 3) throw std::runtime_error("texels: dims needs 3 entries");
    std::string path;
    {
      std::lock_guard<std::mutex> lock(m.open_mutex);
      if (handle >= m.paths.size()) throw std::runtime_error("unknown texture handle");
      path = m.paths[handle];
    }
    const OIIO::ustring name(path);
    OIIO::ImageSpec spec;
    if (!m.cache->get_imagespec(name, spec, 0, 0)) {
      std::string err = one_line(m.cache->geterror());
      throw std::runtime_error(err.empty() ? "cannot read the image header" : err);
    }
    // Down the MIP levels (real ones, or automip's emulated ones) until narrow enough.
    int level = 0;
    while (spec.width > int(std::max(max_width, 1u))) {
      OIIO::ImageSpec next;
      if (!m.cache->get_imagespec(name, next, 0, level + 1)) {
        (void)m.cache->geterror();
        break;
      }
      spec = next;
      ++level;
    }
    const int nch = std::clamp(int(channels), 1, std::max(spec.nchannels, 1));
    std::vector<float> buf(size_t(spec.width) * size_t(spec.height) * size_t(nch));
    if (!m.cache->get_pixels(name, 0, level, spec.x, spec.x + spec.width, spec.y,
                             spec.y + spec.height, spec.z, spec.z + std::max(spec.depth, 1), 0, nch,
                             OIIO::TypeFloat, buf.data())) {
      std::string err = one_line(m.cache->geterror());
      throw std::runtime_error(err.empty() ? "cannot read the MIP level's pixels" : err);
    }
    rust::Vec<float> out;
    out.reserve(buf.size());
    for (float v : buf) out.push_back(v);
    dims[0] = spec.width;
    dims[1] = spec.height;
    dims[2] = nch;
    return out;
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception while reading texels");
  }
}

namespace {

uint8_t code_of(TextureOpt::Wrap w) {
  switch (w) {
    case TextureOpt::WrapBlack: return 1;
    case TextureOpt::WrapClamp: return 2;
    case TextureOpt::WrapPeriodic: return 3;
    case TextureOpt::WrapMirror: return 4;
    default: return 0;
  }
}

// Destroys a private ImageCache however its user returns.
struct CacheGuard {
  OIIO::ImageCache* cache;
  ~CacheGuard() {
    if (cache) OIIO::ImageCache::destroy(cache);
  }
};

}  // namespace

namespace {

// A private ImageCache for reading a texture's levels once, set up as `m`'s (so automip makes
// the levels the lookups read), and the texture's name and first level's header in it.
struct LevelReader {
  CacheGuard ic;
  OIIO::ustring name;
  OIIO::ImageSpec spec;
};

std::unique_ptr<LevelReader> level_reader(OiioTexSys::Impl& m, uint32_t handle, int32_t channel) {
  std::string path;
  {
    std::lock_guard<std::mutex> lock(m.open_mutex);
    if (handle >= m.paths.size()) throw std::runtime_error("unknown texture handle");
    path = m.paths[handle];
  }
  auto r = std::make_unique<LevelReader>();
  r->ic.cache = OIIO::ImageCache::create(false);
  if (!r->ic.cache) throw std::runtime_error("OpenImageIO could not create an ImageCache");
  r->ic.cache->attribute("max_memory_MB", 256.0f);
  r->ic.cache->attribute("autotile", m.autotile);
  r->ic.cache->attribute("automip", m.automip ? 1 : 0);
  r->ic.cache->attribute("unassociatedalpha", 1);
  r->name = OIIO::ustring(path);
  if (!r->ic.cache->get_imagespec(r->name, r->spec, 0, 0)) {
    std::string err = one_line(r->ic.cache->geterror());
    throw std::runtime_error(err.empty() ? "cannot read the image header" : err);
  }
  const OIIO::ImageSpec& s = r->spec;
  if (s.x != 0 || s.y != 0 || s.full_x != 0 || s.full_y != 0 || s.full_width != s.width ||
      s.full_height != s.height || s.depth > 1)
    throw std::runtime_error("its data window is not its display window, or it is a volume");
  if (channel < 0 || channel >= s.nchannels)
    throw std::runtime_error("it has no channel " + std::to_string(channel));
  return r;
}

// The levels' headers, finest first (automip's beyond the file's own), down to 1×1 at most.
template <class F>
void for_each_level(LevelReader& r, F f) {
  for (int level = 0;; ++level) {
    OIIO::ImageSpec ls = r.spec;
    if (level > 0 && !r.ic.cache->get_imagespec(r.name, ls, 0, level)) {
      (void)r.ic.cache->geterror();
      break;
    }
    f(level, ls);
    if (ls.width <= 1 && ls.height <= 1) break;
  }
}

OIIO::TypeDesc format_of(uint8_t code) {
  switch (code) {
    case 0: return OIIO::TypeDesc::UINT8;
    case 1: return OIIO::TypeDesc::UINT16;
    case 2: return OIIO::TypeDesc::HALF;
    default: return OIIO::TypeDesc::FLOAT;
  }
}

}  // namespace

rust::Vec<OiioLevel> OiioTexSys::level_shapes(uint32_t handle, int32_t channel,
                                              rust::Slice<uint8_t> wrap) const {
  try {
    if (wrap.size() < 2) throw std::runtime_error("level_shapes: wrap needs 2 entries");
    std::unique_ptr<LevelReader> r = level_reader(*impl, handle, channel);
    TextureOpt::Wrap sw = TextureOpt::WrapDefault, tw = TextureOpt::WrapDefault;
    const std::string modes = r->spec.get_string_attribute("wrapmodes");
    if (!modes.empty()) TextureOpt::parse_wrapmodes(modes.c_str(), sw, tw);
    wrap[0] = code_of(sw);
    wrap[1] = code_of(tw);
    uint8_t code = 3;
    switch (OIIO::TypeDesc::BASETYPE(r->spec.format.basetype)) {
      case OIIO::TypeDesc::UINT8: code = 0; break;
      case OIIO::TypeDesc::UINT16: code = 1; break;
      case OIIO::TypeDesc::HALF: code = 2; break;
      default: break;
    }
    rust::Vec<OiioLevel> out;
    for_each_level(*r, [&](int, const OIIO::ImageSpec& ls) {
      out.push_back(OiioLevel{uint32_t(ls.width), uint32_t(ls.height), code});
    });
    return out;
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception while reading MIP level headers");
  }
}

void OiioTexSys::read_levels(uint32_t handle, int32_t channel, uint8_t format,
                             rust::Slice<uint8_t> out) const {
  try {
    std::unique_ptr<LevelReader> r = level_reader(*impl, handle, channel);
    const OIIO::TypeDesc fmt = format_of(format);
    std::size_t at = 0;
    for_each_level(*r, [&](int level, const OIIO::ImageSpec& ls) {
      const std::size_t bytes = std::size_t(ls.width) * std::size_t(ls.height) * fmt.size();
      if (at + bytes > out.size())
        throw std::runtime_error("MIP level " + std::to_string(level) + " does not fit");
      if (!r->ic.cache->get_pixels(r->name, 0, level, ls.x, ls.x + ls.width, ls.y,
                                   ls.y + ls.height, ls.z, ls.z + 1, channel, channel + 1, fmt,
                                   out.data() + at)) {
        std::string err = one_line(r->ic.cache->geterror());
        throw std::runtime_error("MIP level " + std::to_string(level) + ": " +
                                 (err.empty() ? "cannot read its pixels" : err));
      }
      at += bytes;
    });
    if (at != out.size()) throw std::runtime_error("the MIP levels changed while being read");
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception while reading MIP levels");
  }
}

rust::Vec<OiioStat> OiioTexSys::cache_stats() const {
  rust::Vec<OiioStat> out;
  for (const StatName& s : kCacheStats) {
    double v = 0;
    auto get = [&](OIIO::TypeDesc t, void* p) { return impl->cache->getattribute(s.oiio, t, p); };
    if (read_stat(s.type, get, v)) out.push_back(OiioStat{rust::String(s.mipray), v});
  }
  return out;
}

rust::Vec<OiioStat> OiioTexSys::file_stats(uint32_t handle) const {
  rust::Vec<OiioStat> out;
  TextureSystem::TextureHandle* h = impl->get(handle);
  if (!h) return out;
  TextureSystem::Perthread* pt = impl->perthread();
  for (const StatName& s : kFileStats) {
    double v = 0;
    auto get = [&](OIIO::TypeDesc t, void* p) {
      return impl->ts->get_texture_info(h, pt, 0, OIIO::ustring(s.oiio), t, p);
    };
    if (read_stat(s.type, get, v)) out.push_back(OiioStat{rust::String(s.mipray), v});
  }
  return out;
}

rust::String OiioTexSys::report(int32_t level) const {
  return rust::String(impl->ts->getstats(std::clamp(level, 1, 5), true));
}

rust::String OiioTexSys::take_error() const { return rust::String(one_line(impl->ts->geterror())); }

bool oiio_auto_is_srgb(rust::Str path_in) {
  try {
    const std::string path(path_in.data(), path_in.size());
    auto in = OIIO::ImageInput::open(path);
    if (!in) {
      std::string err = one_line(OIIO::geterror());
      throw std::runtime_error(err.empty() ? "cannot read the image header" : err);
    }
    const OIIO::ImageSpec& spec = in->spec();
    // HioOIIO_Image::IsColorSpaceSRGB: the file's own colour-space metadata is not consulted.
    const bool srgb = (spec.nchannels == 3 || spec.nchannels == 4) &&
                      spec.format == OIIO::TypeDesc::UINT8;
    in->close();
    return srgb;
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception while reading the image header");
  }
}

void oiio_make_linear_texture(rust::Str src_in, rust::Str dst_in) {
  try {
    const std::string src(src_in.data(), src_in.size());
    const std::string dst(dst_in.data(), dst_in.size());
    // Read with an ImageInput, not ImageBuf(filename): that would go through OpenImageIO's
    // shared ImageCache, which keeps the file's old header and tiles when the file is edited.
    OIIO::ImageSpec unassociated;
    unassociated.attribute("oiio:UnassociatedAlpha", 1);
    auto in = OIIO::ImageInput::open(src, &unassociated);
    if (!in) {
      std::string err = one_line(OIIO::geterror());
      throw std::runtime_error(err.empty() ? "cannot read the image" : err);
    }
    OIIO::ImageSpec spec = in->spec();
    spec.set_format(OIIO::TypeDesc::FLOAT);
    OIIO::ImageBuf encoded(spec);
    if (!in->read_image(0, 0, 0, spec.nchannels, OIIO::TypeDesc::FLOAT, encoded.localpixels())) {
      std::string err = one_line(in->geterror());
      throw std::runtime_error(err.empty() ? "cannot read the image" : err);
    }
    in->close();
    // Decoded here rather than by make_texture's maketx:incolorspace, which in OpenImageIO 2.4
    // insists on an OCIO config file; colorconvert falls back to the built-in sRGB curve.
    OIIO::ImageBuf linear;
    // Alpha is unassociated (see oiio_texsys_new): the curve applies to colour as it is.
    if (!OIIO::ImageBufAlgo::colorconvert(linear, encoded, "sRGB", "linear", false)) {
      std::string err = one_line(linear.geterror());
      throw std::runtime_error(err.empty() ? "cannot decode from sRGB" : err);
    }
    OIIO::ImageSpec config;
    config.tile_width = 64;
    config.tile_height = 64;
    config.tile_depth = 1;
    // Half keeps the 8-bit source's dark steps (linear 8-bit would band them) at half the
    // bytes of float. OpenEXR, because OpenImageIO's TIFF writer has no half and silently
    // writes float (a 1.6 MB JPEG became a 131 MB copy).
    config.set_format(OIIO::TypeDesc::HALF);
    config.attribute("maketx:fileformatname", "openexr");
    config.attribute("maketx:filtername", "box");
    config.attribute("oiio:UnassociatedAlpha", 1);
    std::ostringstream log;
    if (!OIIO::ImageBufAlgo::make_texture(OIIO::ImageBufAlgo::MakeTxTexture, linear, dst, config,
                                          &log)) {
      std::string err = one_line(OIIO::geterror());
      if (err.empty()) err = one_line(log.str());
      throw std::runtime_error(err.empty() ? "maketx failed" : err);
    }
  } catch (const std::exception&) {
    throw;
  } catch (...) {
    throw std::runtime_error("unknown C++ exception while making the linear texture");
  }
}

}  // namespace mipray_bridge
