// embree_driver: renders a job of benchmarks/embree.py with Intel Embree's own Catmull-Clark
// subdivision geometry (RTC_GEOMETRY_TYPE_SUBDIVISION, Embree 3) and one primary ray per
// pixel, for a side-by-side with subtrace. A benchmark tool, never part of subtrace.
//
//     embree_driver JOB.txt OUT
//     embree_driver --version
//
// JOB.txt (written by embree.py; whitespace-separated, keywords checked):
//     embree-job 1
//     threads T
//     image W H
//     frame ex ey ez  dxx dxy dxz  dyx dyy dyz  px py pz     (subtrace's camera_frame)
//     dicing_rate R
//     objects N
//     then N times:
//     object none|edge-only|edge-and-corner
//     vertices NV      then NV lines "x y z"
//     faces NF         then NF lines "n i0 ... i(n-1)" (0-based)
//     creases NC       then NC lines "a b sharpness"   (OpenSubdiv units; >= 10: infinite)
//     corners NK       then NK lines "v sharpness"
//     holes NH         then NH face indices
//
// Camera: the ray of pixel (row, col) leaves the eye along p00 + col dx + row dy, normalised,
// in doubles and in that order (subtrace.camera.ray_direction), then rounded to floats.
//
// Edge levels: Cycles' dicing rule at dicing rate R (intern/cycles/subd split.cpp,
// DiagSplit::T with its default test_steps = 3, on the limit surface). With w(p) =
// |p - eye| * s the world size of a pixel at p (s = |dx|: Camera::world_to_raster_size of a
// perspective camera) and l(x, y) = |y - x| / w((x + y) / 2):
//     T(p, c, q) = max(1, ceil(2 * max(l(p, c), l(c, q)) / R))
//     level = min(4096, T(P0, P1, P2) + T(P2, P3, P4))
// with P0..P4 the limit points at t = 0, 1/4, 1/2, 3/4, 1 along the edge (rtcInterpolate
// on the committed geometry): Cycles splits every patch once at its middle before it dices,
// so every cage edge is diced as two halves of three test points each; 4096 is Embree's
// largest level and Cycles' (2^12). Each edge is measured once, from one of its faces, so
// both its half-edges get the same level (watertight). The time this takes is levels_s, a
// part of build_s.
//
// OUT.txt gets "key value" lines (device_s, build_s, levels_s, trace_s, hits, edges,
// level_mean, level_max); OUT.mask W*H bytes (1: hit), OUT.depth W*H float32 ray distances
// (inf: miss), rows from the top. Exit 2: a bad job (one line on stderr); 3: an Embree error.

#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <string>
#include <thread>
#include <unordered_map>
#include <vector>

namespace {

struct Object {
  std::string boundary;
  // x y z 0 per vertex: Embree reads a vertex as 4 floats (SSE), and its assertions
  // (Debian's build keeps them) reject a fourth lane that is not finite, as the bytes
  // after the last vertex of a 12-byte stride may be
  std::vector<float> positions;
  std::vector<unsigned> face_sizes, indices, crease_pairs, corner_ids, holes;
  std::vector<float> crease_weights, corner_weights;
};

struct Job {
  int threads = 1, width = 0, height = 0;
  double frame[12] = {};  // eye, dx, dy, p00
  double dicing_rate = 1.0;
  std::vector<Object> objects;
};

[[noreturn]] void fail(const std::string& what, int code = 2) {
  std::fprintf(stderr, "embree_driver: %s\n", what.c_str());
  std::exit(code);
}

class Reader {
 public:
  explicit Reader(const char* path) : in_(path), path_(path) {
    if (!in_) fail(std::string(path) + ": cannot open");
  }
  void expect(const char* word) {
    std::string got;
    if (!(in_ >> got) || got != word)
      fail(path_ + ": expected '" + word + "', found '" + got + "'");
  }
  template <typename T> T next(const char* what) {
    T value;
    if (!(in_ >> value)) fail(path_ + ": cannot read " + what);
    return value;
  }
  std::string word(const char* what) { return next<std::string>(what); }

