// The Embree side of `make bench-throughput`: rays/s by ray type on the geometry and rays
// mipray traces, so that every speed claim of mipray's has a peer in its table.
//
//   embree_throughput SCENE.bin [--width 512] [--height 512] [--ao-samples 64]
//       [--ao-distance inf] [--edge-level 16] [--threads 2] [--runs 5] [--image ao.pgm]
//       [--depth depth.pfm]
//
// SCENE.bin is written by `python -m mipray.tools.throughput` (mipray/tools/throughput_scenes.py,
// export_stage: the layout is in its docstring): world-space Catmull-Clark control meshes with
// their creases, corners, vertex st and displacement texture, the camera and the sun.
//
// Geometry: RTC_GEOMETRY_TYPE_SUBDIVISION at a fixed edge level (16: mipray's finest rate is
// 16 quads per subpatch side, so this is the like-for-like accuracy), boundaries pinned at
// corners (USD's edgeAndCorner); `none` meshes as quads or triangles. A displaced mesh gets a
// displacement callback that reads the same texture through OpenImageIO as mipray does: at the
// vertex's st (interpolated by Embree from the exported vertex st), with filter widths of one
// grid step in st, channel · scale + bias object units along the normal. Embree builds every
// displaced grid at commit time (all resident): that cost is `build_s`, not in the rays/s.
//
// Rays, all single rays (rtcIntersect1 / rtcOccluded1), traced by `--threads` std::threads
// over chunks of 64 pixels or hits (Embree's own TBB threads only build the BVH):
//   camera      one per pixel through its centre (closest hit);
//   ao          per camera hit, `--ao-samples` cosine-distributed occlusion rays up to
//               `--ao-distance` (mipray's aoDistance; infinite by default);
//   shadow      per camera hit facing the sun, one occlusion ray toward it (angle 0);
//   reflection  per camera hit, one closest-hit ray in the mirror direction.
// Each type is timed on its own, `--runs` times; the JSON on stdout has every run's wall and
// process CPU seconds and their medians. `--image` writes the unoccluded AO fraction per pixel (8-bit PGM), `--depth` the
// camera-space depth of each camera hit (PFM, 0 where nothing is hit: mipray's `depth` AOV), to
// check against mipray's images that both trace the same scene. Origins of secondary rays are offset along the geometric normal by 1e-4 of the
// hit's distance scale.

#include <embree3/rtcore.h>
#include <sys/resource.h>

#include <OpenImageIO/texture.h>
#include <OpenImageIO/ustring.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