 private:
  std::ifstream in_;
  std::string path_;
};

float weight(double sharpness) {  // OpenSubdiv: sharpness >= 10 is infinitely sharp
  return sharpness >= 10.0 ? std::numeric_limits<float>::infinity() : float(sharpness);
}

Object read_object(Reader& r) {
  Object o;
  r.expect("object");
  o.boundary = r.word("boundary mode");
  r.expect("vertices");
  for (long n = r.next<long>("vertex count"); n > 0; --n) {
    for (int k = 0; k < 3; ++k) o.positions.push_back(float(r.next<double>("a coordinate")));
    o.positions.push_back(0.0f);
  }
  long nv = long(o.positions.size() / 4);
  r.expect("faces");
  for (long n = r.next<long>("face count"); n > 0; --n) {
    unsigned size = r.next<unsigned>("a face size");
    if (size < 3 || size > 15) fail("a face of " + std::to_string(size) +
                                    " vertices: Embree takes 3 to 15");
    o.face_sizes.push_back(size);
    for (unsigned k = 0; k < size; ++k) {
      long v = r.next<long>("a face index");
      if (v < 0 || v >= nv) fail("face index " + std::to_string(v) + " out of range");
      o.indices.push_back(unsigned(v));
    }
  }
  r.expect("creases");
  for (long n = r.next<long>("crease count"); n > 0; --n) {
    o.crease_pairs.push_back(r.next<unsigned>("a crease vertex"));
    o.crease_pairs.push_back(r.next<unsigned>("a crease vertex"));
    o.crease_weights.push_back(weight(r.next<double>("a crease sharpness")));
  }
  r.expect("corners");
  for (long n = r.next<long>("corner count"); n > 0; --n) {
    o.corner_ids.push_back(r.next<unsigned>("a corner vertex"));
    o.corner_weights.push_back(weight(r.next<double>("a corner sharpness")));
  }
  r.expect("holes");
  for (long n = r.next<long>("hole count"); n > 0; --n)
    o.holes.push_back(r.next<unsigned>("a hole face"));
  return o;
}

Job read_job(const char* path) {
  Reader r(path);
  Job job;
  r.expect("embree-job");
  if (r.next<int>("the job version") != 1) fail(std::string(path) + ": unknown version");
  r.expect("threads");
  job.threads = r.next<int>("threads");
  r.expect("image");
  job.width = r.next<int>("width");
  job.height = r.next<int>("height");
  if (job.threads < 1 || job.width < 1 || job.height < 1) fail("bad threads or image size");
  r.expect("frame");
  for (double& v : job.frame) v = r.next<double>("the camera frame");
  r.expect("dicing_rate");
  job.dicing_rate = r.next<double>("the dicing rate");
  r.expect("objects");
  for (int n = r.next<int>("object count"); n > 0; --n) job.objects.push_back(read_object(r));
  return job;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// ------------------------------------------------------------------------------ levels
struct Vec { double x, y, z; };
double dist(Vec a, Vec b) { return std::sqrt((a.x - b.x) * (a.x - b.x) +
                                             (a.y - b.y) * (a.y - b.y) +
                                             (a.z - b.z) * (a.z - b.z)); }

struct LevelRule {
  Vec eye;
  double pixel;  // s: the side of a pixel at unit distance
  double rate;
  double pixels(Vec a, Vec b) const {
    Vec m{(a.x + b.x) * 0.5, (a.y + b.y) * 0.5, (a.z + b.z) * 0.5};
    return dist(a, b) / (dist(eye, m) * pixel);
  }
  double T(Vec p, Vec c, Vec q) const {  // Cycles' DiagSplit::T, test_steps = 3
    return std::max(1.0, std::ceil(2.0 * std::max(pixels(p, c), pixels(c, q)) / rate));
  }
  float level(const Vec p[5]) const {
    return float(std::min(4096.0, T(p[0], p[1], p[2]) + T(p[2], p[3], p[4])));
  }
};

// The limit points at t = 0, 1/4, 1/2, 3/4, 1 along edge k (vertex k to k + 1) of face f of
// n vertices, in Embree's parametrisation: a quad's own (u, v); for other faces the sub-quad
// at each corner (u, v encode its number and local coordinates; corner (0, 0), the next
// edge's middle at (1, 0), the previous edge's at (0, 1)), so the edge's first half is
// sub-quad k's local (2t, 0) and its second half sub-quad k + 1's local (0, 2 - 2t).
void edge_points(RTCGeometry g, unsigned f, unsigned n, unsigned k, Vec out[5]) {
  for (int j = 0; j < 5; ++j) {
    float t = 0.25f * j, u, v;
    if (n == 4) {
      const float uq[4] = {t, 1.0f, 1.0f - t, 0.0f}, vq[4] = {0.0f, t, 1.0f, 1.0f - t};
      u = uq[k], v = vq[k];
    } else {
      unsigned sub = j <= 2 ? k : (k + 1) % n;
      u = 2.0f * float(sub % 4) + 0.5f + (j <= 2 ? 2.0f * t : 0.0f);
      v = 2.0f * float(sub / 4) + 0.5f + (j <= 2 ? 0.0f : 2.0f - 2.0f * t);
    }
    alignas(16) float p[4];
    rtcInterpolate0(g, f, u, v, RTC_BUFFER_TYPE_VERTEX, 0, p, 3);
    out[j] = {p[0], p[1], p[2]};
  }
}

struct EdgeRef { unsigned face, size, k; };

// Every edge's level once (from the first face that is not a hole), for both its half-edges.
std::vector<float> limit_levels(RTCGeometry g, const Object& o, const LevelRule& rule,
                                int threads) {
  std::vector<char> hole(o.face_sizes.size(), 0);
  for (unsigned f : o.holes) if (f < hole.size()) hole[f] = 1;
  std::unordered_map<uint64_t, unsigned> index;
  std::vector<EdgeRef> edges;
  std::vector<unsigned> half_edge(o.indices.size(), ~0u);
  size_t start = 0;
  for (unsigned f = 0; f < o.face_sizes.size(); start += o.face_sizes[f++]) {
    unsigned n = o.face_sizes[f];
    for (unsigned k = 0; k < n && !hole[f]; ++k) {
      uint64_t a = o.indices[start + k], b = o.indices[start + (k + 1) % n];
      auto [it, fresh] = index.emplace(std::min(a, b) << 32 | std::max(a, b), edges.size());
      if (fresh) edges.push_back({f, n, k});
      half_edge[start + k] = it->second;
    }
  }
  std::vector<float> level(edges.size());
  std::atomic<size_t> next{0};
  auto work = [&] {
    for (size_t i; (i = next.fetch_add(1)) < edges.size();) {
      Vec p[5];
      edge_points(g, edges[i].face, edges[i].size, edges[i].k, p);
      level[i] = rule.level(p);
    }
  };
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t) pool.emplace_back(work);
  for (auto& t : pool) t.join();
  std::vector<float> levels(o.indices.size(), 1.0f);  // hole faces' own edges: 1
  for (size_t i = 0; i < levels.size(); ++i)
    if (half_edge[i] != ~0u) levels[i] = level[half_edge[i]];
  return levels;
}

// ------------------------------------------------------------------------------- scene
template <typename T>
void buffer(RTCGeometry g, RTCBufferType type, RTCFormat format, const std::vector<T>& data,
            size_t per_item) {
  size_t count = data.size() / per_item;
  if (count == 0) return;
  void* dst = rtcSetNewGeometryBuffer(g, type, 0, format, sizeof(T) * per_item, count);
  std::copy(data.begin(), data.end(), static_cast<T*>(dst));
}

RTCSubdivisionMode mode(const std::string& boundary) {
  if (boundary == "none") return RTC_SUBDIVISION_MODE_NO_BOUNDARY;
  if (boundary == "edge-and-corner") return RTC_SUBDIVISION_MODE_PIN_CORNERS;
  if (boundary == "edge-only") return RTC_SUBDIVISION_MODE_SMOOTH_BOUNDARY;
  fail("unknown boundary mode " + boundary);
}

void add_object(RTCDevice device, RTCScene scene, const Object& o, const LevelRule& rule,
                int threads, std::vector<float>& all_levels, double& levels_s) {
  RTCGeometry g = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_SUBDIVISION);
  buffer(g, RTC_BUFFER_TYPE_VERTEX, RTC_FORMAT_FLOAT3, o.positions, 4);
  buffer(g, RTC_BUFFER_TYPE_FACE, RTC_FORMAT_UINT, o.face_sizes, 1);
  buffer(g, RTC_BUFFER_TYPE_INDEX, RTC_FORMAT_UINT, o.indices, 1);
  buffer(g, RTC_BUFFER_TYPE_EDGE_CREASE_INDEX, RTC_FORMAT_UINT2, o.crease_pairs, 2);
  buffer(g, RTC_BUFFER_TYPE_EDGE_CREASE_WEIGHT, RTC_FORMAT_FLOAT, o.crease_weights, 1);
  buffer(g, RTC_BUFFER_TYPE_VERTEX_CREASE_INDEX, RTC_FORMAT_UINT, o.corner_ids, 1);
  buffer(g, RTC_BUFFER_TYPE_VERTEX_CREASE_WEIGHT, RTC_FORMAT_FLOAT, o.corner_weights, 1);
  buffer(g, RTC_BUFFER_TYPE_HOLE, RTC_FORMAT_UINT, o.holes, 1);
  rtcSetGeometrySubdivisionMode(g, 0, mode(o.boundary));
  rtcCommitGeometry(g);  // the topology, for rtcInterpolate
  auto t0 = std::chrono::steady_clock::now();
  std::vector<float> levels = limit_levels(g, o, rule, threads);
  levels_s += seconds_since(t0);
  buffer(g, RTC_BUFFER_TYPE_LEVEL, RTC_FORMAT_FLOAT, levels, 1);
  all_levels.insert(all_levels.end(), levels.begin(), levels.end());
  rtcCommitGeometry(g);
  rtcAttachGeometry(scene, g);
  rtcReleaseGeometry(g);
}

// ------------------------------------------------------------------------------- trace
void trace_rows(RTCScene scene, const Job& job, std::atomic<int>& next_row,
                std::vector<uint8_t>& mask, std::vector<float>& depth) {
  const double* f = job.frame;
  RTCIntersectContext context;
  rtcInitIntersectContext(&context);
  for (int row; (row = next_row.fetch_add(1)) < job.height;) {
    for (int col = 0; col < job.width; ++col) {
      double d[3];
      for (int k = 0; k < 3; ++k) d[k] = f[9 + k] + col * f[3 + k] + row * f[6 + k];
      double n = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
      RTCRayHit rh;
      rh.ray.org_x = float(f[0]), rh.ray.org_y = float(f[1]), rh.ray.org_z = float(f[2]);
      rh.ray.dir_x = float(d[0] / n), rh.ray.dir_y = float(d[1] / n);
      rh.ray.dir_z = float(d[2] / n);
      rh.ray.tnear = 0.0f;
      rh.ray.tfar = std::numeric_limits<float>::infinity();
      rh.ray.mask = 0xFFFFFFFFu, rh.ray.time = 0.0f, rh.ray.flags = 0;
      rh.hit.geomID = rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene, &context, &rh);
      size_t i = size_t(row) * job.width + col;
      bool hit = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
      mask[i] = hit ? 1 : 0;
      depth[i] = hit ? rh.ray.tfar : std::numeric_limits<float>::infinity();
    }
  }
}