namespace {

struct V3 {
  float x = 0, y = 0, z = 0;
};
V3 operator+(V3 a, V3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
V3 operator-(V3 a, V3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
V3 operator*(V3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
float dot(V3 a, V3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
V3 normalize(V3 a) { return a * (1.0f / std::sqrt(dot(a, a))); }

struct Displacement {
  std::string texture;
  float scale = 1, bias = 0;
  uint32_t channel = 0, wrap_s = 2, wrap_t = 2;
  OIIO::TextureSystem::TextureHandle* handle = nullptr;
};

struct Mesh {
  std::string path;
  uint32_t scheme = 1;  // 0 none, 1 catmullClark
  std::vector<float> points, crease_weights, corner_weights, st;
  std::vector<int32_t> counts, indices, crease_pairs, corners;
  bool displaced = false;
  Displacement disp;
};

struct Scene {
  V3 eye, forward, right, up, to_sun;
  std::vector<Mesh> meshes;
};

// --- the export file ------------------------------------------------------------------------

class Reader {
 public:
  explicit Reader(const std::string& path) : path_(path) {
    std::ifstream in(path, std::ios::binary);
    if (!in) throw std::runtime_error(path + ": cannot open");
    data_.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  void raw(void* out, size_t n) {
    if (at_ + n > data_.size()) throw std::runtime_error(path_ + ": truncated");
    std::memcpy(out, data_.data() + at_, n);
    at_ += n;
  }
  uint32_t u32() {
    uint32_t v;
    raw(&v, 4);
    return v;
  }
  float f32() {
    float v;
    raw(&v, 4);
    return v;
  }
  V3 v3() {
    V3 v;
    v.x = f32();
    v.y = f32();
    v.z = f32();
    return v;
  }
  template <class T>
  std::vector<T> array() {
    uint32_t n = u32();
    std::vector<T> v(n);
    if (n) raw(v.data(), n * sizeof(T));
    return v;
  }
  std::string str() {
    std::vector<char> c = array<char>();
    return std::string(c.begin(), c.end());
  }

 private:
  std::string path_;
  std::vector<char> data_;
  size_t at_ = 0;
};

Scene load(const std::string& path) {
  Reader r(path);
  char magic[8];
  r.raw(magic, 8);
  if (std::memcmp(magic, "MPRYTHRU", 8) != 0 || r.u32() != 1)
    throw std::runtime_error(path + ": not a version 1 throughput export");
  Scene s;
  s.eye = r.v3();
  s.forward = r.v3();
  s.right = r.v3();
  s.up = r.v3();
  s.to_sun = r.v3();
  uint32_t n = r.u32();
  for (uint32_t i = 0; i < n; ++i) {
    Mesh m;
    m.path = r.str();
    m.scheme = r.u32();
    m.points = r.array<float>();
    m.counts = r.array<int32_t>();
    m.indices = r.array<int32_t>();
    m.crease_pairs = r.array<int32_t>();
    m.crease_weights = r.array<float>();
    m.corners = r.array<int32_t>();
    m.corner_weights = r.array<float>();
    m.st = r.array<float>();
    m.displaced = r.u32() != 0;
    if (m.displaced) {
      m.disp.texture = r.str();
      m.disp.scale = r.f32();
      m.disp.bias = r.f32();
      m.disp.channel = r.u32();
      m.disp.wrap_s = r.u32();
      m.disp.wrap_t = r.u32();
    }
    s.meshes.push_back(std::move(m));
  }
  return s;
}

// --- geometry -------------------------------------------------------------------------------

OIIO::TextureSystem* texture_system() {
  static OIIO::TextureSystem* ts = OIIO::TextureSystem::create(true);
  return ts;
}

OIIO::TextureOpt::Wrap wrap_of(uint32_t code) {
  switch (code) {
    case 0: return OIIO::TextureOpt::WrapBlack;
    case 1: return OIIO::TextureOpt::WrapClamp;
    case 3: return OIIO::TextureOpt::WrapMirror;
    default: return OIIO::TextureOpt::WrapPeriodic;
  }
}

int g_edge_level = 16;

// Embree calls this for batches of grid vertices while it builds (on its TBB threads).
void displace(const RTCDisplacementFunctionNArguments* args) {
  const Displacement& d = *static_cast<const Displacement*>(args->geometryUserPtr);
  OIIO::TextureSystem* ts = texture_system();
  OIIO::TextureSystem::Perthread* thread = ts->get_perthread_info();
  OIIO::TextureOpt opt;
  opt.firstchannel = int(d.channel);
  opt.swrap = wrap_of(d.wrap_s);
  opt.twrap = wrap_of(d.wrap_t);
  // One grid step: the face's parametric [0, 1] is split into g_edge_level quads.
  const float step = 1.0f / float(g_edge_level);
  for (unsigned i = 0; i < args->N; ++i) {
    float st[2], dst_du[2], dst_dv[2];
    RTCInterpolateArguments ia = {};
    ia.geometry = args->geometry;
    ia.primID = args->primID;
    ia.u = args->u[i];
    ia.v = args->v[i];
    ia.bufferType = RTC_BUFFER_TYPE_VERTEX_ATTRIBUTE;
    ia.bufferSlot = 0;
    ia.P = st;
    ia.dPdu = dst_du;
    ia.dPdv = dst_dv;
    ia.valueCount = 2;
    rtcInterpolate(&ia);
    float texel = 0.0f;
    // USD's t runs up the image, OpenImageIO's down from the first scanline (as mipray's
    // bridge flips it).
    if (!ts->texture(d.handle, thread, opt, st[0], 1.0f - st[1], dst_du[0] * step,
                     -dst_du[1] * step, dst_dv[0] * step, -dst_dv[1] * step, 1, &texel))
      texel = 0.0f;
    const float h = texel * d.scale + d.bias;
    V3 n = normalize(V3{args->Ng_x[i], args->Ng_y[i], args->Ng_z[i]});
    args->P_x[i] += n.x * h;
    args->P_y[i] += n.y * h;
    args->P_z[i] += n.z * h;
  }
}

template <class T>
void fill(RTCGeometry g, RTCBufferType type, unsigned slot, RTCFormat format, const T* src,
          size_t count, size_t elem_bytes) {
  void* dst = rtcSetNewGeometryBuffer(g, type, slot, format, elem_bytes, count);
  std::memcpy(dst, src, count * elem_bytes);
}

size_t add_mesh(RTCDevice device, RTCScene scene, Mesh& m) {
  const size_t nverts = m.points.size() / 3;
  RTCGeometry g;
  if (m.scheme == 1) {
    g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_SUBDIVISION);
    fill(g, RTC_BUFFER_TYPE_FACE, 0, RTC_FORMAT_UINT, m.counts.data(), m.counts.size(), 4);
    fill(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT, m.indices.data(), m.indices.size(), 4);
    fill(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m.points.data(), nverts, 12);
    if (!m.crease_weights.empty()) {
      fill(g, RTC_BUFFER_TYPE_EDGE_CREASE_INDEX, 0, RTC_FORMAT_UINT2, m.crease_pairs.data(),
           m.crease_weights.size(), 8);
      fill(g, RTC_BUFFER_TYPE_EDGE_CREASE_WEIGHT, 0, RTC_FORMAT_FLOAT, m.crease_weights.data(),
           m.crease_weights.size(), 4);
    }
    if (!m.corner_weights.empty()) {
      fill(g, RTC_BUFFER_TYPE_VERTEX_CREASE_INDEX, 0, RTC_FORMAT_UINT, m.corners.data(),
           m.corners.size(), 4);
      fill(g, RTC_BUFFER_TYPE_VERTEX_CREASE_WEIGHT, 0, RTC_FORMAT_FLOAT, m.corner_weights.data(),
           m.corner_weights.size(), 4);
    }
    if (!m.st.empty()) {
      // Embree reads attributes with 16-byte loads: st padded to 4 floats, zeros after it.
      std::vector<float> st4(4 * nverts, 0.0f);
      for (size_t i = 0; i < nverts; ++i) {
        st4[4 * i] = m.st[2 * i];
        st4[4 * i + 1] = m.st[2 * i + 1];
      }
      rtcSetGeometryVertexAttributeCount(g, 1);
      fill(g, RTC_BUFFER_TYPE_VERTEX_ATTRIBUTE, 0, RTC_FORMAT_FLOAT4, st4.data(), nverts, 16);
    }
    rtcSetGeometrySubdivisionMode(g, 0, RTC_SUBDIVISION_MODE_PIN_CORNERS);
    rtcSetGeometryTessellationRate(g, float(g_edge_level));
    if (m.displaced) {
      if (m.st.empty()) throw std::runtime_error(m.path + ": displaced but has no vertex st");
      m.disp.handle = texture_system()->get_texture_handle(OIIO::ustring(m.disp.texture));
      if (!m.disp.handle) throw std::runtime_error(m.path + ": cannot open " + m.disp.texture);
      rtcSetGeometryUserData(g, &m.disp);
      rtcSetGeometryDisplacementFunction(g, displace);
    }
  } else {
    const bool quads = std::all_of(m.counts.begin(), m.counts.end(), [](int c) { return c == 4; });
    std::vector<uint32_t> idx;
    if (quads) {
      idx.assign(m.indices.begin(), m.indices.end());
    } else {
      size_t at = 0;
      for (int c : m.counts) {
        for (int k = 1; k + 1 < c; ++k) {
          idx.push_back(uint32_t(m.indices[at]));
          idx.push_back(uint32_t(m.indices[at + k]));
          idx.push_back(uint32_t(m.indices[at + k + 1]));
        }
        at += size_t(c);
      }
    }
    const unsigned per = quads ? 4 : 3;
    g = rtcNewGeometry(device, quads ? RTC_GEOMETRY_TYPE_QUAD : RTC_GEOMETRY_TYPE_TRIANGLE);
    fill(g, RTC_BUFFER_TYPE_INDEX, 0, quads ? RTC_FORMAT_UINT4 : RTC_FORMAT_UINT3, idx.data(),
         idx.size() / per, per * 4);
    fill(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, m.points.data(), nverts, 12);
  }
  rtcCommitGeometry(g);
  rtcAttachGeometry(scene, g);
  rtcReleaseGeometry(g);
  return m.counts.size();
}

// --- tracing --------------------------------------------------------------------------------

struct Hit {
  V3 p, n, d;  // position, unit normal facing the ray, unit ray direction
  float eps;   // origin offset along n
};

// Chunks of 64 items to `threads` workers; fn(begin, end, worker) returns rays traced.
uint64_t parallel_for(size_t n, int threads, const std::function<uint64_t(size_t, size_t, int)>& fn) {
  std::atomic<size_t> next{0};
  std::vector<uint64_t> rays(size_t(threads), 0);
  std::vector<std::thread> pool;
  for (int w = 0; w < threads; ++w) {
    pool.emplace_back([&, w] {
      for (;;) {
        size_t begin = next.fetch_add(64);
        if (begin >= n) break;
        rays[size_t(w)] += fn(begin, std::min(n, begin + 64), w);
      }
    });
  }
  for (auto& t : pool) t.join();
  uint64_t total = 0;
  for (uint64_t r : rays) total += r;
  return total;
}

RTCRay make_ray(V3 o, V3 d, float tfar) {
  RTCRay r = {};
  r.org_x = o.x;
  r.org_y = o.y;
  r.org_z = o.z;
  r.dir_x = d.x;
  r.dir_y = d.y;
  r.dir_z = d.z;
  r.tnear = 0.0f;
  r.tfar = tfar;
  r.mask = 0xFFFFFFFFu;
  return r;
}

bool closest(RTCScene scene, V3 o, V3 d, Hit* out) {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRayHit rh = {};
  rh.ray = make_ray(o, d, std::numeric_limits<float>::infinity());
  rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
  rtcIntersect1(scene, &ctx, &rh);
  if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) return false;
  if (out) {
    V3 p = o + d * rh.ray.tfar;
    V3 n = normalize(V3{rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z});
    if (dot(n, d) > 0) n = n * -1.0f;
    float scale = std::max({std::fabs(p.x), std::fabs(p.y), std::fabs(p.z), rh.ray.tfar, 1.0f});
    *out = Hit{p, n, d, 1e-4f * scale};
  }
  return true;
}

bool occluded(RTCScene scene, V3 o, V3 d, float tfar) {
  RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  RTCRay r = make_ray(o, d, tfar);
  rtcOccluded1(scene, &ctx, &r);
  return r.tfar < 0.0f;  // Embree sets tfar to -inf on a hit
}

// PCG32 (O'Neill), seeded per hit so a run is the same for any thread count.
struct Rng {
  uint64_t state;
  explicit Rng(uint64_t seed) : state(seed * 6364136223846793005ULL + 1442695040888963407ULL) {}
  float next() {
    uint64_t old = state;
    state = old * 6364136223846793005ULL + 1442695040888963407ULL;
    uint32_t x = uint32_t(((old >> 18u) ^ old) >> 27u);
    uint32_t rot = uint32_t(old >> 59u);
    uint32_t v = (x >> rot) | (x << ((32u - rot) & 31u));
    return float(v >> 8) * (1.0f / 16777216.0f);
  }
};

// Cosine-distributed direction about n (Duff et al. 2017's orthonormal basis).
V3 cosine_direction(V3 n, float u1, float u2) {
  float sign = std::copysign(1.0f, n.z);
  float a = -1.0f / (sign + n.z);
  float b = n.x * n.y * a;
  V3 t{1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x};
  V3 bt{b, sign + n.y * n.y * a, -n.y};
  float r = std::sqrt(u1), phi = 6.28318530718f * u2;
  return t * (r * std::cos(phi)) + bt * (r * std::sin(phi)) + n * std::sqrt(std::max(0.0f, 1.0f - u1));
}

struct Timing {
  std::vector<double> seconds, cpu_seconds;
  uint64_t rays = 0;
};

// User + system CPU seconds of the whole process so far (every thread).
double process_cpu_s() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_utime.tv_sec + u.ru_stime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

template <class F>
Timing timed(int runs, F body) {
  Timing t;
  for (int r = 0; r < runs; ++r) {
    auto start = std::chrono::steady_clock::now();
    double cpu = process_cpu_s();
    t.rays = body();
    t.seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count());
    t.cpu_seconds.push_back(process_cpu_s() - cpu);
  }
  return t;
}

void json_timing(const char* name, const Timing& t, bool last) {
  std::printf("    \"%s\": {\"rays\": %llu, \"median_s\": %.6f, \"median_cpu_s\": %.6f, \"seconds\": [",
              name, (unsigned long long)t.rays, median(t.seconds), median(t.cpu_seconds));
  for (size_t i = 0; i < t.seconds.size(); ++i) std::printf("%s%.6f", i ? ", " : "", t.seconds[i]);
  std::printf("], \"cpu_seconds\": [");
  for (size_t i = 0; i < t.cpu_seconds.size(); ++i) std::printf("%s%.6f", i ? ", " : "", t.cpu_seconds[i]);
  std::printf("]}%s\n", last ? "" : ",");
}

[[noreturn]] void usage(const std::string& why) {
  std::fprintf(stderr,
               "embree_throughput: %s\nusage: embree_throughput SCENE.bin [--width N] [--height N] "
               "[--ao-samples N] [--ao-distance D] [--edge-level L] [--threads T] [--runs R] "
               "[--image AO.pgm] [--depth DEPTH.pfm]\n",
               why.c_str());
  std::exit(2);
}

}  // namespace

int main(int argc, char** argv) {
  std::string scene_path, image_path, depth_path;
  int width = 512, height = 512, ao_samples = 64, threads = 2, runs = 5;
  float ao_distance = std::numeric_limits<float>::infinity();
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) usage(a + " needs a value");
      return argv[++i];
    };
    try {
      if (a == "--width") width = std::stoi(value());
      else if (a == "--height") height = std::stoi(value());
      else if (a == "--ao-samples") ao_samples = std::stoi(value());
      else if (a == "--ao-distance") ao_distance = std::stof(value());
      else if (a == "--edge-level") g_edge_level = std::stoi(value());
      else if (a == "--threads") threads = std::stoi(value());
      else if (a == "--runs") runs = std::stoi(value());
      else if (a == "--image") image_path = value();
      else if (a == "--depth") depth_path = value();
      else if (!a.empty() && a[0] == '-') usage("unknown option " + a);
      else scene_path = a;
    } catch (const std::logic_error&) {
      usage(a + ": not a number");
    }
  }
  if (scene_path.empty()) usage("no scene file");
  if (width < 1 || height < 1 || ao_samples < 1 || threads < 1 || runs < 1 || g_edge_level < 1 ||
      !(ao_distance > 0.0f))
    usage("sizes, counts and --ao-distance must be positive");

  try {
    Scene s = load(scene_path);
    const std::string config = "threads=" + std::to_string(threads);
    RTCDevice device = rtcNewDevice(config.c_str());
    if (!device) throw std::runtime_error("rtcNewDevice failed");
    rtcSetDeviceErrorFunction(
        device,
        [](void*, RTCError code, const char* message) {
          std::fprintf(stderr, "embree_throughput: Embree error %d: %s\n", int(code), message ? message : "");
        },
        nullptr);
    RTCScene scene = rtcNewScene(device);
    size_t faces = 0;
    auto build_start = std::chrono::steady_clock::now();
    for (Mesh& m : s.meshes) faces += add_mesh(device, scene, m);
    rtcCommitScene(scene);
    double build_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - build_start).count();

    const size_t pixels = size_t(width) * size_t(height);
    std::vector<Hit> hits_by_pixel(pixels);
    std::vector<uint8_t> hit_mask(pixels, 0);
    Timing camera = timed(runs, [&] {
      return parallel_for(pixels, threads, [&](size_t b, size_t e, int) -> uint64_t {
        for (size_t i = b; i < e; ++i) {
          float x = (2.0f * (float(i % size_t(width)) + 0.5f) / float(width)) - 1.0f;
          float y = 1.0f - (2.0f * (float(i / size_t(width)) + 0.5f) / float(height));
          V3 d = normalize(s.forward + s.right * x + s.up * y);
          hit_mask[i] = closest(scene, s.eye, d, &hits_by_pixel[i]);
        }
        return e - b;
      });
    });
    std::vector<Hit> hits;
    std::vector<size_t> hit_pixel;
    for (size_t i = 0; i < pixels; ++i)
      if (hit_mask[i]) {
        hits.push_back(hits_by_pixel[i]);
        hit_pixel.push_back(i);
      }

    std::vector<float> ao(hits.size(), 0.0f);
    Timing ao_t = timed(runs, [&] {
      return parallel_for(hits.size(), threads, [&](size_t b, size_t e, int) -> uint64_t {
        for (size_t i = b; i < e; ++i) {
          const Hit& h = hits[i];
          Rng rng(hit_pixel[i]);
          V3 o = h.p + h.n * h.eps;
          int open = 0;
          for (int k = 0; k < ao_samples; ++k) {
            float u1 = rng.next(), u2 = rng.next();
            open += !occluded(scene, o, cosine_direction(h.n, u1, u2), ao_distance);
          }
          ao[i] = float(open) / float(ao_samples);
        }
        return (e - b) * uint64_t(ao_samples);
      });
    });
    const V3 sun = normalize(s.to_sun);
    Timing shadow = timed(runs, [&] {
      return parallel_for(hits.size(), threads, [&](size_t b, size_t e, int) -> uint64_t {
        uint64_t n = 0;
        for (size_t i = b; i < e; ++i) {
          const Hit& h = hits[i];
          if (dot(h.n, sun) <= 0.0f) continue;  // facing away: no shadow ray, as in mipray
          occluded(scene, h.p + h.n * h.eps, sun, std::numeric_limits<float>::infinity());
          ++n;
        }
        return n;
      });
    });
    Timing reflection = timed(runs, [&] {
      return parallel_for(hits.size(), threads, [&](size_t b, size_t e, int) -> uint64_t {
        for (size_t i = b; i < e; ++i) {
          const Hit& h = hits[i];
          V3 r = h.d - h.n * (2.0f * dot(h.d, h.n));
          closest(scene, h.p + h.n * h.eps, r, nullptr);
        }
        return e - b;
      });
    });

    if (!image_path.empty()) {
      std::vector<uint8_t> img(pixels, 0);
      for (size_t i = 0; i < hits.size(); ++i) img[hit_pixel[i]] = uint8_t(std::lround(255.0f * ao[i]));
      std::ofstream out(image_path, std::ios::binary);
      out << "P5\n" << width << " " << height << "\n255\n";
      out.write(reinterpret_cast<const char*>(img.data()), std::streamsize(img.size()));
      if (!out) throw std::runtime_error(image_path + ": cannot write");
    }
    if (!depth_path.empty()) {
      // PFM: one float channel, rows from the bottom up, little-endian (negative scale).
      std::vector<float> depth(pixels, 0.0f);
      for (size_t i = 0; i < hits.size(); ++i) depth[hit_pixel[i]] = dot(hits[i].p - s.eye, normalize(s.forward));
      std::ofstream out(depth_path, std::ios::binary);
      out << "Pf\n" << width << " " << height << "\n-1.0\n";
      for (int y = height - 1; y >= 0; --y)
        out.write(reinterpret_cast<const char*>(depth.data() + size_t(y) * size_t(width)),
                  std::streamsize(sizeof(float) * size_t(width)));
      if (!out) throw std::runtime_error(depth_path + ": cannot write");
    }
    double ao_mean = 0.0;
    for (float v : ao) ao_mean += v;
    ao_mean = hits.empty() ? 0.0 : ao_mean / double(hits.size());

    std::printf("{\n  \"embree_version\": \"%s\",\n", RTC_VERSION_STRING);
    std::printf("  \"threads\": %d,\n  \"edge_level\": %d,\n  \"runs\": %d,\n", threads, g_edge_level, runs);
    std::printf("  \"control_faces\": %zu,\n  \"meshes\": %zu,\n  \"build_s\": %.6f,\n", faces,
                s.meshes.size(), build_s);
    std::printf("  \"pixels\": %zu,\n  \"hits\": %zu,\n  \"ao_unoccluded_mean\": %.6f,\n", pixels,
                hits.size(), ao_mean);
    std::printf("  \"types\": {\n");
    json_timing("camera", camera, false);
    json_timing("ao", ao_t, false);
    json_timing("shadow", shadow, false);
    json_timing("reflection", reflection, true);
    std::printf("  }\n}\n");
    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "embree_throughput: %s\n", e.what());
    return 1;
  }
  return 0;
}