void on_error(void*, RTCError code, const char* message) {
  fail("Embree error " + std::to_string(int(code)) + ": " + (message ? message : ""), 3);
}

template <typename T> void write_raw(const std::string& path, const std::vector<T>& data) {
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(data.data()), std::streamsize(sizeof(T) * data.size()));
  if (!out) fail(path + ": cannot write");
}

}  // namespace

int main(int argc, char** argv) {
  if (argc == 2 && std::string(argv[1]) == "--version") {
    std::printf("%s\n", RTC_VERSION_STRING);  // the headers' (Debian's -dev matches its library)
    return 0;
  }
  if (argc != 3) fail("usage: embree_driver JOB.txt OUT  (or --version)");
  Job job = read_job(argv[1]);
  std::string out = argv[2];

  auto t0 = std::chrono::steady_clock::now();
  std::string config = "threads=" + std::to_string(job.threads);
  RTCDevice device = rtcNewDevice(config.c_str());
  if (!device) fail("rtcNewDevice failed", 3);
  rtcSetDeviceErrorFunction(device, on_error, nullptr);
  double device_s = seconds_since(t0);

  auto t1 = std::chrono::steady_clock::now();
  const double* f = job.frame;
  LevelRule rule{{f[0], f[1], f[2]}, std::sqrt(f[3] * f[3] + f[4] * f[4] + f[5] * f[5]),
                 job.dicing_rate};
  RTCScene scene = rtcNewScene(device);
  std::vector<float> levels;
  double levels_s = 0.0;
  for (const Object& o : job.objects)
    add_object(device, scene, o, rule, job.threads, levels, levels_s);
  rtcCommitScene(scene);
  double build_s = seconds_since(t1);

  size_t n = size_t(job.width) * job.height;
  std::vector<uint8_t> mask(n);
  std::vector<float> depth(n);
  auto t2 = std::chrono::steady_clock::now();
  std::atomic<int> next_row{0};
  std::vector<std::thread> pool;
  for (int k = 0; k < job.threads; ++k)
    pool.emplace_back(trace_rows, scene, std::cref(job), std::ref(next_row), std::ref(mask),
                      std::ref(depth));
  for (auto& t : pool) t.join();
  double trace_s = seconds_since(t2);

  size_t hits = 0;
  for (uint8_t m : mask) hits += m;
  double level_sum = 0.0, level_max = 0.0;
  for (float l : levels) level_sum += l, level_max = std::max(level_max, double(l));
  write_raw(out + ".mask", mask);
  write_raw(out + ".depth", depth);
  std::ofstream txt(out + ".txt");
  txt.precision(9);
  txt << "device_s " << device_s << "\nbuild_s " << build_s << "\nlevels_s " << levels_s
      << "\ntrace_s " << trace_s
      << "\nhits " << hits << "\nedges " << levels.size() << "\nlevel_mean "
      << (levels.empty() ? 0.0 : level_sum / levels.size()) << "\nlevel_max " << level_max
      << "\n";
  if (!txt) fail(out + ".txt: cannot write");
  rtcReleaseScene(scene);
  rtcReleaseDevice(device);
  return 0;
}
